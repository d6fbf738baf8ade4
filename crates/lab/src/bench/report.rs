//! The summary of `sublevel-lab bench`: the tables printed on stdout and the `--csv` file.

use super::{PeerRow, Row};
use crate::csv_file::CsvFile;
use crate::peer_coal::CoalFigures;
use std::path::Path;
use sublevel_core::math::Real;
use sublevel_core::Result;

/// Columns of `bench --csv`, one record per degree (times in µs unless named `_s`; errors in
/// meters against the exact mesh–mesh distance).
/// The `coal_*` and `*_over_coal` columns come from `--peer` (empty without it): coal's medians and
/// ours / coal's GJK on the hulls (cold over cold, warm over warm; below 1 is faster than coal).
/// The last three are the batch solver ([`sublevel_query::batch::cold_distances`]): all cold
/// poses one at a time and as one batch, alternated `--repeats` times, µs per pair (medians over
/// the rounds), and single time / batch time (the batch's rate in units of the single-query rate).
/// The `collide_*` columns time a planner's cold collide query (margin 0) at all cold poses, one at
/// a time, alternated with the distance rounds: µs per pair with the bounding spheres alone before
/// the solve (`collide_cold_spheres_us`), with the planner's cheap tests
/// ([`sublevel_scene::planner::collide_cheap`]: the spheres, the separating axis, then a common
/// point; `collide_cold_us`), and how many pairs those tests decided (`collide_decided_by_bounds`,
/// the common point's included); the last two, with the spheres and the axis but no common-point
/// test (`collide_cold_bounds_only_us`), and the pairs the common point proved overlapping.
/// The `coal_*collide*` columns come from the collide peer's lines in `--peer`
/// (`scripts/peer-coal-collide`; empty without them): coal's boolean collide on the hulls, mean µs
/// per pose, narrow phase alone and behind its broad phase's world AABB test, and ours
/// (`collide_cold_us`) over the latter.
pub const CSV_COLUMNS: [&str; 40] = [
    "degree",
    "fit_chair_s",
    "distance_cold_us",
    "distance_warm_us",
    "growth_cold_us",
    "growth_warm_us",
    "paper_s",
    "speedup_cold",
    "speedup_warm",
    "converged",
    "total",
    "parry_hull_cold_us",
    "parry_hull_warm_us",
    "parry_mesh_us",
    "hull_over_ours_cold",
    "hull_over_ours_warm",
    "err_mean_m",
    "err_max_m",
    "hull_err_mean_m",
    "hull_err_max_m",
    "coal_gjk_cold_us",
    "coal_gjk_warm_us",
    "coal_nesterov_cold_us",
    "coal_nesterov_warm_us",
    "coal_mesh_us",
    "distance_cold_over_coal",
    "distance_warm_over_coal",
    "growth_cold_over_coal",
    "growth_warm_over_coal",
    "distance_cold_single_us",
    "distance_cold_batch_us",
    "batch_over_single_rate",
    "collide_cold_spheres_us",
    "collide_cold_us",
    "collide_decided_by_bounds",
    "coal_collide_cold_us",
    "coal_aabb_collide_cold_us",
    "collide_cold_over_coal",
    "collide_cold_bounds_only_us",
    "collide_touching_by_common_point",
];

pub(super) fn print_table(rows: &[Row], peer: &PeerRow) {
    println!("chair_101 vs human_10; query times are medians in microseconds (in-process, this machine)");
    println!(
        "{:>3} {:>9} {:>10} {:>10} {:>10} {:>10} {:>9} {:>11} {:>11} {:>10}",
        "2d", "fit chair", "dist cold", "dist warm", "grow cold", "grow warm", "paper", "x cold", "x warm", "converged"
    );
    for r in rows {
        let v = r.values();
        let fit = if v[0].is_nan() { "-".to_string() } else { format!("{:.2}s", v[0]) };
        println!(
            "{:>3} {:>9} {:>10.2} {:>10.2} {:>10.2} {:>10.2} {:>8.3}s {:>10.0}x {:>10.0}x {:>5}/{:<5}",
            r.degree, fit, v[1], v[2], v[3], v[4], v[5], v[6], v[7], r.converged, r.total
        );
    }
    println!("x cold / x warm: speed-up of our distance query over the paper's Table 2 (MATLAB fmincon).");
    println!("fit chair: `-` where the fit was not timed (--fit-degrees); the queries then use the bundled bodies.");
    for r in rows {
        println!(
            "2d = {}: cold distance at all cold poses, {:.3} µs per pair one at a time, {:.3} µs as one batch \
             (8 pairs per SIMD pass in single precision, then 4): {:.2}x the single-query rate",
            r.degree,
            r.single_us,
            r.batch_us,
            r.single_us / r.batch_us
        );
    }
    for r in rows {
        let c = &r.collide;
        println!(
            "2d = {}: cold collide (margin 0) at all cold poses, {:.3} µs per pair with the spheres, the separating axis \
             and a common point; {:.3} µs without the common point, {:.3} µs with the spheres alone ({:.2}x); the \
             bounds clear {} of {}, the common point proves {} overlapping",
            r.degree,
            c.cheap_us,
            c.axis_us,
            c.spheres_us,
            c.spheres_us / c.cheap_us,
            c.decided,
            c.pairs,
            c.touching
        );
    }
    println!();
    let n_sep = peer.exact.iter().filter(|d| **d > 0.0).count();
    println!(
        "peers (parry3d-f64, same poses): GJK on the convex hulls cold {:.2} µs, warm {:.2} µs; exact mesh–mesh {:.1} µs",
        peer.hull_cold, peer.hull_warm, peer.mesh
    );
    println!(
        "{:>8} {:>10} {:>10} {:>12} {:>12} {:>13} {:>13}",
        "model", "cold µs", "warm µs", "hull/ours c", "hull/ours w", "err mean [m]", "err max [m]"
    );
    for r in rows {
        println!(
            "{:>8} {:>10.2} {:>10.2} {:>11.2}x {:>11.2}x {:>13.4} {:>13.4}",
            format!("sos 2d={}", r.degree),
            r.dist_cold,
            r.dist_warm,
            peer.hull_cold / r.dist_cold,
            peer.hull_warm / r.dist_warm,
            r.err.0,
            r.err.1
        );
    }
    println!(
        "{:>8} {:>10.2} {:>10.2} {:>12} {:>12} {:>13.4} {:>13.4}",
        "hull GJK", peer.hull_cold, peer.hull_warm, "1.00x", "1.00x", peer.hull_err.0, peer.hull_err.1
    );
    println!(
        "{:>8} {:>10.1} {:>10} {:>12} {:>12} {:>13} {:>13}",
        "mesh", peer.mesh, "-", "-", "-", "0 (truth)", "0 (truth)"
    );
    println!(
        "errors: |model − exact mesh–mesh distance| over the {n_sep} separated poses of the first {} cold poses.",
        peer.exact.len()
    );
}

/// coal's figures (from `--peer`) and the ratios ours / coal's GJK on the hulls, per degree.
pub(super) fn print_coal(rows: &[Row], c: &CoalFigures) {
    println!();
    println!(
        "coal 3.0.3 (--peer; hulls of {} / {} vertices): GJK cold {:.2} µs, warm {:.2} µs; Nesterov GJK cold {:.2} µs, \
         warm {:.2} µs; exact mesh–mesh (BVH) {:.1} µs",
        c.hull_vertices[0], c.hull_vertices[1], c.gjk_cold_us, c.gjk_warm_us, c.nesterov_cold_us, c.nesterov_warm_us, c.mesh_us
    );
    println!(
        "{:>8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "model", "dist cold", "/coal", "dist warm", "/coal", "grow cold", "/coal", "grow warm", "/coal"
    );
    for r in rows {
        println!(
            "{:>8} {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x",
            format!("sos 2d={}", r.degree),
            r.dist_cold,
            r.dist_cold / c.gjk_cold_us,
            r.dist_warm,
            r.dist_warm / c.gjk_warm_us,
            r.growth_cold,
            r.growth_cold / c.gjk_cold_us,
            r.growth_warm,
            r.growth_warm / c.gjk_warm_us
        );
    }
    println!("{:>8} {:>10.2} {:>10} {:>10.2} {:>10}", "coal GJK", c.gjk_cold_us, "1.00x", c.gjk_warm_us, "1.00x");
    println!(
        "/coal: our median over coal's median GJK on the hulls (cold over cold, warm over warm); below 1 is faster. \
         Targets: 2d = 6 cold ≤ 0.6x, warm ≤ 0.3x; 2d = 8 cold ≤ 1x."
    );
    if c.aabb_collide_us.is_nan() {
        return;
    }
    let [decided, colliding, poses] = c.collide_counts;
    println!(
        "coal collide (boolean, margin 0, mean over {poses} cold poses, {colliding} touching): narrow phase alone \
         {:.2} µs; behind its broad phase's world AABB test {:.2} µs (the AABBs decide {decided})",
        c.collide_us, c.aabb_collide_us
    );
    for r in rows {
        let k = &r.collide;
        println!(
            "2d = {}: cold collide {:.3} µs (the cheap tests decide {} of {}) = {:.2}x coal's AABB + GJK, {:.2}x its \
             narrow phase",
            r.degree,
            k.cheap_us,
            k.decided + k.touching,
            k.pairs,
            k.cheap_us / c.aabb_collide_us,
            k.cheap_us / c.collide_us
        );
    }
}

/// A CSV field: the value with `digits` decimals, empty when absent or not finite.
fn opt(v: Option<Real>, digits: usize) -> String {
    v.filter(|v| v.is_finite()).map(|v| format!("{v:.digits$}")).unwrap_or_default()
}

/// Writes the summary as CSV ([`CSV_COLUMNS`], one record per degree; the `coal_*` columns are empty
/// without `coal`) and names the file on stderr.
///
/// # Errors
/// [`Error::Io`](sublevel_core::Error::Io) when the file cannot be created or written.
pub(super) fn write_csv(path: &Path, rows: &[Row], peer: &PeerRow, coal: Option<&CoalFigures>) -> Result<()> {
    let mut csv = CsvFile::create(path, &CSV_COLUMNS)?;
    for r in rows {
        let v = r.values();
        csv.record([
            r.degree.to_string(),
            format!("{:.4}", v[0]),
            format!("{:.3}", v[1]),
            format!("{:.3}", v[2]),
            format!("{:.3}", v[3]),
            format!("{:.3}", v[4]),
            format!("{}", v[5]),
            format!("{:.0}", v[6]),
            format!("{:.0}", v[7]),
            r.converged.to_string(),
            r.total.to_string(),
            format!("{:.3}", peer.hull_cold),
            format!("{:.3}", peer.hull_warm),
            format!("{:.1}", peer.mesh),
            format!("{:.3}", peer.hull_cold / r.dist_cold),
            format!("{:.3}", peer.hull_warm / r.dist_warm),
            format!("{:.5}", r.err.0),
            format!("{:.5}", r.err.1),
            format!("{:.5}", peer.hull_err.0),
            format!("{:.5}", peer.hull_err.1),
            opt(coal.map(|c| c.gjk_cold_us), 3),
            opt(coal.map(|c| c.gjk_warm_us), 3),
            opt(coal.map(|c| c.nesterov_cold_us), 3),
            opt(coal.map(|c| c.nesterov_warm_us), 3),
            opt(coal.map(|c| c.mesh_us), 1),
            opt(coal.map(|c| r.dist_cold / c.gjk_cold_us), 3),
            opt(coal.map(|c| r.dist_warm / c.gjk_warm_us), 3),
            opt(coal.map(|c| r.growth_cold / c.gjk_cold_us), 3),
            opt(coal.map(|c| r.growth_warm / c.gjk_warm_us), 3),
            format!("{:.3}", r.single_us),
            format!("{:.3}", r.batch_us),
            format!("{:.3}", r.single_us / r.batch_us),
            format!("{:.3}", r.collide.spheres_us),
            format!("{:.3}", r.collide.cheap_us),
            (r.collide.decided + r.collide.touching).to_string(),
            opt(coal.map(|c| c.collide_us), 3),
            opt(coal.map(|c| c.aabb_collide_us), 3),
            opt(coal.map(|c| r.collide.cheap_us / c.aabb_collide_us), 3),
            format!("{:.3}", r.collide.axis_us),
            r.collide.touching.to_string(),
        ])?;
    }
    eprintln!("wrote {}", csv.finish()?.display());
    Ok(())
}
