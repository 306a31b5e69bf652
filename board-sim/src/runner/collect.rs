//! The collector: what the worker threads report, gathered as the run goes.

use std::collections::BTreeMap;

use link_proto::recovery::FaceRecovery;
use link_proto::recovery::GlobalRecovery;
use pe_firmware::physics::vec3::add;

use crate::check::Observed;
use crate::results::{BoardResult, LinkRecovery};

/// Messages from board threads to the collector.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Report {
    /// Owned nodes' displacements at a step: (global, u).
    Frame {
        step: u64,
        nodes: Vec<(u32, [f64; 3])>,
    },
    Done {
        board: usize,
        result: BoardResult,
        reaction_prescribed: [f64; 3],
        reaction_fixed: [f64; 3],
        kinetic_energy: f64,
    },
    Failed(Observed),
    /// What link recovery cost on a board's faces and global port, at the end.
    Recovery {
        board: usize,
        faces: [FaceRecovery; 6],
        global: Option<GlobalRecovery>,
    },
}

/// What the collector gathers from the board threads.
pub(crate) struct Collected {
    steps: u64,
    n_nodes: usize,
    pub displacements: Vec<[f64; 3]>,
    /// Frames being assembled: step → (nodes received, displacements).
    pending: BTreeMap<u64, (usize, Vec<[f64; 3]>)>,
    pub frames: Vec<(u64, Vec<[f64; 3]>)>,
    pub results: Vec<Option<BoardResult>>,
    /// Per board: prescribed and fixed reactions and kinetic energy, summed in board order
    /// at the end (so a report does not depend on which thread finished first).
    energies: Vec<([f64; 3], [f64; 3], f64)>,
    pub faults: Vec<Observed>,
    pub recovery: Vec<Option<LinkRecovery>>,
}

impl Collected {
    pub fn new(steps: u64, n_nodes: usize, boards: usize) -> Self {
        Collected {
            steps,
            n_nodes,
            displacements: vec![[0.0; 3]; n_nodes],
            pending: Default::default(),
            frames: Vec::new(),
            results: vec![None; boards],
            energies: vec![([0.0; 3], [0.0; 3], 0.0); boards],
            faults: Vec::new(),
            recovery: vec![None; boards],
        }
    }

    pub fn file(&mut self, report: Report) {
        match report {
            Report::Frame { step, nodes } => self.frame(step, nodes),
            Report::Done {
                board,
                result,
                reaction_prescribed,
                reaction_fixed,
                kinetic_energy,
            } => {
                self.energies[board] = (reaction_prescribed, reaction_fixed, kinetic_energy);
                self.results[board] = Some(result);
            }
            Report::Failed(f) => self.faults.push(f),
            Report::Recovery {
                board,
                faces,
                global,
            } => {
                if let Some(r) = self.recovery.get_mut(board) {
                    *r = Some(LinkRecovery { faces, global });
                }
            }
        }
    }

    /// A board's share of the frame of `step`; a frame every node has arrived for is kept
    /// (the last step's as the final displacements).
    fn frame(&mut self, step: u64, nodes: Vec<(u32, [f64; 3])>) {
        let n_nodes = self.n_nodes;
        let e = self
            .pending
            .entry(step)
            .or_insert_with(|| (0, vec![[0.0; 3]; n_nodes]));
        for (g, u) in nodes {
            if let Some(d) = e.1.get_mut(g as usize) {
                *d = u;
                e.0 += 1;
            }
        }
        if e.0 == n_nodes {
            if let Some((_, v)) = self.pending.remove(&step) {
                if step == self.steps {
                    self.displacements = v;
                } else {
                    self.frames.push((step, v));
                }
            }
        }
    }

    /// The prescribed and fixed reactions (N) and the kinetic energy, summed in board order.
    pub fn energies(&self) -> ([f64; 3], [f64; 3], f64) {
        (
            self.energies.iter().fold([0.0; 3], |s, e| add(s, e.0)),
            self.energies.iter().fold([0.0; 3], |s, e| add(s, e.1)),
            self.energies.iter().fold(0.0, |s, e| s + e.2),
        )
    }
}
