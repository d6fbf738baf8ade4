//! `sublevel query distance|growth A.json B.json --pose-a w,x,y,z,tx,ty,tz --pose-b … [--json] [--certify]
//! [--gradient]`:
//! one query between two body files, for scripts and debugging.
//!
//! Compound body files (`sublevel.compound.v1`) are answered by branch and bound over the
//! two containment trees ([`sublevel::query::tree`]): the same fields, plus `compound`, the bounds
//! `lower` / `upper`, the `level` reached, the active `leaves` pair and `pairs_evaluated`. A file
//! holding one body (or a one-node compound) is answered as a single body.

use serde_json::json;
use sublevel::compound::CompoundBody;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::query::tree::{tree_collide, tree_distance, TreeQueryParams};
use sublevel::query::{
    certified_distance, certified_growth, distance_gradient, growth_gradient, CertificateSummary, CertifyMode,
    CertifyParams, NewtonParams, PoseGradient,
};
use sublevel::{Error, Result};

/// Which query to run.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum QueryKind {
    /// Euclidean distance with witness points (paper eq. "distance").
    Distance,
    /// Growth measure d(A‖B) = min p_A'(x) s.t. p_B'(x) ≤ 1 (paper eq. "overlap").
    Growth,
}

/// Arguments of `sublevel query`.
#[derive(clap::Args, Debug)]
pub struct QueryArgs {
    /// distance or growth.
    #[arg(value_enum)]
    kind: QueryKind,
    /// Body file of A (JSON from `sublevel fit`).
    a: std::path::PathBuf,
    /// Body file of B.
    b: std::path::PathBuf,
    /// Pose of A: unit quaternion and translation in meters, `w,x,y,z,tx,ty,tz`.
    #[arg(long, default_value = "1,0,0,0,0,0,0", allow_hyphen_values = true)]
    pose_a: String,
    /// Pose of B, same form.
    #[arg(long, default_value = "1,0,0,0,0,0,0", allow_hyphen_values = true)]
    pose_b: String,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Always solve the level-0 sos certificate (an SDP with Clarabel), compare it with Newton's answer
    /// and print it (without it the SDP runs only as a fallback when Newton fails, or for nonconvex
    /// bodies as a lower bound).
    #[arg(long)]
    certify: bool,
    /// Also print the gradients of the value with respect to both poses (twists: linear [value/m],
    /// angular about the world origin [value/rad]; pose ← exp(ξ^)·pose).
    #[arg(long)]
    gradient: bool,
    /// KKT-residual tolerance of the Newton solver.
    #[arg(long, default_value_t = sublevel::math::NEWTON_KKT_TOLERANCE)]
    tolerance: f64,
    /// Compound bodies only: stop refining the distance once upper − lower ≤ this (meters, ≥ 0;
    /// 0 = the exact distance of the two models).
    #[arg(long, default_value_t = 0.0)]
    bound_tolerance: f64,
}

fn parse_pose(field: &str, text: &str) -> Result<Isometry3> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| Error::invalid(field, format!("expected 7 numbers w,x,y,z,tx,ty,tz: {e}")))?;
    if v.len() != 7 {
        return Err(Error::invalid(field, format!("expected 7 numbers w,x,y,z,tx,ty,tz, got {}", v.len())));
    }
    pose_from_parts(field, [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]])
}

fn certificate_json(c: &Option<CertificateSummary>) -> serde_json::Value {
    match c {
        None => serde_json::Value::Null,
        Some(c) => json!({
            "bound": c.bound, "verified_bound": c.verified_bound, "agrees": c.agrees,
            "relative_gap": c.relative_gap, "gram_min_eigenvalue": c.gram_min_eigenvalue,
            "solve_seconds": c.solve_seconds, "solver_status": c.solver_status, "kind": c.kind.as_str(), "verified": c.verified,
            "newton_value": c.newton_value,
        }),
    }
}

fn gradient_json(g: &PoseGradient) -> serde_json::Value {
    json!({ "linear": [g.linear.x, g.linear.y, g.linear.z], "angular": [g.angular.x, g.angular.y, g.angular.z] })
}

/// Runs `sublevel query`.
pub fn run(args: QueryArgs) -> Result<()> {
    let ta = CompoundBody::load(&args.a)?;
    let tb = CompoundBody::load(&args.b)?;
    let pose_a = parse_pose("--pose-a", &args.pose_a)?;
    let pose_b = parse_pose("--pose-b", &args.pose_b)?;
    let params = CertifyParams {
        newton: NewtonParams { kkt_tolerance: args.tolerance, ..NewtonParams::default() },
        ..CertifyParams::default()
    };
    let mode = if args.certify { CertifyMode::Certify } else { CertifyMode::Newton };
    let out = if ta.node_count() == 1 && tb.node_count() == 1 {
        single(&args, ta.body(ta.root()), &pose_a, tb.body(tb.root()), &pose_b, &params, mode)
    } else {
        let tree = TreeQueryParams {
            newton: params.newton,
            certificate: params.certificate,
            certify: mode,
            tolerance: args.bound_tolerance,
            ..TreeQueryParams::default()
        };
        compound(&args, &ta, &pose_a, &tb, &pose_b, &tree)?
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for (k, v) in out.as_object().into_iter().flatten() {
            println!("{k:>14}: {v}");
        }
    }
    Ok(())
}

/// The query between two compound bodies (branch and bound; module docs).
fn compound(
    args: &QueryArgs,
    a: &CompoundBody,
    pose_a: &Isometry3,
    b: &CompoundBody,
    pose_b: &Isometry3,
    params: &TreeQueryParams,
) -> Result<serde_json::Value> {
    let start = std::time::Instant::now();
    Ok(match args.kind {
        QueryKind::Distance => {
            let t = tree_distance(a, pose_a, b, pose_b, None, params)?;
            let micros = start.elapsed().as_secs_f64() * 1e6;
            let best = t.best.as_ref();
            let r = best.map(|l| &l.result);
            let point = |p: Option<sublevel::math::Point3>| p.map(|p| json!([p.x, p.y, p.z]));
            let mut v = json!({
                "query": "distance",
                "compound": true,
                "distance": t.upper,
                "lower": t.lower,
                "upper": t.upper,
                "witness_a": point(r.map(|r| r.witness_a)),
                "witness_b": point(r.map(|r| r.witness_b)),
                "normal": r.map(|r| [r.normal.x, r.normal.y, r.normal.z]),
                "overlapping": t.overlapping(),
                "converged": t.converged,
                "within_tolerance": t.within_tolerance,
                "source": best.map(|l| format!("{:?}", l.source)),
                "lower_bound": false,
                "tight": false,
                "status": r.map(|r| format!("{:?}", r.status)),
                "iterations": r.map(|r| r.iterations),
                "kkt_residual": r.map(|r| r.kkt_residual),
                "microseconds": micros,
                "certificate": certificate_json(&best.and_then(|l| l.certificate.clone())),
                "leaves": best.map(|l| [l.leaves.0, l.leaves.1]),
                "level": t.level,
                "pairs_evaluated": t.pairs_evaluated,
                "pairs_pruned_by_spheres": t.pairs_pruned_by_spheres,
                "leaf_certificates": t.leaf_pairs.iter().filter(|l| l.certificate.is_some()).map(|l| json!({
                    "leaves": [l.leaves.0, l.leaves.1], "distance": l.result.distance,
                    "certificate": certificate_json(&l.certificate),
                })).collect::<Vec<_>>(),
            });
            if args.gradient {
                if let Some((ga, gb)) = t.gradient() {
                    v["gradient_a"] = gradient_json(&ga);
                    v["gradient_b"] = gradient_json(&gb);
                }
            }
            v
        }
        QueryKind::Growth => {
            let t = tree_collide(a, pose_a, b, pose_b, true, None, params)?;
            let micros = start.elapsed().as_secs_f64() * 1e6;
            let r = t.growth.as_ref();
            let mut v = json!({
                "query": "growth",
                "compound": true,
                "value": r.map(|r| r.value),
                "minimizer": r.map(|r| [r.minimizer.x, r.minimizer.y, r.minimizer.z]),
                "multiplier": r.map(|r| r.multiplier),
                "separated": !t.colliding,
                "converged": t.converged,
                "source": "Newton",
                "lower_bound": false,
                "tight": false,
                "status": r.map(|r| format!("{:?}", r.status)),
                "iterations": r.map(|r| r.iterations),
                "kkt_residual": r.map(|r| r.kkt_residual),
                "microseconds": micros,
                "certificate": serde_json::Value::Null,
                "leaves": t.leaves.map(|l| [l.0, l.1]),
                "level": t.level,
                "pairs_evaluated": t.pairs_evaluated,
                "pairs_pruned_by_spheres": t.pairs_pruned_by_spheres,
            });
            if args.gradient {
                if let Some((g1, g2)) = t.gradient {
                    v["gradient_a"] = gradient_json(&g1);
                    v["gradient_b"] = gradient_json(&g2);
                }
            }
            v
        }
    })
}

/// The query between two single bodies.
fn single(
    args: &QueryArgs,
    a: &sublevel::Body,
    pose_a: &Isometry3,
    b: &sublevel::Body,
    pose_b: &Isometry3,
    params: &CertifyParams,
    mode: CertifyMode,
) -> serde_json::Value {
    let start = std::time::Instant::now();
    match args.kind {
        QueryKind::Distance => {
            let c = certified_distance(a, pose_a, b, pose_b, None, params, mode);
            let micros = start.elapsed().as_secs_f64() * 1e6;
            let r = &c.result;
            let mut v = json!({
                "query": "distance",
                "distance": r.distance,
                "witness_a": [r.witness_a.x, r.witness_a.y, r.witness_a.z],
                "witness_b": [r.witness_b.x, r.witness_b.y, r.witness_b.z],
                "normal": [r.normal.x, r.normal.y, r.normal.z],
                "overlapping": r.overlapping,
                "converged": c.converged,
                "source": format!("{:?}", c.source),
                "lower_bound": c.lower_bound,
                "tight": c.tight,
                "status": format!("{:?}", r.status),
                "iterations": r.iterations,
                "kkt_residual": r.kkt_residual,
                "microseconds": micros,
                "certificate": certificate_json(&c.certificate),
            });
            if args.gradient && !c.lower_bound {
                let (ga, gb) = distance_gradient(r);
                v["gradient_a"] = gradient_json(&ga);
                v["gradient_b"] = gradient_json(&gb);
            }
            v
        }
        QueryKind::Growth => {
            let c = certified_growth(a, pose_a, b, pose_b, None, params, mode);
            let micros = start.elapsed().as_secs_f64() * 1e6;
            let r = &c.result;
            let mut v = json!({
                "query": "growth",
                "value": r.value,
                "minimizer": [r.minimizer.x, r.minimizer.y, r.minimizer.z],
                "multiplier": r.multiplier,
                "separated": r.value > 1.0,
                "converged": c.converged,
                "source": format!("{:?}", c.source),
                "lower_bound": c.lower_bound,
                "tight": c.tight,
                "status": format!("{:?}", r.status),
                "iterations": r.iterations,
                "kkt_residual": r.kkt_residual,
                "microseconds": micros,
                "certificate": certificate_json(&c.certificate),
            });
            if args.gradient && !c.lower_bound {
                let (g1, g2) = growth_gradient(a, pose_a, r);
                v["gradient_a"] = gradient_json(&g1);
                v["gradient_b"] = gradient_json(&g2);
            }
            v
        }
    }
}
