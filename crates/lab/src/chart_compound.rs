//! Compound models in `sublevel-lab chart speed-accuracy`: each `--compound CHAIR:HUMAN` pair of
//! compound body files, at each `--bound-tolerances` value, is timed cold (random poses, no warm
//! start) and warm (the smooth motion of `sublevel-lab bench`, the previous answer's warm
//! start), scored against the exact mesh–mesh distance by its conservative answer (the lower
//! bound of [`tree_distance`]), and asked the margin query "closer than m?" on the cold poses,
//! whose decisive tree levels make the level histogram.

use super::bench::{median, time_us};
use super::chart::ModelRow;
use super::peer_parry::error_stats;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::{Error, Result};
use sublevel_fit::compound::CompoundBody;
use sublevel_query::tree::{tree_closer_than, tree_distance, TreeQueryParams, TreeWarmStart};

/// Slack of the conservativeness check: an answer counts as ≤ exact when below exact + this (m).
pub const CONSERVATIVE_SLACK: Real = 1e-9;

/// Share of `answers` that are ≤ `exact` (+ [`CONSERVATIVE_SLACK`]), over all poses.
pub fn conservative_share(answers: &[Real], exact: &[Real]) -> Real {
    let n = answers.len().min(exact.len());
    if n == 0 {
        return Real::NAN;
    }
    answers.iter().zip(exact).filter(|(a, e)| **a <= **e + CONSERVATIVE_SLACK).count() as Real / n as Real
}

/// One `--compound` argument `CHAIR.json:HUMAN.json`, loaded (either file may hold one body).
pub struct CompoundPair {
    /// Label: the chair file's stem.
    pub label: String,
    /// The chair's compound body (the posed one).
    pub chair: CompoundBody,
    /// The human's compound body (at the identity).
    pub human: CompoundBody,
}

impl CompoundPair {
    /// Parses and loads `CHAIR.json:HUMAN.json`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--compound` without a `:`; the loading errors of
    /// [`CompoundBody::load`].
    pub fn load(arg: &str) -> Result<Self> {
        let (a, b) = arg
            .split_once(':')
            .ok_or_else(|| Error::invalid("--compound", format!("expected CHAIR.json:HUMAN.json, got {arg:?}")))?;
        let (a, b) = (std::path::Path::new(a), std::path::Path::new(b));
        let label = a.file_stem().map_or_else(|| a.display().to_string(), |s| s.to_string_lossy().into_owned());
        Ok(Self { label, chair: CompoundBody::load(a)?, human: CompoundBody::load(b)? })
    }
}

/// The rows of the compound models: for every pair and tolerance, cold and warm medians, errors,
/// conservativeness and the level histogram of the margin query at `margin` meters.
///
/// # Errors
/// A tree query's input error (bad tolerance or margin, broken tree).
pub fn compound_rows(
    pairs: &[CompoundPair],
    tolerances: &[Real],
    margin: Real,
    poses: &[Isometry3],
    motion: &[Isometry3],
    exact: &[Real],
    repeats: usize,
) -> Result<Vec<ModelRow>> {
    let id = Isometry3::identity();
    let mut rows = Vec::new();
    for pair in pairs {
        let leaves = (pair.chair.leaf_count(), pair.human.leaf_count());
        for &tol in tolerances {
            let params = TreeQueryParams { tolerance: tol, ..TreeQueryParams::default() };
            let (mut cold, mut answers) = (Vec::new(), Vec::new());
            for p in poses {
                let (us, r) = time_us(repeats, || tree_distance(&pair.chair, p, &pair.human, &id, None, &params));
                cold.push(us);
                answers.push(r?.lower);
            }
            let mut warm = Vec::new();
            let mut state: Option<TreeWarmStart> = None;
            for (k, p) in motion.iter().enumerate() {
                let (us, r) =
                    time_us(repeats, || tree_distance(&pair.chair, p, &pair.human, &id, state.as_ref(), &params));
                if k > 0 {
                    warm.push(us);
                }
                state = Some(r?.warm_start);
            }
            let mut levels = vec![0usize; pair.chair.height().max(pair.human.height()) + 1];
            for p in poses {
                let m = tree_closer_than(&pair.chair, p, &pair.human, &id, margin, None, &params)?;
                if m.level >= levels.len() {
                    levels.resize(m.level + 1, 0);
                }
                levels[m.level] += 1;
            }
            let (err_mean, err_max) = error_stats(&answers, exact);
            rows.push(ModelRow {
                name: format!("{} {}x{} tol={tol}", pair.label, leaves.0, leaves.1),
                time_us: median(cold),
                warm_us: median(warm),
                err_mean,
                err_max,
                conservative: conservative_share(&answers, exact),
                levels: Some(levels),
            });
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conservative_share_counts_answers_at_or_below_exact() {
        assert_eq!(conservative_share(&[0.1, 0.2, 0.3, 0.0], &[0.1, 0.25, 0.29, 0.0]), 0.75);
        assert!(conservative_share(&[], &[]).is_nan());
    }
}
