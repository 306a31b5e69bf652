//! Step 3 of the search: the solver settings of the held model: a longer step where the
//! model allows one (with contact, first keeping the contact stiffness, see
//! [`PENALTY_MAX`]), mass scaling ([`MASS_SCALINGS`]: the step grows by its root), then f32.

use anyhow::Result;
use pe_firmware::image::Precision;

use super::search::{Held, Model, Search};
use super::{MASS_SCALINGS, PENALTY_MAX};
use crate::problem::Problem;
use crate::scene::Scene;

/// A change of the held model's scene.
type Tweak = Box<dyn Fn(&mut Scene)>;

/// The settings the held model tries, in order, each named by its row's choice.
fn tweaks(held: &Held) -> Vec<(String, Tweak)> {
    let mut tweaks: Vec<(String, Tweak)> = Vec::new();
    // A longer step where the model allows it. With contact, the penalty is a fraction β of
    // m/dt²: the first try keeps the contact stiffness (β grows with dt², up to
    // PENALTY_MAX), the second takes the model's own critical step with the scene's β.
    let (dt, ts) = (held.problem.time_step.dt_s, held.problem.time_step);
    let longest = held.problem.solver.dt_safety * ts.critical.dt_critical_s;
    if let Some(beta) = held.problem.contact.as_ref().map(|c| c.settings.penalty) {
        let dt_new = longest.min(dt * (PENALTY_MAX / beta).sqrt());
        if dt_new > 1.02 * dt {
            let beta_new = beta * (dt_new / dt).powi(2);
            tweaks.push((
                format!("a {:.2}x longer step, the contact stiffness kept (penalty {beta} -> {beta_new:.3})", dt_new / dt),
                Box::new(move |sc: &mut Scene| {
                    sc.solver.dt = Some(dt_new);
                    if let Some(c) = &mut sc.contact {
                        c.penalty = beta_new;
                    }
                }),
            ));
        }
    }
    if longest > 1.02 * dt {
        tweaks.push((
            "the step from the model's own critical step".to_string(),
            Box::new(|sc: &mut Scene| sc.solver.dt = None),
        ));
    }
    for m in MASS_SCALINGS {
        tweaks.push((
            format!("mass scaling {m}"),
            Box::new(move |sc: &mut Scene| {
                sc.solver.mass_scaling = m;
                sc.solver.dt = None;
            }),
        ));
    }
    tweaks.push((
        "precision f32".to_string(),
        Box::new(|sc: &mut Scene| sc.solver.precision = Precision::F32),
    ));
    tweaks
}

/// Tries each of [`tweaks`] on the held model, holding each that passes (a longer step and
/// a mass scaling once each, f32 once).
pub(super) fn try_settings(s: &mut Search<'_>, held: &mut Held) -> Result<()> {
    let tweaks = tweaks(held);
    let mut longer = false;
    let mut scaled = false;
    for (choice, apply) in tweaks {
        if scaled && choice.starts_with("mass") {
            continue;
        }
        let cur = match &held.model {
            Model::Full { scene, .. } => scene.solver.clone(),
            Model::Pruned(r) => r.scene.solver.clone(),
        };
        if choice == "precision f32" && cur.precision == Precision::F32 {
            continue;
        }
        if (choice.starts_with("the step") || choice.starts_with("a "))
            && (longer || cur.dt.is_none())
        {
            continue;
        }
        if choice.starts_with("mass") && cur.mass_scaling != 1.0 {
            continue;
        }
        let mut model = held.model.clone();
        let p = match &mut model {
            Model::Full { scene, .. } => {
                apply(scene);
                Problem::from_scene(scene, s.dir)?
            }
            Model::Pruned(r) => {
                apply(&mut r.scene);
                r.problem()?
            }
        };
        let view = held.view.clone();
        if let Some(t) = s.try_model(&choice, &p, &view)? {
            scaled |= choice.starts_with("mass");
            longer |= choice.starts_with("a ") || choice.starts_with("the step");
            *held = Held {
                model,
                problem: p,
                trace: t,
                view,
            };
        }
    }
    Ok(())
}
