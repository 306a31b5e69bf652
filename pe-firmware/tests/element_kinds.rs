//! The element-kind registry ([`ElementKind`]) against the record types and the geometry:
//! each kind's record says its kind, every kind has a table of its integration and no two
//! kinds of one integration share one, the one precision x integration dispatch
//! ([`pe_firmware::with_element_types`]) names the image's scalar and general record, and
//! the per-cell choice ([`ElementKind::of`]) follows the cell's shape, judged from its
//! corners here (an axis-aligned box, a sheared parallelepiped, a cell with one corner
//! moved).

use pe_firmware::image::{ElementRecord, ImageReal, Integration, Precision};
use pe_firmware::physics::element::hex::NODE_XI;
use pe_firmware::physics::ReferenceHex;
use pe_firmware::physics::{Element, ElementKind, HexBox, HexCuboid, HexFull, HexReduced};

#[test]
fn every_record_says_its_kind_and_every_kind_has_its_own_table() {
    assert_eq!(
        <HexReduced<f64> as Element<f64>>::KIND,
        ElementKind::HexReduced
    );
    assert_eq!(<HexBox<f32> as Element<f32>>::KIND, ElementKind::HexBox);
    assert_eq!(
        <HexCuboid<f64> as Element<f64>>::KIND,
        ElementKind::HexCuboid
    );
    assert_eq!(<HexFull<f32> as Element<f32>>::KIND, ElementKind::HexFull);
    assert_eq!(ElementKind::ALL.len(), 4);
    for k in ElementKind::ALL {
        assert!(k.table() < ElementKind::TABLES, "{k}: table {}", k.table());
        assert_eq!(
            ElementKind::in_table(k.integration(), k.table()),
            Some(k),
            "{k}"
        );
        for o in ElementKind::ALL {
            if o != k && o.integration() == k.integration() {
                assert_ne!(o.table(), k.table(), "{k} and {o} share a table");
            }
        }
    }
    // Every integration has a general record (table 0); full integration only that one.
    for i in [Integration::Reduced, Integration::Full] {
        assert!(ElementKind::in_table(i, 0).is_some(), "{i}");
    }
    assert_eq!(ElementKind::in_table(Integration::Full, 1), None);
    assert_eq!(ElementKind::in_table(Integration::Full, 2), None);
    assert_eq!(
        ElementKind::in_table(Integration::Reduced, ElementKind::TABLES),
        None
    );
}

/// What the dispatch gives for one setting: the scalar's precision, the record's kind and
/// integration, and the record's size (so the four arms are not one type).
fn dispatched(p: Precision, i: Integration) -> (Precision, ElementKind, Integration, usize) {
    fn of<T: ImageReal, E: ElementRecord<T>>() -> (Precision, ElementKind, Integration, usize) {
        (
            T::PRECISION,
            E::KIND,
            E::INTEGRATION,
            core::mem::size_of::<E>(),
        )
    }
    pe_firmware::with_element_types!(p, i, |T, E| of::<T, E>())
}

#[test]
fn the_dispatch_names_the_scalar_and_the_general_record_of_each_setting() {
    let mut sizes = Vec::new();
    for p in [Precision::F32, Precision::F64] {
        for i in [Integration::Reduced, Integration::Full] {
            let (precision, kind, integration, size) = dispatched(p, i);
            assert_eq!(precision, p);
            assert_eq!(integration, i);
            assert_eq!(Some(kind), ElementKind::in_table(i, 0), "{p:?} {i}");
            sizes.push(size);
        }
    }
    // f32 records are smaller than f64 ones, full ones (8 Gauss points) larger than reduced.
    assert_eq!(sizes.len(), 4);
    let [f32_red, f32_full, f64_red, f64_full] = [sizes[0], sizes[1], sizes[2], sizes[3]];
    assert!(f32_red < f64_red && f32_full < f64_full, "{sizes:?}");
    assert!(f32_red < f32_full && f64_red < f64_full, "{sizes:?}");
}

/// The cube [-1,1]³ mapped by `X = A ξ + c`.
fn mapped(a: [[f64; 3]; 3], c: [f64; 3]) -> [[f64; 3]; 8] {
    core::array::from_fn(|n| {
        core::array::from_fn(|i| c[i] + (0..3).map(|j| a[i][j] * NODE_XI[n][j]).sum::<f64>())
    })
}

#[test]
fn each_cell_takes_the_kind_its_shape_allows() {
    // An axis-aligned box 2 x 1 x 0.5 mm: every edge along an axis.
    let cuboid = mapped(
        [[1e-3, 0.0, 0.0], [0.0, 0.5e-3, 0.0], [0.0, 0.0, 0.25e-3]],
        [0.1, 0.2, 0.3],
    );
    // The same box sheared (x += 0.3 y) and turned: still an affine image of the cube.
    let sheared = mapped(
        [
            [1e-3, 0.15e-3, 0.0],
            [0.0, 0.5e-3, 0.1e-3],
            [0.0, 0.0, 0.25e-3],
        ],
        [0.0; 3],
    );
    // The box with one corner moved by a fifth of its shortest edge: not affine.
    let mut distorted = cuboid;
    distorted[6][2] += 0.1e-3;
    let cases = [
        ("cuboid", cuboid, ElementKind::HexCuboid),
        ("sheared", sheared, ElementKind::HexBox),
        ("distorted", distorted, ElementKind::HexReduced),
    ];
    for (name, x, reduced) in cases {
        let r = ReferenceHex::new(&x).expect("a valid cell");
        assert!(r.volume > 0.0, "{name}");
        assert_eq!(ElementKind::of(&r, Integration::Reduced), reduced, "{name}");
        assert_eq!(
            ElementKind::of(&r, Integration::Full),
            ElementKind::HexFull,
            "{name}"
        );
    }
}
