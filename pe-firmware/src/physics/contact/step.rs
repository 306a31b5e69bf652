//! A step's contact evaluation: the one sequence the serial solver (`pe solve`) and every
//! board run, so both compute the same bits. At a check step the candidate search
//! ([`build_candidates`], positions kept for the travel check, the groups that give the
//! caller's nodes a force kept, the faces they name marked); at every step the travel
//! check, the tool forces, each named face's state refreshed and the pair forces over the
//! kept candidates. What differs between callers is passed in: which nodes they apply
//! forces to (`own`: a board its owned nodes, the serial solver all), where positions come
//! from, how faces are held ([`FaceStates`]) and the room for candidates.

use super::super::explicit::PhysicsError;
use super::pairs::{evaluate_pairs_with, FaceStates};
use super::search::{build_candidates, keep_applied_groups};
use super::tool::{evaluate_tools, Capsule};
use super::travel::check_travel;
use super::{Candidate, ContactModel, ContactParams, ContactStats, V3};

/// The stages of [`contact_step`], reported as each ends (the board's cost marks).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// The candidate search (on a step that is not a check step, at once).
    Searched,
    /// The travel check.
    TravelChecked,
    /// The tool forces.
    ToolForces,
}

/// Why [`contact_step`] failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactError {
    /// The check's search found `needed` candidates, more than the room for them (nothing
    /// after the search ran: give it more room and run the step again).
    Candidates {
        needed: usize,
    },
    Physics(PhysicsError),
}

impl From<PhysicsError> for ContactError {
    fn from(e: PhysicsError) -> Self {
        ContactError::Physics(e)
    }
}

/// A step's contact state, lent by its owner (a board's storage, the serial solver's
/// vectors): per contact node its position at the last check and its force this step; the
/// candidates (their room; the first `kept` are those kept at the last check); the faces
/// the kept candidates name (bit `f % 32` of word `f / 32`; a face beyond the words counts
/// as named); the faces' states; the force on each tool and the statistics of this step.
pub struct ContactWork<'a, F> {
    pub at_check: &'a mut [V3],
    pub candidates: &'a mut [Candidate],
    pub kept: &'a mut usize,
    pub faces_used: &'a mut [u32],
    pub faces: F,
    pub force: &'a mut [V3],
    pub tool_force: &'a mut [V3],
    pub stats: &'a mut ContactStats,
}

/// The contact forces of a step on the model `m` with the settings `p`, at the positions
/// `pos` (`None`: unknown here) with the tools' capsules at `capsules`, for the contact
/// nodes with `own` (the forces, tool forces and statistics are those of the contacts that
/// give such a node a force); the candidate search first if `check`. Returns the
/// candidates the search found (`None` on other steps). `stage` is called as each stage
/// ends.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn contact_step<F: FaceStates>(
    m: &ContactModel<'_>,
    p: &ContactParams,
    check: bool,
    capsules: &[Capsule],
    pos: impl Fn(usize) -> Option<V3> + Copy,
    own: impl Fn(usize) -> bool + Copy,
    w: &mut ContactWork<'_, F>,
    mut stage: impl FnMut(Stage),
) -> Result<Option<usize>, ContactError> {
    let found = if check {
        Some(search(m, p, pos, own, w)?)
    } else {
        None
    };
    stage(Stage::Searched);
    check_travel(m, pos, w.at_check, own, p.pair_surfaces, p.travel_max_m)?;
    stage(Stage::TravelChecked);
    w.force.fill([0.0; 3]);
    w.tool_force.fill([0.0; 3]);
    *w.stats = ContactStats::default();
    let tol = p.tolerance_m;
    evaluate_tools(m, capsules, pos, own, tol, w.force, w.tool_force, w.stats)?;
    stage(Stage::ToolForces);
    pair_forces(m, tol, pos, own, w)?;
    Ok(found)
}

/// A check's search: the positions kept for the travel check, the candidates found, the
/// groups that give a node with `own` a force kept at the front, the faces they name
/// marked. Returns the candidates found.
#[inline(always)]
fn search<F: FaceStates>(
    m: &ContactModel<'_>,
    p: &ContactParams,
    pos: impl Fn(usize) -> Option<V3> + Copy,
    own: impl Fn(usize) -> bool + Copy,
    w: &mut ContactWork<'_, F>,
) -> Result<usize, ContactError> {
    for (k, x) in w.at_check.iter_mut().enumerate() {
        *x = pos(k).unwrap_or([0.0; 3]);
    }
    let margin = p.candidate_margin_m;
    let n = build_candidates(m, pos, margin, w.faces.search_boxes(), w.candidates)
        .map_err(|needed| ContactError::Candidates { needed })?;
    // (build_candidates wrote n <= candidates.len() of them.)
    let room = w.candidates.len();
    let kept = &mut w.candidates[..n.min(room)];
    *w.kept = keep_applied_groups(m, kept, own)?;
    w.faces_used.fill(0);
    for c in &kept[..(*w.kept).min(kept.len())] {
        let f = c.face as usize;
        if let Some(word) = w.faces_used.get_mut(f / 32) {
            *word |= 1 << (f % 32);
        }
    }
    Ok(n)
}

/// The pair forces over the kept candidates: the state of each face they name refreshed
/// once, then every candidate tested against it (the groups are the check's kept ones, for
/// the same `own`).
#[inline(always)]
fn pair_forces<F: FaceStates>(
    m: &ContactModel<'_>,
    tolerance_m: f64,
    pos: impl Fn(usize) -> Option<V3> + Copy,
    own: impl Fn(usize) -> bool + Copy,
    w: &mut ContactWork<'_, F>,
) -> Result<(), PhysicsError> {
    let cand = &w.candidates[..(*w.kept).min(w.candidates.len())];
    if cand.is_empty() {
        return Ok(());
    }
    let used = &*w.faces_used;
    for f in 0..m.faces.len().min(w.faces.len()) {
        if used
            .get(f / 32)
            .is_none_or(|word| word & (1 << (f % 32)) != 0)
        {
            w.faces.refresh(m, f, &pos)?;
        }
    }
    let faces = &w.faces;
    let face_test = |f, x, depth_max| faces.penetration(m, f, x, depth_max, &pos);
    evaluate_pairs_with(
        m,
        cand,
        &pos,
        own,
        tolerance_m,
        w.force,
        w.stats,
        face_test,
        true,
    )
}
