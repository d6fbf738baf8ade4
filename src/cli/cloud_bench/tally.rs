//! What `sublevel cloud bench` measures per frame format: latency histograms, points kept, and the
//! bodies model's work, printed and returned as JSON.

use super::FrameFormat;
use hdrhistogram::Histogram;
use std::time::Duration;

/// Microseconds of `d`, saturating.
pub(super) fn micros(d: Duration) -> u64 {
    d.as_micros().min(u128::from(u64::MAX)) as u64
}

/// A latency histogram: 1 µs to 10 minutes, 3 significant digits.
pub(super) fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 600_000_000, 3).expect("valid histogram bounds")
}

/// What the updates of one format measured.
pub(super) struct Tally {
    pub(super) format: FrameFormat,
    pub(super) update: Histogram<u64>,
    pub(super) server: Histogram<u64>,
    pub(super) first_check: Histogram<u64>,
    pub(super) check: Histogram<u64>,
    pub(super) kept: Vec<u64>,
    /// The bodies model's clusters, reused, rescaled and fitted per update (`--model bodies`).
    pub(super) bodies: Vec<[u64; 4]>,
    /// The bodies model's clustering and fitting seconds per update.
    pub(super) body_seconds: Vec<[f64; 2]>,
    pub(super) holes: Vec<u64>,
    pub(super) input: u64,
    pub(super) memory: u64,
    pub(super) colliding: u64,
    pub(super) stale: u64,
}

impl Tally {
    pub(super) fn new(format: FrameFormat) -> Tally {
        Tally {
            format,
            update: histogram(),
            server: histogram(),
            first_check: histogram(),
            check: histogram(),
            kept: Vec::new(),
            holes: Vec::new(),
            bodies: Vec::new(),
            body_seconds: Vec::new(),
            input: 0,
            memory: 0,
            colliding: 0,
            stale: 0,
        }
    }

    fn name(&self) -> &'static str {
        if self.format == FrameFormat::Packed {
            "packed float32 (16 B/point)"
        } else {
            "depth uint16 mm"
        }
    }

    /// Prints the figures; returns them as JSON.
    pub(super) fn report(&self) -> serde_json::Value {
        let ms = |h: &Histogram<u64>, q: f64| h.value_at_quantile(q) as f64 / 1e3;
        let line = |what: &str, h: &Histogram<u64>| {
            println!(
                "  {what:<34} median {:>8.2} ms  p95 {:>8.2} ms  max {:>8.2} ms",
                ms(h, 0.5),
                ms(h, 0.95),
                h.max() as f64 / 1e3
            );
        };
        let median = |v: &[u64]| {
            let mut v = v.to_vec();
            v.sort_unstable();
            v.get(v.len() / 2).copied().unwrap_or(0)
        };
        println!("{}: {} updates", self.name(), self.update.len());
        line("UpdatePointCloud round trip", &self.update);
        line("server seconds", &self.server);
        line("first check answer (update sent)", &self.first_check);
        line("the check alone", &self.check);
        println!(
            "  points kept median {} of {} (holes median {}), cloud memory {:.0} KiB, the check collides {} of {}",
            median(&self.kept),
            self.input,
            median(&self.holes),
            self.memory as f64 / 1024.0,
            self.colliding,
            self.update.len()
        );
        let bodies: [u64; 4] = std::array::from_fn(|k| self.bodies.iter().map(|b| b[k]).sum());
        if !self.bodies.is_empty() {
            let ms = |k: usize| {
                let mut v: Vec<f64> = self.body_seconds.iter().map(|s| 1e3 * s[k]).collect();
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            println!(
                "  bodies: clusters median {}; of all clusters {} reused, {} rescaled, {} fitted; \
                 clustering median {:.2} ms, reuse checks and fits median {:.2} ms",
                median(&self.bodies.iter().map(|b| b[0]).collect::<Vec<_>>()),
                bodies[1],
                bodies[2],
                bodies[3],
                ms(0),
                ms(1)
            );
        }
        let q = |h: &Histogram<u64>| serde_json::json!({"median_ms": ms(h, 0.5), "p95_ms": ms(h, 0.95), "max_ms": h.max() as f64 / 1e3});
        serde_json::json!({
            "format": self.name(),
            "updates": self.update.len(),
            "update": q(&self.update),
            "server_seconds": q(&self.server),
            "first_check": q(&self.first_check),
            "check_alone": q(&self.check),
            "points_input": self.input,
            "points_kept_median": median(&self.kept),
            "holes_median": median(&self.holes),
            "cloud_memory_bytes": self.memory,
            "colliding": self.colliding,
            "bodies": (!self.bodies.is_empty()).then(|| serde_json::json!({
                "reused": bodies[1], "rescaled": bodies[2], "fitted": bodies[3],
            })),
        })
    }
}
