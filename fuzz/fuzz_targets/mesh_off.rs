//! `parse_points_limited(data, "off", 100_000)`: Ok or Err, never a panic, an abort or an
//! unbounded allocation (run with `-malloc_limit_mb`).
#![no_main]

use libfuzzer_sys::fuzz_target;

/// The limit the targets parse under (small enough that a lying count shows as a big allocation).
const MAX_POINTS: usize = 100_000;

fuzz_target!(|data: &[u8]| {
    if let Ok(points) = sublevel::fit::mesh::parse_points_limited(data, sublevel::fit::mesh::MeshFormat::Off, MAX_POINTS) {
        assert!(!points.is_empty() && points.len() <= MAX_POINTS, "{} points", points.len());
        assert!(points.iter().all(|p| p.coords.iter().all(|c| c.is_finite())), "a non-finite coordinate");
    }
});
