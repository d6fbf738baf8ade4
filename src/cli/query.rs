//! `sublevel query distance|growth A.json B.json --pose-a w,x,y,z,tx,ty,tz --pose-b … [--json] [--certify]
//! [--gradient]`:
//! one query between two body files, for scripts and debugging.
//!
//! Compound body files (`sublevel.compound.v1`) are answered by branch and bound over the
//! two containment trees ([`sublevel::query::tree`]): the same fields, plus `compound`, the bounds
//! `lower` / `upper`, the `level` reached, the active `leaves` pair and `pairs_evaluated`. A file
//! holding one body (or a one-node compound) is answered as a single body.
//!
//! Either file may be an exact primitive's file (a JSON object with a `primitive` key, as
//! `sublevel primitive` writes it; [`sublevel::primitive::PrimitiveFile`]). A distance query with
//! a primitive against a primitive or a single body is answered by
//! [`sublevel::query::shape::shape_distance`]: the single body's fields where they apply, plus
//! `method` (`ClosedForm` or `ActiveSet`) and `certified_lower_bound` (the
//! separating plane's lower bound between two separated primitives, else null). A primitive
//! against a compound body, the growth query (defined for sos-convex bodies only) and `--certify`
//! are refused with an error; the answer adds `signed_distance` (minus the penetration depth in
//! contact) and `--gradient` prints that signed distance's pose gradients.

use serde_json::json;
use sublevel::compound::CompoundBody;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::primitive::{Primitive, PrimitiveFile};
use sublevel::query::shape::{separating_plane_bound, shape_distance, shape_signed_distance, ShapeRef};
use sublevel::query::tree::{tree_collide, tree_distance, TreeQueryParams};
use sublevel::query::{
    certified_distance, certified_growth, distance_gradient, growth_gradient, CertificateSummary, CertifyMode,
    CertifyParams, NewtonParams, PoseGradient, SolveStatus,
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
    /// Body file of A (JSON from `sublevel fit`), or a primitive file (from `sublevel primitive`).
    a: std::path::PathBuf,
    /// Body or primitive file of B.
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
    /// KKT-residual tolerance of the Newton solver (body pairs; the primitives' solvers keep their
    /// own).
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

/// What a query's file holds: an exact primitive, or a body / compound body.
enum Shape {
    /// A primitive file (a JSON object with a `primitive` key).
    Primitive(Primitive),
    /// A body file or a compound body file (a one-node tree for a single body).
    Bodies(Box<CompoundBody>),
}

/// Reads side `side`'s file: a primitive file when it is a JSON object with a `primitive` key,
/// else a body or compound body file ([`CompoundBody::from_json`]). A primitive's validation error
/// names the side too (`a.size[1]`).
fn load_shape(side: &str, path: &std::path::Path) -> Result<Shape> {
    let text = std::fs::read_to_string(path)?;
    let value: serde_json::Value = serde_json::from_str(&text)?;
    if value.as_object().is_some_and(|o| o.contains_key("primitive")) {
        let file: PrimitiveFile = serde_json::from_value(value)?;
        return Primitive::from_file(&file).map(Shape::Primitive).map_err(|e| match e {
            Error::InvalidArgument { field, reason } => Error::invalid(format!("{side}.{field}"), reason),
            e => e,
        });
    }
    CompoundBody::from_json(&text).map(|t| Shape::Bodies(Box::new(t)))
}

/// Runs `sublevel query`.
pub fn run(args: QueryArgs) -> Result<()> {
    let sa = load_shape("a", &args.a)?;
    let sb = load_shape("b", &args.b)?;
    let pose_a = parse_pose("--pose-a", &args.pose_a)?;
    let pose_b = parse_pose("--pose-b", &args.pose_b)?;
    let (ta, tb) = match (sa, sb) {
        (Shape::Bodies(ta), Shape::Bodies(tb)) => (*ta, *tb),
        (sa, sb) => return print(&args, &with_primitive(&args, &sa, &pose_a, &sb, &pose_b)?),
    };
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
    print(&args, &out)
}

/// Prints an answer: pretty JSON with `--json`, else one `field: value` line per field.
fn print(args: &QueryArgs, out: &serde_json::Value) -> Result<()> {
    if args.json {
        println!("{}", serde_json::to_string_pretty(out)?);
    } else {
        for (k, v) in out.as_object().into_iter().flatten() {
            println!("{k:>14}: {v}");
        }
    }
    Ok(())
}

/// The distance between two shapes of which at least one is a primitive (module docs).
///
/// # Errors
/// [`Error::InvalidArgument`] for the growth query (naming `kind`), `--certify` with a primitive, a primitive against a compound body of several nodes (naming the compound
/// side), or two halfspaces (naming `b`; [`shape_distance`]).
fn with_primitive(
    args: &QueryArgs,
    a: &Shape,
    pose_a: &Isometry3,
    b: &Shape,
    pose_b: &Isometry3,
) -> Result<serde_json::Value> {
    if matches!(args.kind, QueryKind::Growth) {
        return Err(Error::invalid(
            "kind",
            "the growth measure is defined for sos-convex bodies only, not for primitive files; use `distance`",
        ));
    }
    if args.certify {
        return Err(Error::invalid(
            "--certify",
            "the sos certificate is for body pairs only; a primitive's distance carries its own bound \
             (`certified_lower_bound`)",
        ));
    }
    let (ra, rb) = (shape_ref("a", a)?, shape_ref("b", b)?);
    let start = std::time::Instant::now();
    let r = shape_distance(ra, pose_a, rb, pose_b, None)?;
    let micros = start.elapsed().as_secs_f64() * 1e6;
    let signed = shape_signed_distance(ra, pose_a, rb, pose_b, None)?;
    // A body's side: the separating plane through its support point certifies the distance too.
    let certified = match r.lower_bound {
        Some(bound) => Some(bound),
        None if !r.overlapping => separating_plane_bound(ra, pose_a, rb, pose_b, &r.normal).ok(),
        None => None,
    };
    let mut v = json!({
        "query": "distance",
        "distance": r.distance,
        "witness_a": [r.witness_a.x, r.witness_a.y, r.witness_a.z],
        "witness_b": [r.witness_b.x, r.witness_b.y, r.witness_b.z],
        "normal": [r.normal.x, r.normal.y, r.normal.z],
        "overlapping": r.overlapping,
        "converged": r.status == SolveStatus::Converged,
        "method": format!("{:?}", r.method),
        "certified_lower_bound": certified,
        "status": format!("{:?}", r.status),
        "iterations": r.iterations,
        "kkt_residual": r.kkt_residual,
        "microseconds": micros,
        "signed_distance": signed.value,
        "signed_distance_converged": signed.converged,
    });
    if args.gradient {
        // The signed distance's gradients: the distance's apart, continuous through contact.
        let (ga, gb) = signed.gradient();
        v["gradient_a"] = gradient_json(&ga);
        v["gradient_b"] = gradient_json(&gb);
    }
    Ok(v)
}

/// Side `side` as a shape query's operand: its primitive, or its single body.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `side` for a compound body of several nodes.
fn shape_ref<'s>(side: &str, s: &'s Shape) -> Result<ShapeRef<'s>> {
    match s {
        Shape::Primitive(p) => Ok(ShapeRef::Primitive(p)),
        Shape::Bodies(t) if t.node_count() == 1 => Ok(ShapeRef::Body(t.body(t.root()))),
        Shape::Bodies(_) => {
            Err(Error::invalid(side, "a primitive against a compound body is not supported yet; use a single body"))
        }
    }
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
