//! The hourglass controls (`[solver] hourglass`: the physical form and the scalar form's
//! coefficients) against references that do not depend on them: beam theory for MacNeal and Harder's straight cantilever (regular,
//! trapezoidal and parallelogram cells), the converged value of Cook's membrane, and the
//! closed form of a neo-Hookean block under homogeneous compression.
//!
//! The static solutions are those of the solver's own discrete problem: the tangent
//! stiffness is assembled from the elements' internal forces (the same kernels `pe solve`
//! runs) by central differences, probing all nodes of one colour of a distance-2 colouring
//! at once, and solved with a banded Cholesky factorisation (Newton iterations for the
//! large-strain block). The linear cases are the small-load limit of the solver's static
//! equilibrium, the state a damped explicit run settles to; `tests/solver/hourglass.rs` checks
//! one against a damped explicit run.
//!
//! `pe hourglass-study` prints the study's tables (`docs/measurements/hourglass-calibration.md`).

use anyhow::Result;
use pe_firmware::image::Integration;
use pe_firmware::physics::HourglassControl;

mod cases;
mod grid;
mod statics;

pub use cases::*;
pub use grid::*;
pub use statics::*;

/// The forms the study compares: the physical form and the scalar one's coefficients.
pub const COEFFICIENTS: [HourglassControl; 8] = [
    HourglassControl::Physical,
    HourglassControl::Scalar(0.01),
    HourglassControl::Scalar(0.03),
    HourglassControl::Scalar(0.05),
    HourglassControl::Scalar(0.1),
    HourglassControl::Scalar(0.2),
    HourglassControl::Scalar(0.3),
    HourglassControl::Scalar(0.5),
];

/// One row of a table: a case's name, its reference and its result at each coefficient
/// (and with full integration, which has no hourglass control).
pub struct Row {
    pub name: String,
    pub reference: f64,
    pub reduced: Vec<f64>,
    pub full: f64,
}

fn pct(v: f64, r: f64) -> String {
    format!("{:+.2}", 100.0 * (v / r - 1.0))
}

/// Markdown table of rows: error in % of the reference per coefficient.
pub fn table(title: &str, rows: &[Row], coefficients: &[HourglassControl]) -> String {
    let mut s = format!("#### {title}\n\n| case | reference |");
    for c in coefficients {
        s += &format!(" {c} |");
    }
    s += " full |\n|---|---|";
    for _ in coefficients {
        s += "---|";
    }
    s += "---|\n";
    for r in rows {
        s += &format!("| {} | {:.5e} |", r.name, r.reference);
        for v in &r.reduced {
            s += &format!(" {} |", pct(*v, r.reference));
        }
        s += &format!(" {} |\n", pct(r.full, r.reference));
    }
    s
}

fn sweep(
    coefficients: &[HourglassControl],
    name: String,
    reference: f64,
    run: impl Fn(Integration, HourglassControl) -> Result<f64>,
) -> Result<Row> {
    let reduced = coefficients
        .iter()
        .map(|&c| run(Integration::Reduced, c))
        .collect::<Result<Vec<_>>>()?;
    let full = run(Integration::Full, HourglassControl::DEFAULT)?;
    eprintln!("  {name}: done");
    Ok(Row {
        name,
        reference,
        reduced,
        full,
    })
}

/// The whole study as markdown: error (%) of each case at each coefficient.
pub fn study(coefficients: &[HourglassControl]) -> Result<String> {
    let mut out = String::new();
    // (a) MacNeal-Harder cantilever.
    for load in [TipLoad::Shear, TipLoad::Moment] {
        out += &macneal_harder_table(coefficients, load)?;
        out += "\n";
    }
    out += &slender_cantilever_table(coefficients)?;
    out += "\n";
    // (b) Cook's membrane.
    out += &cook_table(coefficients)?;
    out += "\n";
    // (c) Block compression.
    out += &block_table(coefficients)?;
    Ok(out)
}

/// MacNeal-Harder's cantilever under `load`: regular, trapezoidal and parallelogram cells
/// through several depths, then cubic cells (regular and slanted).
fn macneal_harder_table(coefficients: &[HourglassControl], load: TipLoad) -> Result<String> {
    let mut rows = Vec::new();
    for cells in [Cells::Regular, Cells::Trapezoidal, Cells::Parallelogram] {
        let depths: &[usize] = if cells == Cells::Regular {
            &[1, 2, 4, 8]
        } else {
            &[1, 2, 4]
        };
        for &ny in depths {
            let c = Cantilever::macneal_harder(ny, cells, load);
            let name = format!("{} {}x{}x{}", cells.name(), c.n[0], c.n[1], c.n[2]);
            rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                c.tip(i, h)
            })?);
        }
    }
    // Cubic cells (aspect 1) through the same depth; distorted: interfaces slanted at
    // 11° (45° would fold cubes against the square ends).
    for (cells, slant, depths) in [
        (Cells::Regular, 0.0, &[2usize, 4, 8][..]),
        (Cells::Parallelogram, 0.2, &[4][..]),
        (Cells::Trapezoidal, 0.2, &[4][..]),
    ] {
        for &ny in depths {
            let mut c = Cantilever::macneal_harder(ny, cells, load);
            c.n = [30 * ny, ny, (ny / 2).max(1)];
            c.slant = slant;
            let name = format!(
                "{} cubes{} {}x{}x{}",
                cells.name(),
                if slant > 0.0 && slant < 1.0 {
                    " (±11°)"
                } else {
                    ""
                },
                c.n[0],
                c.n[1],
                c.n[2]
            );
            rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                c.tip(i, h)
            })?);
        }
    }
    let title = match load {
        TipLoad::Shear => "MacNeal-Harder cantilever, tip shear (Timoshenko; MH's 0.1081)",
        TipLoad::Moment => "MacNeal-Harder cantilever, end moment (ML²/2EI)",
    };
    Ok(table(title, &rows, coefficients))
}

/// Soft slender cantilevers (L/h = 10, square section, cubic cells), ν = 0.3 and 0.49.
fn slender_cantilever_table(coefficients: &[HourglassControl]) -> Result<String> {
    let mut rows = Vec::new();
    for nu in [0.3, 0.49] {
        for n in [2, 4] {
            let c = Cantilever {
                l: 0.1,
                h: 0.01,
                b: 0.01,
                e: 5e3,
                nu,
                n: [10 * n, n, n],
                cells: Cells::Regular,
                slant: 0.0,
                load: TipLoad::Shear,
            };
            let name = format!("L/h=10 nu={nu} {}x{}x{}", c.n[0], c.n[1], c.n[2]);
            rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                c.tip(i, h)
            })?);
        }
    }
    Ok(table(
        "Square cantilever L/h = 10, E = 5 kPa, tip shear (Timoshenko, Cowper's κ)",
        &rows,
        coefficients,
    ))
}

/// Cook's membrane from 2x2 to 48x48 cells.
fn cook_table(coefficients: &[HourglassControl]) -> Result<String> {
    let mut rows = Vec::new();
    for m in [2, 4, 8, 16, 32, 48] {
        rows.push(sweep(
            coefficients,
            format!("{m}x{m}x1"),
            COOK_REFERENCE,
            |i, h| cook_tip(m, i, h),
        )?);
    }
    Ok(table(
        "Cook's membrane, top-right vertical displacement (plane stress, converged 25.18)",
        &rows,
        coefficients,
    ))
}

/// The distorted block compressed by 20%: its lateral stretch and nominal stress.
fn block_table(coefficients: &[HourglassControl]) -> Result<String> {
    let (e, nu, l) = (3000.0, 0.45, 0.8);
    let (t_ref, p_ref) = neo_hookean_uniaxial(e, nu, l);
    let mut rows_t = Vec::new();
    let mut rows_p = Vec::new();
    let mut ts = Vec::new();
    let mut ps = Vec::new();
    for &c in coefficients {
        let (t, p) = block_compression(4, e, nu, l, c)?;
        ts.push(t);
        ps.push(p);
    }
    rows_t.push(Row {
        name: "4x4x4 distorted, lateral stretch".into(),
        reference: t_ref,
        reduced: ts,
        full: f64::NAN,
    });
    rows_p.push(Row {
        name: "4x4x4 distorted, nominal stress (Pa)".into(),
        reference: p_ref,
        reduced: ps,
        full: f64::NAN,
    });
    rows_t.extend(rows_p);
    Ok(table(
        "Block, 20% compression between frictionless faces (neo-Hookean E = 3 kPa, ν = 0.45)",
        &rows_t,
        coefficients,
    ))
}
