//! `pe inspect`: a readable dump of one board's schedule.

use std::path::Path;

use anyhow::{anyhow, Context, Result};

use pe_firmware::runtime::{Op, Program};

use super::{decode_image, image_file_name, FACE_NAMES};

/// `pe inspect`: a readable dump of one board's schedule.
pub fn inspect(dir: &Path, board: [usize; 3]) -> Result<String> {
    let p = dir.join(image_file_name(board));
    let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
    let d = decode_image(&bytes, Some(board.map(|c| c as u8)))
        .map_err(|e| anyhow!("{}: {e}", p.display()))?;
    let h = &d.header;
    let c = &h.counts;
    let mut s = format!(
        "{}: board ({},{},{}) of a {}x{}x{} machine, format v{}, {:?} {:?}, {} bytes\n",
        p.display(),
        h.board[0],
        h.board[1],
        h.board[2],
        h.machine[0],
        h.machine[1],
        h.machine[2],
        h.version,
        h.precision,
        h.integration,
        bytes.len()
    );
    s += &format!("  compilation {}\n", h.compilation);
    s += &format!(
        "  dt = {:.4e} s, {} steps, damping {} 1/s\n",
        h.params.dt_s, h.params.steps, h.params.damping_per_s
    );
    // Every kernel's elements per batch (general, parallelepiped, cuboid).
    let per_batch = |k: usize| {
        [c.batch_ends, c.box_batch_ends, c.cuboid_batch_ends]
            .iter()
            .map(|e| e[k] - if k == 0 { 0 } else { e[k - 1] })
            .sum::<u32>()
    };
    s += &format!(
        "  {} elements ({} general, {} parallelepipeds, {} cuboids): batch x {}, batch y {}, batch z {}, inner {}\n",
        c.elements + c.boxes + c.cuboids,
        c.elements,
        c.boxes,
        c.cuboids,
        per_batch(0),
        per_batch(1),
        per_batch(2),
        per_batch(3)
    );
    let owned = d.nodes.iter().filter(|n| n.owner).count();
    s += &format!(
        "  {} nodes ({} owned, {} replicas), {} materials, {} path points, {} loads\n",
        c.nodes,
        owned,
        c.nodes as usize - owned,
        c.materials,
        c.path_points,
        c.loads
    );
    let e = c.external;
    s += &format!(
        "  {} external forces (owned nodes with gravity, loads or contact) by stage: x {}, y {}, z {}, update {}\n",
        c.external_records(),
        e[0],
        e[1],
        e[2],
        e[3]
    );
    s += &format!("  schedule: {}\n", schedule(c));
    let g = |l: u16| {
        d.nodes
            .get(l as usize)
            .map(|n| n.global)
            .unwrap_or(u32::MAX)
    };
    let list = |v: Vec<u32>| {
        let shown: Vec<String> = v.iter().take(20).map(|x| x.to_string()).collect();
        format!(
            "{} [{}{}]",
            v.len(),
            shown.join(" "),
            if v.len() > 20 { " ..." } else { "" }
        )
    };
    for a in 0..3 {
        for (k, round) in d.rounds[a].iter().enumerate() {
            for f in 0..2 {
                let face = FACE_NAMES[2 * a + f];
                s += &format!(
                    "  {} round {k} face {face}: send {}\n",
                    ["x", "y", "z"][a],
                    list(round.send[f].iter().map(|&l| g(l)).collect())
                );
                s += &format!(
                    "  {} round {k} face {face}: recv {}\n",
                    ["x", "y", "z"][a],
                    list(round.recv[f].iter().map(|e| g(e.node)).collect())
                );
            }
        }
    }
    Ok(s)
}

/// The step program the board runs ([`Program::new`], its graphics and contact left out),
/// one entry per operation on both faces of an axis: "recover x", "send ±y0", "add ±x0",
/// "update".
fn schedule(c: &pe_firmware::image::Counts) -> String {
    let axis = |a: u8| ["x", "y", "z"].get(a as usize).copied().unwrap_or("?");
    let program = Program::new(&c.rounds, &c.late_rounds, false, false);
    let mut out: Vec<String> = Vec::new();
    for op in program.ops() {
        let entry = match *op {
            Op::Batch(k) => format!("recover {}", ["x", "y", "z", "inner"][(k as usize).min(3)]),
            Op::Send(a, r, 0) => format!("send ±{}{r}", axis(a)),
            Op::Recv(a, r, 1) => format!("add ±{}{r}", axis(a)),
            Op::Update => "update".to_string(),
            _ => continue,
        };
        out.push(entry);
    }
    out.join(" | ")
}
