//! Euclidean clusters of a point cloud (PCL's `EuclideanClusterExtraction`), the first step of
//! [`super`]: union-find over a grid of cubes, small clusters dropped as outliers, large ones
//! split.

use crate::cloud::MAX_CLOUD_POINTS;
use crate::{Error, Result};
use petgraph::unionfind::UnionFind;
use std::collections::HashMap;
use sublevel_core::error::show_real;
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

/// Checks the clustering parameters of [`euclidean_clusters`]: `tolerance` in (0,
/// [`super::MAX_TOLERANCE`]] m, `max_points` at least 4, `min_points` in [1, `max_points`].
pub(super) fn validate_clustering(tolerance: Real, min_points: usize, max_points: usize) -> Result<()> {
    let most = super::MAX_TOLERANCE;
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance <= most) {
        return Err(Error::invalid(
            "tolerance",
            format!("must be finite and in (0, {most}] m, got {}", show_real(tolerance)),
        ));
    }
    if max_points < 4 {
        return Err(Error::invalid("max_points", format!("must be at least 4, got {max_points}")));
    }
    if min_points == 0 || min_points > max_points {
        return Err(Error::invalid(
            "min_points",
            format!("must be at least 1 and at most max_points ({max_points}), got {min_points}"),
        ));
    }
    Ok(())
}

/// Euclidean clusters of `points` (meters), as PCL's `EuclideanClusterExtraction`: two points
/// are in one cluster when a chain of points links them with every step at most `tolerance`
/// meters long. The points are sorted into a grid of cubes of side `tolerance`, so that the
/// points within `tolerance` of a point lie in its cube or the 26 around it; every pair of points
/// of a cube and of each of its 13 "forward" neighbors (or of the cube itself) at most
/// `tolerance` apart is joined in a union-find (petgraph's). Clusters of fewer than `min_points`
/// points are outliers and dropped. A cluster of more than `max_points` points is split at the
/// median of its longest bounding-box axis, recursively, until every part has at most
/// `max_points` (so that each part's fit stays small); parts are kept whatever their size (each
/// has at least ⌊max_points / 2⌋ + 1 points, they are not outliers).
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
    // Cube keys (saturating casts: far or tiny-tolerance keys may share a cube, which only costs
    // distance checks), the points sorted by key, and each occupied cube's range of them.
    let key = |p: &[Real; 3]| p.map(|v| (v / tolerance).floor() as i64);
    let mut keyed: Vec<([i64; 3], u32)> = points.iter().enumerate().map(|(i, p)| (key(p), i as u32)).collect();
    keyed.sort_unstable();
    let order: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
    let mut cubes: Vec<([i64; 3], usize, usize)> = Vec::new();
    for (n, &(k, _)) in keyed.iter().enumerate() {
        match cubes.last_mut() {
            Some(last) if last.0 == k => last.2 = n + 1,
            _ => cubes.push((k, n, n + 1)),
        }
    }
    drop(keyed);
    let index: HashMap<[i64; 3], usize, foldhash::fast::FixedState> =
        cubes.iter().enumerate().map(|(c, &(k, _, _))| (k, c)).collect();
    let t2 = tolerance * tolerance;
    let near = |a: u32, b: u32| {
        let (p, q) = (points[a as usize], points[b as usize]);
        (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2) <= t2
    };
    let mut sets = UnionFind::<u32>::new(points.len());
    // The pairs within each cube; then whether the cube is whole (its points all one set, which
    // later unions keep true).
    let mut whole = Vec::with_capacity(cubes.len());
    for &(_, s, e) in &cubes {
        let cube = &order[s..e];
        for (n, &a) in cube.iter().enumerate() {
            for &b in &cube[n + 1..] {
                if near(a, b) {
                    sets.union(a, b);
                }
            }
        }
        let root = sets.find_mut(cube[0]);
        whole.push(cube[1..].iter().all(|&b| sets.find_mut(b) == root));
    }
    // The pairs across each cube and its forward neighbors. Two whole cubes need one near pair:
    // none when they are one set already, and the search stops at the first.
    for (c, &(k, s, e)) in cubes.iter().enumerate() {
        let cube = &order[s..e];
        for d in FORWARD {
            let Some(&o) =
                index.get(&[k[0].saturating_add(d[0]), k[1].saturating_add(d[1]), k[2].saturating_add(d[2])])
            else {
                continue;
            };
            let other = &order[cubes[o].1..cubes[o].2];
            if whole[c] && whole[o] {
                if sets.find_mut(cube[0]) == sets.find_mut(other[0]) {
                    continue;
                }
                if let Some((a, b)) = cube.iter().find_map(|&a| other.iter().find(|&&b| near(a, b)).map(|&b| (a, b))) {
                    sets.union(a, b);
                }
                continue;
            }
            for &a in cube {
                for &b in other {
                    if near(a, b) {
                        sets.union(a, b);
                    }
                }
            }
        }
    }
    // Components in the order of their smallest index, each ascending.
    let mut slot: HashMap<u32, usize, foldhash::fast::FixedState> = HashMap::default();
    let mut components: Vec<Vec<usize>> = Vec::new();
    for i in 0..points.len() {
        let root = sets.find_mut(i as u32);
        let c = *slot.entry(root).or_insert_with(|| {
            components.push(Vec::new());
            components.len() - 1
        });
        components[c].push(i);
    }
    let mut clusters = Vec::new();
    for cluster in components.into_iter().filter(|c| c.len() >= min_points) {
        split_cluster(points, cluster, max_points, &mut clusters);
    }
    Ok(clusters)
}

/// The 13 neighbor cubes of a cube that follow it in lexicographic order: each unordered pair of
/// adjacent cubes is visited once.
const FORWARD: [[i64; 3]; 13] = [
    [0, 0, 1],
    [0, 1, -1],
    [0, 1, 0],
    [0, 1, 1],
    [1, -1, -1],
    [1, -1, 0],
    [1, -1, 1],
    [1, 0, -1],
    [1, 0, 0],
    [1, 0, 1],
    [1, 1, -1],
    [1, 1, 0],
    [1, 1, 1],
];

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

    /// The components of the chains of steps ≤ `tolerance`, by a flood fill over all n² pairs.
    fn brute_force(points: &[[Real; 3]], tolerance: Real) -> Vec<Vec<usize>> {
        let mut seen = vec![false; points.len()];
        let mut out = Vec::new();
        for seed in 0..points.len() {
            if seen[seed] {
                continue;
            }
            seen[seed] = true;
            let mut c = vec![seed];
            let mut head = 0;
            while head < c.len() {
                let p = Vector3::from(points[c[head]]);
                head += 1;
                for j in 0..points.len() {
                    if !seen[j] && (Vector3::from(points[j]) - p).norm_squared() <= tolerance * tolerance {
                        seen[j] = true;
                        c.push(j);
                    }
                }
            }
            c.sort_unstable();
            out.push(c);
        }
        out
    }

    #[test]
    fn clusters_equal_a_brute_force_flood_fill() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (n, spread, tolerance) in [(600, 0.5, 0.05), (800, 1.0, 0.04), (400, 0.2, 0.01), (300, 3.0, 0.5)] {
            // Clumps and strands: points near a few random centers, with some far from any.
            let centers: Vec<Vector3> =
                (0..8).map(|_| Vector3::new(rng.random(), rng.random(), rng.random()) * spread).collect();
            let points: Vec<[Real; 3]> = (0..n)
                .map(|k| {
                    let c = centers[k % centers.len()];
                    let r = if k % 17 == 0 { spread } else { 0.15 * spread };
                    (c + Vector3::new(rng.random(), rng.random(), rng.random()).add_scalar(-0.5) * r).into()
                })
                .collect();
            let expected = brute_force(&points, tolerance);
            assert!(expected.len() > 1 && expected.iter().any(|c| c.len() > 1), "a degenerate case");
            let got = euclidean_clusters(&points, tolerance, 1, points.len()).unwrap();
            assert_eq!(got, expected, "n {n}, tolerance {tolerance}");
            // Outliers under min_points dropped, the rest in the same order.
            let kept: Vec<Vec<usize>> = expected.into_iter().filter(|c| c.len() >= 5).collect();
            assert_eq!(euclidean_clusters(&points, tolerance, 5, points.len()).unwrap(), kept);
        }
        // Points beyond any cube's range (a tolerance far below the spacing) stay apart.
        let far = [[1e6, 0.0, 0.0], [1e6, 1e-3, 0.0], [-1e6, 0.0, 0.0]];
        assert_eq!(euclidean_clusters(&far, 1e-300, 1, 10).unwrap(), vec![vec![0], vec![1], vec![2]]);
    }
}
