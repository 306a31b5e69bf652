//! Which faces a board links, which UART each takes under QEMU, and the Hello frame that
//! checks the cables: against independent constructions.

use link_proto::machine::{across, Machine};
use link_proto::Face;
use pe_firmware::image::{linked_faces, CompilationId};
use pe_firmware::profile::mps2_uarts::{face_uarts, FACE_UARTS, GLOBAL_UART, UART_BASES};
use pe_firmware::runtime::HelloFrame;

fn boards(m: [u8; 3]) -> impl Iterator<Item = [u8; 3]> {
    (0..m[2]).flat_map(move |z| (0..m[1]).flat_map(move |y| (0..m[0]).map(move |x| [x, y, z])))
}

/// A face is linked exactly when link-proto's grid has a neighbour there that lies inside
/// the machine and its axis has exchange rounds; every link is linked from both ends.
#[test]
fn linked_faces_are_the_machine_neighbours_on_axes_with_rounds() {
    let mut checked = 0;
    for m in [
        [1, 1, 1],
        [2, 1, 1],
        [2, 2, 2],
        [3, 2, 1],
        [4, 4, 4],
        [1, 3, 2],
    ] {
        for rounds in [[1, 1, 1], [1, 0, 2], [0, 0, 0]] {
            for b in boards(m) {
                let l = linked_faces(b, m, rounds);
                let machine = Machine::new(m.map(usize::from)).expect("a machine");
                for f in Face::ALL {
                    let inside = machine.neighbour(b.map(usize::from), f).is_some();
                    let axis = f.index() / 2;
                    assert_eq!(
                        l[f.index()],
                        inside && rounds[axis] > 0,
                        "{b:?} of {m:?} {f:?}"
                    );
                    if l[f.index()] {
                        let n = across(b.map(usize::from), f).unwrap().map(|c| c as u8);
                        assert!(linked_faces(n, m, rounds)[f.opposite().index()]);
                        checked += 1;
                    }
                }
            }
        }
    }
    assert!(checked > 500, "only {checked} links checked");
}

/// The QEMU plan gives every linked face its own UART, never the global port's, in face
/// order; it fits every board up to four linked faces and refuses five or six.
#[test]
fn qemu_uarts_serve_up_to_four_faces_and_never_take_the_global_port() {
    assert_eq!(UART_BASES.len(), FACE_UARTS.len() + 1);
    assert!(!FACE_UARTS.contains(&GLOBAL_UART));
    let mut fits = Vec::new();
    for m in [
        [2, 2, 2],
        [3, 2, 2],
        [3, 3, 1],
        [5, 2, 1],
        [3, 3, 2],
        [3, 3, 3],
        [4, 4, 4],
    ] {
        let mut all = true;
        for b in boards(m) {
            let l = linked_faces(b, m, [1, 1, 1]);
            let n = l.iter().filter(|&&x| x).count();
            match face_uarts(l) {
                Ok(u) => {
                    assert!(n <= FACE_UARTS.len());
                    let used: Vec<usize> = u.iter().flatten().copied().collect();
                    assert_eq!(used.len(), n, "{b:?}: every linked face has a UART");
                    assert_eq!(used, FACE_UARTS[..n].to_vec(), "{b:?}: in face order");
                    for f in 0..6 {
                        assert_eq!(u[f].is_some(), l[f]);
                    }
                }
                Err(k) => {
                    assert_eq!(k, n);
                    assert!(n > FACE_UARTS.len());
                    all = false;
                }
            }
        }
        fits.push((m, all));
    }
    assert_eq!(
        fits,
        vec![
            ([2, 2, 2], true),
            ([3, 2, 2], true),
            ([3, 3, 1], true),
            ([5, 2, 1], true),
            ([3, 3, 2], false),
            ([3, 3, 3], false),
            ([4, 4, 4], false)
        ]
    );
}

/// A Hello frame's bytes give back what was written (id, position, machine, face); a
/// face index past 5, a non-zero pad or a wrong length is no Hello.
#[test]
fn hello_frames_round_trip_and_refuse_malformed_bytes() {
    let h = HelloFrame {
        compilation: CompilationId([1, 2, 3, 4, 5, 6, 7, 0xFE]),
        board: [1, 0, 3],
        machine: [2, 1, 4],
        face: Face::NegZ,
    };
    let b = h.to_bytes();
    assert_eq!(b.len(), HelloFrame::LEN);
    assert_eq!(HelloFrame::parse(&b), Some(h));
    for f in Face::ALL {
        let h2 = HelloFrame { face: f, ..h };
        assert_eq!(HelloFrame::parse(&h2.to_bytes()).map(|x| x.face), Some(f));
    }
    let mut bad = b;
    bad[14] = 6;
    assert_eq!(HelloFrame::parse(&bad), None);
    let mut bad = b;
    bad[15] = 1;
    assert_eq!(HelloFrame::parse(&bad), None);
    assert_eq!(HelloFrame::parse(&b[..15]), None);
    assert_eq!(HelloFrame::parse(&[b.as_slice(), &[0]].concat()), None);
}
