//! `board-sim campaign`: a seeded fault campaign. Many short runs of one compiled machine,
//! each with faults drawn from the campaign's seed (drop, corrupt, delay, stall, alone and
//! mixed; and, given another compilation of the machine, one board's image swapped for
//! that compilation's), each classified against the clean run: the clean run's bits, or
//! stopped naming the true first cause; anything else is counted, a silent wrong answer
//! above all.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use board_sim::faults::{FaultSpec, Rng};
use board_sim::{run, SimFault, SimOptions};
use host_tools::compile::image_file_name;
use link_proto::machine::across;
use pe_firmware::runtime::FaultKind;

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Verdict {
    /// Finished with the clean run's bits.
    Identical,
    /// Stopped, naming an injected fault that explains what was detected.
    TrueCause,
    /// Stopped, naming something else.
    WrongCause,
    /// Finished with other results: a silent wrong answer.
    SilentWrong,
}

/// The fault spec of run `k`, drawn from `rng`: one kind or a mix, at rates from
/// recoverable (1e-3) to beyond recovery (0.3), and a stall somewhere in the run.
fn draw(rng: &mut Rng, steps: u64, dims: [usize; 3]) -> String {
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
enum Swap {
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
fn draw_swap(rng: &mut Rng, dims: [usize; 3]) -> Option<(Swap, [usize; 3])> {
    if !rng.next_u64().is_multiple_of(6) {
        return None;
    }
    let how = [Swap::Image, Swap::WithManifest, Swap::Unchecked][(rng.next_u64() % 3) as usize];
    Some((how, dims.map(|d| (rng.next_u64() % d as u64) as usize)))
}

/// A copy of the set in `dir` with board `b`'s image (and with `manifest` the manifest)
/// from `other`, in a fresh directory.
fn mixed_set(dir: &Path, other: &Path, b: [usize; 3], manifest: bool, k: u64) -> Result<PathBuf> {
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

/// Whether a swapped run was refused naming the odd board `b`: by the host before any
/// board ran (its message names exactly that board), or by the boards, every mismatch on a
/// link of `b` (and at least one).
fn names_swap(result: &Result<board_sim::SimOutput>, b: [usize; 3]) -> bool {
    let b8 = b.map(|c| c as u8);
    match result {
        Ok(_) => false,
        Err(e) => match e.downcast_ref::<SimFault>() {
            None => {
                let m = format!("{e:#}");
                let name = format!("board ({},{},{})", b[0], b[1], b[2]);
                m.contains(&name) && m.matches("board (").count() == 1
            }
            Some(f) => {
                let mismatches: Vec<bool> = f
                    .observed
                    .iter()
                    .filter_map(|o| match o.fault.kind {
                        FaultKind::CompilationMismatch { face, .. } => Some(
                            o.fault.board == b8
                                || across(o.fault.board.map(usize::from), face)
                                    == Some(b8.map(usize::from)),
                        ),
                        _ => None,
                    })
                    .collect();
                let detected = f
                    .observed
                    .get(f.cause.detected)
                    .is_some_and(|o| matches!(o.fault.kind, FaultKind::CompilationMismatch { .. }));
                detected && !mismatches.is_empty() && mismatches.iter().all(|&x| x)
            }
        },
    }
}

/// Whether a stopped run names the true first cause: an injected fault (ground truth) that
/// explains the observation that detected it (which attribution checks), and no injected
/// stall earlier than it (a stall stops a run for certain; faults before it may have been
/// recovered).
fn true_cause(f: &SimFault) -> bool {
    let c = &f.cause;
    let injected = f.injected.iter().any(|i| {
        Some(&i.face) == c.face.as_ref()
            && i.board == c.board
            && i.step as u64 == c.step
            && c.what == format!("injected {}", i.what)
    });
    let stall_before = f
        .injected
        .iter()
        .any(|i| i.what == "stall" && (i.step as u64) < c.step);
    c.injected && injected && (!stall_before || c.what == "injected stall")
}

/// Runs the campaign on the machine compiled in `dir`; prints one line per run that is not
/// bit-identical and a summary; fails if any run was a silent wrong answer or named a
/// wrong cause.
pub fn campaign(
    dir: &Path,
    swap_from: Option<&Path>,
    runs: u64,
    seed: u64,
    steps: u64,
    recovery: bool,
) -> Result<()> {
    let manifest = host_tools::compile::read_manifest(dir)?;
    let dims = manifest.machine;
    if let Some(other) = swap_from {
        let m = host_tools::compile::read_manifest(other)?;
        if m.machine != dims || m.compilation == manifest.compilation {
            bail!(
                "--swap-from {}: wants another compilation ({}) of the same {}x{}x{} machine, found compilation {} on {}x{}x{}",
                other.display(),
                manifest.compilation,
                dims[0],
                dims[1],
                dims[2],
                m.compilation,
                m.machine[0],
                m.machine[1],
                m.machine[2]
            );
        }
    }
    let base = SimOptions {
        steps: Some(steps),
        link_timeout: Duration::from_secs(2),
        recovery: if recovery {
            SimOptions::default().recovery
        } else {
            None
        },
        global_recovery: if recovery {
            SimOptions::default().global_recovery
        } else {
            None
        },
        ..Default::default()
    };
    let clean = run(dir, &base, &mut |_, _| {})?;
    let u_max = host_tools::firmware::max_abs(&clean.displacements);
    if u_max <= 0.0 || clean.steps != steps {
        bail!("the clean run is trivial (max |u| {u_max} m after {} steps): choose a scene or more steps that move", clean.steps);
    }
    println!(
        "campaign seed {seed}: {runs} runs of {steps} steps on {} ({}x{}x{}), recovery {}; clean run max |u| = {u_max:.3e} m",
        manifest.scene,
        dims[0],
        dims[1],
        dims[2],
        if recovery { "on" } else { "off" }
    );
    let mut rng = Rng::new(seed);
    let mut counts = std::collections::BTreeMap::<Verdict, u64>::new();
    let (mut low_rate, mut low_rate_identical) = (0u64, 0u64);
    let (mut swaps, mut swaps_named) = (0u64, 0u64);
    let mut swap_kinds = std::collections::BTreeMap::<String, u64>::new();
    let start = Instant::now();
    for k in 0..runs {
        let spec = draw(&mut rng, steps, dims);
        let workers = [1, 2, 8][(rng.next_u64() % 3) as usize];
        let swap = swap_from.and_then(|other| draw_swap(&mut rng, dims).map(|s| (other, s)));
        if let Some((other, (how, b))) = swap {
            // A swapped set runs without injected faults: its first cause is the swap.
            let mixed = mixed_set(dir, other, b, matches!(how, Swap::WithManifest), k)?;
            let opts = SimOptions {
                workers: Some(workers),
                check_manifest: !matches!(how, Swap::Unchecked),
                ..base.clone()
            };
            let result = run(&mixed, &opts, &mut |_, _| {});
            let _ = std::fs::remove_dir_all(&mixed);
            let verdict = match &result {
                Ok(_) => {
                    println!(
                        "run {k} (board ({},{},{})'s image swapped, {how:?}, {workers} workers): SILENT WRONG ANSWER",
                        b[0], b[1], b[2]
                    );
                    Verdict::SilentWrong
                }
                Err(_) if names_swap(&result, b) => Verdict::TrueCause,
                Err(e) => {
                    println!(
                        "run {k} (board ({},{},{})'s image swapped, {how:?}, {workers} workers): wrong cause named:\n{e:#}",
                        b[0], b[1], b[2]
                    );
                    Verdict::WrongCause
                }
            };
            swaps += 1;
            *swap_kinds.entry(format!("{how:?}")).or_default() += 1;
            swaps_named += (verdict == Verdict::TrueCause) as u64;
            *counts.entry(verdict).or_default() += 1;
            continue;
        }
        let opts = SimOptions {
            faults: Some(FaultSpec::parse(&spec)?),
            workers: Some(workers),
            ..base.clone()
        };
        let verdict = match run(dir, &opts, &mut |_, _| {}) {
            Ok(out) => {
                let same = out.steps == clean.steps
                    && out.displacements.len() == clean.displacements.len()
                    && out
                        .displacements
                        .iter()
                        .zip(&clean.displacements)
                        .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits));
                if same {
                    Verdict::Identical
                } else {
                    println!("run {k} ({spec}, {workers} workers): SILENT WRONG ANSWER");
                    Verdict::SilentWrong
                }
            }
            Err(e) => match e.downcast::<SimFault>() {
                Ok(f) if true_cause(&f) => Verdict::TrueCause,
                Ok(f) => {
                    println!("run {k} ({spec}, {workers} workers): wrong cause named:\n{f}");
                    Verdict::WrongCause
                }
                Err(e) => bail!("run {k} ({spec}): {e}"),
            },
        };
        // Runs whose only faults are drop/corrupt at 1e-3 (recovery's design rate).
        let low = !spec.contains("stall")
            && !spec.contains("delay")
            && !spec.contains("=0.01")
            && !spec.contains("=0.3");
        if low {
            low_rate += 1;
            low_rate_identical += (verdict == Verdict::Identical) as u64;
        }
        *counts.entry(verdict).or_default() += 1;
    }
    let wall = start.elapsed().as_secs_f64();
    let n = |v| counts.get(&v).copied().unwrap_or(0);
    println!(
        "summary: {runs} runs in {wall:.1} s ({:.2} s a run): {} bit-identical to the clean run, {} stopped naming the true first cause, {} stopped naming a wrong cause, {} silent wrong answers",
        wall / runs.max(1) as f64,
        n(Verdict::Identical),
        n(Verdict::TrueCause),
        n(Verdict::WrongCause),
        n(Verdict::SilentWrong)
    );
    println!(
        "  runs with only drop/corrupt at 1e-3 per frame: {low_rate}, of which {low_rate_identical} bit-identical ({:.1}%)",
        100.0 * low_rate_identical as f64 / low_rate.max(1) as f64
    );
    if swap_from.is_some() {
        let kinds: Vec<String> = swap_kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
        println!(
            "  runs with one board's image from the other compilation: {swaps} ({}), of which {swaps_named} refused naming that board",
            kinds.join(", ")
        );
    }
    if n(Verdict::SilentWrong) > 0 || n(Verdict::WrongCause) > 0 {
        bail!("the campaign found silent wrong answers or wrong causes (replay: same seed)");
    }
    Ok(())
}
