//! The problem's hexahedra as the physics kernels take them, in scalar type `T`: full
//! integration, or reduced with one kernel per element kind, chosen from the reference
//! geometry ([`kind_of`], the firmware's [`ElementKind::of`]): the cuboid kernel
//! ([`HexCuboid`]) for cells that are axis-aligned rectangular cuboids to round-off, the
//! parallelepiped kernel ([`HexBox`]) for the other parallelepipeds, the general one
//! ([`HexReduced`]) for the rest. The serial solver runs the general elements, then the
//! parallelepipeds, then the cuboids (the image's element tables, [`ElementKind::table`]),
//! each in mesh order: the order a one-board machine runs them in (see `compile::image`),
//! so the two compute the same bits. Tetrahedra ([`Tetrahedra`]) run after every
//! hexahedron, in mesh order, plain or with averaged nodal pressure (`[solver]
//! tetrahedron`); they run on the host only.

use pe_firmware::image::Integration;
use pe_firmware::physics::explicit::{accumulate_internal_forces, stored_energy};
pub use pe_firmware::physics::ElementKind;
use pe_firmware::physics::{
    Connectivity, Element, HexBox, HexCuboid, HexFull, HexReduced, Hourglass, MaterialLaw,
    PhysicsError, Real, ReferenceHex,
};

use crate::problem::Problem;

mod tetrahedra;
pub use tetrahedra::Tetrahedra;

/// A problem's elements: its hexahedra (prisms included) and its tetrahedra.
pub struct Elements<T> {
    pub hexes: Hexahedra<T>,
    pub tets: Tetrahedra<T>,
}

/// Hexahedra of one integration kind.
pub enum Hexahedra<T> {
    Reduced {
        general: Vec<HexReduced<T>>,
        boxes: Vec<HexBox<T>>,
        cuboids: Vec<HexCuboid<T>>,
        /// Mesh cell of each element, the general ones first, then the parallelepipeds,
        /// then the cuboids.
        cells: Vec<u32>,
    },
    Full {
        records: Vec<HexFull<T>>,
        /// Mesh cell of each element.
        cells: Vec<u32>,
    },
}

/// Mesh cell `e` of `p` as a hexahedron (None: a tetrahedron).
pub fn hex_of(p: &Problem, e: usize) -> Option<&ReferenceHex> {
    p.reference.get(e).and_then(|r| r.hex())
}

/// The kind hexahedral mesh cell `e` of `p` takes ([`ElementKind::of`] under the scene's
/// integration); None for a tetrahedron.
pub fn kind_of(p: &Problem, e: usize) -> Option<ElementKind> {
    hex_of(p, e).map(|r| ElementKind::of(r, p.solver.integration))
}

/// The record of kind `E` of hexahedral mesh cell `r` (cell `e` of `p`), its nodes
/// numbered by `nodes`: the one place the problem's cells become hexahedral element records
/// (the serial solver's and every image's).
pub fn record_of<T: Real, E: Element<T>>(
    p: &Problem,
    e: usize,
    r: &ReferenceHex,
    nodes: [u32; 8],
) -> E {
    let material = p.cell_material[e];
    let hourglass = Hourglass::of_law(&p.laws[material as usize], p.solver.hourglass);
    E::from_reference(r, Connectivity { nodes, material }, hourglass)
}

impl<T: Real> Elements<T> {
    pub fn build(p: &Problem) -> Self {
        Elements {
            hexes: Hexahedra::build(p),
            tets: Tetrahedra::build(p),
        }
    }

    /// Elements of both kinds.
    pub fn len(&self) -> usize {
        self.hexes.len() + self.tets.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds the internal forces at `u` into `f`: the hexahedra's, then the tetrahedra's.
    pub fn internal_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        self.hexes.internal_forces(laws, u, f)?;
        self.tets.add_forces(laws, u, f)
    }

    /// Stored energy (J) of every element.
    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        Ok(self.hexes.stored_energy(laws, u)? + self.tets.stored_energy(laws, u)?)
    }

    /// Stored energy of each mesh cell (J), in mesh order.
    pub fn cell_energies(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<Vec<f64>, PhysicsError> {
        let mut out = vec![0.0; self.len()];
        self.hexes.cell_energies(laws, u, &mut out)?;
        self.tets.cell_energies(laws, u, &mut out)?;
        Ok(out)
    }
}

/// An error naming element `k` of a table renamed to its mesh cell `cells[k]` (errors that
/// name no element pass unchanged).
pub(crate) fn renamed_to_cells(cells: &[u32], e: PhysicsError) -> PhysicsError {
    let cell = |k: u32| cells.get(k as usize).copied().unwrap_or(k);
    match e {
        PhysicsError::InvertedElement { element, jacobian } => PhysicsError::InvertedElement {
            element: cell(element),
            jacobian,
        },
        PhysicsError::BadIndex { element } => PhysicsError::BadIndex {
            element: cell(element),
        },
        e => e,
    }
}

impl<T: Real> Hexahedra<T> {
    pub fn build(p: &Problem) -> Self {
        // Each element table's cells, in mesh order.
        let mut cells = [const { Vec::new() }; ElementKind::TABLES];
        for e in 0..p.mesh.cells.len() {
            if let Some(kind) = kind_of(p, e) {
                cells[kind.table()].push(e as u32);
            }
        }
        fn table<T: Real, E: Element<T>>(p: &Problem, cells: &[u32]) -> Vec<E> {
            cells
                .iter()
                .filter_map(|&e| {
                    let e = e as usize;
                    hex_of(p, e).map(|r| record_of(p, e, r, p.mesh.cells[e]))
                })
                .collect()
        }
        match p.solver.integration {
            Integration::Full => Hexahedra::Full {
                records: table(p, &cells[0]),
                cells: cells[0].clone(),
            },
            Integration::Reduced => Hexahedra::Reduced {
                general: table(p, &cells[0]),
                boxes: table(p, &cells[1]),
                cuboids: table(p, &cells[2]),
                cells: cells.concat(),
            },
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Hexahedra::Reduced { cells, .. } => cells.len(),
            Hexahedra::Full { records, .. } => records.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Elements of each kernel ([`Kernel`] order).
    pub fn per_kernel(&self) -> [usize; 3] {
        match self {
            Hexahedra::Reduced {
                general,
                boxes,
                cuboids,
                ..
            } => [general.len(), boxes.len(), cuboids.len()],
            Hexahedra::Full { records, .. } => [records.len(), 0, 0],
        }
    }

    /// An error naming an element in kernel order, renamed to its mesh cell.
    pub(crate) fn in_mesh(&self, e: PhysicsError) -> PhysicsError {
        let (Hexahedra::Reduced { cells, .. } | Hexahedra::Full { cells, .. }) = self;
        renamed_to_cells(cells, e)
    }

    pub fn internal_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        match self {
            Hexahedra::Reduced {
                general,
                boxes,
                cuboids,
                ..
            } => {
                let first_cuboid = (general.len() + boxes.len()) as u32;
                accumulate_internal_forces(general, 0, laws, u, f)
                    .and_then(|()| {
                        accumulate_internal_forces(boxes, general.len() as u32, laws, u, f)
                    })
                    .and_then(|()| accumulate_internal_forces(cuboids, first_cuboid, laws, u, f))
                    .map_err(|e| self.in_mesh(e))
            }
            Hexahedra::Full { records, .. } => {
                accumulate_internal_forces(records, 0, laws, u, f).map_err(|e| self.in_mesh(e))
            }
        }
    }

    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        match self {
            Hexahedra::Reduced {
                general,
                boxes,
                cuboids,
                ..
            } => {
                let shifted = |first: usize| {
                    move |e| match e {
                        PhysicsError::InvertedElement { element, jacobian } => {
                            self.in_mesh(PhysicsError::InvertedElement {
                                element: element + first as u32,
                                jacobian,
                            })
                        }
                        e => e,
                    }
                };
                Ok(stored_energy(general, laws, u).map_err(shifted(0))?
                    + stored_energy(boxes, laws, u).map_err(shifted(general.len()))?
                    + stored_energy(cuboids, laws, u)
                        .map_err(shifted(general.len() + boxes.len()))?)
            }
            Hexahedra::Full { records, .. } => {
                stored_energy(records, laws, u).map_err(|e| self.in_mesh(e))
            }
        }
    }

    /// Stored energy of each hexahedral mesh cell (J) into `out` (indexed by mesh cell):
    /// [`Self::stored_energy`] cell by cell.
    pub fn cell_energies(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        out: &mut [f64],
    ) -> Result<(), PhysicsError> {
        match self {
            Hexahedra::Reduced {
                general,
                boxes,
                cuboids,
                cells,
            } => {
                let per = general
                    .chunks(1)
                    .map(|e| stored_energy(e, laws, u))
                    .chain(boxes.chunks(1).map(|e| stored_energy(e, laws, u)))
                    .chain(cuboids.chunks(1).map(|e| stored_energy(e, laws, u)));
                for (k, w) in per.enumerate() {
                    out[cells[k] as usize] = w.map_err(|e| self.in_mesh(e))?;
                }
            }
            Hexahedra::Full { records, cells } => {
                for (k, e) in records.chunks(1).enumerate() {
                    out[cells[k] as usize] =
                        stored_energy(e, laws, u).map_err(|e| self.in_mesh(e))?;
                }
            }
        }
        Ok(())
    }
}
