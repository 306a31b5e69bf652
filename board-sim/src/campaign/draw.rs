//! What each run of a campaign injects, drawn from the campaign's seed: a fault spec, or
//! one board's image from another compilation.

use std::path::{Path, PathBuf};

use anyhow::Result;
use host_tools::compile::image_file_name;

use crate::faults::Rng;

/// The fault spec of run `k`, drawn from `rng`: one kind or a mix, at rates from
/// recoverable (1e-3) to beyond recovery (0.3), and a stall somewhere in the run.
pub(super) fn draw(rng: &mut Rng, steps: u64, dims: [usize; 3]) -> String {
    let seed = rng.next_u64() % 1_000_000;
    let rate = |rng: &mut Rng| [1e-3, 1e-3, 1e-2, 0.3][(rng.next_u64() % 4) as usize];
    let mut parts = vec![format!("seed={seed}")];
    let mix = rng.next_u64() % 6;
    if matches!(mix, 0 | 4 | 5) {
        parts.push(format!("drop={}", rate(rng)));
    }
    if matches!(mix, 1 | 4 | 5) {
        parts.push(format!("corrupt={}", rate(rng)));
    }
    if matches!(mix, 2 | 5) {
        parts.push("delay=1".into());
    }
    if matches!(mix, 3 | 5) || rng.next_u64().is_multiple_of(8) {
        let b = dims.map(|d| (rng.next_u64() % d as u64) as usize);
        let s = rng.next_u64() % steps.max(1);
        parts.push(format!("stall={}.{}.{}@{s}", b[0], b[1], b[2]));
    }
    parts.join(",")
}

/// How a run's set is mixed: one board's image from the other compilation.
#[derive(Clone, Copy, Debug)]
pub(super) enum Swap {
    /// The image alone: the host's start check must name the board.
    Image,
    /// The image and the other compilation's manifest: the host must still name the one
    /// odd board (the set's majority).
    WithManifest,
    /// The image, with the host's manifest check off: the boards must refuse it with
    /// their neighbours (the Hello frames before step 0), on the odd board's links.
    Unchecked,
}

/// Whether run `k` swaps an image (one run in six, when another compilation is given),
/// how, and which board's.
pub(super) fn draw_swap(rng: &mut Rng, dims: [usize; 3]) -> Option<(Swap, [usize; 3])> {
    if !rng.next_u64().is_multiple_of(6) {
        return None;
    }
    let how = [Swap::Image, Swap::WithManifest, Swap::Unchecked][(rng.next_u64() % 3) as usize];
    Some((how, dims.map(|d| (rng.next_u64() % d as u64) as usize)))
}

/// A copy of the set in `dir` with board `b`'s image (and with `manifest` the manifest)
/// from `other`, in a fresh directory.
pub(super) fn mixed_set(
    dir: &Path,
    other: &Path,
    b: [usize; 3],
    manifest: bool,
    k: u64,
) -> Result<PathBuf> {
    let mixed = std::env::temp_dir().join(format!("pe-campaign-{}-{k}", std::process::id()));
    let _ = std::fs::remove_dir_all(&mixed);
    std::fs::create_dir_all(&mixed)?;
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        std::fs::copy(e.path(), mixed.join(e.file_name()))?;
    }
    let name = image_file_name(b);
    std::fs::copy(other.join(&name), mixed.join(&name))
        .map_err(|e| anyhow::anyhow!("{}: {e}", other.join(&name).display()))?;
    if manifest {
        std::fs::copy(other.join("manifest.json"), mixed.join("manifest.json"))?;
    }
    Ok(mixed)
}
