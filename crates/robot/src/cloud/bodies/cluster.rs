//! Euclidean clusters of a point cloud (PCL's `EuclideanClusterExtraction`), the first step of
//! [`super`]: a flood fill over a k-d tree, small clusters dropped as outliers, large ones split.

use crate::cloud::MAX_CLOUD_POINTS;
use crate::{Error, Result};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use sublevel_core::math::{Real, Vector3, MAX_COORDINATE};

/// Checks a point set: at most [`MAX_CLOUD_POINTS`], every coordinate finite within
/// ±[`MAX_COORDINATE`] m.
pub(super) fn validate_points(points: &[[Real; 3]]) -> Result<()> {
    if points.len() > MAX_CLOUD_POINTS {
        return Err(Error::ResourceExhausted(format!(
            "points: {} points, more than the {MAX_CLOUD_POINTS} a cloud obstacle may keep",
            points.len()
        )));
    }
    if let Some(k) = points.iter().position(|p| p.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_COORDINATE))) {
        return Err(Error::invalid(
            format!("points[{k}]"),
            format!("{:?} must be finite and within ±{MAX_COORDINATE:e} m", points[k]),
        ));
    }
    Ok(())
}

/// Checks the clustering parameters of [`euclidean_clusters`].
pub(super) fn validate_clustering(tolerance: Real, min_points: usize, max_points: usize) -> Result<()> {
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance <= MAX_COORDINATE) {
        return Err(Error::invalid(
            "tolerance",
            format!("must be finite and in (0, {MAX_COORDINATE:e}] m, got {tolerance}"),
        ));
    }
    if min_points == 0 {
        return Err(Error::invalid("min_points", "must be at least 1"));
    }
    if max_points < 4 || max_points < min_points {
        return Err(Error::invalid(
            "max_points",
            format!("must be at least 4 and at least min_points ({min_points}), got {max_points}"),
        ));
    }
    Ok(())
}

/// Euclidean clusters of `points` (meters), as PCL's `EuclideanClusterExtraction`: two points
/// are in one cluster when a chain of points links them with every step at most `tolerance`
/// meters long (a flood fill over a k-d tree, one radius query per point). Clusters of fewer
/// than `min_points` points are outliers and dropped. A cluster of more than `max_points` points
/// is split at the median of its longest bounding-box axis, recursively, until every part has at
/// most `max_points` (so that each part's fit stays small); parts are kept whatever their size
/// (each has at least ⌊max_points / 2⌋ + 1 points, they are not outliers).
///
/// Returns the clusters as indices into `points`, each sorted ascending, in the order of their
/// smallest index (deterministic). An empty cloud has no clusters.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `tolerance` (not finite and > 0), `min_points` (0),
/// `max_points` (under 4 or under `min_points`) or `points[k]` (a coordinate not finite or
/// beyond ±10⁶ m); [`Error::ResourceExhausted`] naming `points` past [`MAX_CLOUD_POINTS`].
pub fn euclidean_clusters(
    points: &[[Real; 3]],
    tolerance: Real,
    min_points: usize,
    max_points: usize,
) -> Result<Vec<Vec<usize>>> {
    validate_clustering(tolerance, min_points, max_points)?;
    validate_points(points)?;
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let tree = ImmutableKdTree::<Real, 3>::new_from_slice(points)
        .map_err(|e| Error::invalid("points", format!("the k-d tree could not be built: {e:?}")))?;
    let t2 = tolerance * tolerance;
    let mut assigned = vec![false; points.len()];
    let mut clusters = Vec::new();
    for seed in 0..points.len() {
        if assigned[seed] {
            continue;
        }
        assigned[seed] = true;
        // Breadth-first: `cluster[head..]` are found but not yet expanded.
        let mut cluster = vec![seed];
        let mut head = 0;
        while head < cluster.len() {
            let q = points[cluster[head]];
            head += 1;
            for n in tree.query(&q).within::<SquaredEuclidean<Real>>(t2).unsorted().execute().iter() {
                let j = n.item as usize;
                if !assigned[j] {
                    assigned[j] = true;
                    cluster.push(j);
                }
            }
        }
        if cluster.len() >= min_points {
            split_cluster(points, cluster, max_points, &mut clusters);
        }
    }
    Ok(clusters)
}

/// Appends `cluster` to `out`, split at the median of the longest axis of its bounding box until
/// every part has at most `max_points` points.
fn split_cluster(points: &[[Real; 3]], cluster: Vec<usize>, max_points: usize, out: &mut Vec<Vec<usize>>) {
    let mut stack = vec![cluster];
    while let Some(mut part) = stack.pop() {
        if part.len() <= max_points {
            part.sort_unstable();
            out.push(part);
            continue;
        }
        let (lo, hi) = index_box(points, &part);
        let axis = (hi - lo).imax();
        let mid = part.len() / 2;
        part.select_nth_unstable_by(mid, |&a, &b| points[a][axis].total_cmp(&points[b][axis]));
        let upper = part.split_off(mid);
        stack.push(upper);
        stack.push(part);
    }
}

/// Bounding box (min and max corners) of `points[indices]`; `indices` non-empty.
pub(super) fn index_box(points: &[[Real; 3]], indices: &[usize]) -> (Vector3, Vector3) {
    let first = Vector3::from(points[indices[0]]);
    indices.iter().fold((first, first), |(lo, hi), &i| {
        let p = Vector3::from(points[i]);
        (lo.inf(&p), hi.sup(&p))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clusters_split_and_drop_by_size() {
        // A line of 100 points 1 cm apart, a pair far away, one lone point.
        let mut pts: Vec<[Real; 3]> = (0..100).map(|i| [i as Real * 0.01, 0.0, 0.0]).collect();
        pts.extend([[5.0, 5.0, 5.0], [5.005, 5.0, 5.0], [-5.0, 0.0, 0.0]]);
        let c = euclidean_clusters(&pts, 0.015, 2, 1000).unwrap();
        assert_eq!(c.iter().map(Vec::len).collect::<Vec<_>>(), vec![100, 2]);
        assert_eq!(c[1], vec![100, 101]);
        // Split into parts of at most 30: 100 → 50 + 50 → 25 ×4, contiguous along the line.
        let c = euclidean_clusters(&pts, 0.015, 3, 30).unwrap();
        assert_eq!(c.iter().map(Vec::len).collect::<Vec<_>>(), vec![25; 4]);
        assert_eq!(c[0], (0..25).collect::<Vec<_>>());
        assert!(euclidean_clusters(&[], 0.1, 1, 10).unwrap().is_empty());
    }
}
