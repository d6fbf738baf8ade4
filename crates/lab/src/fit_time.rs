//! `sublevel-lab fit-time [MESH]`: the paper's construction-time figure
//! (`fig:bv_construction_time`): fit time against degree for log det P (eq. "VAG.log.det") and log det H (Magnani et al., eq.
//! "Magnani.log.det") on the chair, measured in one run. Run it from the repository root (the
//! default `MESH` is a relative path).
//!
//! Measurements are interleaved (repeat r: every degree, every method) so that load changes on a
//! shared machine hit both methods alike; each figure is the median over the repeats (`--repeats`
//! for 2d ≤ 4, one run for higher degrees, which take seconds each). Reported: Clarabel's solve
//! time (the paper's SDP time) and the whole fit's time, and the ratio H/P of the solve medians.

use super::csv_file::CsvFile;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};
use sublevel_fit::{fit_points, mesh::load_points, FitMethod, FitSettings};

/// Arguments of `sublevel-lab fit-time`.
#[derive(clap::Args, Debug)]
pub struct FitTimeArgs {
    /// Mesh to fit.
    #[arg(default_value = "data/psb/chair_101.off")]
    pub mesh: PathBuf,
    /// Total degrees 2d, comma separated.
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',')]
    pub degrees: Vec<usize>,
    /// Formulations, comma separated (logdet_p, trace_p, logdet_h, trace_h, inverse_moment).
    #[arg(long, default_value = "logdet_p,logdet_h", value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Repeats for degrees 2d ≤ 4 (higher degrees run once).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Monte Carlo samples of each fit's volume (not part of the solve time).
    #[arg(long, default_value_t = 50_000)]
    pub samples: usize,
    /// CSV output: method, degree, repeat, solve_seconds, total_seconds, volume, status.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// PNG chart: median solve time against degree, log-scale y.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// One timed fit.
#[derive(Clone, Debug)]
struct Sample {
    method: FitMethod,
    degree: usize,
    repeat: usize,
    solve: Real,
    total: Real,
    volume: Real,
    status: String,
}

fn median(mut v: Vec<Real>) -> Option<Real> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// Runs `sublevel-lab fit-time`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `methods`, `degrees` or `repeats`; mesh, CSV or PNG I/O
/// errors. A failing fit is recorded with its error, not returned.
pub fn run(args: FitTimeArgs) -> Result<()> {
    let methods: Vec<FitMethod> = args.methods.iter().map(|m| m.trim().parse()).collect::<Result<_>>()?;
    if methods.is_empty() {
        return Err(Error::invalid("methods", "name at least one method"));
    }
    if args.degrees.is_empty() || args.degrees.iter().any(|d| !sublevel_core::body::SUPPORTED_DEGREES.contains(d)) {
        return Err(Error::invalid("degrees", format!("must be among 2, 4, 6, 8, got {:?}", args.degrees)));
    }
    if args.repeats == 0 {
        return Err(Error::invalid("repeats", "must be at least 1"));
    }
    let points = load_points(&args.mesh)?;
    let reps = |degree: usize| if degree <= 4 { args.repeats } else { 1 };
    let max_reps = args.degrees.iter().map(|&d| reps(d)).max().unwrap_or(1);
    let mut samples: Vec<Sample> = Vec::new();
    for repeat in 0..max_reps {
        for &degree in &args.degrees {
            if repeat >= reps(degree) {
                continue;
            }
            for &method in &methods {
                let settings = FitSettings { degree, method, volume_samples: args.samples, ..FitSettings::default() };
                let s = match fit_points(&points, &settings, &mut |_| {}) {
                    Ok(b) => Sample {
                        method,
                        degree,
                        repeat,
                        solve: b.report.solve_seconds,
                        total: b.report.total_seconds,
                        volume: b.report.volume,
                        status: b.report.solver_status.to_string(),
                    },
                    Err(e) => Sample {
                        method,
                        degree,
                        repeat,
                        solve: Real::NAN,
                        total: Real::NAN,
                        volume: Real::NAN,
                        status: e.to_string(),
                    },
                };
                eprintln!(
                    "repeat {} degree {} {}: solve {:.3} s, total {:.3} s, volume {:.4} ({})",
                    repeat + 1,
                    degree,
                    method.name(),
                    s.solve,
                    s.total,
                    s.volume,
                    s.status
                );
                samples.push(s);
            }
        }
    }

    // Medians per (method, degree).
    let med = |m: FitMethod, d: usize, total: bool| {
        median(
            samples
                .iter()
                .filter(|s| s.method == m && s.degree == d && s.solve.is_finite())
                .map(|s| if total { s.total } else { s.solve })
                .collect(),
        )
    };
    let fmt = |v: Option<Real>| v.map_or_else(|| "—".to_string(), |v| format!("{v:.3}"));
    print!("{:>4} {:>4}", "2d", "runs");
    for m in &methods {
        print!("  {:>16} {:>16}", format!("{} solve [s]", m.name()), format!("{} total [s]", m.name()));
    }
    let ratio_of = methods
        .iter()
        .position(|m| *m == FitMethod::LogDetH)
        .zip(methods.iter().position(|m| *m == FitMethod::LogDetP));
    if ratio_of.is_some() {
        print!("  {:>12}", "ratio H/P");
    }
    println!();
    for &d in &args.degrees {
        print!("{d:>4} {:>4}", reps(d));
        for &m in &methods {
            print!("  {:>16} {:>16}", fmt(med(m, d, false)), fmt(med(m, d, true)));
        }
        if let Some((h, p)) = ratio_of {
            let r = med(methods[h], d, false).zip(med(methods[p], d, false)).map(|(h, p)| h / p);
            print!("  {:>12}", r.map_or_else(|| "—".to_string(), |r| format!("{r:.2}")));
        }
        println!();
    }

    if let Some(path) = &args.csv {
        let mut csv = CsvFile::create(
            path,
            &["method", "degree", "repeat", "solve_seconds", "total_seconds", "volume", "status"],
        )?;
        for s in &samples {
            csv.record([
                s.method.name().to_string(),
                s.degree.to_string(),
                s.repeat.to_string(),
                s.solve.to_string(),
                s.total.to_string(),
                s.volume.to_string(),
                s.status.clone(),
            ])?;
        }
        eprintln!("wrote {}", csv.finish()?.display());
    }
    if let Some(path) = &args.png {
        let series: Vec<(String, Vec<(f64, f64)>)> = methods
            .iter()
            .map(|&m| {
                let pts = args.degrees.iter().filter_map(|&d| med(m, d, false).map(|t| (d as f64, t))).collect();
                (m.name().to_string(), pts)
            })
            .collect();
        match draw(path, &series) {
            Ok(()) => eprintln!("wrote {}", path.display()),
            Err(e) => eprintln!("could not draw {}: {e}", path.display()),
        }
    }
    Ok(())
}

fn draw(path: &Path, series: &[(String, Vec<(f64, f64)>)]) -> std::result::Result<(), Box<dyn std::error::Error>> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let all: Vec<f64> = series.iter().flat_map(|(_, p)| p.iter().map(|q| q.1)).filter(|t| *t > 0.0).collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min).min(1.0) / 2.0;
    let hi = all.iter().copied().fold(0.0, f64::max).max(lo * 10.0) * 2.0;
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption("Bounding volume construction times (chair)", ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(1.5f64..8.5, (lo..hi).log_scale())?;
    chart.configure_mesh().x_desc("degree 2d").y_desc("median solve time [s] (log scale)").draw()?;
    let colors = [BLUE, RED, GREEN, MAGENTA, CYAN];
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = colors[i % colors.len()];
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 5, color.filled())))?;
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
    root.present()?;
    Ok(())
}
