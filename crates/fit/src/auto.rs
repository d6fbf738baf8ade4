//! Choosing the degree of a fit (`--degree auto`): the lowest degree that is not much worse than
//! the next one.
//!
//! ```text
//! fit 2d₀ < 2d₁ < … in turn (default 2, 4, 6, 8)
//! keep the first 2dₖ with  vol(2dₖ) ≤ (1 + τ) · vol(2dₖ₊₁)        (stop as soon as found)
//! otherwise keep the last degree
//! ```
//!
//! Higher degrees fit tighter (Table 1 of the paper) but cost more per query (Table 2): a degree
//! whose volume the next one improves by no more than τ is not worth its query time. Volumes are
//! the fits' seeded Monte Carlo estimates, so τ should exceed their relative standard error
//! (≈ 1 %). The choice and every candidate's volume go into `report.degree_choice`.

use super::{fit_points, FitProgress, FitSettings};
use crate::{Error, Result};
use sublevel_core::body::{Body, DegreeChoice, SUPPORTED_DEGREES};
use sublevel_core::math::{Point3, Real};

/// The degrees `--degree auto` tries by default.
pub const DEFAULT_AUTO_DEGREES: [usize; 4] = [2, 4, 6, 8];

/// Checks a candidate degree list and a volume tolerance.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degrees` (empty, unsupported or not strictly increasing) or
/// `volume_tolerance` (not finite, negative, or ≥ 1).
pub fn validate_auto(degrees: &[usize], tolerance: Real) -> Result<()> {
    if degrees.is_empty() {
        return Err(Error::invalid("degrees", "need at least one candidate degree"));
    }
    if let Some(d) = degrees.iter().find(|d| !SUPPORTED_DEGREES.contains(d)) {
        return Err(Error::invalid("degrees", format!("must be among 2, 4, 6, 8, got {d}")));
    }
    if degrees.windows(2).any(|w| w[0] >= w[1]) {
        return Err(Error::invalid("degrees", format!("must be strictly increasing, got {degrees:?}")));
    }
    if !(tolerance.is_finite() && (0.0..1.0).contains(&tolerance)) {
        return Err(Error::invalid("volume_tolerance", format!("must be in [0, 1), got {tolerance}")));
    }
    Ok(())
}

/// Fits `points` at increasing degrees and keeps the lowest degree whose volume is within
/// `tolerance` (relative) of the next degree's: `vol(2dₖ) ≤ (1 + τ) vol(2dₖ₊₁)` (see the module
/// docs). Every other setting comes from `settings` (its `degree` is ignored). Progress messages
/// are prefixed with the degree being fitted ("degree 4: …"); fractions span all candidates.
///
/// The returned body's `report.degree_choice` lists every fitted candidate `(2d, volume,
/// std_error)`, the chosen degree and a one-sentence reason; the reason is also added to
/// `report.notes`. A numerical failure at a higher degree keeps the best degree so far (and says
/// so); the lowest degree's failure is returned.
///
/// # Errors
/// [`Error::InvalidArgument`] from [`validate_auto`] or from the fit (points, settings); the
/// first candidate's fit error.
pub fn fit_auto(
    points: &[Point3],
    settings: &FitSettings,
    degrees: &[usize],
    tolerance: Real,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    validate_auto(degrees, tolerance)?;
    let n = degrees.len() as Real;
    let mut candidates: Vec<(usize, Real, Real)> = Vec::new();
    let mut previous: Option<Body> = None;
    let fit_at = |k: usize, progress: &mut dyn FnMut(&FitProgress)| -> Result<Body> {
        let degree = degrees[k];
        let s = FitSettings { degree, ..settings.clone() };
        let mut inner = |p: &FitProgress| {
            progress(&FitProgress {
                stage: p.stage,
                fraction: ((k as Real + p.fraction) / n).min(1.0),
                message: format!("degree {degree}: {}", p.message),
                part: p.part,
            })
        };
        fit_points(points, &s, &mut inner)
    };
    for (k, &degree) in degrees.iter().enumerate() {
        let body = match fit_at(k, progress) {
            Ok(b) => b,
            Err(e) if k > 0 && matches!(e, Error::Numerical(_)) => {
                let Some(prev) = previous.take() else { return Err(e) };
                let reason =
                    format!("degree {} was kept because the degree-{} fit failed ({e})", prev.degree(), degree);
                return Ok(finish(prev, tolerance, candidates, reason));
            }
            Err(e) => return Err(e),
        };
        let (vol, err) = (body.report.volume, body.report.volume_std_error);
        candidates.push((degree, vol, err));
        if let Some(prev) = previous.take() {
            let prev_vol = prev.report.volume;
            if prev_vol <= (1.0 + tolerance) * vol {
                let reason = format!(
                    "degree {} was kept because degree {} shrinks the volume only from {:.4} to {:.4} ({:+.1} %, within the tolerance of {:.1} %)",
                    prev.degree(),
                    degree,
                    prev_vol,
                    vol,
                    100.0 * (vol / prev_vol - 1.0),
                    100.0 * tolerance
                );
                return Ok(finish(prev, tolerance, candidates, reason));
            }
        }
        previous = Some(body);
    }
    let last = previous.ok_or_else(|| Error::invalid("degrees", "need at least one candidate degree"))?;
    let reason = if degrees.len() == 1 {
        format!("degree {} was the only candidate", last.degree())
    } else {
        format!(
            "degree {} was kept because every lower degree is more than {:.1} % larger than the next one",
            last.degree(),
            100.0 * tolerance
        )
    };
    Ok(finish(last, tolerance, candidates, reason))
}

fn finish(mut body: Body, tolerance: Real, candidates: Vec<(usize, Real, Real)>, reason: String) -> Body {
    body.report.notes.push(format!("--degree auto: {reason}"));
    body.report.degree_choice =
        Some(DegreeChoice { volume_tolerance: tolerance, candidates, chosen: body.degree(), reason });
    body
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidate_lists_and_tolerances_are_validated_by_field() {
        let field = |r: Result<()>| match r {
            Err(Error::InvalidArgument { field, .. }) => field,
            other => panic!("expected InvalidArgument, got {other:?}"),
        };
        assert_eq!(field(validate_auto(&[], 0.05)), "degrees");
        assert_eq!(field(validate_auto(&[2, 3], 0.05)), "degrees");
        assert_eq!(field(validate_auto(&[4, 2], 0.05)), "degrees");
        assert_eq!(field(validate_auto(&[2, 4], -0.1)), "volume_tolerance");
        assert_eq!(field(validate_auto(&[2, 4], Real::NAN)), "volume_tolerance");
        assert!(validate_auto(&DEFAULT_AUTO_DEGREES, 0.05).is_ok());
    }
}
