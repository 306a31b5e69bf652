//! The face links: the force vectors, bytes and frames every link direction sends per
//! step, and the time each needs on the profile's links.

use link_proto::frame::frame_len;
use pe_firmware::image::Precision;
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use crate::compile::plan::{Plan, FACE_NAMES};

/// Force vectors and bytes sent per step on every link direction (board, face), over all
/// rounds (one frame per round).
pub(super) struct LinkTraffic {
    pub(super) vectors: Vec<usize>,
    pub(super) bytes: Vec<usize>,
    pub(super) frames: Vec<usize>,
}

impl LinkTraffic {
    /// The traffic of `plan` with values of `precision`: per link direction, one frame per
    /// round that sends (its length [`frame_len`], three values a vector; no recovery
    /// envelope: the board firmware's links run none, board-sim's link model adds it when
    /// it runs recovery).
    pub(super) fn of(plan: &Plan, precision: Precision) -> LinkTraffic {
        let mut t = LinkTraffic {
            vectors: Vec::new(),
            bytes: Vec::new(),
            frames: Vec::new(),
        };
        for b in &plan.boards {
            for f in 0..6 {
                let sent = b.rounds[f / 2]
                    .iter()
                    .map(|r| r.send[f % 2].len())
                    .filter(|&n| n > 0);
                t.vectors.push(sent.clone().sum());
                t.bytes.push(
                    sent.clone()
                        .map(|n| frame_len(3 * n, precision.wire()))
                        .sum(),
                );
                t.frames.push(sent.count());
            }
        }
        t
    }

    /// Every link direction that sends, with its time per step on `profile`'s links
    /// ([`BoardProfile::link_time_s`]).
    pub(super) fn loads(&self, plan: &Plan, profile: &BoardProfile) -> Vec<LinkLoad> {
        (0..self.bytes.len())
            .filter(|&i| self.frames[i] > 0)
            .map(|i| {
                let (bytes, frames) = (self.bytes[i], self.frames[i]);
                LinkLoad {
                    board: plan.boards[i / 6].coords,
                    face: FACE_NAMES[i % 6].to_string(),
                    bytes_per_step: bytes,
                    frames_per_step: frames,
                    time_per_step_s: profile.link_time_s(bytes, frames),
                }
            })
            .collect()
    }
}

/// One link direction (a board's face) and what it sends per step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LinkLoad {
    pub board: [usize; 3],
    pub face: String,
    pub bytes_per_step: usize,
    pub frames_per_step: usize,
    /// Bytes at the link's rate plus the frames' fixed cost (s,
    /// [`BoardProfile::link_time_s`]).
    pub time_per_step_s: f64,
}
