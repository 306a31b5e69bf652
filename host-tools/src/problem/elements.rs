//! The problem's hexahedra as the physics kernels take them, in scalar type `T`: full
//! integration, or reduced with one kernel per element kind, chosen from the reference
//! geometry: the parallelepiped kernel ([`HexBox`]) for cells that are parallelepipeds to
//! round-off, the general one ([`HexReduced`]) for the others. The serial solver runs the
//! general elements, then the parallelepipeds, each in mesh order: the order a one-board
//! machine runs them in (see `compile::image`), so the two compute the same bits.

use pe_firmware::image::Integration;
use pe_firmware::physics::explicit::{accumulate_internal_forces, stored_energy};
use pe_firmware::physics::{HexBox, HexFull, HexReduced, MaterialLaw, PhysicsError, Real};

use crate::problem::Problem;

/// Elements of one integration kind.
pub enum Elements<T> {
    Reduced {
        general: Vec<HexReduced<T>>,
        boxes: Vec<HexBox<T>>,
        /// Mesh cell of each element, the general ones first, then the parallelepipeds.
        cells: Vec<u32>,
    },
    Full(Vec<HexFull<T>>),
}

/// Whether mesh cell `e` of `p` takes the parallelepiped kernel (reduced integration only).
pub fn is_box(p: &Problem, e: usize) -> bool {
    p.solver.integration == Integration::Reduced && p.reference[e].is_parallelepiped()
}

impl<T: Real> Elements<T> {
    pub fn build(p: &Problem) -> Self {
        let cells = p.mesh.cells.iter().zip(&p.reference).zip(&p.cell_material);
        if p.solver.integration == Integration::Full {
            return Elements::Full(cells.map(|((c, r), m)| r.full(*c, *m)).collect());
        }
        let (mut general, mut boxes) = (Vec::new(), Vec::new());
        let (mut general_cells, mut box_cells) = (Vec::new(), Vec::new());
        for (e, ((c, r), m)) in cells.enumerate() {
            let modulus = p.laws[*m as usize].hourglass_modulus();
            if is_box(p, e) {
                boxes.push(r.parallelepiped(*c, *m, modulus, p.solver.hourglass));
                box_cells.push(e as u32);
            } else {
                general.push(r.reduced(*c, *m, modulus, p.solver.hourglass));
                general_cells.push(e as u32);
            }
        }
        general_cells.extend(box_cells);
        Elements::Reduced {
            general,
            boxes,
            cells: general_cells,
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Elements::Reduced { cells, .. } => cells.len(),
            Elements::Full(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Elements of the parallelepiped kernel.
    pub fn boxes(&self) -> usize {
        match self {
            Elements::Reduced { boxes, .. } => boxes.len(),
            Elements::Full(_) => 0,
        }
    }

    /// An error naming an element in kernel order, renamed to its mesh cell.
    pub(crate) fn in_mesh(&self, e: PhysicsError) -> PhysicsError {
        let Elements::Reduced { cells, .. } = self else {
            return e;
        };
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

    pub fn internal_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        match self {
            Elements::Reduced { general, boxes, .. } => {
                accumulate_internal_forces(general, 0, laws, u, f)
                    .and_then(|()| {
                        accumulate_internal_forces(boxes, general.len() as u32, laws, u, f)
                    })
                    .map_err(|e| self.in_mesh(e))
            }
            Elements::Full(v) => accumulate_internal_forces(v, 0, laws, u, f),
        }
    }

    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        match self {
            Elements::Reduced { general, boxes, .. } => Ok(stored_energy(general, laws, u)
                .map_err(|e| self.in_mesh(e))?
                + stored_energy(boxes, laws, u).map_err(|e| match e {
                    PhysicsError::InvertedElement { element, jacobian } => {
                        self.in_mesh(PhysicsError::InvertedElement {
                            element: element + general.len() as u32,
                            jacobian,
                        })
                    }
                    e => e,
                })?),
            Elements::Full(v) => stored_energy(v, laws, u),
        }
    }

    /// Stored energy of each mesh cell (J), in mesh order: [`Self::stored_energy`] cell by
    /// cell.
    pub fn cell_energies(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<Vec<f64>, PhysicsError> {
        let mut out = vec![0.0; self.len()];
        match self {
            Elements::Reduced {
                general,
                boxes,
                cells,
            } => {
                let per = general
                    .chunks(1)
                    .map(|e| stored_energy(e, laws, u))
                    .chain(boxes.chunks(1).map(|e| stored_energy(e, laws, u)));
                for (k, w) in per.enumerate() {
                    out[cells[k] as usize] = w.map_err(|e| self.in_mesh(e))?;
                }
            }
            Elements::Full(v) => {
                for (k, e) in v.chunks(1).enumerate() {
                    out[k] = stored_energy(e, laws, u)?;
                }
            }
        }
        Ok(out)
    }
}
