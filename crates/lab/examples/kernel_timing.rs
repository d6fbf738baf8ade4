//! Timing of the polynomial kernels alone: the chair_101 body of `tests/data` at one
//! degree, 1024 points inside it, each evaluated 200 times per round; prints ns per evaluation for
//! a full evaluation (p, ∇p, ∇²p) on independent points, on a chain where each point depends on
//! the previous answer (the Newton solvers' pattern), for value + gradient, and for full
//! evaluations four points per pass (`SoaPoly::eval4`, per point), and the same in single precision
//! (`SoaPoly::eval4_rows_f32`). Run it from the repository root (it reads the bundled body from
//! `tests/data`):
//!
//! ```text
//! cargo run --release -p sublevel-lab --example kernel_timing -- 6      # 2d = 6 (2, 4, 6 or 8)
//! ```
//!
//! Compare two builds by alternating their runs on one machine within minutes: the machine's
//! speed drifts between minutes.

use std::time::Instant;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::Body;

fn main() -> sublevel_core::Result<()> {
    let degree: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let chair = Body::load(&std::path::Path::new("tests/data").join(format!("chair_101.deg{degree}.json")))?;
    let f = chair.fast_polynomial();
    let soa = sublevel_core::poly::SoaPoly::new(f);
    let points: Vec<Vector3> = (0..1024)
        .map(|i| {
            let t = i as Real * 0.01;
            Vector3::new(t.sin() * 0.3, (1.3 * t).cos() * 0.3, (0.7 * t).sin() * 0.3)
        })
        .collect();
    let per_eval = |t: Instant| t.elapsed().as_secs_f64() * 1e9 / (200.0 * points.len() as f64);
    // The single-precision kernel's largest error on these points, relative to max(1, |q|) for
    // each quantity q of p, ∇p, ∇²p.
    let mut worst: Real = 0.0;
    for q in points.chunks_exact(4) {
        let rows: [[Real; 4]; 3] = std::array::from_fn(|i| [q[0][i], q[1][i], q[2][i], q[3][i]]);
        let (e, s) = (soa.eval4_rows(&rows), soa.eval4_rows_f32(&rows));
        let mut pairs = vec![(e.value, s.value)];
        pairs.extend(e.gradient.iter().zip(&s.gradient).map(|(a, b)| (*a, *b)));
        pairs.extend(e.hessian.iter().zip(&s.hessian).map(|(a, b)| (*a, *b)));
        for (a, b) in pairs {
            for k in 0..4 {
                worst = worst.max((a[k] - b[k]).abs() / a[k].abs().max(1.0));
            }
        }
    }
    println!("2d = {degree}: single-precision kernel, largest relative error {worst:.1e}");
    for round in 0..3 {
        let t = Instant::now();
        let mut sum = 0.0;
        for _ in 0..200 {
            for u in &points {
                let e = f.eval(std::hint::black_box(u));
                sum += e.value + e.hessian[(0, 0)];
            }
        }
        let independent = per_eval(t);
        // Each point moved by a negligible multiple of the previous answer: a dependency chain.
        let t = Instant::now();
        let mut u = points[0];
        for _ in 0..200 {
            for p in &points {
                let e = f.eval(&u);
                u = p + Vector3::new(e.value, e.gradient.x, e.hessian[(2, 2)]) * 1e-30;
            }
        }
        let dependent = per_eval(t);
        let t = Instant::now();
        for _ in 0..200 {
            for u in &points {
                let (v, g) = f.value_gradient(std::hint::black_box(u));
                sum += v + g.x;
            }
        }
        let gradient = per_eval(t);
        // Four points per pass (the structure-of-arrays table).
        let t = Instant::now();
        for _ in 0..200 {
            for q in points.chunks_exact(4) {
                let e = soa.eval4(std::hint::black_box(&[q[0], q[1], q[2], q[3]]));
                sum += e.value[0] + e.hessian[0][3];
            }
        }
        let four = per_eval(t);
        // The same in single precision (`SoaPoly::eval4_rows_f32`).
        let rows: Vec<[[Real; 4]; 3]> =
            points.chunks_exact(4).map(|q| std::array::from_fn(|i| [q[0][i], q[1][i], q[2][i], q[3][i]])).collect();
        let t = Instant::now();
        for _ in 0..200 {
            for r in &rows {
                let e = soa.eval4_rows_f32(std::hint::black_box(r));
                sum += e.value[0] + e.hessian[0][3];
            }
        }
        let single = per_eval(t);
        println!(
            "2d = {degree}, round {round}: full {independent:.1} ns independent, {dependent:.1} ns dependent; \
             value + gradient {gradient:.1} ns; full, four points per pass {four:.1} ns, in f32 {single:.1} ns \
             (checksum {:.6e})",
            sum + u.x
        );
    }
    Ok(())
}
