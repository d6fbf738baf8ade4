//! The joint space a plan moves in: each configuration entry's bounds, the continuous joints
//! that wrap, the joint-space distance and straight segments, and the low-discrepancy sampler
//! that draws configurations in the bounds.
//!
//! Distances are Euclidean in joint space (radians and meters mixed, as OMPL's and VAMP's
//! real-vector spaces measure them); a continuous joint's difference is taken the shorter way
//! round (wrapped into (−π, π]), as [`sublevel_robot::MotionChecker`] interpolates it.

use rand::Rng;
use std::f64::consts::PI;
use sublevel_core::math::Real;
use sublevel_robot::{JointKind, RobotModel};

/// Bounds and wrapping of each configuration entry.
#[derive(Clone, Debug, PartialEq)]
pub struct JointSpace {
    /// `(lower, upper)` per entry (radians or meters); a continuous joint's is (−π, π).
    pub bounds: Vec<(Real, Real)>,
    /// Whether each entry is a continuous joint (its differences wrap into (−π, π]).
    pub wraps: Vec<bool>,
}

impl JointSpace {
    /// The space of `model`'s configuration entries, in [`RobotModel::variable_names`] order: the
    /// URDF limits, (−π, π) and wrapping for continuous joints.
    pub fn of(model: &RobotModel) -> Self {
        let (mut bounds, mut wraps) = (Vec::new(), Vec::new());
        for k in 0..model.dof() {
            let joint = model.variable_joint(k);
            let wrap = joint.kind == JointKind::Continuous || joint.limits.is_none();
            bounds.push(if wrap { (-PI, PI) } else { joint.limits.unwrap_or((-PI, PI)) });
            wraps.push(wrap);
        }
        Self { bounds, wraps }
    }

    /// A box `bounds` with no wrapping entry (tests, toy problems).
    pub fn boxed(bounds: Vec<(Real, Real)>) -> Self {
        let wraps = vec![false; bounds.len()];
        Self { bounds, wraps }
    }

    /// Holds entry `k` at `value` (radians or meters): its bounds become `(value, value)` and it
    /// no longer wraps, so the sampler, the distance and the segments leave it there. The joints a
    /// plan does not move (those outside MoveIt's planning group) are held so, and the search
    /// runs in the space of the others.
    pub fn hold(&mut self, k: usize, value: Real) {
        self.bounds[k] = (value, value);
        self.wraps[k] = false;
    }

    /// The number of configuration entries.
    pub fn dof(&self) -> usize {
        self.bounds.len()
    }

    /// The difference `b − a` of entry `k`, wrapped into (−π, π] for a continuous joint.
    #[inline]
    pub fn delta(&self, k: usize, a: Real, b: Real) -> Real {
        let d = b - a;
        if self.wraps[k] {
            let w = d.rem_euclid(2.0 * PI);
            if w > PI {
                w - 2.0 * PI
            } else {
                w
            }
        } else {
            d
        }
    }

    /// The joint-space distance from `a` to `b` (module docs).
    #[inline]
    pub fn distance(&self, a: &[Real], b: &[Real]) -> Real {
        self.distance_squared(a, b).sqrt()
    }

    /// The squared joint-space distance from `a` to `b`.
    #[inline]
    pub fn distance_squared(&self, a: &[Real], b: &[Real]) -> Real {
        let mut s = 0.0;
        for k in 0..a.len() {
            let d = self.delta(k, a[k], b[k]);
            s += d * d;
        }
        s
    }

    /// The point at `t ∈ [0, 1]` of the straight segment from `a` to `b`, written to `out`
    /// (continuous joints along the shorter way, wrapped back into (−π, π]).
    #[inline]
    pub fn interpolate(&self, a: &[Real], b: &[Real], t: Real, out: &mut Vec<Real>) {
        out.clear();
        for k in 0..a.len() {
            let v = a[k] + t * self.delta(k, a[k], b[k]);
            out.push(if self.wraps[k] { wrap(v) } else { v });
        }
    }

    /// The path's length: the sum of its segments' distances.
    pub fn length(&self, path: &[Vec<Real>]) -> Real {
        path.windows(2).map(|w| self.distance(&w[0], &w[1])).sum()
    }
}

/// `v` wrapped into (−π, π].
fn wrap(v: Real) -> Real {
    let w = (v + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

/// Configurations drawn from a Halton sequence (one prime base per entry) under a random shift
/// per entry (Cranley and Patterson, 1976), seeded: the same seed gives the same samples on
/// every machine, and the points fill the joint box more evenly than independent uniform draws
/// (the low-discrepancy sampling VAMP's planners use).
#[derive(Clone, Debug)]
pub struct HaltonSampler {
    bases: Vec<u64>,
    shift: Vec<Real>,
    index: u64,
}

impl HaltonSampler {
    /// A sampler of `dof` entries whose shifts come from `rng`.
    pub fn new(dof: usize, rng: &mut impl Rng) -> Self {
        let bases = primes(dof);
        let shift = (0..dof).map(|_| rng.random::<Real>()).collect();
        Self { bases, shift, index: 0 }
    }

    /// The next point of the unit cube `[0, 1)^dof`, written to `out`.
    pub fn next_unit(&mut self, out: &mut Vec<Real>) {
        self.index += 1;
        out.clear();
        for (k, &b) in self.bases.iter().enumerate() {
            let u = radical_inverse(self.index, b) + self.shift[k];
            out.push(u - u.floor());
        }
    }

    /// The next configuration in `space`'s bounds, written to `out`.
    pub fn next_in(&mut self, space: &JointSpace, out: &mut Vec<Real>) {
        self.next_unit(out);
        for (v, &(lo, hi)) in out.iter_mut().zip(&space.bounds) {
            *v = lo + *v * (hi - lo);
        }
    }
}

/// The radical inverse of `i` in base `b`: its digits mirrored about the point.
fn radical_inverse(mut i: u64, b: u64) -> Real {
    let (mut value, mut scale) = (0.0, 1.0 / b as Real);
    while i > 0 {
        value += (i % b) as Real * scale;
        i /= b;
        scale /= b as Real;
    }
    value
}

/// The first `n` primes.
fn primes(n: usize) -> Vec<u64> {
    let mut out: Vec<u64> = Vec::with_capacity(n);
    let mut c = 2u64;
    while out.len() < n {
        if out.iter().take_while(|&&p| p * p <= c).all(|&p| !c.is_multiple_of(p)) {
            out.push(c);
        }
        c += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn halton_base_two_and_three_match_their_closed_form() {
        // Base 2: 1/2, 1/4, 3/4, 1/8; base 3: 1/3, 2/3, 1/9, 4/9.
        let expect2 = [0.5, 0.25, 0.75, 0.125];
        let expect3 = [1.0 / 3.0, 2.0 / 3.0, 1.0 / 9.0, 4.0 / 9.0];
        for i in 0..4 {
            assert!((radical_inverse(i as u64 + 1, 2) - expect2[i]).abs() < 1e-15);
            assert!((radical_inverse(i as u64 + 1, 3) - expect3[i]).abs() < 1e-15);
        }
        assert_eq!(primes(8), vec![2, 3, 5, 7, 11, 13, 17, 19]);
    }

    #[test]
    fn halton_points_fill_the_box_evenly_and_repeat_with_their_seed() {
        // 4 096 points in the unit square: every cell of a 16 × 16 grid holds 16 ± 4 of them
        // (independent uniform draws would leave cells with 16 ± 12 at 3σ).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut s = HaltonSampler::new(2, &mut rng);
        let mut counts = [[0usize; 16]; 16];
        let mut u = Vec::new();
        let mut first = Vec::new();
        for i in 0..4096 {
            s.next_unit(&mut u);
            if i == 0 {
                first = u.clone();
            }
            counts[(u[0] * 16.0) as usize][(u[1] * 16.0) as usize] += 1;
        }
        for row in counts {
            for c in row {
                assert!((12..=20).contains(&c), "cell count {c}");
            }
        }
        let mut again = HaltonSampler::new(2, &mut rand_chacha::ChaCha8Rng::seed_from_u64(7));
        again.next_unit(&mut u);
        assert_eq!(u, first);
    }

    #[test]
    fn continuous_entries_take_the_shorter_way_round() {
        let space = JointSpace { bounds: vec![(-PI, PI), (-1.0, 1.0)], wraps: vec![true, false] };
        let (a, b) = ([3.0, 0.0], [-3.0, 1.0]);
        let d = space.distance(&a, &b);
        let expect = ((2.0 * PI - 6.0) * (2.0 * PI - 6.0) + 1.0 as Real).sqrt();
        assert!((d - expect).abs() < 1e-12);
        let mut mid = Vec::new();
        space.interpolate(&a, &b, 0.5, &mut mid);
        // Halfway from 3 to −3 the short way is ±π.
        assert!((mid[0].abs() - PI).abs() < 1e-12 && (mid[1] - 0.5).abs() < 1e-15);
    }
}
