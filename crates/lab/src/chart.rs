//! `sublevel-lab chart`: speed against accuracy of the collision models, and the Newton tolerance's
//! price, as CSV and PNG (plotters, bitmap backend). Run it from the repository root (the default
//! `--psb` and `--bodies` folders are relative paths).
//!
//! ```text
//! speed-accuracy   x = median cold distance-query time (µs, log scale), y = |distance − exact
//!                  mesh–mesh distance| (mean and max over the separated poses, meters); one point
//!                  per model: sos-convex 2d = 2/4/6/8, convex hull (parry GJK), [+ baselines],
//!                  compound models (`--compound CHAIR:HUMAN`, per `--bound-tolerances`), and the
//!                  coal peers (`--peer coal.txt`: hull GJK, exact mesh BVH); the table adds the
//!                  median warm time (smooth motion), the conservative share (answers ≤ exact)
//!                  and, for compound models, the level histogram of the margin query
//! tolerance        x = Newton KKT tolerance 1e-4 … 1e-12 (log), y = median time and the error
//!                  against the tolerance-1e-12 answer, per degree
//! ```
//!
//! A model is a [`ModelRow`] (name, time, errors); adding one is adding a row (see
//! [`extra_model_rows`], which holds the sphere, oriented-box and relaxed-convexity models).

use super::bench::{cold_poses, load_or_fit_body, median, motion_poses, time_us};
use super::chart_compound::{compound_rows, conservative_share, CompoundPair};
use super::csv_file::CsvFile;
use super::peer_coal::CoalPeer;
use super::peer_parry::{error_stats, load_off_mesh, parry_pose, PeerShapes};
use plotters::prelude::*;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::{Error, Result};
use sublevel_fit::mesh::load_points;
use sublevel_query::{distance, NewtonParams};

/// Arguments of `sublevel-lab chart`.
#[derive(clap::Args, Debug)]
pub struct ChartArgs {
    /// Which chart.
    #[command(subcommand)]
    kind: ChartKind,
}

/// The charts.
#[derive(clap::Subcommand, Debug)]
enum ChartKind {
    /// Query time against distance error per model (sos-convex degrees, hull GJK, baselines).
    SpeedAccuracy(CommonArgs),
    /// Newton KKT tolerance against median query time and error vs the 1e-12 answer.
    Tolerance(CommonArgs),
}

/// Options shared by both charts.
#[derive(clap::Args, Debug)]
struct CommonArgs {
    /// Folder with the PSB meshes (`SHAPE.off` and human_10.off).
    #[arg(long, default_value = "data/psb")]
    psb: std::path::PathBuf,
    /// The posed shape, against human_10 at the identity: chair_101 (default, the pair of the paper's Table 2),
    /// hand_181, octopus_121 or vase_361 (any `SHAPE.off` in `--psb`).
    #[arg(long, default_value = "chair_101")]
    shape: String,
    /// Folder of fitted bodies `{SHAPE,human_10}.deg{2d}.json` (missing ones are fitted).
    #[arg(long, default_value = "tests/data")]
    bodies: std::path::PathBuf,
    /// Degrees 2d, comma separated.
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',')]
    degrees: Vec<usize>,
    /// Random poses of the shape around the human (the exact mesh–mesh distance is computed at each).
    #[arg(long, default_value_t = 100)]
    poses: usize,
    /// Back-to-back calls averaged per timed query.
    #[arg(long, default_value_t = 20)]
    repeats: usize,
    /// Seed of the poses (same as `sublevel-lab bench`).
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// CSV output.
    #[arg(long)]
    csv: Option<std::path::PathBuf>,
    /// PNG output.
    #[arg(long)]
    png: Option<std::path::PathBuf>,
    /// Speed-accuracy: a compound model pair `CHAIR.json:HUMAN.json` (files of `sublevel fit
    /// --parts`; either may be a single body); repeat for several part counts.
    #[arg(long)]
    compound: Vec<String>,
    /// Speed-accuracy: query tolerances (upper − lower, meters) of the compound models.
    #[arg(long, default_value = "0", value_delimiter = ',')]
    bound_tolerances: Vec<f64>,
    /// Speed-accuracy: margin of the "closer than m?" query whose level histogram is reported (m).
    #[arg(long, default_value_t = 0.05)]
    margin: f64,
    /// Speed-accuracy: steps of the smooth motion for the warm times (the recipe of `sublevel-lab bench`
    /// and of the coal script).
    #[arg(long, default_value_t = 500)]
    motion: usize,
    /// Speed-accuracy: output of the coal peer benchmark (`bash PEERS/coal/run.sh A.off B.off >
    /// coal.txt`, PEERS being where the peer benchmarks are checked out): its hull GJK and exact
    /// mesh BVH rows are added.
    #[arg(long)]
    peer: Option<std::path::PathBuf>,
}

/// One model of the speed-accuracy chart.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelRow {
    /// Display name, e.g. `sos 2d=6` or `hull (parry GJK)`.
    pub name: String,
    /// Median cold distance-query time in microseconds.
    pub time_us: Real,
    /// Median warm distance-query time along the smooth motion (µs); NaN when not measured.
    pub warm_us: Real,
    /// Mean |distance − exact| over separated poses (meters).
    pub err_mean: Real,
    /// Max |distance − exact| over separated poses (meters).
    pub err_max: Real,
    /// Share of answers ≤ the exact mesh distance over all poses (1 = conservative); NaN when not
    /// measured.
    pub conservative: Real,
    /// Compound models: how many margin queries were decided at tree level 0, 1, …
    pub levels: Option<Vec<usize>>,
}

/// The baseline models of Table 1 and the relaxed-convexity body, timed and scored on `poses`
/// (chair posed, human at the identity) against `exact`:
///
/// - bounding sphere (exact minimum ball, `sublevel_fit::baselines::min_enclosing_ball`): closed-form
///   distance max(0, ‖c₁ − c₂‖ − r₁ − r₂);
/// - oriented box (`sublevel_fit::baselines::min_volume_obb`): parry3d's cuboid–cuboid distance;
/// - sos c = 10, 2d = 4 (eq. "VAG.param.convex", fitted here): the level-0 SDP lower bound of
///   `sublevel_query::certified_distance` (nonconvex bodies), timed once per pose (an SDP per query).
///
/// # Errors
/// A failed baseline or fit.
pub fn extra_model_rows(
    chair: &[sublevel_core::math::Point3],
    human: &[sublevel_core::math::Point3],
    poses: &[Isometry3],
    exact: &[Real],
    repeats: usize,
) -> Result<Vec<ModelRow>> {
    use sublevel_fit::baselines::{convex_hull, min_enclosing_ball, min_volume_obb, OrientedBox};
    let id = Isometry3::identity();
    let mut rows = Vec::new();
    let score = |name: &str, times: Vec<Real>, dists: Vec<Real>| {
        let (err_mean, err_max) = error_stats(&dists, exact);
        let conservative = conservative_share(&dists, exact);
        ModelRow {
            name: name.into(),
            time_us: median(times),
            warm_us: Real::NAN,
            err_mean,
            err_max,
            conservative,
            levels: None,
        }
    };

    let (ball_a, ball_b) = (min_enclosing_ball(chair, 1)?, min_enclosing_ball(human, 1)?);
    let (mut times, mut dists) = (Vec::new(), Vec::new());
    for p in poses {
        let (us, d) = time_us(repeats, || {
            let gap = (p * ball_a.center - ball_b.center).norm() - ball_a.radius - ball_b.radius;
            gap.max(0.0)
        });
        times.push(us);
        dists.push(d);
    }
    rows.push(score("sphere", times, dists));

    let cuboid = |b: &OrientedBox| -> Result<(parry3d_f64::shape::Cuboid, Isometry3)> {
        let m = sublevel_core::math::Matrix3::from_columns(&b.axes);
        let r = nalgebra::Rotation3::from_matrix_eps(&m, 1e-12, 100, nalgebra::Rotation3::identity());
        let h = b.half_extents;
        let pose = Isometry3::from_parts(b.center.coords.into(), nalgebra::UnitQuaternion::from_rotation_matrix(&r));
        Ok((parry3d_f64::shape::Cuboid::new(parry3d_f64::math::Vector::new(h.x, h.y, h.z)), pose))
    };
    let (box_a, local_a) = cuboid(&min_volume_obb(&convex_hull(chair)?)?)?;
    let (box_b, local_b) = cuboid(&min_volume_obb(&convex_hull(human)?)?)?;
    let pose_b = parry_pose(&(id * local_b));
    let (mut times, mut dists) = (Vec::new(), Vec::new());
    for p in poses {
        let pose_a = parry_pose(&(p * local_a));
        let (us, d) = time_us(repeats, || {
            parry3d_f64::query::distance(&pose_a, &box_a, &pose_b, &box_b).map_or(Real::NAN, |d| d.distance)
        });
        times.push(us);
        dists.push(d);
    }
    rows.push(score("oriented box", times, dists));

    eprintln!("fitting both meshes with c = 10 at 2d = 4 (relaxed convexity)");
    let settings =
        sublevel_fit::FitSettings { degree: 4, volume_samples: 20_000, ..Default::default() }.with_relaxation(10.0);
    let chair_c = sublevel_fit::fit_points(chair, &settings, &mut |_| {})?;
    let human_c = sublevel_fit::fit_points(human, &settings, &mut |_| {})?;
    let params = sublevel_query::CertifyParams::default();
    let (mut times, mut dists) = (Vec::new(), Vec::new());
    for p in poses {
        let (us, r) = time_us(1, || {
            sublevel_query::certified_distance(
                &chair_c,
                p,
                &human_c,
                &id,
                None,
                &params,
                sublevel_query::CertifyMode::Newton,
            )
        });
        times.push(us);
        dists.push(r.result.distance);
    }
    rows.push(score("sos c=10 2d=4 (lower bound)", times, dists));
    Ok(rows)
}

/// Runs `sublevel-lab chart`.
///
/// # Errors
/// Bad arguments ([`Error::InvalidArgument`] naming the flag), unreadable meshes or bodies, or a
/// failed write.
pub fn run(args: ChartArgs) -> Result<()> {
    match args.kind {
        ChartKind::SpeedAccuracy(a) => speed_accuracy(&a),
        ChartKind::Tolerance(a) => tolerance(&a),
    }
}

fn check(a: &CommonArgs) -> Result<()> {
    if a.repeats == 0 {
        return Err(Error::invalid("--repeats", "must be at least 1"));
    }
    if a.poses == 0 {
        return Err(Error::invalid("--poses", "must be at least 1"));
    }
    Ok(())
}

fn speed_accuracy(a: &CommonArgs) -> Result<()> {
    check(a)?;
    let shape_off = a.psb.join(format!("{}.off", a.shape));
    let chair_mesh = load_off_mesh(&shape_off)?;
    let human_mesh = load_off_mesh(&a.psb.join("human_10.off"))?;
    let peers = PeerShapes::new(&chair_mesh, &human_mesh)?;
    let (chair_pts, human_pts) = (load_points(&shape_off)?, load_points(&a.psb.join("human_10.off"))?);
    let poses = cold_poses(a.seed, a.poses);
    let id = Isometry3::identity();
    eprintln!("exact mesh–mesh distances at {} poses", poses.len());
    let exact: Vec<Real> = poses.iter().map(|p| peers.mesh_distance(p, &id)).collect();
    let params = NewtonParams::default();
    let motion = motion_poses(a.motion);
    let compound: Vec<CompoundPair> = a.compound.iter().map(|c| CompoundPair::load(c)).collect::<Result<_>>()?;
    let mut rows = Vec::new();
    for &degree in &a.degrees {
        let (chair, human) = (
            load_or_fit_body(&a.bodies, &a.shape, degree, &chair_pts)?,
            load_or_fit_body(&a.bodies, "human_10", degree, &human_pts)?,
        );
        let mut times = Vec::new();
        let mut dists = Vec::new();
        for p in &poses {
            let (us, r) = time_us(a.repeats, || distance(&chair, p, &human, &id, None, &params));
            times.push(us);
            dists.push(r.distance);
        }
        let mut warm = Vec::new();
        let mut state = None;
        for (k, p) in motion.iter().enumerate() {
            let (us, r) = time_us(a.repeats, || distance(&chair, p, &human, &id, state.as_deref(), &params));
            if k > 0 {
                warm.push(us);
            }
            state = Some(r.warm_start);
        }
        let (err_mean, err_max) = error_stats(&dists, &exact);
        rows.push(ModelRow {
            name: format!("sos 2d={degree}"),
            time_us: median(times),
            warm_us: median(warm),
            err_mean,
            err_max,
            conservative: conservative_share(&dists, &exact),
            levels: None,
        });
    }
    rows.extend(compound_rows(&compound, &a.bound_tolerances, a.margin, &poses, &motion, &exact, a.repeats)?);
    let mut times = Vec::new();
    let mut dists = Vec::new();
    for p in &poses {
        let (us, d) = time_us(a.repeats, || peers.hull_distance(p, &id));
        times.push(us);
        dists.push(d);
    }
    let mut warm = Vec::new();
    let mut dir = parry3d_f64::math::Vector::ZERO;
    for (k, p) in motion.iter().enumerate() {
        let mut d = dir;
        let (us, _) = time_us(a.repeats, || {
            d = dir;
            peers.hull_distance_warm(p, &id, &mut d)
        });
        dir = d;
        if k > 0 {
            warm.push(us);
        }
    }
    let (err_mean, err_max) = error_stats(&dists, &exact);
    rows.push(ModelRow {
        name: "hull (parry GJK)".into(),
        time_us: median(times),
        warm_us: median(warm),
        err_mean,
        err_max,
        conservative: conservative_share(&dists, &exact),
        levels: None,
    });
    let mesh_us = median(poses.iter().map(|p| time_us(1, || peers.mesh_distance(p, &id)).0).collect());
    rows.push(ModelRow {
        name: "mesh (parry BVH)".into(),
        time_us: mesh_us,
        warm_us: Real::NAN,
        err_mean: 0.0,
        err_max: 0.0,
        conservative: 1.0,
        levels: None,
    });
    if let Some(path) = &a.peer {
        rows.extend(coal_rows(&CoalPeer::load(path)?));
    }
    rows.extend(extra_model_rows(&chair_pts, &human_pts, &poses, &exact, a.repeats)?);

    let n_sep = exact.iter().filter(|d| **d > 0.0).count();
    println!("speed vs accuracy: {} vs human_10, {n_sep} separated of {} poses", a.shape, poses.len());
    println!(
        "{:>30} {:>10} {:>10} {:>13} {:>13} {:>7}  margin {} m levels",
        "model", "cold µs", "warm µs", "err mean [m]", "err max [m]", "≤exact", a.margin
    );
    for r in &rows {
        let levels = r.levels.as_ref().map_or(String::new(), |l| format!("{l:?}"));
        println!(
            "{:>30} {:>10.2} {:>10.2} {:>13.5} {:>13.5} {:>6.1}%  {levels}",
            r.name,
            r.time_us,
            r.warm_us,
            r.err_mean,
            r.err_max,
            100.0 * r.conservative
        );
    }
    if let Some(path) = &a.csv {
        let mut csv = CsvFile::create(
            path,
            &["model", "median_us", "warm_us", "err_mean_m", "err_max_m", "conservative", "margin_levels"],
        )?;
        for r in &rows {
            let levels = r
                .levels
                .as_ref()
                .map_or(String::new(), |l| l.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(" "));
            csv.record([
                r.name.clone(),
                format!("{:.4}", r.time_us),
                format!("{:.4}", r.warm_us),
                format!("{:.6}", r.err_mean),
                format!("{:.6}", r.err_max),
                format!("{:.4}", r.conservative),
                levels,
            ])?;
        }
        eprintln!("wrote {}", csv.finish()?.display());
    }
    if let Some(path) = &a.png {
        let pts: Vec<(String, Real, Real, Real)> =
            rows.iter().map(|r| (r.name.clone(), r.time_us, r.err_mean, r.err_max)).collect();
        plot_points(
            path,
            &format!("Speed vs accuracy ({} vs human_10)", a.shape),
            ("median distance query time [µs] (log)", "|d − d_mesh| [m]"),
            &pts,
            "filled: mean error, ring: max error",
        )?;
    }
    Ok(())
}

/// The coal peer rows (from its own output, its own poses; see [`CoalPeer`]): hull GJK (cold, warm,
/// mean error) and the exact mesh BVH (cold; error 0 by definition).
fn coal_rows(peer: &CoalPeer) -> Vec<ModelRow> {
    vec![
        ModelRow {
            name: "hull (coal GJK)".into(),
            time_us: peer.get("hull_gjk_cold_us"),
            warm_us: peer.get("hull_gjk_warm_us"),
            err_mean: peer.get("hull_err_mean"),
            err_max: Real::NAN,
            conservative: 1.0,
            levels: None,
        },
        ModelRow {
            name: "mesh (coal BVH)".into(),
            time_us: peer.get("mesh_bvh_cold_us"),
            warm_us: Real::NAN,
            err_mean: 0.0,
            err_max: 0.0,
            conservative: 1.0,
            levels: None,
        },
    ]
}

/// Tolerances of the tolerance chart.
pub const TOLERANCES: [Real; 5] = [1e-4, 1e-6, 1e-8, 1e-10, 1e-12];

fn tolerance(a: &CommonArgs) -> Result<()> {
    check(a)?;
    let (chair_pts, human_pts) =
        (load_points(&a.psb.join(format!("{}.off", a.shape)))?, load_points(&a.psb.join("human_10.off"))?);
    let poses = cold_poses(a.seed, a.poses);
    let id = Isometry3::identity();
    let mut rows: Vec<(usize, Real, Real, Real, Real)> = Vec::new();
    for &degree in &a.degrees {
        let (chair, human) = (
            load_or_fit_body(&a.bodies, &a.shape, degree, &chair_pts)?,
            load_or_fit_body(&a.bodies, "human_10", degree, &human_pts)?,
        );
        let tight = NewtonParams { kkt_tolerance: 1e-12, ..NewtonParams::default() };
        let reference: Vec<Real> =
            poses.iter().map(|p| distance(&chair, p, &human, &id, None, &tight).distance).collect();
        for &tol in &TOLERANCES {
            let params = NewtonParams { kkt_tolerance: tol, ..NewtonParams::default() };
            let mut times = Vec::new();
            let mut errs = Vec::new();
            for (p, r) in poses.iter().zip(&reference) {
                let (us, d) = time_us(a.repeats, || distance(&chair, p, &human, &id, None, &params));
                times.push(us);
                errs.push((d.distance - r).abs());
            }
            let mean = errs.iter().sum::<Real>() / errs.len() as Real;
            let max = errs.iter().cloned().fold(0.0, Real::max);
            rows.push((degree, tol, median(times), mean, max));
        }
    }
    println!("Newton KKT tolerance: cold distance, {} vs human_10, {} poses", a.shape, poses.len());
    println!("{:>3} {:>9} {:>11} {:>14} {:>14}", "2d", "tolerance", "median µs", "err mean [m]", "err max [m]");
    for r in &rows {
        println!("{:>3} {:>9.0e} {:>11.2} {:>14.3e} {:>14.3e}", r.0, r.1, r.2, r.3, r.4);
    }
    if let Some(path) = &a.csv {
        let mut csv = CsvFile::create(path, &["degree", "kkt_tolerance", "median_us", "err_mean_m", "err_max_m"])?;
        for r in &rows {
            csv.record([
                r.0.to_string(),
                format!("{:e}", r.1),
                format!("{:.4}", r.2),
                format!("{:e}", r.3),
                format!("{:e}", r.4),
            ])?;
        }
        eprintln!("wrote {}", csv.finish()?.display());
    }
    if let Some(path) = &a.png {
        plot_tolerance(path, &rows)?;
    }
    Ok(())
}

fn plot_err(e: impl std::fmt::Display) -> Error {
    Error::invalid("--png", format!("plotting failed: {e}"))
}

/// Height of a label line in the scatter charts (pixels, 16 px font).
const LABEL_LINE: i32 = 18;

/// Log-x scatter of (name, x, y_mean, y_max): a filled dot at the mean, a ring at the max (not
/// drawn where it is NaN), a label, and `legend` in the top left corner.
pub(crate) fn plot_points(
    path: &std::path::Path,
    title: &str,
    (x_label, y_label): (&str, &str),
    pts: &[(String, Real, Real, Real)],
    legend: &str,
) -> Result<()> {
    let finite = |v: Real| v.is_finite() && v >= 0.0;
    let xs: Vec<Real> = pts.iter().map(|p| p.1).filter(|v| finite(*v) && *v > 0.0).collect();
    let ys: Vec<Real> = pts.iter().flat_map(|p| [p.2, p.3]).filter(|v| finite(*v)).collect();
    if xs.is_empty() || ys.is_empty() {
        return Err(Error::invalid("--png", "no finite points to plot"));
    }
    let (x0, x1) = (xs.iter().cloned().fold(Real::INFINITY, Real::min), xs.iter().cloned().fold(0.0, Real::max));
    let y1 = ys.iter().cloned().fold(0.0, Real::max) * 1.15 + 1e-6;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0 / 2.0..x1 * 2.0).log_scale(), 0.0..y1)
        .map_err(plot_err)?;
    chart.configure_mesh().x_desc(x_label).y_desc(y_label).draw().map_err(plot_err)?;
    let palette = [&BLUE, &RED, &GREEN, &MAGENTA, &CYAN, &BLACK];
    // Labels in pixels: each starts right of its ring (left of it at the right edge) and moves down
    // by a line until it overlaps no label placed before it (close times and errors, e.g. sos
    // 2d = 6 and 8, would collide).
    let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
    let mut labels: Vec<(String, (i32, i32))> = Vec::new();
    for (name, x, mean, max) in pts {
        if !(finite(*x) && *x > 0.0) {
            continue;
        }
        let y_text = if finite(*max) { *max } else { *mean };
        let (mut px, mut py) = chart.backend_coord(&(*x * 1.08, y_text));
        let width = 9 * name.chars().count() as i32;
        // A label that would run off the right edge goes to the left of its point.
        if px + width > root.dim_in_pixel().0 as i32 - 5 {
            px = chart.backend_coord(&(*x, y_text)).0 - width - 10;
        }
        let overlaps = |py: i32, placed: &[(i32, i32, i32, i32)]| {
            placed.iter().any(|&(x0, y0, x1, y1)| px < x1 && x0 < px + width && py < y1 && y0 < py + LABEL_LINE)
        };
        while overlaps(py, &placed) {
            py += LABEL_LINE;
        }
        placed.push((px, py, px + width, py + LABEL_LINE));
        labels.push((name.clone(), (px, py)));
    }
    for (i, (_, x, mean, max)) in pts.iter().enumerate() {
        if !(finite(*x) && *x > 0.0) {
            continue;
        }
        let color = palette[i % palette.len()];
        if finite(*mean) {
            chart.draw_series(std::iter::once(Circle::new((*x, *mean), 6, color.filled()))).map_err(plot_err)?;
        }
        if finite(*max) {
            chart.draw_series(std::iter::once(Circle::new((*x, *max), 6, color.stroke_width(2)))).map_err(plot_err)?;
            chart
                .draw_series(std::iter::once(PathElement::new(vec![(*x, mean.max(0.0)), (*x, *max)], color)))
                .map_err(plot_err)?;
        }
    }
    for (name, at) in labels {
        root.draw(&Text::new(name, at, ("sans-serif", 16).into_font())).map_err(plot_err)?;
    }
    chart
        .draw_series(std::iter::once(Text::new(
            legend.to_string(),
            (x0 / 1.8, y1 * 0.95),
            ("sans-serif", 15).into_font(),
        )))
        .map_err(plot_err)?;
    root.present().map_err(plot_err)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// Tolerance chart: per degree, median time against tolerance (left) and max error (right).
fn plot_tolerance(path: &std::path::Path, rows: &[(usize, Real, Real, Real, Real)]) -> Result<()> {
    if rows.is_empty() {
        return Err(Error::invalid("--png", "no rows to plot"));
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let root = BitMapBackend::new(path, (1200, 550)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (left, right) = root.split_horizontally(600);
    let t_max = rows.iter().map(|r| r.2).fold(0.0, Real::max) * 1.2 + 1e-3;
    let e_min = rows.iter().map(|r| r.4).filter(|v| *v > 0.0).fold(Real::INFINITY, Real::min).min(1e-12);
    let e_max = rows.iter().map(|r| r.4).fold(0.0, Real::max).max(1e-10) * 10.0;
    let mut degrees: Vec<usize> = rows.iter().map(|r| r.0).collect();
    degrees.dedup();
    let palette = [&BLUE, &RED, &GREEN, &MAGENTA];
    let mut c1 = ChartBuilder::on(&left)
        .caption("median cold distance time", ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d((1e-13..1e-3).log_scale(), 0.0..t_max)
        .map_err(plot_err)?;
    c1.configure_mesh().x_desc("KKT tolerance").y_desc("µs").draw().map_err(plot_err)?;
    let mut c2 = ChartBuilder::on(&right)
        .caption("max |d − d(1e-12)|", ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((1e-13..1e-3).log_scale(), (e_min / 10.0..e_max).log_scale())
        .map_err(plot_err)?;
    c2.configure_mesh().x_desc("KKT tolerance").y_desc("m").draw().map_err(plot_err)?;
    for (i, d) in degrees.iter().enumerate() {
        let color = palette[i % palette.len()];
        let pts: Vec<_> = rows.iter().filter(|r| r.0 == *d).collect();
        c1.draw_series(LineSeries::new(pts.iter().map(|r| (r.1, r.2)), color))
            .map_err(plot_err)?
            .label(format!("2d = {d}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        c2.draw_series(LineSeries::new(pts.iter().map(|r| (r.1, r.4.max(e_min / 10.0))), color)).map_err(plot_err)?;
    }
    c1.configure_series_labels().border_style(BLACK).background_style(WHITE).draw().map_err(plot_err)?;
    root.present().map_err(plot_err)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
