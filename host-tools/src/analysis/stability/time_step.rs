//! Stability cases about the time step and run length: fractions of the critical step,
//! long runs, load cycles, and the guards that refuse an unstable step.

use super::*;

fn dt_scene() -> Result<Scene> {
    Ok(
        box_scene([0.05, 0.01, 0.01], [10, 2, 2], 1e6, 0.45, true, |s| {
            s.damping = 0.0
        })
        .with_gravity(builders::gravity_down()),
    )
}

/// A step of `fraction` × critical: stable below 1, refused (or caught when forced) above.
pub fn dt_fraction(fraction: f64) -> Result<Case> {
    timed(
        &format!("dt_{fraction}_of_critical"),
        |c| {
            let base = dt_scene()?;
            let p = problem(&base)?;
            let crit = p.time_step.critical.dt_critical_s;
            if fraction < 1.0 {
                let mut sc = base.clone();
                sc.solver.dt_safety = fraction;
                let p = problem(&sc)?;
                let dt = p.time_step.dt_s;
                let mut m = Model::<f64>::new(&p, dt);
                // 20000 undamped steps under suddenly applied gravity: a stable scheme keeps
                // the energy in a band well under 1% of the peak stored energy.
                // A fault would have ended the case with an error (energy_band's `?`).
                let (lo, hi, smax) = energy_band(&mut m, 20_000, 10, 0)?;
                c.note(format!("20000 steps without a fault at dt = {dt:.3e} s"));
                // The band is only a measure if the beam moved: a cantilever under a uniform
                // load q = W/L stores W·δ/5 at rest (δ = qL⁴/8EI, Euler-Bernoulli), about
                // four times that at the peak of the undamped swing. A tenth of W·δ leaves
                // room for the coarse mesh's stiffness (2 cells through the depth).
                let (length_m, depth_m) = (0.05f64, 0.01f64);
                let weight_n = p.mass.iter().sum::<f64>() * 9.81;
                let inertia_m4 = depth_m.powi(4) / 12.0;
                let sag_m = weight_n / length_m * length_m.powi(4) / (8.0 * 1e6 * inertia_m4);
                c.gt(
                    "peak stored energy / (weight × beam-theory tip sag)",
                    smax / (weight_n * sag_m),
                    0.1,
                );
                c.lt("energy band / peak stored energy", (hi - lo) / smax, 0.01);
            } else {
                let mut sc = base.clone();
                sc.solver.dt = Some(fraction * crit);
                let e = problem(&sc).err().map(|e| e.to_string());
                c.is(
                    "explicit dt refused",
                    e.as_deref()
                        .is_some_and(|e| e.contains("exceeds the critical step")),
                    e.unwrap_or_else(|| "accepted".into()),
                );
                let mut sc2 = base.clone();
                sc2.solver.dt_safety = fraction;
                let e = problem(&sc2).err().map(|e| e.to_string());
                c.is(
                    "dt_safety > 1 refused",
                    e.as_deref().is_some_and(|e| e.contains("force_dt")),
                    e.unwrap_or_else(|| "accepted".into()),
                );
                sc.solver.force_dt = true;
                sc.solver.steps = Some(100_000);
                let p = problem(&sc)?;
                let dt = p.time_step.dt_s;
                let mut m = Model::<f64>::new(&p, dt);
                let mut fault = None;
                for _ in 0..100_000 {
                    if let Err(e) = m.advance() {
                        fault = Some((e.step, solver::describe_step_error(&p, &e)));
                        break;
                    }
                }
                match fault {
                    Some((step, msg)) => {
                        // The unstable mode grows by |λ| ≥ 1.33 per step at 1.01 × critical
                        // (from round-off to the speed bound: ~130 steps), faster above.
                        c.lt("forced: steps until the fault", step as f64, 1000.0);
                        c.is(
                            "fault names the step and a node or element",
                            msg.contains("step")
                                && (msg.contains("node") || msg.contains("element")),
                            msg,
                        );
                    }
                    None => c.is("forced run faults", false, "ran 100000 steps"),
                }
            }
            Ok(())
        },
        if fraction < 1.0 {
            "stable: 20000 undamped steps with bounded energy"
        } else {
            "refused (explicit dt and dt_safety); forced, the blow-up is caught within a few hundred steps by a guard naming the step and the node or element"
        },
    )
}

/// Undamped cantilever under suddenly applied gravity for `steps` steps in f64 and f32:
/// bounded energy, no drift in either precision.
pub fn long_run(steps: u64) -> Result<Case> {
    timed(
        &format!("long_run_{steps}_steps_f32_f64"),
        |c| {
            let sc = box_scene(
                [0.05, 0.01, 0.01],
                [8, 2, 2],
                1e6,
                0.45,
                true,
                |s| s.damping = 0.0,
            )
            .with_gravity(builders::gravity_down());
            let p = problem(&sc)?;
            let dt = p.time_step.dt_s;
            let window = steps / 10;
            fn run<T: Real>(
                p: &Problem,
                dt: f64,
                steps: u64,
                window: u64,
            ) -> Result<(f64, f64, f64, f64)> {
                let mut m = Model::<T>::new(p, dt);
                let (lo1, hi1, s1) = energy_band(&mut m, window, 10, 0)?;
                let (lo, hi, s) = energy_band(&mut m, steps - 2 * window, 10, 0)?;
                let (lo2, hi2, s2) = energy_band(&mut m, window, 10, 0)?;
                let smax = s1.max(s).max(s2);
                // (band over the run, mean of the first window, mean of the last, peak)
                Ok((
                    hi.max(hi1).max(hi2) - lo.min(lo1).min(lo2),
                    0.5 * (lo1 + hi1),
                    0.5 * (lo2 + hi2),
                    smax,
                ))
            }
            let (b64, a64, z64, s64) = run::<f64>(&p, dt, steps, window)?;
            let (b32, a32, z32, s32) = run::<f32>(&p, dt, steps, window)?;
            // f64: the central difference conserves a shadow energy; round-off adds a random
            // walk of ~1e-16 per step, so over 1e6 steps the band stays < 0.5% of the peak
            // stored energy (the O(ω²dt²) shadow oscillation dominates).
            c.lt("f64: energy band / peak stored", b64 / s64, 0.005);
            c.lt(
                "f64: drift of the mean energy, first to last tenth / peak stored",
                (z64 - a64).abs() / s64,
                1e-3,
            );
            // f32: the velocity lives in u − u_prev, a small difference of two f32 numbers:
            // each step rounds it by ~ε|u|/|Δu| (ε = 6e-8; |u|/|Δu| ~ 1/(ωdt) ~ 100 for the
            // bending mode), so the energy of the f32 trajectory (evaluated in f64) wanders
            // by ~1e-8 of itself per step. Measured: 1.6% by 1e6 steps, ~10% by 1e7 (faster
            // than a √N random walk: partly systematic). The bound is a drift rate, 5% per
            // 1e6 steps: an unstable mode would grow exponentially, not linearly. In the
            // scenes, damping removes this drift; long undamped runs need f64.
            let f32_bound = 0.05 * steps as f64 / 1e6;
            c.lt("f32: energy band / peak stored", b32 / s32, f32_bound);
            c.lt(
                "f32: drift of the mean energy, first to last tenth / peak stored",
                (z32 - a32).abs() / s32,
                f32_bound,
            );
            c.note(format!(
                "dt = {dt:.3e} s, {steps} steps = {:.1} s simulated; f64 band {:.2e}, f32 band {:.2e} of peak stored",
                steps as f64 * dt,
                b64 / s64,
                b32 / s32
            ));
            Ok(())
        },
        "energy bounded in both; f64 free of drift (< 1e-3 of the peak stored energy); f32 drifts with round-off at a bounded rate (< 5% of the peak stored energy per 1e6 undamped steps)",
    )
}

/// `cycles` load cycles on a damped cantilever: periodic response, no drift, back to rest.
pub fn load_cycles(cycles: usize) -> Result<Case> {
    timed(
        &format!("load_cycles_{cycles}"),
        |c| {
            let period = 0.2;
            let ramp: Vec<[f64; 2]> = (0..cycles)
                .flat_map(|k| {
                    let t0 = k as f64 * period;
                    [
                        [t0, 0.0],
                        [t0 + 0.05, 1.0],
                        [t0 + 0.1, 1.0],
                        [t0 + 0.15, 0.0],
                    ]
                })
                .collect();
            let sc = box_scene([0.1, 0.02, 0.02], [10, 2, 2], 5e5, 0.45, true, |s| {
                s.damping = 60.0
            })
            .with_load(
                [[0.0999, -1.0, -1.0], [1.0, 1.0, 1.0]],
                [0.0, 0.0, -0.2],
                Some(ramp),
            );
            let mut sc = sc;
            // A whole number of steps per cycle (at most 0.9 of critical), so that every
            // cycle samples the same phases.
            let crit = problem(&sc)?.time_step.critical.dt_critical_s;
            let per_cycle = (period / (0.9 * crit)).ceil();
            sc.solver.dt = Some(period / per_cycle);
            let p = problem(&sc)?;
            let dt = p.time_step.dt_s;
            let tip = node_near(&p, [0.1, 0.01, 0.01]);
            let mut m = Model::<f64>::new(&p, dt);
            let mut ends = Vec::new();
            let mut peaks = Vec::new();
            for _ in 0..cycles {
                let mut peak = 0.0f64;
                for _ in 0..per_cycle as u64 {
                    m.advance()
                        .map_err(|e| anyhow!("{}", solver::describe_step_error(&p, &e)))?;
                    peak = peak.max(norm(m.u[tip]));
                }
                ends.push(m.u[tip]);
                peaks.push(peak);
            }
            let peak = peaks.iter().cloned().fold(0.0, f64::max);
            c.gt("peak tip deflection / length", peak / 0.1, 0.02);
            // The transient decays as e^(-30 t) (damping 60/s): after 10 cycles (2 s) it is
            // e^-54, so every later cycle repeats the same states to round-off; a drift
            // (accumulating hourglass or history error) would show as a trend.
            let half = (cycles / 10).max(1);
            let ref_end = ends[half - 1];
            let drift = ends[half..]
                .iter()
                .map(|u| norm(core::array::from_fn(|i| u[i] - ref_end[i])))
                .fold(0.0, f64::max);
            c.lt(
                &format!("tip at cycle end, cycles {half}..{cycles} vs cycle {half}, / peak"),
                drift / peak,
                1e-9,
            );
            let pdrift = peaks[half..]
                .iter()
                .map(|q| (q - peaks[half - 1]).abs())
                .fold(0.0, f64::max);
            c.lt(
                "peak per cycle vs that of cycle 10, / peak",
                pdrift / peak,
                1e-9,
            );
            // Then unloaded and damped for 1 s (e^-30): every node back to rest within
            // 1e-9 of the peak (the Total Lagrangian hourglass forces keep no history).
            let t_end = m.time_s() + 1.0;
            while m.time_s() < t_end {
                m.advance()
                    .map_err(|e| anyhow!("{}", solver::describe_step_error(&p, &e)))?;
            }
            let rest = m.u.iter().map(|u| norm(*u)).fold(0.0, f64::max);
            c.lt("max |u| after unloading / peak", rest / peak, 1e-9);
            c.note(format!("{} steps of {dt:.3e} s", m.step));
            Ok(())
        },
        "periodic response from the 10th cycle on with no drift; returns to rest",
    )
}

/// The runtime guards: each one trips with a message naming the step and the node or
/// element.
pub fn guards() -> Result<Case> {
    timed(
        "runtime_guards",
        |c| {
            // Speed bound: a forced step 1.02 × critical blows up, and the speed guard set
            // at 1 m/s (ten times what tissue reaches) trips while the displacement jump
            // per step is still far from inverting a 5 mm cell. (At the default 100 m/s
            // the physical hourglass form's fastest mode inverts a cell first, at step
            // 114, and the J ≤ 0 guard names it: checked below on its own.)
            let mut sc = dt_scene()?;
            sc.solver.speed_limit = 1.0;
            let crit = problem(&sc)?.time_step.critical.dt_critical_s;
            sc.solver.dt = Some(1.02 * crit);
            sc.solver.force_dt = true;
            let p = problem(&sc)?;
            let mut m = Model::<f64>::new(&p, 1.02 * crit);
            let err = loop {
                if let Err(e) = m.advance() {
                    break Some(e);
                }
                if m.step > 10_000 {
                    break None;
                }
            };
            match err {
                Some(e) => {
                    let msg = solver::describe_step_error(&p, &e);
                    c.is(
                        "speed guard: forced 1.02 × critical step",
                        matches!(e.error, PhysicsError::SpeedLimit { .. })
                            && msg.contains(&format!("step {}", e.step))
                            && msg.contains("mesh node tag"),
                        msg,
                    );
                }
                None => c.is("speed guard trips", false, "no fault in 10000 steps"),
            }
            // Non-finite guard: a corrupted history value (as a bit flip would leave) at
            // one node gives NaN there in the next update.
            let p = problem(&dt_scene()?)?;
            let dt = p.time_step.dt_s;
            let mut m = Model::<f64>::new(&p, dt);
            for _ in 0..10 {
                m.advance()
                    .map_err(|e| anyhow!("{}", solver::describe_step_error(&p, &e)))?;
            }
            let victim = node_near(&p, [0.05, 0.01, 0.01]);
            m.du[victim][1] = f64::NAN;
            match m.advance() {
                Err(e) => {
                    let msg = solver::describe_step_error(&p, &e);
                    c.is(
                        "NaN guard: names the node and step 10",
                        e.error == PhysicsError::NonFinite { node: victim as u32 }
                            && e.step == 10
                            && msg.contains("not finite"),
                        msg,
                    );
                }
                Ok(()) => c.is("NaN guard trips", false, "no fault"),
            }
            // J ≤ 0 guard: the free corner at the tip is pulled back through its cell (a
            // prescribed jump of 6 cells in −x at the first step: the one-point J is
            // 1 + B·u = 1 − 6/4 < 0; the speed bound is lifted so that the jump itself is not
            // what trips).
            let mut sc = dt_scene()?;
            sc.solver.speed_limit = 1e12;
            let mut p = problem(&sc)?;
            let corner = node_near(&p, [0.05, 0.0, 0.0]);
            p.node_kind[corner] = NodeKind::Prescribed(p.paths.len() as u32);
            p.paths.push(Path1::linear(vec![
                (0.0, [0.0; 3]),
                (1e-9, [-0.03, 0.0, 0.0]),
            ]));
            p.update_time_step()?;
            let dt = p.time_step.dt_s;
            let mut m = Model::<f64>::new(&p, dt);
            let err = (0..10).find_map(|_| m.advance().err());
            match err {
                Some(e) => {
                    let msg = solver::describe_step_error(&p, &e);
                    let ok = match e.error {
                        PhysicsError::InvertedElement { element, .. } => {
                            p.mesh.cells[element as usize].contains(&(corner as u32))
                                && msg.contains("inverted")
                        }
                        _ => false,
                    };
                    c.is(
                        "J ≤ 0 guard: names the element holding the pulled node",
                        ok,
                        msg,
                    );
                }
                None => c.is("J ≤ 0 guard trips", false, "no fault"),
            }
            Ok(())
        },
        "each guard (speed bound, non-finite value, J ≤ 0) stops the run with a message naming the step and the node (mesh tag, position) or element (cell, nodes)",
    )
}
