//! Stability cases about mesh quality: stretched and skewed elements, and a sagging
//! cantilever on a distorted mesh.

use super::*;

/// Patch test and undamped stability on a distorted mesh, both integrations.
fn distorted(name: &str, mesh_of: impl Fn() -> Mesh, expected: &str) -> Result<Case> {
    timed(
        name,
        |c| {
            let mesh = mesh_of();
            let sj = mesh.min_scaled_jacobian();
            let (lo, hi) = mesh.bounding_box();
            let size = (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f64::max);
            c.note(format!(
                "{} cells, min scaled Jacobian {sj:.3}",
                mesh.cells.len()
            ));
            // A general small linear field (stretch, shear, rotation parts).
            let g = [
                [1e-3, 4e-4, -2e-4],
                [-3e-4, -5e-4, 6e-4],
                [2e-4, -1e-4, 8e-4],
            ];
            let lin = |x: [f64; 3]| -> [f64; 3] {
                core::array::from_fn(|i| (0..3).map(|j| g[i][j] * (x[j] - lo[j])).sum())
            };
            for integration in [Integration::Reduced, Integration::Full] {
                let mk = |solver: &dyn Fn(&mut SolverSpec)| -> Result<Problem> {
                    let sc = box_scene([1.0; 3], [1; 3], 1e4, 0.45, false, solver);
                    let mut p = Problem::new(&sc, mesh.clone(), BTreeMap::new())?;
                    prescribe_boundary(&mut p, &[0.0], |x, _| lin(x))?;
                    Ok(p)
                };
                // Patch test: boundary on the linear field, interior free and damped: the
                // interior settles onto the field (one-point elements with the uniform
                // gradient pass it on any mesh; Γ is orthogonal to linear fields).
                let p = mk(&|s| {
                    s.integration = integration;
                    s.damping = 2000.0;
                })?;
                let dt = p.time_step.dt_s;
                let mut m = Model::<f64>::new(&p, dt);
                let probe = p
                    .node_kind
                    .iter()
                    .position(|k| *k == NodeKind::Free)
                    .unwrap_or(0);
                settle(&mut m, 200_000, 1e-10, |m| norm(m.u[probe]))?;
                let mut err = 0.0f64;
                let mut umax = 0.0f64;
                for n in 0..p.mesh.nodes.len() {
                    let want = lin(p.mesh.nodes[n]);
                    umax = umax.max(norm(want));
                    err = err.max(norm(core::array::from_fn(|i| m.u[n][i] - want[i])));
                }
                c.lt(
                    &format!("{integration}: patch test, interior error / max |u|"),
                    err / umax,
                    1e-6,
                );
                // Undamped from rest with the boundary jumping onto the field (every mode
                // excited, the highest included): 20000 steps at safety 0.99. Stable means
                // bounded: the largest energy of the last 2000 steps is not above that of
                // steps 10..2000 (1% slack); an unstable mode would grow by ≥ 1% per step.
                // (The sampled energy itself oscillates: kinetic energy from half-step
                // velocities differs from the shadow energy by (ωdt/2)² in the top modes.)
                let p = mk(&|s| {
                    s.integration = integration;
                    s.dt_safety = 0.99;
                })?;
                let (dt, crit) = (p.time_step.dt_s, p.time_step.critical.dt_critical_s);
                let mut m = Model::<f64>::new(&p, dt);
                let (_, first, _) = energy_band(&mut m, 2_000, 1, 10)?;
                let _ = energy_band(&mut m, 16_000, 100, 0)?;
                let (_, last, _) = energy_band(&mut m, 2_000, 1, 0)?;
                c.lt(
                    &format!("{integration}: undamped, max energy last 2000 / first 2000 steps (safety 0.99)"),
                    last / first,
                    1.01,
                );
                c.note(format!(
                    "{integration}: critical step {crit:.3e} s (L_e/c {:.3e} s), size {size:.3} m",
                    p.element_dt_estimate().0
                ));
            }
            Ok(())
        },
        expected,
    )
}

/// Cells 10 times longer than thick.
pub fn distorted_aspect() -> Result<Case> {
    distorted(
        "distorted_aspect_10",
        || crate::mesh::io::generate_box([0.1, 0.01, 0.01], [4, 4, 4]),
        "aspect ratio 10: stable at 0.99 of critical; the patch test passes in both integrations",
    )
}

/// A cube skewed by 40° with its interior nodes shifted by up to a quarter cell.
pub fn distorted_skew() -> Result<Case> {
    distorted(
        "distorted_skew",
        skewed_mesh,
        "strong skew (40° shear plus interior nodes moved by up to 1/4 cell): stable at 0.99 of critical; the patch test passes in both integrations",
    )
}

/// The skewed, perturbed 4×4×4 cube of [`distorted_skew`].
pub fn skewed_mesh() -> Mesh {
    let h = 0.01 / 4.0;
    let mut mesh = crate::mesh::io::generate_box([0.01; 3], [4, 4, 4]);
    let boundary: std::collections::HashSet<u32> = mesh.boundary_nodes().into_iter().collect();
    let shear = 40f64.to_radians().tan();
    for (n, x) in mesh.nodes.iter_mut().enumerate() {
        if !boundary.contains(&(n as u32)) {
            // Deterministic pseudo-random shifts in [-h/4, h/4].
            for i in 0..3 {
                let r = (((n * 3 + i) as f64) * 0.618_033_988_75).fract() - 0.5;
                x[i] += 0.5 * h * r;
            }
        }
        x[0] += shear * x[2];
    }
    mesh
}

/// The sagging cantilever: soft, nearly incompressible, damped, under gravity for 2 s.
fn sagging_scene() -> Scene {
    box_scene([0.1, 0.01, 0.01], [20, 2, 2], 3e3, 0.49, true, |s| {
        s.damping = 10.0;
        s.duration = Some(2.0);
    })
    .with_gravity(builders::gravity_down())
}

/// A soft cantilever sagging under its own weight: the stable step shrinks as its elements
/// compress; re-estimating it during the run catches or follows that.
pub fn sagging_cantilever() -> Result<Case> {
    timed(
        "sagging_cantilever_dt",
        |c| {
            let mk = |solver: &dyn Fn(&mut SolverSpec)| -> Result<Problem> {
                problem(&sagging_scene().with_solver(solver))
            };
            // 1. Re-checked every 20 steps, adapting dt: completes; how far the step fell.
            let p = mk(&|s| {
                s.dt_recheck_interval = Some(20);
                s.adapt_dt = true;
            })?;
            let (dt0, crit0) = (p.time_step.dt_s, p.time_step.critical.dt_critical_s);
            let adaptive = solver::run(&p, "sagging, adaptive", &mut ())?;
            let r = &adaptive.report;
            let tip = node_near(&p, [0.1, 0.005, 0.005]);
            let sag = -adaptive.displacements[tip][2];
            c.gt("tip sag / length (large deformation)", sag / 0.1, 0.3);
            // 0.9 × rest critical would be unstable if the step fell by more than 10%.
            c.lt(
                "smallest critical step during the sag / at rest (expected to shrink)",
                r.dt_critical_min_s / crit0,
                0.95,
            );
            c.note(format!(
                "rest critical {crit0:.3e} s (L_e/c {:.3e} s), dt {dt0:.3e} s; smallest critical {:.3e} s = {:.2} of the rest one = {:.2} of L_e/c; {} re-checks, {} reductions; final dt {:.3e} s",
                p.element_dt_estimate().0,
                r.dt_critical_min_s,
                r.dt_critical_min_s / crit0,
                r.dt_critical_min_s / p.element_dt_estimate().0,
                r.dt_rechecks,
                r.dt_reductions,
                r.dt_final_s
            ));
            // 2. The same run without re-checks at 0.9 of the rest step: the step ends up
            // above the shrunken critical one and a guard stops the blow-up.
            let plain = solver::run(&mk(&|_| {})?, "sagging, fixed dt", &mut ());
            c.is(
                "without re-checks (dt = 0.9 × rest critical) the run blows up, caught by a guard",
                plain.is_err(),
                match &plain {
                    Ok(_) => "completed".to_string(),
                    Err(e) => format!("stopped: {e}"),
                },
            );
            // 3. Re-checked without adapting: stops with an error naming the step and the
            // new critical step before any blow-up.
            let e = solver::run(
                &mk(&|s| s.dt_recheck_interval = Some(20))?,
                "sagging, checked",
                &mut (),
            )
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            c.is(
                "re-check without adapt_dt stops with a clear error",
                e.contains("critical step about the deformed state") && e.contains("step "),
                e,
            );
            // 4. The adaptive run's answer equals one at a constant step below every
            // critical step met (0.9 × the smallest found): the rescaled history changed
            // nothing but the step. Settled by damping 10/s over 1.5 s, so 1e-3.
            let mut sc = sagging_scene();
            sc.solver.dt = Some(0.9 * r.dt_critical_min_s);
            let fixed = solver::run(&problem(&sc)?, "sagging, small fixed dt", &mut ())?;
            let sag2 = -fixed.displacements[tip][2];
            c.lt(
                "adaptive tip sag vs a constant small step, relative",
                (sag / sag2 - 1.0).abs(),
                1e-3,
            );
            Ok(())
        },
        "the critical step falls as the cantilever sags; re-checks either stop the run with a clear error or lower dt, and the adapted run matches a constant small step",
    )
}
