//! The trade-off study's outputs: the table as CSV and markdown, the full-against-reduced
//! summary, and the error-against-cost plot.

use super::*;

/// The CSV: one row per configuration, a header naming every column.
pub fn to_csv(rows: &[Row]) -> Result<String> {
    let header: Vec<String> = match serde_json::to_value(rows.first())? {
        serde_json::Value::Object(m) => m.keys().cloned().collect(),
        _ => vec![],
    };
    // serde_json's map is sorted; keep the struct's order instead.
    let order = [
        "varied",
        "precision",
        "integration",
        "hourglass",
        "dt_safety",
        "level",
        "mass_scaling",
        "elements",
        "nodes",
        "dt_s",
        "steps",
        "simulated_s",
        "wall_s",
        "host_ns_per_element_step",
        "real_time_factor",
        "board_instructions_per_element_step",
        "compared_nodes",
        "u_err_max_m",
        "u_err_rms_m",
        "u_err_max_rel",
        "u_err_rms_rel",
        "qoi",
        "qoi_value",
        "qoi_err_rel",
        "energy_j",
        "energy_err_rel",
        "pareto",
    ];
    debug_assert_eq!(header.len(), order.len());
    let values = rows
        .iter()
        .map(serde_json::to_value)
        .collect::<Result<Vec<_>, _>>()?;
    let records = values.iter().map(|v| {
        order.iter().map(|k| match &v[*k] {
            serde_json::Value::String(s) => s.clone(),
            serde_json::Value::Null => String::new(),
            other => other.to_string(),
        })
    });
    crate::output::csv_string(&order, records)
}

/// Cost ratio full/reduced and the accuracy of each, per precision, from the cross rows at
/// the baseline.
pub fn full_reduced(rows: &[Row]) -> Vec<(String, f64, f64, f64)> {
    let base = rows.iter().find(|r| r.varied == "baseline");
    let mut v = Vec::new();
    for p in [Precision::F64, Precision::F32] {
        let find = |i: Integration| {
            rows.iter().find(|r| {
                r.precision == p
                    && r.integration == i
                    && base.is_some_and(|b| {
                        r.level == b.level
                            && r.dt_safety == b.dt_safety
                            && r.mass_scaling == b.mass_scaling
                            && (i == Integration::Full || r.hourglass == b.hourglass)
                    })
            })
        };
        if let (Some(f), Some(red)) = (find(Integration::Full), find(Integration::Reduced)) {
            v.push((
                p.to_string(),
                f.host_ns_per_element_step / red.host_ns_per_element_step,
                red.u_err_rms_rel,
                f.u_err_rms_rel,
            ));
        }
    }
    v
}

/// The markdown report: table, full/reduced cost ratio, how errors were measured.
pub fn to_markdown(rows: &[Row], name: &str, profile: &BoardProfile) -> String {
    let mut s = format!("# Speed/accuracy trade-off: {name}\n\n");
    if let Some(r) = rows.first() {
        let _ = writeln!(
            s,
            "Reference: {} {} integration, level {}, dt safety {}, mass scaling {} ({} elements, {} steps, {:.1} s wall). Errors are at the end of {:.3} s simulated, relative ones over the reference's largest displacement (u) or its value (quantity of interest `{}`, energy = stored + kinetic). Cost: host wall time on one thread of this machine. `board instr/elem-step`: {}. `*` marks the Pareto front of (wall s per simulated s, RMS displacement error).\n",
            r.precision, r.integration, r.level, r.dt_safety, r.mass_scaling, r.elements, r.steps, r.wall_s, r.simulated_s, r.qoi, board_note(profile)
        );
    }
    s.push_str("| varied | prec. | integr. | hg | safety | level | mass sc. | elements | steps | wall s | ns/elem-step | RTF | board instr/elem-step | u max err | u RMS err | QoI err | energy err | Pareto |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let hg = if r.integration == Integration::Full {
            "–".to_string()
        } else {
            format!("{}", r.hourglass)
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {:.0} | {:.3} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {} |",
            r.varied,
            r.precision,
            r.integration,
            hg,
            r.dt_safety,
            r.level,
            r.mass_scaling,
            r.elements,
            r.steps,
            r.wall_s,
            r.host_ns_per_element_step,
            r.real_time_factor,
            r.board_instructions_per_element_step,
            r.u_err_max_rel,
            r.u_err_rms_rel,
            r.qoi_err_rel,
            r.energy_err_rel,
            if r.pareto { "*" } else { "" }
        );
    }
    s.push_str("\n## Full against reduced integration\n\n");
    s.push_str("The seed claims reduced integration is 5 to 7 times cheaper than full.\n\n");
    s.push_str("| precision | measured cost full/reduced (host ns per element-step) | reduced: u RMS err | full: u RMS err |\n|---|---|---|---|\n");
    for (p, ratio, er, ef) in full_reduced(rows) {
        let _ = writeln!(s, "| {p} | {ratio:.2} | {er:.2e} | {ef:.2e} |");
    }
    s.push_str("\n## How the errors are measured\n\n");
    s.push_str("- Nodal displacement: at every node of the configuration's mesh, against the reference's field at the same point: node by node on the reference's own mesh, otherwise interpolated with the trilinear shape functions of the reference cell that holds the point (found by inverting the cell map); nodes more than a quarter cell outside the reference mesh are left out (`compared_nodes` in the CSV).\n");
    s.push_str("- Quantity of interest: the force of the tissue on the first tool (the probe) when the scene has tools, else the force the prescribed nodes exert on the tissue when the scene prescribes motion, otherwise the mean displacement of the tip face (largest x); the norm of the vector difference over the reference's norm.\n");
    s.push_str("- Energy: stored + kinetic energy at the end, relative to the reference's.\n");
    s.push_str("- Wall time is measured on a shared 2-core machine: expect ±20% between runs.\n");
    s
}

/// The PNG: error against cost, log axes, Pareto front drawn as a line, points labelled.
pub fn plot(rows: &[Row], path: &Path, title: &str) -> Result<()> {
    use plotters::prelude::*;
    crate::output::font::register_font();
    let pts: Vec<(f64, f64, &Row)> = rows
        .iter()
        .filter(|r| r.varied != "reference")
        .map(|r| (1.0 / r.real_time_factor, r.u_err_rms_rel.max(1e-16), r))
        .collect();
    if pts.is_empty() {
        bail!("nothing to plot");
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y, _) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    let (x0, x1, y0, y1) = (x0 / 2.0, x1 * 3.0, y0 / 3.0, y1 * 3.0);
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    let err = |e: &dyn std::fmt::Debug| anyhow::anyhow!("plotting {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("cost: host wall seconds per simulated second (1 / real-time factor)")
        .y_desc("RMS nodal displacement error / max reference displacement")
        .x_label_formatter(&|v| format!("{v:.2e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 18))
        .draw()
        .map_err(|e| err(&e))?;
    let mut front: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.2.pareto)
        .map(|p| (p.0, p.1))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front.clone(), RED.stroke_width(2)))
        .map_err(|e| err(&e))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    let colour = |r: &Row| match r.varied.as_str() {
        "baseline" => BLACK,
        "precision×integration" => BLUE,
        "hourglass" => GREEN,
        "dt_safety" => MAGENTA,
        "level" => CYAN,
        _ => RGBColor(230, 140, 0),
    };
    for group in [
        "baseline",
        "precision×integration",
        "hourglass",
        "dt_safety",
        "level",
        "mass_scaling",
    ] {
        let g: Vec<&(f64, f64, &Row)> = pts.iter().filter(|p| p.2.varied == group).collect();
        if g.is_empty() {
            continue;
        }
        let c = colour(g[0].2);
        chart
            .draw_series(g.iter().map(|p| Circle::new((p.0, p.1), 6, c.filled())))
            .map_err(|e| err(&e))?
            .label(format!("varied: {group}"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 6, c.filled()));
    }
    chart
        .draw_series(
            front
                .iter()
                .map(|p| Circle::new(*p, 11, RED.stroke_width(2))),
        )
        .map_err(|e| err(&e))?;
    // Short labels: what differs from the baseline; alternately above and below the
    // point so that neighbours do not overwrite each other.
    for (k, (x, y, r)) in pts.iter().enumerate() {
        let text = match r.varied.as_str() {
            "baseline" => format!("baseline ({} {})", r.precision, r.integration),
            "precision×integration" => format!("{} {}", r.precision, r.integration),
            "hourglass" => format!("hourglass {}", r.hourglass),
            "dt_safety" => format!("safety {}", r.dt_safety),
            "level" => format!("level {}", r.level),
            "mass_scaling" => format!("mass ×{}", r.mass_scaling),
            other => other.to_string(),
        };
        let dy = if k % 2 == 0 { 1.12 } else { 0.86 };
        chart
            .draw_series(std::iter::once(Text::new(
                text,
                (*x * 1.1, *y * dy),
                ("sans-serif", 14).into_font(),
            )))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
