//! Volume of a sublevel set `{u : p(u) ≤ 1}` by seeded Monte Carlo in a region that provably
//! contains it.
//!
//! Convex p ([`monte_carlo_volume`]): a box from supporting halfspaces, see below. Nonconvex sos p
//! ([`monte_carlo_volume_sos`]): cubes proven to cover the set, see [`sos_radius`] and
//! [`covering_cells`].
//!
//! The box comes from six supporting halfspaces of the convex body (see [`bounding_box`]), taken
//! at approximate support points along ±eₖ. A support point maximizes eᵀu on `{p ≤ 1}`; it is
//! the maximizer u(λ) of the smooth concave `eᵀu − λ p(u)` (damped Newton, stationarity
//! λ∇p(u) = e) with λ bisected in log scale until p(u(λ)) = 1.
//! Every sample uses one `ChaCha8` stream seeded by the caller, so the estimate is reproducible.

use crate::{Error, Result};
use rand::{Rng, SeedableRng};
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::monomial::index3;
use sublevel_core::poly::Polynomial;

/// A Monte Carlo volume estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeEstimate {
    /// Estimated volume (units of the polynomial's coordinates, cubed).
    pub volume: Real,
    /// Standard error of `volume`: box_volume · sqrt(f(1 − f)/n), f the hit fraction.
    pub std_error: Real,
    /// Samples drawn.
    pub samples: usize,
    /// The sampling box `[lo, hi]`.
    pub lo: Vector3,
    /// Upper corner of the sampling box.
    pub hi: Vector3,
}

/// Minimizes `λ p(u) − eᵀu` by damped Newton from `u`; returns the minimizer.
fn inner_newton(p: &Polynomial, lambda: Real, e: &Vector3, mut u: Vector3) -> Vector3 {
    let f = |v: &Vector3| lambda * p.value(v) - e.dot(v);
    for _ in 0..100 {
        let ev = p.eval(&u);
        let g = ev.gradient * lambda - e;
        let h = ev.hessian * lambda;
        let reg = 1e-14 * (1.0 + h.norm());
        let h = h + sublevel_core::math::Matrix3::identity() * reg;
        let step = match nalgebra::Cholesky::new(h) {
            Some(ch) => -ch.solve(&g),
            None => -g,
        };
        let dec = -g.dot(&step);
        if dec.is_nan() || dec <= 1e-28 {
            break;
        }
        let f0 = f(&u);
        let mut t = 1.0;
        let mut moved = false;
        while t > 1e-14 {
            let trial = u + step * t;
            let ft = f(&trial);
            if ft.is_finite() && ft <= f0 - 0.25 * t * dec {
                u = trial;
                moved = true;
                break;
            }
            t *= 0.5;
        }
        if !moved {
            break;
        }
    }
    u
}

/// A point near the maximizer of `eᵀu` over `{p ≤ 1}`: the inner maximizer u(λ) with λ bisected
/// (in log scale) towards p(u(λ)) = 1, starting from an interior point `u0` with p(u0) < 1.
fn support_point(p: &Polynomial, e: &Vector3, u0: &Vector3) -> Result<Vector3> {
    let (mut lo, mut hi) = (0.0_f64, 0.0_f64);
    let mut u = *u0;
    let mut lam: Real = 1.0;
    let (mut found_lo, mut found_hi) = (false, false);
    for _ in 0..80 {
        u = inner_newton(p, lam, e, u);
        if p.value(&u) > 1.0 {
            lo = lam.ln();
            found_lo = true;
            if found_hi {
                break;
            }
            lam *= 4.0;
        } else {
            hi = lam.ln();
            found_hi = true;
            if found_lo {
                break;
            }
            lam /= 4.0;
        }
    }
    if !(found_lo && found_hi) {
        return Err(Error::Numerical("could not bracket the support function of the fitted body".into()));
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        u = inner_newton(p, mid.exp(), e, u);
        if p.value(&u) > 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-13 {
            break;
        }
    }
    Ok(u)
}

/// A box that contains `{u : p(u) ≤ 1}` for convex p.
///
/// For any point v, convexity gives the supporting halfspace
///
/// ```text
/// p(w) ≥ p(v) + ∇p(v)ᵀ(w − v)   ⇒   {p ≤ 1} ⊂ { w : ∇p(v)ᵀ w ≤ ∇p(v)ᵀ v + 1 − p(v) }
/// ```
///
/// whatever the accuracy of v. Taking v near the support points along ±x, ±y, ±z gives six
/// halfspaces with normals close to the axes, i.e. a slightly skewed cube; the box is the
/// bounding box of its 8 corners (each one solves a 3 × 3 system), padded by 1e-9 of its width
/// for rounding. Accuracy of v only affects how tight the box is, not whether it contains the body.
///
/// # Errors
/// [`Error::Numerical`] when a support point cannot be found or the halfspaces do not form a
/// cube-like polytope (p not convex / not coercive).
pub fn bounding_box(p: &Polynomial, interior: &Vector3) -> Result<(Vector3, Vector3)> {
    bounding_box_from_support(p, |e| support_point(p, e, interior))
}

pub use sublevel_core::poly::support::bounding_box_from_support;

/// Estimates the volume of `{u : p(u) ≤ 1}` with at least `samples` uniform samples of its bounding
/// box, doubling the sample count (up to 16×) until the relative standard error is below 1 %.
///
/// # Errors
/// [`Error::Numerical`] when the bounding box cannot be computed.
pub fn monte_carlo_volume(p: &Polynomial, interior: &Vector3, samples: usize, seed: u64) -> Result<VolumeEstimate> {
    let (lo, hi) = bounding_box(p, interior)?;
    let w = hi - lo;
    let box_volume = w.x * w.y * w.z;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (mut n, mut hits) = (0usize, 0usize);
    let mut target = samples.max(1000);
    let cap = target * 16;
    loop {
        while n < target {
            let u = Vector3::new(
                lo.x + w.x * rng.random::<Real>(),
                lo.y + w.y * rng.random::<Real>(),
                lo.z + w.z * rng.random::<Real>(),
            );
            if p.value(&u) <= 1.0 {
                hits += 1;
            }
            n += 1;
        }
        let f = hits as Real / n as Real;
        let se = box_volume * (f * (1.0 - f) / n as Real).sqrt();
        let vol = box_volume * f;
        if (hits > 0 && se < 0.01 * vol) || n >= cap {
            return Ok(VolumeEstimate { volume: vol, std_error: se, samples: n, lo, hi });
        }
        target *= 2;
    }
}

/// Largest multinomial coefficient d!/(a! b! c!) over a + b + c = d, d ≤ 4: K_d with
/// (‖u‖²)ᵈ ≤ K_d Σ_{|α| = d} u^{2α}.
const MAX_MULTINOMIAL: [Real; 5] = [1.0, 1.0, 2.0, 6.0, 12.0];

/// A radius R with `{u : p(u) ≤ 1} ⊂ {‖u‖ ≤ R}` for p = z(u)ᵀ P z(u) of degree 2d, P ⪰ λ I, λ > 0.
///
/// ```text
/// p(u) ≥ λ ‖z(u)‖² ≥ λ Σ_{|α|=d} u^{2α} ≥ λ ‖u‖^{2d} / K_d     (multinomial theorem)
/// ⇒ p(u) > 1 whenever ‖u‖ > R = (K_d / λ)^{1/(2d)}
/// ```
///
/// `lambda_min` must be a lower bound on λ_min(P) of the Gram matrix the coefficients of p were
/// expanded from; R is padded by 1e-6 relative for the rounding of that expansion.
///
/// # Errors
/// [`Error::Numerical`] when `lambda_min` is not positive and finite or `degree` is not 2, 4, 6, 8.
pub fn sos_radius(degree: usize, lambda_min: Real) -> Result<Real> {
    if !(lambda_min.is_finite() && lambda_min > 0.0) {
        return Err(Error::Numerical(format!("the sos Gram matrix is not positive definite (λ_min = {lambda_min:e})")));
    }
    if !matches!(degree, 2 | 4 | 6 | 8) {
        return Err(Error::Numerical(format!("no sos radius for degree {degree}")));
    }
    let d = degree / 2;
    Ok((MAX_MULTINOMIAL[d] / lambda_min).powf(1.0 / degree as Real) * (1.0 + 1e-6))
}

/// Interval bounds of a polynomial on axis-aligned cubes, by re-expansion at the cube's center:
/// with `q(t) = p(b + h t) = Σ_β q_β t^β`, `t ∈ [−1, 1]³`,
///
/// ```text
/// q_β = h^{|β|} Σ_{α ≥ β} c_α Πₖ C(αₖ, βₖ) bₖ^{αₖ − βₖ}
/// q₀ + Σ_{β ≠ 0} lo_β ≤ p ≤ q₀ + Σ_{β ≠ 0} hi_β,   (lo, hi)_β = (min(0, q_β), max(0, q_β)) if every
///                                                  βₖ is even (t^β ∈ [0, 1]), else (−|q_β|, |q_β|)
/// ```
pub struct CubeBounds<'a> {
    p: &'a Polynomial,
    /// (index of α, index of β, Πₖ C(αₖ, βₖ), α − β).
    terms: Vec<(usize, usize, Real, [u8; 3])>,
    even: Vec<bool>,
    total_degree: Vec<i32>,
}

impl<'a> CubeBounds<'a> {
    /// Precomputes the re-expansion of `p`.
    pub fn new(p: &'a Polynomial) -> Self {
        let binom = |n: u8, k: u8| -> Real { (0..k).fold(1.0, |acc, i| acc * (n - i) as Real / (i + 1) as Real) };
        let mut terms = Vec::new();
        for (ia, a) in p.exponents().iter().enumerate() {
            for b0 in 0..=a[0] {
                for b1 in 0..=a[1] {
                    for b2 in 0..=a[2] {
                        let w = binom(a[0], b0) * binom(a[1], b1) * binom(a[2], b2);
                        terms.push((ia, index3([b0, b1, b2]), w, [a[0] - b0, a[1] - b1, a[2] - b2]));
                    }
                }
            }
        }
        let even = p.exponents().iter().map(|e| e.iter().all(|k| k % 2 == 0)).collect();
        let total_degree = p.exponents().iter().map(|e| e.iter().map(|k| *k as i32).sum()).collect();
        Self { p, terms, even, total_degree }
    }

    /// Lower and upper bounds of p on the cube `center + [−half, half]³`.
    pub fn bounds(&self, center: &Vector3, half: Real) -> (Real, Real) {
        let deg = self.p.degree();
        let mut bp = [[1.0; 9]; 3];
        for k in 0..3 {
            for e in 1..=deg {
                bp[k][e] = bp[k][e - 1] * center[k];
            }
        }
        let c = self.p.coefficients();
        let mut q = [0.0; 165];
        for &(ia, ib, w, r) in &self.terms {
            q[ib] += c[ia] * w * bp[0][r[0] as usize] * bp[1][r[1] as usize] * bp[2][r[2] as usize];
        }
        let (mut lo, mut hi) = (q[0], q[0]);
        for ((qb, deg), even) in q.iter().zip(&self.total_degree).zip(&self.even).take(c.len()).skip(1) {
            let v = qb * half.powi(*deg);
            if *even {
                lo += v.min(0.0);
                hi += v.max(0.0);
            } else {
                lo -= v.abs();
                hi += v.abs();
            }
        }
        (lo, hi)
    }
}

/// Cubes covering `{u : p(u) ≤ 1}` inside the cube `[−radius, radius]³`.
#[derive(Clone, Debug)]
pub struct CubeCover {
    /// Centers of the cubes on which p may cross 1 (neither bound settles it).
    pub boundary: Vec<Vector3>,
    /// Number of cubes proven inside (upper bound of p ≤ 1 − 1e-9).
    pub inside: usize,
    /// Half side of every cube.
    pub half: Real,
    /// Bounding box of all kept cubes.
    pub lo: Vector3,
    /// Upper corner of that box.
    pub hi: Vector3,
}

/// Most boundary cubes a cover may hold before refinement stops.
const MAX_CUBES: usize = 2_000_000;

/// Refines `[−radius, radius]³` by octree subdivision down to cubes of side ≤ `target_side`
/// (or until [`MAX_CUBES`] would be exceeded), dropping cubes where the lower bound of
/// [`CubeBounds`] exceeds 1 + 1e-9 (p > 1 on the whole cube) and setting aside cubes where the
/// upper bound is below 1 − 1e-9 (inside). If `{p ≤ 1}` lies in the starting cube (e.g. radius from
/// [`sos_radius`]), the kept cubes cover it; the 1e-9 margins absorb the rounding of the bounds.
pub fn covering_cells(p: &Polynomial, radius: Real, target_side: Real) -> CubeCover {
    let bounds = CubeBounds::new(p);
    let mut cells = vec![Vector3::zeros()];
    let mut half = radius;
    let mut inside_cells: Vec<Vector3> = Vec::new();
    let mut inside_half: Vec<Real> = Vec::new();
    loop {
        let mut keep = Vec::with_capacity(cells.len());
        for c in &cells {
            let (lo, hi) = bounds.bounds(c, half);
            if lo > 1.0 + 1e-9 {
                continue;
            }
            if hi < 1.0 - 1e-9 {
                inside_cells.push(*c);
                inside_half.push(half);
            } else {
                keep.push(*c);
            }
        }
        if 2.0 * half <= target_side || keep.len() * 8 > MAX_CUBES || keep.is_empty() {
            cells = keep;
            break;
        }
        let h2 = half / 2.0;
        cells = keep
            .iter()
            .flat_map(|c| {
                (0..8).map(move |k| {
                    c + Vector3::new(
                        if k & 1 == 0 { -h2 } else { h2 },
                        if k & 2 == 0 { -h2 } else { h2 },
                        if k & 4 == 0 { -h2 } else { h2 },
                    )
                })
            })
            .collect();
        half = h2;
    }
    // Inside cubes of coarser levels are split into cubes of the final size so that every cube
    // has the same volume (the count is what matters; their volume is exact).
    let mut inside = 0usize;
    let mut lo = Vector3::repeat(Real::INFINITY);
    let mut hi = Vector3::repeat(Real::NEG_INFINITY);
    for (c, h) in inside_cells.iter().zip(&inside_half) {
        let ratio = (h / half).round() as usize;
        inside += ratio * ratio * ratio;
        lo = lo.inf(&c.add_scalar(-h));
        hi = hi.sup(&c.add_scalar(*h));
    }
    for c in &cells {
        lo = lo.inf(&c.add_scalar(-half));
        hi = hi.sup(&c.add_scalar(half));
    }
    CubeCover { boundary: cells, inside, half, lo, hi }
}

/// A volume estimate of a (possibly nonconvex) sos body and the cover it sampled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SosVolumeEstimate {
    /// The estimate; `lo`/`hi` are the bounding box of the cover.
    pub estimate: VolumeEstimate,
    /// Radius of the ball that provably contains the body ([`sos_radius`]).
    pub radius: Real,
    /// Side of the cover's cubes.
    pub cell_side: Real,
}

/// Estimates the volume of `{u : p(u) ≤ 1}` for an sos p = z(u)ᵀ P z(u) with λ_min(P) ≥
/// `lambda_min` > 0, convex or not: cubes proven inside count exactly, and at least `samples`
/// uniform samples of the boundary cubes (doubled up to 16× until the relative standard error is
/// below 1 %) estimate the rest. The body provably lies in the cover: in the ball of
/// [`sos_radius`], and outside the kept cubes p > 1 by [`CubeBounds`].
///
/// # Errors
/// [`Error::Numerical`] when `lambda_min` is not positive (see [`sos_radius`]).
pub fn monte_carlo_volume_sos(
    p: &Polynomial,
    lambda_min: Real,
    samples: usize,
    seed: u64,
) -> Result<SosVolumeEstimate> {
    let radius = sos_radius(p.degree(), lambda_min)?;
    let cover = covering_cells(p, radius, 0.04);
    let side = 2.0 * cover.half;
    let cell_volume = side.powi(3);
    let inside_volume = cover.inside as Real * cell_volume;
    let boundary_volume = cover.boundary.len() as Real * cell_volume;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (mut n, mut hits) = (0usize, 0usize);
    let mut target = samples.max(1000);
    let cap = target * 16;
    let finish = |vol: Real, se: Real, n: usize| SosVolumeEstimate {
        estimate: VolumeEstimate { volume: vol, std_error: se, samples: n, lo: cover.lo, hi: cover.hi },
        radius,
        cell_side: side,
    };
    if cover.boundary.is_empty() {
        return Ok(finish(inside_volume, 0.0, 0));
    }
    loop {
        while n < target {
            let c = cover.boundary[rng.random_range(0..cover.boundary.len())];
            let u = Vector3::new(
                c.x + cover.half * (2.0 * rng.random::<Real>() - 1.0),
                c.y + cover.half * (2.0 * rng.random::<Real>() - 1.0),
                c.z + cover.half * (2.0 * rng.random::<Real>() - 1.0),
            );
            if p.value(&u) <= 1.0 {
                hits += 1;
            }
            n += 1;
        }
        let f = hits as Real / n as Real;
        let se = boundary_volume * (f * (1.0 - f) / n as Real).sqrt();
        let vol = inside_volume + boundary_volume * f;
        if (vol > 0.0 && se < 0.01 * vol) || n >= cap {
            return Ok(finish(vol, se, n));
        }
        target *= 2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipsoid_box_and_volume() {
        // p = (x/2)² + y² + (z/0.5)²: box [±2, ±1, ±0.5], volume 4/3 π.
        let p = Polynomial::from_terms(2, &[([2, 0, 0], 0.25), ([0, 2, 0], 1.0), ([0, 0, 2], 4.0)]).unwrap();
        let (lo, hi) = bounding_box(&p, &Vector3::zeros()).unwrap();
        let want = Vector3::new(2.0, 1.0, 0.5);
        assert!((hi - want).norm() < 1e-5 && (lo + want).norm() < 1e-5, "{lo} {hi}");
        // Provable: never below the true support.
        assert!(hi.iter().zip(want.iter()).all(|(h, w)| h >= w));
        let v = monte_carlo_volume(&p, &Vector3::zeros(), 100_000, 7).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(v.std_error < 0.01 * v.volume);
        assert!((v.volume - exact).abs() < 4.0 * v.std_error, "{} vs {exact} ± {}", v.volume, v.std_error);
    }

    #[test]
    fn quartic_support_is_exact() {
        // p = x⁴ + y⁴ + z⁴ (Hessian singular at 0): support 1 in every axis direction; volume of the
        // unit 4-norm ball is 8 Γ(5/4)³ / Γ(7/4) ≈ 6.482.
        let p = Polynomial::from_terms(4, &[([4, 0, 0], 1.0), ([0, 4, 0], 1.0), ([0, 0, 4], 1.0)]).unwrap();
        let (lo, hi) = bounding_box(&p, &Vector3::new(0.1, 0.0, -0.1)).unwrap();
        for k in 0..3 {
            assert!((hi[k] - 1.0).abs() < 1e-5 && (lo[k] + 1.0).abs() < 1e-5, "{lo} {hi}");
            assert!(hi[k] >= 1.0 && lo[k] <= -1.0);
        }
        let v = monte_carlo_volume(&p, &Vector3::zeros(), 100_000, 3).unwrap();
        let g54: Real = 0.906_402_477_055_477;
        let g74: Real = 0.919_062_526_848_883;
        let exact = 8.0 * g54.powi(3) / g74;
        assert!((v.volume - exact).abs() < 4.0 * v.std_error, "{} vs {exact}", v.volume);
    }

    #[test]
    fn cube_bounds_enclose_sampled_values() {
        let p =
            Polynomial::from_coefficients(4, (0..35).map(|k| ((k * 7) % 11) as Real / 5.0 - 1.0).collect()).unwrap();
        let b = CubeBounds::new(&p);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..50 {
            let c = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let h = rng.random_range(0.01..0.5);
            let (lo, hi) = b.bounds(&c, h);
            // Exact at the center for a zero-size cube, and enclosing on random points of the cube.
            assert!((b.bounds(&c, 0.0).0 - p.value(&c)).abs() < 1e-12 * (1.0 + p.value(&c).abs()));
            for _ in 0..50 {
                let t = Vector3::new(rng.random_range(-h..h), rng.random_range(-h..h), rng.random_range(-h..h));
                let v = p.value(&(c + t));
                assert!(lo <= v + 1e-12 && v <= hi + 1e-12, "{lo} ≤ {v} ≤ {hi}");
            }
        }
    }

    #[test]
    fn sos_cover_volume_of_an_ellipsoid() {
        // p = 1/2 + 1/2 (x²/4 + y² + 4z²) = zᵀ diag(1/2, 1/8, 1/2, 2) z, z = (1, x, y, z):
        // {p ≤ 1} is the ellipsoid with semi-axes (2, 1, 1/2), volume 4/3 π.
        let p = Polynomial::from_terms(2, &[([0, 0, 0], 0.5), ([2, 0, 0], 0.125), ([0, 2, 0], 0.5), ([0, 0, 2], 2.0)])
            .unwrap();
        let r = sos_radius(2, 0.125).unwrap();
        assert!((r - 8f64.sqrt()).abs() < 1e-5 && r >= 2.0, "radius {r}");
        let est = monte_carlo_volume_sos(&p, 0.125, 100_000, 3).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        let v = est.estimate;
        assert!(v.std_error < 0.01 * v.volume);
        assert!((v.volume - exact).abs() < 4.0 * v.std_error + 1e-12, "{} vs {exact} ± {}", v.volume, v.std_error);
        // The cover's box holds the ellipsoid's extent and is at most a cube side larger.
        let want = Vector3::new(2.0, 1.0, 0.5);
        for k in 0..3 {
            assert!(v.hi[k] >= want[k] && v.lo[k] <= -want[k]);
            assert!(v.hi[k] <= want[k] + est.cell_side && v.lo[k] >= -want[k] - est.cell_side);
        }
        assert!(sos_radius(2, 0.0).is_err() && sos_radius(2, Real::NAN).is_err());
    }

    #[test]
    fn sos_cover_volume_of_a_nonconvex_body_matches_plain_sampling() {
        // A nonconvex sos quartic: p = ((x² − 1/2)² + y² + z²)·2 + 0.05 ‖z(u)‖²-ish terms, whose
        // sublevel set is two lobes around x = ±0.7 joined near the origin.
        let d = 2;
        let half = sublevel_core::poly::monomial::graded_exponents3(d);
        let n = half.len();
        let mut gram = nalgebra::DMatrix::<Real>::identity(n, n) * 0.05;
        // (x² − 1/2)²: z_x² = index of [2,0,0], constant index 0.
        let ix2 = half.iter().position(|e| *e == [2, 0, 0]).unwrap();
        gram[(0, 0)] += 0.5;
        gram[(ix2, ix2)] += 2.0;
        gram[(0, ix2)] -= 1.0;
        gram[(ix2, 0)] -= 1.0;
        for e in [[0, 1, 0], [0, 0, 1]] {
            let i = half.iter().position(|h| *h == e).unwrap();
            gram[(i, i)] += 2.0;
        }
        let lambda = gram.symmetric_eigenvalues().min();
        assert!(lambda > 0.0);
        let p = crate::sdp::polynomial_of_gram(d, &gram).unwrap();
        // Nonconvex: the Hessian at the origin has a negative eigenvalue.
        assert!(p.eval(&Vector3::zeros()).hessian.symmetric_eigenvalues().min() < 0.0);
        let est = monte_carlo_volume_sos(&p, lambda, 100_000, 9).unwrap();
        // Plain uniform sampling of the provable cube [−R, R]³.
        let r = est.radius;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(10);
        let m = 2_000_000;
        let hits = (0..m)
            .filter(|_| {
                let u = Vector3::new(rng.random_range(-r..r), rng.random_range(-r..r), rng.random_range(-r..r));
                p.value(&u) <= 1.0
            })
            .count();
        let f = hits as Real / m as Real;
        let cube = (2.0 * r).powi(3);
        let (vol, se) = (cube * f, cube * (f * (1.0 - f) / m as Real).sqrt());
        let v = est.estimate;
        assert!(v.std_error < 0.01 * v.volume);
        assert!((v.volume - vol).abs() < 4.0 * (se + v.std_error), "{} ± {} vs {vol} ± {se}", v.volume, v.std_error);
    }
}
