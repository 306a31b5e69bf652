//! Penalty contact, shared by the serial solver and the board runtime.
//!
//! Two kinds, both frictionless:
//!
//! - **Rigid tools** (a capsule: the points within `radius_m` of a segment `a–b`) against
//!   the nodes of a declared tissue surface. A node at `x` inside the capsule by depth
//!   `p = r − |x − c(x)|` (`c(x)` the closest point of the axis) gets `f = k p n`,
//!   `n = (x − c)/|x − c|`; the tool takes `−f` (what a haptic device renders).
//! - **Tissue against tissue**, node to surface as in Székely et al.: the nodes of one
//!   surface (slave) against the faces of the other (master), then the roles flipped, each
//!   direction with half the penalty ("flipped and averaged"). A slave node below a master
//!   triangle's plane by `0 < p ≤ depth_max`, with its projection inside the triangle
//!   (or outside an edge by at most [`EDGE_TOLERANCE`], so a node on the rim of two equal
//!   bodies cannot slip between faces), penetrates it; of all the triangles it penetrates,
//!   the shallowest wins (depths within [`DEPTH_TIE_M`] are a tie, won by the lowest face
//!   index), so the answer depends neither on search order nor on round-off. The slave takes
//!   `F = ½ k p n` and the triangle's nodes `−wᵢ F` (barycentric `wᵢ`, `Σ wᵢ = 1`): each
//!   contact's forces sum to zero to round-off.
//!
//! `k` is the slave node's penalty stiffness, `β m / Δt²` (`m` its inertial mass): the
//! contact spring raises `(ω Δt)²` by at most `β`, so the explicit step stays stable.
//!
//! Everything is `f64` (positions `x = X + u`), whatever the element scalar. The search is
//! split: [`search::build_candidates`] every check interval (slave nodes within a margin of
//! a face's bounding box), the pair forces every step over the candidates. As long as no
//! node moves farther than the margin allows between checks (checked every step by
//! [`travel::check_travel`]), the candidates contain every contact, so the result is
//! independent of the search, of the partition and of the board the sum runs on. Forces are
//! applied only to nodes the caller accepts (`own`): a board applies them to the nodes it
//! owns, in the same order as the serial solver, so both get the same bits. A step's
//! sequence is written once, [`contact_step`]: the runtime and the serial solver both call
//! it.
//!
//! Nothing here panics: indices are checked and problems come back as [`PhysicsError`].
//!
//! Rooms: [`tool`] the tool kernel (capsules), [`face`] the node-face kernel, [`search`] a
//! check step's candidate search, [`pairs`] the node-to-surface forces and how faces are
//! held for them, [`travel`] the travel check, [`step`] a step's sequence. Public: what
//! the runtime and the serial solver use.

use serde::{Deserialize, Serialize};

use super::explicit::PhysicsError;

pub mod face;
pub mod pairs;
pub mod search;
pub mod step;
pub mod tool;
pub mod travel;

pub use face::{FaceGeometry, FacePenetration, QuadBounds, DEPTH_TIE_M, EDGE_TOLERANCE};
pub use pairs::{FaceBounds, FaceGeometries, FaceStates};
pub use search::search_tests;
pub use step::{contact_step, ContactError, ContactWork, Stage};
pub use tool::Capsule;

pub type V3 = [f64; 3];

/// Most declared contact surfaces (bits of [`ContactNode::surfaces`]).
pub const SURFACES_MAX: usize = 8;

/// A node of a contact surface (the table is the same on every board).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactNode {
    /// Index of the node in the scene's mesh.
    pub global: u32,
    /// Initial position (m).
    pub reference: V3,
    /// Penalty stiffness `β m_inertial / Δt²` when this node is the slave (N/m).
    pub penalty_n_per_m: f64,
    /// Bit `s` set: the node belongs to surface `s`.
    pub surfaces: u8,
}

/// A face of a contact surface: four contact-node indices, counter-clockwise seen from
/// outside the body it bounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContactFace {
    pub nodes: [u32; 4],
    pub surface: u8,
}

/// Two surfaces that may touch; each is slave against the other's faces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactPair {
    pub a: u8,
    pub b: u8,
    /// Deepest penetration still taken as contact (m): below it a node is taken to be on
    /// the far side of a thin master, not in it. Less than half the master's thickness.
    pub depth_max_m: f64,
}

/// A rigid tool: a capsule (at time 0) moved by a displacement path, touching the nodes of
/// one surface.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tool {
    pub capsule: Capsule,
    /// Index of the displacement path (in the path table) the tool follows.
    pub path: u16,
    pub surface: u8,
}

/// Contact search parameters (all zero without contact).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Bounding boxes are exchanged (and the candidates rebuilt) every this many steps.
    pub check_interval_steps: u32,
    /// Farthest a pair-surface node may move between two checks (m): `speed_bound ·
    /// check_interval · Δt`, at most half the scene's gap.
    pub travel_max_m: f64,
    /// A slave node is a candidate of a face whose bounding box, grown by this, holds it.
    pub candidate_margin_m: f64,
    /// Boards whose boxes, grown by this, overlap exchange nodes until the next check:
    /// twice (face diameter + contact depth) plus twice the travel.
    pub box_margin_m: f64,
    /// Deepest penetration tolerated (m).
    pub tolerance_m: f64,
    /// Bit mask of the surfaces that take part in a pair.
    pub pair_surfaces: u8,
}

/// A candidate of the search: slave node against master face, in direction
/// `2 · pair + (0: a's nodes on b's faces, 1: b's nodes on a's faces)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Candidate {
    pub direction: u16,
    pub slave: u32,
    pub face: u32,
}

/// What a step of contact found (for reports and checkers).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactStats {
    /// Active node-face and node-tool contacts applied.
    pub active: u32,
    /// Deepest penetration among the applied contacts (m).
    pub max_depth_m: f64,
    /// Per pair: the sum of all forces of its contacts (zero to round-off), and the sum
    /// of their magnitudes (the scale).
    pub pair_sum_n: [V3; SURFACES_MAX],
    pub pair_magnitude_n: [f64; SURFACES_MAX],
}

/// The contact problem: tables shared by every board.
#[derive(Clone, Copy, Debug)]
pub struct ContactModel<'a> {
    pub nodes: &'a [ContactNode],
    pub faces: &'a [ContactFace],
    pub pairs: &'a [ContactPair],
    pub tools: &'a [Tool],
}

pub(super) fn bad(index: usize) -> PhysicsError {
    PhysicsError::BadContactIndex {
        index: index as u32,
    }
}

impl ContactModel<'_> {
    /// Master and slave surfaces of a direction.
    pub(super) fn roles(&self, direction: usize) -> Option<(u8, u8, f64)> {
        let p = self.pairs.get(direction / 2)?;
        Some(if direction.is_multiple_of(2) {
            (p.a, p.b, p.depth_max_m)
        } else {
            (p.b, p.a, p.depth_max_m)
        })
    }

    /// Face `f`'s [`FaceGeometry`] at the positions `pos` (`None` if one is unknown), for
    /// [`evaluate_pairs_at`].
    pub fn face_geometry(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<Option<FaceGeometry>, PhysicsError> {
        let mut q = [[0.0; 3]; 4];
        Ok(if self.face_points(f, pos, &mut q)? {
            Some(FaceGeometry::new(q))
        } else {
            None
        })
    }

    /// Face `f`'s [`QuadBounds`] at the positions `pos` ([`QuadBounds::UNKNOWN`] if one is
    /// unknown), for [`evaluate_pairs_bounded`].
    pub fn face_bounds(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<QuadBounds, PhysicsError> {
        // `QuadBounds::new` of `face_points`' corners, the same operations in the same
        // order, folded into the reading of the corners (no array of the four corners
        // kept: on the board it was spilled and read back, about half of the cost).
        let face = self.faces.get(f).ok_or(bad(f))?;
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for (k, &c) in face.nodes.iter().enumerate() {
            if c as usize >= self.nodes.len() {
                return Err(bad(c as usize));
            }
            let Some(p) = pos(c as usize) else {
                return Ok(QuadBounds::UNKNOWN);
            };
            if k == 0 {
                (lo, hi) = (p, p);
            } else {
                QuadBounds::include(&mut lo, &mut hi, &p);
            }
        }
        Ok(QuadBounds::from_extent(lo, hi))
    }

    /// The positions of face `f`'s nodes into `q`: `Ok(false)` if one is unknown. (Into
    /// the caller's array: a returned one is copied out through memory.)
    #[inline(always)]
    pub(super) fn face_points(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
        q: &mut [V3; 4],
    ) -> Result<bool, PhysicsError> {
        let face = self.faces.get(f).ok_or(bad(f))?;
        for (k, &c) in face.nodes.iter().enumerate() {
            if c as usize >= self.nodes.len() {
                return Err(bad(c as usize));
            }
            match pos(c as usize) {
                Some(x) => q[k] = x,
                None => return Ok(false),
            }
        }
        Ok(true)
    }
}

/// Bit mask of the surfaces that take part in some pair.
pub fn pair_surface_mask(pairs: &[ContactPair]) -> u8 {
    pairs.iter().fold(0u8, |m, p| {
        m | 1u8.checked_shl(p.a as u32).unwrap_or(0) | 1u8.checked_shl(p.b as u32).unwrap_or(0)
    })
}

#[cfg(test)]
mod tests;
