//! `board-sim campaign`: a seeded fault campaign. Many short runs of one compiled machine,
//! each with faults drawn from the campaign's seed (drop, corrupt, delay, stall, alone and
//! mixed; and, given another compilation of the machine, one board's image swapped for
//! that compilation's), each classified against the clean run: the clean run's bits, or
//! stopped naming the true first cause; anything else is counted, a silent wrong answer
//! above all.

mod draw;
mod verdict;

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use host_tools::compile::{read_manifest, Manifest};

use crate::check::SimFault;
use crate::clock::Clocking;
use crate::faults::{FaultSpec, Rng};
use crate::results::SimOutput;
use crate::runner::{run, SimOptions};
use draw::{draw, draw_swap, mixed_set, Swap};
use verdict::{identical, names_swap, true_cause, Verdict};

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
    clocking: Clocking,
) -> Result<()> {
    let manifest = read_manifest(dir)?;
    let dims = manifest.machine;
    if let Some(other) = swap_from {
        check_other(other, &manifest)?;
    }
    let base = SimOptions {
        clocking,
        ..base_options(steps, recovery)
    };
    let clean = run(dir, &base, &mut |_, _| {})?;
    let u_max = host_tools::compare::max_abs(&clean.displacements);
    if u_max <= 0.0 || clean.steps != steps {
        bail!("the clean run is trivial (max |u| {u_max} m after {} steps): choose a scene or more steps that move", clean.steps);
    }
    println!(
        "campaign seed {seed}: {runs} runs of {steps} steps on {} ({}x{}x{}), recovery {}, {} clock; clean run max |u| = {u_max:.3e} m",
        manifest.scene,
        dims[0],
        dims[1],
        dims[2],
        if recovery { "on" } else { "off" },
        match clocking {
            Clocking::Wall => "wall",
            Clocking::Simulated { .. } => "simulated",
        }
    );
    let mut rng = Rng::new(seed);
    let mut tally = Tally::default();
    let start = Instant::now();
    for k in 0..runs {
        let spec = draw(&mut rng, steps, dims);
        let workers = [1, 2, 8][(rng.next_u64() % 3) as usize];
        let swap = swap_from.and_then(|other| draw_swap(&mut rng, dims).map(|s| (other, s)));
        let opts = SimOptions {
            workers: Some(workers),
            ..base.clone()
        };
        if let Some((other, (how, b))) = swap {
            // A swapped set runs without injected faults: its first cause is the swap.
            let verdict = swapped_run(dir, other, (how, b), k, opts)?;
            tally.swapped(how, verdict);
            continue;
        }
        let verdict = faulty_run(dir, &spec, k, opts, &clean)?;
        tally.faulty(&spec, verdict);
    }
    tally.print(runs, start.elapsed(), swap_from.is_some());
    if tally.n(Verdict::SilentWrong) > 0 || tally.n(Verdict::WrongCause) > 0 {
        bail!("the campaign found silent wrong answers or wrong causes (replay: same seed)");
    }
    Ok(())
}

/// Refuses as `--swap-from` anything but another compilation of the same machine.
fn check_other(other: &Path, manifest: &Manifest) -> Result<()> {
    let dims = manifest.machine;
    let m = read_manifest(other)?;
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
    Ok(())
}

/// Every run's options: `steps` steps, a 2 s link timeout, recovery on or off.
fn base_options(steps: u64, recovery: bool) -> SimOptions {
    SimOptions {
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
    }
}

/// Run `k` with board `b`'s image taken from `other` (`how`).
fn swapped_run(
    dir: &Path,
    other: &Path,
    (how, b): (Swap, [usize; 3]),
    k: u64,
    opts: SimOptions,
) -> Result<Verdict> {
    let mixed = mixed_set(dir, other, b, matches!(how, Swap::WithManifest), k)?;
    let opts = SimOptions {
        check_manifest: !matches!(how, Swap::Unchecked),
        ..opts
    };
    let workers = opts.workers.unwrap_or(0);
    let result = run(&mixed, &opts, &mut |_, _| {});
    let _ = std::fs::remove_dir_all(&mixed);
    Ok(match &result {
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
    })
}

/// Run `k` with the faults of `spec`, against the clean run.
fn faulty_run(
    dir: &Path,
    spec: &str,
    k: u64,
    opts: SimOptions,
    clean: &SimOutput,
) -> Result<Verdict> {
    let opts = SimOptions {
        faults: Some(FaultSpec::parse(spec)?),
        ..opts
    };
    let workers = opts.workers.unwrap_or(0);
    Ok(match run(dir, &opts, &mut |_, _| {}) {
        Ok(out) if identical(&out, clean) => Verdict::Identical,
        Ok(_) => {
            println!("run {k} ({spec}, {workers} workers): SILENT WRONG ANSWER");
            Verdict::SilentWrong
        }
        Err(e) => match e.downcast::<SimFault>() {
            Ok(f) if true_cause(&f) => Verdict::TrueCause,
            Ok(f) => {
                println!("run {k} ({spec}, {workers} workers): wrong cause named:\n{f}");
                Verdict::WrongCause
            }
            Err(e) => bail!("run {k} ({spec}): {e}"),
        },
    })
}

/// The campaign's counts.
#[derive(Default)]
struct Tally {
    counts: BTreeMap<Verdict, u64>,
    /// Runs whose only faults are drop/corrupt at 1e-3 (recovery's design rate), and how
    /// many of them were bit-identical.
    low_rate: u64,
    low_rate_identical: u64,
    /// Runs with a swapped image, and how many were refused naming the board.
    swaps: u64,
    swaps_named: u64,
    swap_kinds: BTreeMap<String, u64>,
}

impl Tally {
    fn n(&self, v: Verdict) -> u64 {
        self.counts.get(&v).copied().unwrap_or(0)
    }

    fn swapped(&mut self, how: Swap, verdict: Verdict) {
        self.swaps += 1;
        *self.swap_kinds.entry(format!("{how:?}")).or_default() += 1;
        self.swaps_named += (verdict == Verdict::TrueCause) as u64;
        *self.counts.entry(verdict).or_default() += 1;
    }

    fn faulty(&mut self, spec: &str, verdict: Verdict) {
        let low = !spec.contains("stall")
            && !spec.contains("delay")
            && !spec.contains("=0.01")
            && !spec.contains("=0.3");
        if low {
            self.low_rate += 1;
            self.low_rate_identical += (verdict == Verdict::Identical) as u64;
        }
        *self.counts.entry(verdict).or_default() += 1;
    }

    fn print(&self, runs: u64, wall: Duration, swapping: bool) {
        let wall = wall.as_secs_f64();
        println!(
            "summary: {runs} runs in {wall:.1} s ({:.2} s a run): {} bit-identical to the clean run, {} stopped naming the true first cause, {} stopped naming a wrong cause, {} silent wrong answers",
            wall / runs.max(1) as f64,
            self.n(Verdict::Identical),
            self.n(Verdict::TrueCause),
            self.n(Verdict::WrongCause),
            self.n(Verdict::SilentWrong)
        );
        println!(
            "  runs with only drop/corrupt at 1e-3 per frame: {}, of which {} bit-identical ({:.1}%)",
            self.low_rate,
            self.low_rate_identical,
            100.0 * self.low_rate_identical as f64 / self.low_rate.max(1) as f64
        );
        if swapping {
            let kinds: Vec<String> = self
                .swap_kinds
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect();
            println!(
                "  runs with one board's image from the other compilation: {} ({}), of which {} refused naming that board",
                self.swaps,
                kinds.join(", "),
                self.swaps_named
            );
        }
    }
}
