//! Blends proven free: each arc of a [`BlendedPath`] by one box check around its corner, else as
//! chords in tubes, tightened down to a stop where it cannot be proven.

use super::path::{BlendedPath, Piece};
use crate::validity::{Certificate, Validity};
use sublevel_core::math::Real;
use sublevel_core::Result;

/// How [`certify_blends`] left a path.
#[derive(Clone, Debug, PartialEq)]
pub struct BlendCertificate {
    /// The path, every arc proven free (arcs that could not be are tightened or made stops).
    pub path: BlendedPath,
    /// Arcs proven free.
    pub arcs_certified: usize,
    /// Corners whose blend was tightened at least once.
    pub tightened: usize,
    /// Corners that became stops because no blend could be proven.
    pub stops_added: usize,
}

/// The gaps (joint-space distance, radians or meters) between an arc and the chords that
/// certify it, coarsest first: a chord that cannot be proven with the coarser gap's tube is tried
/// again as shorter chords with a finer one (module docs of [`certify_blends`]).
const CHORD_SAGITTAS: [Real; 3] = [4e-3, 1e-3, 2.5e-4];
/// Most times a corner's deviation is quartered before the corner becomes a stop.
const MAX_TIGHTENINGS: usize = 4;

/// Proves every arc of `path` free with `checker` at contact `tolerance` (meters), tightening an
/// arc that cannot be proven (its deviation quartered, at most [`MAX_TIGHTENINGS`] times) and
/// then making its corner a stop. The straight pieces are parts of the waypoints' segments; they
/// are the caller's to have certified (a planner's path is).
///
/// An arc is proven first by one check: every configuration of the arc lies in the triangle of
/// its ends and its corner, so within `ℓ·max(|y1ₖ|, |y2ₖ|)` of the corner in entry k (ℓ the
/// tangent length, y1 and y2 the segments' directions), and a box of those half-widths proven
/// free ([`Validity::box_free`]) proves the arc; a corner far from everything is proven so.
/// Else it is proven as chords: a chord of the arc whose sagitta (the most the arc strays from
/// it) is h leaves every configuration of its part of the arc within `h·√(xₖ² + yₖ²)` of the
/// chord in entry k (the gap lies in the arc's plane), so the chord proven free with a tube of
/// those half-widths ([`Validity::certify_tube`]) proves its part of the arc. Chords start with
/// the coarsest sagitta of [`CHORD_SAGITTAS`] (few chords, a wide tube); a chord that fails is
/// taken again as shorter chords with the next finer one, and only a chord that fails at the
/// finest (at the tolerance and at a hundredth of it) fails the arc.
///
/// # Errors
/// The checker's errors.
pub fn certify_blends(checker: &mut dyn Validity, path: &BlendedPath, tolerance: Real) -> Result<BlendCertificate> {
    let mut deviation = path.deviation.clone();
    let mut tightenings = vec![0usize; deviation.len()];
    let mut proven: Vec<Option<Real>> = vec![None; deviation.len()];
    loop {
        let current = BlendedPath::with_deviations(path.waypoints.clone(), deviation.clone());
        let mut changed = false;
        for (_, arc) in current.arcs() {
            let Piece::Arc { corner, .. } = arc else { continue };
            let corner = *corner;
            if proven[corner] == Some(current.deviation[corner]) {
                continue;
            }
            if arc_free(checker, arc, tolerance)? {
                proven[corner] = Some(current.deviation[corner]);
                continue;
            }
            changed = true;
            tightenings[corner] += 1;
            deviation[corner] =
                if tightenings[corner] > MAX_TIGHTENINGS { 0.0 } else { current.deviation[corner] / 4.0 };
        }
        if !changed {
            let arcs_certified = current.arcs().count();
            return Ok(BlendCertificate {
                arcs_certified,
                tightened: tightenings.iter().filter(|&&t| t > 0).count(),
                stops_added: tightenings.iter().filter(|&&t| t > MAX_TIGHTENINGS).count(),
                path: current,
            });
        }
    }
}

/// Whether `arc` is proven free: first in one box around its corner (see [`certify_blends`]),
/// else as chords in tubes.
pub(super) fn arc_free(checker: &mut dyn Validity, arc: &Piece, tolerance: Real) -> Result<bool> {
    let Piece::Arc { x, y, radius, angle, .. } = arc else { return Ok(true) };
    // The arc lies in the triangle of its ends and its corner: within `ℓ·max(|y1ₖ|, |y2ₖ|)` of
    // the corner in entry k, ℓ = r·tan(α/2) the tangent length, y1 and y2 the segments' unit
    // directions (y1 = y, y2 = y cos α − x sin α).
    let ell = radius * (angle / 2.0).tan();
    let (start, end) = (arc.at(0.0), arc.at(arc.length()));
    let corner: Vec<Real> = start.iter().zip(y).map(|(s, d)| s + ell * d).collect();
    let reach: Vec<Real> = x
        .iter()
        .zip(y)
        .zip(corner.iter().zip(&end))
        .map(|((_, d1), (c, e))| ell * d1.abs().max(((e - c) / ell).abs()))
        .collect();
    if checker.box_free(&corner, &reach)? {
        return Ok(true);
    }
    let plane: Vec<Real> = x.iter().zip(y).map(|(a, b)| a.hypot(*b)).collect();
    let length = arc.length();
    // The chord length (arc length) of each sagitta: 2r·acos(1 − h / r).
    let chord = |h: Real| 2.0 * radius * (1.0 - h / radius).clamp(-1.0, 1.0).acos().max(1e-9);
    let (mut u, mut level) = (0.0, 0);
    let mut a = arc.at(0.0);
    let mut tube = vec![0.0; plane.len()];
    while u < length {
        let step = chord(CHORD_SAGITTAS[level]);
        let end = if u + step >= length * (1.0 - 1e-12) { length } else { u + step };
        let b = arc.at(end);
        let sagitta = radius * (1.0 - ((end - u) / (2.0 * radius)).cos());
        for (t, p) in tube.iter_mut().zip(&plane) {
            *t = sagitta * p;
        }
        let finest = level + 1 == CHORD_SAGITTAS.len();
        let free = checker.certify_tube(&a, &b, &tube, tolerance)? == Certificate::Free
            || (finest
                && checker.certify_tube(&a, &b, &tube, crate::certify::certificate_tolerance(tolerance))?
                    == Certificate::Free);
        if free {
            (u, a) = (end, b);
        } else if finest {
            return Ok(false);
        } else {
            level += 1;
        }
    }
    Ok(true)
}
