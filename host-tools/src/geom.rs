//! Small 3-vector arithmetic (the firmware's `physics::vec3`, re-exported, and what the host
//! adds to it) and the hexahedron's scaled Jacobian: what every mesh generator, analysis and
//! renderer on the host uses.

/// A point or vector in 3D.
pub type V3 = [f64; 3];

/// `a + b`, `a − b`, `s a`, `a · b`, `a × b` and `√(a · a)`: the firmware's
/// ([`pe_firmware::physics::vec3`], the one home of the small vector helpers), so a value
/// is the same bits on the host and on the boards.
pub use pe_firmware::physics::vec3::{add, cross, dot, norm, scale, sub};

/// `a / |a|` (as `a · (1/|a|)`).
pub fn unit(a: V3) -> V3 {
    scale(a, 1.0 / norm(a))
}

/// `a + t (b − a)`.
pub fn lerp(a: V3, b: V3, t: f64) -> V3 {
    add(a, scale(sub(b, a), t))
}

/// For each hexahedron corner (Gmsh/VTK order), its three edge neighbours in right-handed
/// order (the corner's local ξ, η, ζ directions).
pub const HEX_CORNER_NEIGHBOURS: [[usize; 3]; 8] = [
    [1, 3, 4],
    [2, 0, 5],
    [3, 1, 6],
    [0, 2, 7],
    [7, 5, 0],
    [4, 6, 1],
    [5, 7, 2],
    [6, 4, 3],
];

/// Scaled Jacobian of a hexahedron with corners `x` (Gmsh/VTK order): the minimum over the
/// eight corners of `det[e1 e2 e3] / (|e1| |e2| |e3|)` with `e` the corner's three edges.
/// 1 for a cube, <= 0 for an inverted or degenerate corner.
pub fn scaled_jacobian(x: &[V3; 8]) -> f64 {
    let mut min = f64::INFINITY;
    for (a, nb) in HEX_CORNER_NEIGHBOURS.iter().enumerate() {
        let e = nb.map(|b| sub(x[b], x[a]));
        let det = dot(e[0], cross(e[1], e[2]));
        let len = norm(e[0]) * norm(e[1]) * norm(e[2]);
        let sj = if len > 0.0 { det / len } else { 0.0 };
        min = min.min(sj);
    }
    min
}
