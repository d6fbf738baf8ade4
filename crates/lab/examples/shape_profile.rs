//! Profiling driver for the active-set shape solver: the chair_101 body (2d = 6) against the box
//! bounding human_10, at the cold poses of `sublevel-lab primitives`' body row, repeated; prints
//! the median time per query and the mean iterations. Run it from the repository root under
//! `perf record -g` for the profile:
//!
//! ```text
//! cargo build --release -p sublevel-lab --example shape_profile
//! perf record -g target/release/examples/shape_profile 200 && perf report
//! ```

use std::time::Instant;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::primitive::{Primitive, PrimitiveFile};
use sublevel_query::shape::{shape_distance, ShapeRef};

fn main() {
    let repeats: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(100);
    let chair =
        Body::load(std::path::Path::new("tests/data/chair_101.deg6.json")).expect("run from the repository root");
    let boxed = Primitive::from_file(&PrimitiveFile::Box { size: [0.6, 0.5, 1.7] }).unwrap();
    let mut seed = 7u64;
    let mut u = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 11) as Real / (1u64 << 53) as Real) * 2.0 - 1.0
    };
    let poses: Vec<Isometry3> = (0..300)
        .map(|_| {
            let t = Vector3::new(u(), u(), u()) * 2.5;
            let q = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(u(), u(), u(), u()));
            Isometry3::from_parts(t.into(), q)
        })
        .collect();
    let mut times = Vec::new();
    let mut iterations = 0;
    for p in &poses {
        let t = Instant::now();
        for _ in 0..repeats {
            let r =
                shape_distance(ShapeRef::Body(&chair), p, ShapeRef::Primitive(&boxed), &Isometry3::identity(), None);
            std::hint::black_box(r.ok());
        }
        times.push(t.elapsed().as_secs_f64() * 1e9 / repeats as Real);
        iterations +=
            shape_distance(ShapeRef::Body(&chair), p, ShapeRef::Primitive(&boxed), &Isometry3::identity(), None)
                .map(|r| r.iterations)
                .unwrap_or(0);
    }
    times.sort_by(Real::total_cmp);
    println!(
        "body–box cold: median {:.0} ns, mean iterations {:.2}",
        times[times.len() / 2],
        iterations as Real / poses.len() as Real
    );
}
