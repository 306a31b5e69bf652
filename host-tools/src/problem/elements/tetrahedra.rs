//! The problem's tetrahedra as the host runs them: records in mesh order, their nodal
//! volumes, and the nodal pass's work arrays ([`TetLoop`]); errors name mesh cells.

use std::sync::Mutex;

use pe_firmware::physics::element::tet_pressure::add_nodal_volumes;
use pe_firmware::physics::element::Scratch;
use pe_firmware::physics::{MaterialLaw, PhysicsError, Real, Tet4, TetLoop, TetPressure};

use crate::mesh::as_tetrahedron;
use crate::problem::{CellReference, Problem};

/// The tetrahedra of a problem (none in a hexahedral mesh).
pub struct Tetrahedra<T> {
    pub records: Vec<Tet4<T>>,
    /// Mesh cell of each record.
    pub cells: Vec<u32>,
    pub form: TetPressure,
    /// `V_n = Σ_{e∋n} V_e/4` (m³), one per mesh node (zero off the tetrahedra).
    pub nodal_volume: Vec<T>,
    /// `J_n` and `p_n` of the nodal pass, one per mesh node (empty without tetrahedra).
    scratch: Mutex<(Vec<T>, Vec<T>)>,
}

impl<T: Real> Default for Tetrahedra<T> {
    /// No tetrahedra (a hexahedral mesh).
    fn default() -> Self {
        Tetrahedra {
            records: Vec::new(),
            cells: Vec::new(),
            form: TetPressure::Nodal,
            nodal_volume: Vec::new(),
            scratch: Mutex::new((Vec::new(), Vec::new())),
        }
    }
}

impl<T: Real> Tetrahedra<T> {
    pub fn build(p: &Problem) -> Self {
        let mut records = Vec::new();
        let mut cells = Vec::new();
        for (e, c) in p.mesh.cells.iter().enumerate() {
            if let (Some(t), Some(CellReference::Tet(r))) = (as_tetrahedron(c), p.reference.get(e))
            {
                records.push(r.record(t, p.cell_material[e]));
                cells.push(e as u32);
            }
        }
        let n = if records.is_empty() {
            0
        } else {
            p.mesh.nodes.len()
        };
        let mut nodal_volume = vec![T::ZERO; n];
        add_nodal_volumes(&records, &mut nodal_volume);
        Tetrahedra {
            records,
            cells,
            form: p.solver.tetrahedron,
            nodal_volume,
            scratch: Mutex::new((vec![T::ZERO; n], vec![T::ZERO; n])),
        }
    }

    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Runs `run` on the tetrahedra's loop and its scratch; errors renamed to mesh cells.
    pub(crate) fn with_loop<R>(
        &self,
        laws: &[MaterialLaw<T>],
        run: impl FnOnce(&TetLoop<'_, T>, Scratch<'_, T>) -> Result<R, PhysicsError>,
    ) -> Result<R, PhysicsError> {
        let mut guard = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        let (ratio, pressure) = &mut *guard;
        let tl = TetLoop {
            tets: &self.records,
            first: 0,
            laws,
            form: self.form,
            nodal_volume: &self.nodal_volume,
        };
        run(&tl, Scratch { ratio, pressure }).map_err(|e| self.in_mesh(e))
    }

    /// Adds the tetrahedra's internal forces at `u` into `f`.
    pub fn add_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        if self.is_empty() {
            return Ok(());
        }
        self.with_loop(laws, |tl, s| tl.accumulate(s, u, f))
    }

    /// Stored energy (J) of the tetrahedra at `u` (the nodal form's, with its nodal part).
    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        if self.is_empty() {
            return Ok(0.0);
        }
        self.with_loop(laws, |tl, s| tl.stored_energy(s, u))
    }

    /// Each tetrahedron's energy into `out` (indexed by mesh cell): its own with the plain
    /// form; with the nodal one its isochoric energy and a quarter of its volume times the
    /// volumetric energy at each of its nodes (they sum to [`Self::stored_energy`]).
    pub fn cell_energies(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        out: &mut [f64],
    ) -> Result<(), PhysicsError> {
        if self.is_empty() {
            return Ok(());
        }
        self.with_loop(laws, |tl, s| {
            tl.for_each_energy(s, u, |k, w| {
                if let Some(o) = self.cells.get(k).and_then(|&c| out.get_mut(c as usize)) {
                    *o = w;
                }
            })
        })
    }

    /// An error naming a tetrahedron by its index here, renamed to its mesh cell.
    fn in_mesh(&self, e: PhysicsError) -> PhysicsError {
        super::renamed_to_cells(&self.cells, e)
    }
}
