//! Criterion benchmarks of the query engine on the paper's chair and human (fitted bodies bundled in
//! tests/data): cold and warm distance and growth at every degree present.
//!
//! `cargo bench -p sublevel-query --bench queries` (add `-- distance/6` to filter). Targets (2d = 6,
//! medians): warm growth ≤ 0.5 µs, warm distance ≤ 0.7 µs, cold distance ≤ 2.5 µs. Each measured
//! iteration runs the query at all 16 poses of [`poses`], so divide the reported time by 16 for one
//! query (`sublevel-lab bench` prints per-query medians).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;
use sublevel_core::math::{Isometry3, UnitQuaternion, Vector3};
use sublevel_core::Body;
use sublevel_query::{distance, growth, NewtonParams};

fn load(name: &str, degree: usize) -> Option<Body> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(format!("tests/data/{name}.deg{degree}.json"));
    Body::load(&path).ok()
}

/// A fixed set of chair poses around the human: separated, touching-ish and overlapping.
fn poses() -> Vec<Isometry3> {
    (0..16)
        .map(|k| {
            let s = k as f64 / 15.0;
            let t = Vector3::new(-2.2 + 4.4 * s, 0.4 * (3.0 * s).sin(), 0.2);
            let r = UnitQuaternion::from_euler_angles(0.3 * s, 1.1 * s, -0.4 * s);
            Isometry3::from_parts(t.into(), r)
        })
        .collect()
}

/// One value + gradient + Hessian evaluation: the reference `Polynomial::eval` against the
/// table-free, degree-specialised `FastPoly::eval` (the query hot path), and value + gradient only.
fn bench_eval(c: &mut Criterion) {
    for degree in [2, 4, 6, 8] {
        let Some(chair) = load("chair_101", degree) else { continue };
        let pts: Vec<Vector3> =
            (0..16).map(|k| Vector3::new(0.1 * k as f64 - 0.8, 0.3 - 0.02 * k as f64, 0.05 * k as f64 - 0.4)).collect();
        let mut group = c.benchmark_group("eval");
        group.bench_function(BenchmarkId::new("reference", degree), |b| {
            b.iter(|| pts.iter().map(|u| black_box(chair.polynomial().eval(black_box(u))).value).sum::<f64>())
        });
        group.bench_function(BenchmarkId::new("fast", degree), |b| {
            b.iter(|| pts.iter().map(|u| black_box(chair.fast_polynomial().eval(black_box(u))).value).sum::<f64>())
        });
        group.bench_function(BenchmarkId::new("fast_value_gradient", degree), |b| {
            b.iter(|| {
                pts.iter().map(|u| black_box(chair.fast_polynomial().value_gradient(black_box(u))).0).sum::<f64>()
            })
        });
        group.finish();
    }
}

fn bench_queries(c: &mut Criterion) {
    let params = NewtonParams::default();
    let human_pose = Isometry3::identity();
    for degree in [2, 4, 6, 8] {
        let (Some(chair), Some(human)) = (load("chair_101", degree), load("human_10", degree)) else {
            eprintln!("skipping 2d = {degree}: bodies not bundled");
            continue;
        };
        let ps = poses();
        // Warm starts from a slightly earlier pose along the same motion.
        let near: Vec<Isometry3> = ps
            .iter()
            .map(|p| Isometry3::from_parts((p.translation.vector - Vector3::new(0.01, 0.0, 0.0)).into(), p.rotation))
            .collect();
        let wd: Vec<_> =
            near.iter().map(|p| distance(&chair, p, &human, &human_pose, None, &params).warm_start).collect();
        let wg: Vec<_> =
            near.iter().map(|p| growth(&chair, p, &human, &human_pose, None, &params).warm_start).collect();
        let mut group = c.benchmark_group("distance");
        group.bench_function(BenchmarkId::new("cold", degree), |b| {
            b.iter(|| {
                for p in &ps {
                    black_box(distance(&chair, p, &human, &human_pose, None, &params));
                }
            })
        });
        group.bench_function(BenchmarkId::new("warm", degree), |b| {
            b.iter(|| {
                for (p, w) in ps.iter().zip(&wd) {
                    black_box(distance(&chair, p, &human, &human_pose, Some(w), &params));
                }
            })
        });
        group.finish();
        let mut group = c.benchmark_group("growth");
        group.bench_function(BenchmarkId::new("cold", degree), |b| {
            b.iter(|| {
                for p in &ps {
                    black_box(growth(&chair, p, &human, &human_pose, None, &params));
                }
            })
        });
        group.bench_function(BenchmarkId::new("warm", degree), |b| {
            b.iter(|| {
                for (p, w) in ps.iter().zip(&wg) {
                    black_box(growth(&chair, p, &human, &human_pose, Some(w), &params));
                }
            })
        });
        group.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(2));
    targets = bench_eval, bench_queries
}
criterion_main!(benches);
