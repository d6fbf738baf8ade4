//! Point-cloud obstacles as bodies ([`sublevel_robot::cloud::bodies`]): two blobs and scattered
//! outliers, noise radius 1 cm.
//!
//! - Clustering finds the two blobs with their exact point sets; singletons and a clump of 5
//!   points (under `min_points` = 10) are dropped as outliers.
//! - Every inlier's ball is inside its cluster's body: p ≤ 1 at the 8 cube corners p ± r of every
//!   inlier (the containment certificate for a convex body), and, as an independent check, at
//!   1000 random points of every ball (half of them on its sphere).
//! - The same frame again (shuffled) reuses both bodies, the same allocations, with 0 refits;
//!   moving one blob refits that one only; jitter below the fit's slack is reused.
//! - A blob grown by 1.5 % is rescaled, not fitted: its new p is the old one over the factor, at
//!   100 random points to 1e-9; grown by 10 % (past the limit of 1.25 since the fit) it is fitted
//!   again; a limit of 1 never rescales; fits on one thread equal fits on two.
//!
//! The ignored `fit_table` prints the cost and tightness of cluster fits of 50–2000 points at
//! 2d = 2 and 4 (run it in release: `cargo test --release -p sublevel-robot --test cloud_bodies
//! -- --ignored --nocapture`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use sublevel_core::math::{Point3, Real, Vector3};
use sublevel_robot::cloud::bodies::{
    ball_hull_volume, euclidean_clusters, fit_cluster, BallCover, CloudBodies, CloudBodySettings, ClusterOutcome,
};

const R: Real = 0.01;

/// A jittered 2 cm grid inside the ball of radius 0.1 m about (0, 0, 1): 515 points.
fn blob_a(rng: &mut ChaCha8Rng) -> Vec<[Real; 3]> {
    let mut out = Vec::new();
    for i in -5..=5 {
        for j in -5..=5 {
            for k in -5..=5 {
                let v = Vector3::new(i as Real, j as Real, k as Real) * 0.02;
                if v.norm() <= 0.1 {
                    let jitter = Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * 0.008;
                    out.push((v + jitter + Vector3::new(0.0, 0.0, 1.0)).into());
                }
            }
        }
    }
    out
}

/// A jittered 2 cm grid on the box [0.8, 1.0] × [−0.05, 0.05] × [0.9, 0.96]: 11 × 6 × 4 = 264 points.
fn blob_b(rng: &mut ChaCha8Rng) -> Vec<[Real; 3]> {
    let mut out = Vec::new();
    for i in 0..11 {
        for j in 0..6 {
            for k in 0..4 {
                let jitter = Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * 0.008;
                let v = Vector3::new(0.8 + 0.02 * i as Real, -0.05 + 0.02 * j as Real, 0.9 + 0.02 * k as Real);
                out.push((v + jitter).into());
            }
        }
    }
    out
}

/// 12 lone points 0.25 m apart on a line 1 m away from the blobs, and a clump of 5 points.
fn outliers() -> Vec<[Real; 3]> {
    let mut out: Vec<[Real; 3]> = (0..12).map(|k| [-1.5 + 0.25 * k as Real, 1.0, 0.5]).collect();
    out.extend((0..5).map(|k| [0.5, -1.0, 1.0 + 0.01 * k as Real]));
    out
}

/// The scene shuffled: the points, and for each blob its indices in the shuffled list (sorted).
fn scene(a: &[[Real; 3]], b: &[[Real; 3]], seed: u64) -> (Vec<[Real; 3]>, Vec<usize>, Vec<usize>) {
    let mut tagged: Vec<(u8, [Real; 3])> = a.iter().map(|p| (0, *p)).collect();
    tagged.extend(b.iter().map(|p| (1, *p)));
    tagged.extend(outliers().into_iter().map(|p| (2, p)));
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in (1..tagged.len()).rev() {
        tagged.swap(i, rng.random_range(0..=i));
    }
    let of = |tag: u8| tagged.iter().enumerate().filter(|(_, t)| t.0 == tag).map(|(i, _)| i).collect::<Vec<_>>();
    let (ia, ib) = (of(0), of(1));
    (tagged.into_iter().map(|t| t.1).collect(), ia, ib)
}

/// Asserts that every ball B(p_i, R) of every cluster is in its body: p ≤ 1 at the vertices of a
/// polytope circumscribing the ball — for the cube cover the 8 exact corners p ± R (not the fit's
/// cover, pushed out by 10⁻⁹), for the icosahedron its 12 vertices — and at 1000 random points
/// of the ball.
fn assert_balls_contained(bodies: &CloudBodies, points: &[[Real; 3]], cover: BallCover, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for (c, cluster) in bodies.clusters().iter().enumerate() {
        assert!(cluster.fallback.is_none(), "cluster {c}: {:?}", cluster.fallback);
        let body = &cluster.body;
        let mut worst: Real = 0.0;
        for &i in &cluster.indices {
            let p = Vector3::from(points[i]);
            let vertices: Vec<Vector3> = match cover {
                BallCover::Cube => (0..8)
                    .map(|k| {
                        let s = |b: usize| if k & b == 0 { -R } else { R };
                        Vector3::new(s(1), s(2), s(4))
                    })
                    .collect(),
                BallCover::Icosahedron => cover.offsets(R),
            };
            for (k, o) in vertices.iter().enumerate() {
                let v = body.value_at(&Point3::from(p + o));
                assert!(v <= 1.0, "cluster {c}, point {i}, vertex {k}: p = {v}");
                worst = worst.max(v);
            }
            for n in 0..1000 {
                let d =
                    Vector3::new(rng.random::<Real>() - 0.5, rng.random::<Real>() - 0.5, rng.random::<Real>() - 0.5);
                let Some(d) = d.try_normalize(1e-9) else { continue };
                let t = if n % 2 == 0 { 1.0 } else { rng.random::<Real>().cbrt() };
                let v = body.value_at(&Point3::from(p + d * (R * t)));
                assert!(v <= 1.0, "cluster {c}, point {i}, ball sample {n}: p = {v}");
            }
        }
        // The body is tight somewhere: some corner is near its boundary.
        assert!(worst > 0.5, "cluster {c}: largest p at the corners {worst}");
    }
}

#[test]
fn two_blobs_cluster_with_their_exact_points_and_outliers_dropped() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (a, b) = (blob_a(&mut rng), blob_b(&mut rng));
    assert_eq!((a.len(), b.len()), (515, 264));
    let (points, ia, ib) = scene(&a, &b, 2);
    let clusters = euclidean_clusters(&points, 0.05, 10, 2000).unwrap();
    let mut found = clusters.clone();
    found.sort_by_key(|c| std::cmp::Reverse(c.len()));
    assert_eq!(found, vec![ia.clone(), ib.clone()]);
    // Every outlier dropped: 12 singletons and the clump of 5.
    assert_eq!(points.len() - clusters.iter().map(Vec::len).sum::<usize>(), 17);
    // min_points 5 keeps the clump; max_points 300 splits blob A (515) into 258 + 257.
    let clusters = euclidean_clusters(&points, 0.05, 5, 300).unwrap();
    let mut sizes: Vec<usize> = clusters.iter().map(Vec::len).collect();
    sizes.sort_unstable();
    assert_eq!(sizes, vec![5, 257, 258, 264]);
}

#[test]
fn every_inlier_ball_is_inside_its_body_and_frames_reuse_or_refit() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (a, b) = (blob_a(&mut rng), blob_b(&mut rng));
    let (points, ia, ib) = scene(&a, &b, 2);
    let settings = CloudBodySettings::default();
    let mut bodies = CloudBodies::new();
    let first = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((first.clusters, first.outliers, first.refitted, first.added, first.reused), (2, 17, 2, 2, 0));
    assert_eq!(first.fallbacks, 0);
    let mut sets: Vec<Vec<usize>> = bodies.clusters().iter().map(|c| c.indices.clone()).collect();
    sets.sort_by_key(|c| std::cmp::Reverse(c.len()));
    assert_eq!(sets, vec![ia, ib]);
    assert_balls_contained(&bodies, &points, BallCover::Cube, 3);

    // The same points in another order: both bodies reused as they are.
    let (shuffled, ..) = scene(&a, &b, 7);
    let held: Vec<Arc<_>> = bodies.clusters().iter().map(|c| Arc::clone(&c.body)).collect();
    let same = bodies.update(&shuffled, R, &settings).unwrap();
    assert_eq!((same.reused, same.unchanged, same.refitted, same.removed), (2, 2, 0, 0));
    for c in bodies.clusters() {
        assert!(held.iter().any(|h| Arc::ptr_eq(h, &c.body)));
        assert_eq!(c.reused_for, 1);
    }
    assert_balls_contained(&bodies, &shuffled, BallCover::Cube, 4);

    // Blob B moved 0.3 m along x (past match_distance): it alone is fitted; A is reused.
    let moved: Vec<[Real; 3]> = b.iter().map(|p| [p[0] + 0.3, p[1], p[2]]).collect();
    let (points, ..) = scene(&a, &moved, 8);
    let report = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((report.reused, report.refitted, report.added, report.removed), (1, 1, 1, 1));
    assert_balls_contained(&bodies, &points, BallCover::Cube, 5);

    // Blob B shifted 2 cm (within match_distance): matched, its body no longer holds every
    // ball, refitted; A is reused.
    let shifted: Vec<[Real; 3]> = moved.iter().map(|p| [p[0] + 0.02, p[1], p[2]]).collect();
    let (points, ..) = scene(&a, &shifted, 9);
    let report = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((report.reused, report.refitted, report.added, report.removed), (1, 1, 0, 0));
    assert!(report
        .outcomes
        .iter()
        .any(|o| matches!(o, ClusterOutcome::Refitted { max_value, .. } if *max_value > 1.0)));
    assert_balls_contained(&bodies, &points, BallCover::Cube, 6);

    // Nothing left: no clusters.
    let report = bodies.update(&[], R, &settings).unwrap();
    assert_eq!((report.clusters, report.removed, bodies.len()), (0, 2, 0));
}

#[test]
fn a_body_that_grew_out_is_rescaled_within_the_limit_then_refitted() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let (a, b) = (blob_a(&mut rng), blob_b(&mut rng));
    // Blob A's points pushed out from its center (0, 0, 1) by `k`.
    let grown =
        |k: Real| -> Vec<[Real; 3]> { a.iter().map(|p| [p[0] * k, p[1] * k, 1.0 + (p[2] - 1.0) * k]).collect() };
    let settings = CloudBodySettings::default();
    assert_eq!(settings.rescale_limit, 1.25);
    let mut bodies = CloudBodies::new();
    let (points, ia, _) = scene(&a, &b, 2);
    bodies.update(&points, R, &settings).unwrap();
    let body_of = |bodies: &CloudBodies, ia: &[usize]| {
        bodies.clusters().iter().find(|c| c.indices == ia).map(|c| (Arc::clone(&c.body), c.growth)).unwrap()
    };
    let (fitted, growth) = body_of(&bodies, &ia);
    assert_eq!(growth, 1.0);

    // 1.5 % larger: matched, not contained, rescaled (no fit): p / v with v the largest p at the
    // new cover vertices; B is reused.
    let (points, ia, _) = scene(&grown(1.015), &b, 3);
    let report = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((report.reused, report.rescaled, report.refitted), (1, 1, 0));
    let factor = report
        .outcomes
        .iter()
        .find_map(|o| match o {
            ClusterOutcome::Rescaled { factor, .. } => Some(*factor),
            _ => None,
        })
        .unwrap();
    assert!(factor > 1.0 && factor <= 1.25, "factor {factor}");
    let (rescaled, growth) = body_of(&bodies, &ia);
    assert!(!Arc::ptr_eq(&fitted, &rescaled));
    assert!((growth - factor).abs() <= 1e-12 * factor, "growth {growth} against factor {factor}");
    // The new p is the old one over the factor, anywhere (to rounding).
    for _ in 0..100 {
        let x = Point3::new(rng.random::<Real>() - 0.5, rng.random::<Real>() - 0.5, 0.5 + rng.random::<Real>());
        let (old, new) = (fitted.value_at(&x), rescaled.value_at(&x));
        assert!((old / factor - new).abs() <= 1e-9 * old.abs().max(1.0), "{old} / {factor} against {new}");
    }
    assert_balls_contained(&bodies, &points, BallCover::Cube, 32);

    // 10 % larger than at first: the growth since the fit would pass 1.25, so it is fitted again.
    let (points, ia, _) = scene(&grown(1.10), &b, 4);
    let report = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((report.reused, report.rescaled, report.refitted, report.added), (1, 0, 1, 0));
    assert_eq!(body_of(&bodies, &ia).1, 1.0);
    assert_balls_contained(&bodies, &points, BallCover::Cube, 33);

    // A limit of 1 never rescales; one thread fits the same bodies as several.
    let never = CloudBodySettings { rescale_limit: 1.0, threads: 1, ..Default::default() };
    let mut one = CloudBodies::new();
    let (points, ..) = scene(&a, &b, 2);
    one.update(&points, R, &never).unwrap();
    let (points, ..) = scene(&grown(1.015), &b, 3);
    let report = one.update(&points, R, &never).unwrap();
    assert_eq!((report.reused, report.rescaled, report.refitted), (1, 0, 1));
    let (mut single, mut many) = (CloudBodies::new(), CloudBodies::new());
    single.update(&points, R, &never).unwrap();
    many.update(&points, R, &CloudBodySettings { threads: 2, ..Default::default() }).unwrap();
    for (x, y) in single.clusters().iter().zip(many.clusters()) {
        assert_eq!(x.indices, y.indices);
        for &i in x.indices.iter().step_by(17) {
            let v = Point3::from(points[i]);
            assert_eq!(x.body.value_at(&v), y.body.value_at(&v));
        }
    }
    let bad = CloudBodySettings { rescale_limit: 0.9, ..Default::default() };
    assert!(matches!(
        one.update(&points, R, &bad),
        Err(sublevel_robot::Error::InvalidArgument { field, .. }) if field == "rescale_limit"
    ));
}

#[test]
fn slack_absorbs_jitter_and_the_icosahedron_cover_contains_too() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (a, b) = (blob_a(&mut rng), blob_b(&mut rng));
    let (points, ..) = scene(&a, &b, 12);
    let settings = CloudBodySettings {
        cover: BallCover::Icosahedron,
        slack: 0.005,
        fit: CloudBodySettings::default().fit.with_degree(2),
        ..Default::default()
    };
    let mut bodies = CloudBodies::new();
    bodies.update(&points, R, &settings).unwrap();
    for c in bodies.clusters() {
        // The icosahedron's vertices (reach 1.258 R) of every ball at R + slack are inside.
        let offsets = BallCover::Icosahedron.offsets(R + 0.005);
        for &i in &c.indices {
            for o in &offsets {
                assert!(c.body.value_at(&Point3::from(Vector3::from(points[i]) + o)) <= 1.0);
            }
        }
    }
    // Each point moved by at most 2.5 mm (< slack): both bodies reused, though no point is the same.
    let jitter = |p: &[Real; 3], rng: &mut ChaCha8Rng| {
        let d = Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * 0.0025;
        (Vector3::from(*p) + d).into()
    };
    let a2: Vec<[Real; 3]> = a.iter().map(|p| jitter(p, &mut rng)).collect();
    let b2: Vec<[Real; 3]> = b.iter().map(|p| jitter(p, &mut rng)).collect();
    let (points, ..) = scene(&a2, &b2, 13);
    let report = bodies.update(&points, R, &settings).unwrap();
    assert_eq!((report.reused, report.unchanged, report.refitted), (2, 0, 0));
    assert_balls_contained(&bodies, &points, BallCover::Icosahedron, 14);
    // A change of degree (2 → 4) refits every cluster.
    let four = CloudBodySettings { cover: BallCover::Icosahedron, ..Default::default() };
    let report = bodies.update(&points, R, &four).unwrap();
    assert_eq!((report.reused, report.refitted), (0, 2));
}

/// Points seen by a depth camera on a cluster-sized object: a jittered 2 cm grid on the visible
/// faces (−x, +z, −y) of a box of `n`-dependent size, then the first `n`.
fn box_faces(n: usize, rng: &mut ChaCha8Rng) -> Vec<[Real; 3]> {
    let side = ((n as Real) / 3.0).sqrt().ceil() as usize + 1;
    let mut out = Vec::new();
    for i in 0..side {
        for j in 0..side {
            let (u, v) = (0.02 * i as Real, 0.02 * j as Real);
            for p in [[0.0, u, v], [u, v, 0.02 * side as Real], [u, 0.0, v]] {
                let d = Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * 0.004;
                out.push((Vector3::from(p) + d).into());
            }
        }
    }
    for i in (1..out.len()).rev() {
        out.swap(i, rng.random_range(0..=i));
    }
    out.truncate(n);
    out
}

#[test]
#[ignore = "a timing table; run in release with --nocapture"]
fn fit_table() {
    println!(
        "| n | shape | 2d | cover | hull vertices | fit ms | of it: Clarabel ms | of it: fit crate ms | reuse check ms | body / hull(balls) | hull(cover) / hull(balls) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for n in [50, 200, 500, 1000, 2000] {
        let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
        let shapes = [
            ("ball", {
                // A 2 cm grid cut to the n points nearest its center: a ball of n points.
                let k = ((n as Real).cbrt() * 0.7).ceil() as i32 + 1;
                let mut pts: Vec<[Real; 3]> = Vec::new();
                for i in -k..=k {
                    for j in -k..=k {
                        for l in -k..=k {
                            pts.push((Vector3::new(i as Real, j as Real, l as Real) * 0.02).into());
                        }
                    }
                }
                pts.sort_by(|p, q| Vector3::from(*p).norm().total_cmp(&Vector3::from(*q).norm()));
                pts.truncate(n);
                pts
            }),
            ("box faces", box_faces(n, &mut rng)),
        ];
        for (shape, points) in shapes {
            let idx: Vec<usize> = (0..points.len()).collect();
            let centers: Vec<Point3> = points.iter().map(|p| Point3::from(*p)).collect();
            let balls = ball_hull_volume(&centers, R).unwrap();
            for degree in [2, 4] {
                for cover in [BallCover::Cube, BallCover::Icosahedron] {
                    let mut settings = CloudBodySettings { cover, ..Default::default() };
                    settings.fit = settings.fit.with_degree(degree);
                    // The fastest of 3 (the machine is shared).
                    let fit = (0..3)
                        .map(|_| fit_cluster(&points, &idx, R, &settings).unwrap())
                        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
                        .unwrap();
                    assert!(fit.fallback.is_none() && fit.max_value <= 1.0);
                    let t = std::time::Instant::now();
                    let m = sublevel_robot::cloud::bodies::max_cover_value(&fit.body, &points, &idx, R, cover, None);
                    let check = t.elapsed().as_secs_f64();
                    assert!(m <= 1.0);
                    let cover_hull = ball_hull_volume(&cover.vertices(&points, &idx, R), 0.0).unwrap();
                    println!(
                        "| {n} | {shape} | {degree} | {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.3} | {:.3} |",
                        cover.name(),
                        fit.body.report.num_hull_vertices,
                        fit.seconds * 1e3,
                        fit.body.report.solve_seconds * 1e3,
                        fit.body.report.total_seconds * 1e3,
                        check * 1e3,
                        fit.body.report.volume / balls,
                        cover_hull / balls
                    );
                }
            }
        }
    }
}

#[test]
#[ignore = "a timing table; run in release with --nocapture"]
fn update_timing() {
    // 12 objects 0.5 m apart (six balls of 515 points, six box-face patches of 600), and 200
    // scattered points: about 6900 points.
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let mut objects: Vec<Vec<[Real; 3]>> = Vec::new();
    for k in 0..12 {
        let offset = Vector3::new(0.5 * (k % 4) as Real, 0.5 * (k / 4) as Real, 0.0);
        let pts = if k % 2 == 0 { blob_a(&mut rng) } else { box_faces(600, &mut rng) };
        objects.push(pts.iter().map(|p| (Vector3::from(*p) + offset).into()).collect());
    }
    let frame = |objects: &[Vec<[Real; 3]>], rng: &mut ChaCha8Rng, jitter: Real| {
        let mut pts: Vec<[Real; 3]> = objects
            .iter()
            .flatten()
            .map(|p| {
                (Vector3::from(*p) + Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * jitter)
                    .into()
            })
            .collect();
        pts.extend((0..200).map(|k| [-1.0 - 0.1 * (k % 20) as Real, 0.1 * (k / 20) as Real, 3.0]));
        pts
    };
    let still = frame(&objects, &mut rng, 0.0);
    println!(
        "| settings | frame | clusters | reused | rescaled | refitted | cluster ms | check ms | fit ms | total ms |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (name, settings) in [
        ("2d=4 cube", CloudBodySettings::default()),
        ("2d=2 cube", CloudBodySettings { fit: CloudBodySettings::default().fit.with_degree(2), ..Default::default() }),
        ("2d=4 cube slack 5 mm", CloudBodySettings { slack: 0.005, ..Default::default() }),
    ] {
        let mut bodies = CloudBodies::new();
        let jittered = frame(&objects, &mut rng, 0.004);
        let moved: Vec<Vec<[Real; 3]>> = objects
            .iter()
            .enumerate()
            .map(|(k, o)| if k == 3 { o.iter().map(|p| [p[0], p[1] + 0.03, p[2]]).collect() } else { o.clone() })
            .collect();
        let moved = frame(&moved, &mut rng, 0.0);
        for (what, pts) in
            [("first", &still), ("same", &still), ("jitter ±2 mm", &jittered), ("one moved 3 cm", &moved)]
        {
            let r = bodies.update(pts, R, &settings).unwrap();
            println!(
                "| {name} | {what} | {} | {} | {} | {} | {:.1} | {:.2} | {:.1} | {:.1} |",
                r.clusters,
                r.reused,
                r.rescaled,
                r.refitted,
                r.cluster_seconds * 1e3,
                r.check_seconds * 1e3,
                r.fit_seconds * 1e3,
                r.total_seconds * 1e3
            );
        }
    }
}
