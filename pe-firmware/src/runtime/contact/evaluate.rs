//! The contact evaluation of a board's step: the tools' capsules at the step's time, each
//! contact node's position once, then [`contact_step`] (the serial solver's sequence) over
//! the board's tables for the nodes it owns; and the entry points of the cost measurement
//! (`pe-board-bench`). The protocol that gathers the positions is the parent module's.

use super::super::marks::cost_mark;
use super::super::storage::ContactStorage;
use super::super::{Fault, FaultKind, Runtime, WireReal};
use super::{Positions, TOOLS_MAX};
use crate::image::ElementRecord;
use crate::physics::contact::{
    contact_step, search_tests, Capsule, ContactError, ContactModel, ContactStats, ContactWork,
    FaceBounds, Stage,
};

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// The contact evaluation of a step that is not a check step (positions, travel check,
    /// tool and pair tests) at the current displacements and step index: the contact forces,
    /// tool forces and statistics that the next step's evaluation computes from the same
    /// state (nothing else changes). For the cost measurement (`pe-board-bench`,
    /// `scripts/board-cost.sh`: what a step's contact costs a board that owns contact
    /// nodes, the compile report's charge per contact node). A board without contact does
    /// nothing.
    pub fn evaluate_contact_again(&mut self) -> Result<(), Fault> {
        if self.header.counts.contact_nodes == 0 {
            return Ok(());
        }
        self.evaluate_contact_at(false)
    }

    /// The contact evaluation of a check step at the current displacements and step index:
    /// the candidate search and the groups kept for this board, then the evaluation of
    /// [`Self::evaluate_contact_again`]. For the cost measurement (`pe-board-bench`: a check
    /// step's search, the compile report's charge per search test); the candidates are
    /// then those of this state. A board without pairs (or without contact) does nothing.
    pub fn check_contact_again(&mut self) -> Result<(), Fault> {
        if self.header.counts.contact_nodes == 0 || !self.has_pairs() {
            return Ok(());
        }
        self.evaluate_contact_at(true)
    }

    /// The node-face tests of this board's candidate search with every position known
    /// ([`search_tests`] of its contact tables; 0 without pairs).
    pub fn contact_search_tests(&self) -> usize {
        let c = self.header.counts;
        if c.pairs == 0 {
            return 0;
        }
        let t = &self.st.contact;
        let model = ContactModel {
            nodes: t.nodes.get(..c.contact_nodes as usize).unwrap_or(&[]),
            faces: t.faces.get(..c.contact_faces as usize).unwrap_or(&[]),
            pairs: self.contact.pairs.get(..c.pairs as usize).unwrap_or(&[]),
            tools: &[],
        };
        search_tests(&model)
    }

    /// Contact forces of the owned nodes at this step (the serial solver's arithmetic, in
    /// its order, restricted to the owned nodes) and this board's share of the tool forces.
    pub(super) fn evaluate_contact(&mut self) -> Result<(), Fault> {
        let check = self.has_pairs() && self.is_check_step();
        self.evaluate_contact_at(check)
    }

    /// [`Self::evaluate_contact`], with the candidate search if `check`: the tools' capsules
    /// at this step's time, each contact node's position once, then the step's contact
    /// evaluation for the owned nodes ([`contact_step`], the serial solver's sequence).
    fn evaluate_contact_at(&mut self, check: bool) -> Result<(), Fault> {
        if !self.contact.owns_nodes {
            self.no_contact_here();
            return Ok(());
        }
        let capsules = self.tool_capsules();
        self.positions_at_step();
        cost_mark(2);
        if let Some(found) = self.contact_step(check, &capsules)? {
            self.port.stats.checks += 1;
            self.port.stats.candidates_max = self.port.stats.candidates_max.max(found as u32);
        }
        Ok(())
    }

    /// A board that owns no contact node: every result of the evaluation is filtered by
    /// `own`, which is false for every node, so they would all be zero (`check` is false
    /// too: only owners of pair nodes hold a slot). The contact forces stay as the load
    /// cleared them: nothing else writes them.
    fn no_contact_here(&mut self) {
        self.contact.tool_force = [[0.0; 3]; TOOLS_MAX];
        self.contact.stats = ContactStats::default();
        // The stage marks all the same, so that every step has the same marks.
        for id in 2..=5 {
            cost_mark(id);
        }
    }

    /// Each contact node's position this step, once (the values `Positions::at` gives), not
    /// once per test that needs it: a candidate face reads four.
    fn positions_at_step(&mut self) {
        let c = self.header.counts;
        let nc = c.contact_nodes as usize;
        let ContactStorage {
            nodes,
            places,
            at_step,
            remote,
            ..
        } = &mut self.st.contact;
        let positions = Positions {
            nodes: &nodes[..nc],
            places: &places[..nc],
            remote: &remote[..nc],
            u: &self.st.u[..c.nodes as usize],
            step: self.step,
        };
        for (k, x) in at_step[..nc].iter_mut().enumerate() {
            *x = positions.at(k);
        }
    }

    /// The step's contact forces, tool forces and statistics for the owned nodes
    /// ([`contact_step`] over this board's tables, its candidates' room and its faces'
    /// bounds), with the cost marks 3 to 5 at its stages; the candidates found if `check`.
    fn contact_step(
        &mut self,
        check: bool,
        capsules: &[Capsule; TOOLS_MAX],
    ) -> Result<Option<usize>, Fault> {
        let c = self.header.counts;
        let nc = c.contact_nodes as usize;
        let fault = |kind| Fault {
            board: self.header.board,
            step: self.step,
            kind,
        };
        let state = &mut self.contact;
        let ContactStorage {
            nodes,
            places,
            faces,
            face_bounds,
            at_check,
            force,
            at_step,
            candidates,
            ..
        } = &mut self.st.contact;
        let model = ContactModel {
            nodes: &nodes[..nc],
            faces: &faces[..c.contact_faces as usize],
            pairs: &state.pairs[..c.pairs as usize],
            tools: &state.tools[..c.tools as usize],
        };
        let at_step = &at_step[..nc];
        let pos = |k: usize| at_step.get(k).copied().flatten();
        let own = |k: usize| places.get(k).is_some_and(|p| p.owned);
        let room = candidates.len();
        // The step's face bounds lend the check's search its boxes (they are computed
        // again after it).
        let nf = model.faces.len().min(face_bounds.len());
        let mut tool_force = [[0.0; 3]; TOOLS_MAX];
        let mut stats = ContactStats::default();
        let mut work = ContactWork {
            at_check: &mut at_check[..nc],
            candidates,
            kept: &mut state.candidates_len,
            faces_used: &mut state.faces_used,
            faces: FaceBounds(&mut face_bounds[..nf]),
            force: &mut force[..nc],
            tool_force: &mut tool_force,
            stats: &mut stats,
        };
        let params = &self.header.contact;
        let capsules = &capsules[..c.tools as usize];
        let mark = |s| {
            cost_mark(match s {
                Stage::Searched => 3,
                Stage::TravelChecked => 4,
                Stage::ToolForces => 5,
            })
        };
        let found = contact_step(&model, params, check, capsules, pos, own, &mut work, mark)
            .map_err(|e| {
                fault(match e {
                    ContactError::Candidates { needed } => FaultKind::ContactCapacity {
                        what: "contact candidates",
                        needed: needed as u32,
                        max: room as u32,
                    },
                    ContactError::Physics(e) => FaultKind::Physics(e),
                })
            })?;
        state.tool_force = tool_force;
        state.stats = stats;
        Ok(found)
    }
}
