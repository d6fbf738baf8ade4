//! Filters from a sensor frame to the points of a cloud obstacle, each step optional, in this
//! order: holes, range crop, world transform, workspace crop, voxel grid, statistical outliers,
//! self filter (module docs of [`crate::cloud`]).

use super::{point_to_geometry, PointCloud};
use crate::fitted::FittedRobot;
use crate::{Error, Result};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::collections::HashMap;
use std::num::NonZero;
use sublevel_core::error::show_real;
use sublevel_core::math::{Isometry3, Real, Vector3};

/// Statistical outlier removal (as PCL's `StatisticalOutlierRemoval`): a point whose mean
/// distance to its `neighbors` nearest points exceeds the mean of that value over the cloud by
/// more than `std_ratio` standard deviations is dropped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutlierFilter {
    /// k, the neighbours averaged (1–64; default 8).
    pub neighbors: usize,
    /// α, the standard deviations allowed above the mean (> 0; default 2).
    pub std_ratio: Real,
}

impl Default for OutlierFilter {
    fn default() -> Self {
        Self { neighbors: 8, std_ratio: 2.0 }
    }
}

/// The filters of a frame (module docs). The default keeps every finite point within 0–10 m of
/// the sensor, anywhere, with a 2 cm voxel grid and no outlier or self filter.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudFilter {
    /// Points nearer the sensor than this are dropped (meters, ≥ 0; default 0).
    pub min_range: Real,
    /// Points farther from the sensor than this are dropped (meters, > min_range; default 10).
    pub max_range: Real,
    /// The workspace: points outside this world box (min corner, max corner; meters) are dropped;
    /// `None` keeps every point.
    pub workspace: Option<(Vector3, Vector3)>,
    /// Edge of the voxel grid (meters; 0 turns it off; default 0.02): each occupied voxel keeps
    /// the mean of its points.
    pub voxel: Real,
    /// Statistical outlier removal; `None` (the default) keeps every point.
    pub outliers: Option<OutlierFilter>,
}

impl Default for CloudFilter {
    fn default() -> Self {
        Self { min_range: 0.0, max_range: 10.0, workspace: None, voxel: 0.02, outliers: None }
    }
}

/// What a frame's filters did: points in, points dropped by each step, points kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterCounts {
    /// Points in the frame.
    pub input: usize,
    /// Holes: a coordinate NaN or infinite (or a zero depth, counted by the deprojection).
    pub holes: usize,
    /// Outside the range crop.
    pub range: usize,
    /// Outside the workspace.
    pub workspace: usize,
    /// Merged into another point of their voxel.
    pub voxel: usize,
    /// Statistical outliers.
    pub outliers: usize,
    /// Within the self filter's padding of the robot.
    pub robot: usize,
    /// Points kept.
    pub kept: usize,
}

impl CloudFilter {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `filter.min_range`, `filter.max_range`,
    /// `filter.workspace`, `filter.voxel`, `filter.outliers.neighbors` or
    /// `filter.outliers.std_ratio`.
    pub fn validate(&self) -> Result<()> {
        if !(self.min_range.is_finite() && self.min_range >= 0.0) {
            return Err(Error::invalid(
                "filter.min_range",
                format!("must be finite and ≥ 0 m, got {}", show_real(self.min_range)),
            ));
        }
        if self.max_range.is_nan() || self.max_range <= self.min_range {
            return Err(Error::invalid(
                "filter.max_range",
                format!("must exceed min_range ({} m), got {}", show_real(self.min_range), show_real(self.max_range)),
            ));
        }
        if let Some((lo, hi)) = &self.workspace {
            if !(lo.iter().chain(hi.iter()).all(|v| v.is_finite()) && (hi - lo).min() >= 0.0) {
                return Err(Error::invalid(
                    "filter.workspace",
                    format!("must be finite with min ≤ max on every axis, got {lo:?} – {hi:?}"),
                ));
            }
        }
        if !(self.voxel.is_finite() && (self.voxel == 0.0 || (1e-4..=1.0).contains(&self.voxel))) {
            return Err(Error::invalid(
                "filter.voxel",
                format!("must be 0 (off) or in [1e-4, 1] m, got {}", show_real(self.voxel)),
            ));
        }
        if let Some(o) = &self.outliers {
            if !(1..=64).contains(&o.neighbors) {
                return Err(Error::invalid("filter.outliers.neighbors", format!("must be 1–64, got {}", o.neighbors)));
            }
            if !(o.std_ratio.is_finite() && o.std_ratio > 0.0) {
                return Err(Error::invalid(
                    "filter.outliers.std_ratio",
                    format!("must be finite and > 0, got {}", show_real(o.std_ratio)),
                ));
            }
        }
        Ok(())
    }

    /// Filters `points` (x, y, z in the sensor frame, meters, as a PointCloud2's float32 fields)
    /// seen from `sensor_pose` (sensor frame → world) into world points, through every step but
    /// the self filter ([`self_filter`]); `counts` gains what each step dropped.
    ///
    /// # Errors
    /// As [`CloudFilter::validate`]; [`Error::InvalidArgument`] naming `sensor_pose` when it is
    /// not finite.
    pub fn apply(
        &self,
        points: &[[f32; 3]],
        sensor_pose: &Isometry3,
        counts: &mut FilterCounts,
    ) -> Result<Vec<[Real; 3]>> {
        self.validate()?;
        if sensor_pose.to_homogeneous().iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("sensor_pose", "must be finite"));
        }
        counts.input += points.len();
        let (lo2, hi2) = (self.min_range * self.min_range, self.max_range * self.max_range);
        // The voxel grid takes the points as they pass the crops: the frame's points are never
        // held twice.
        let mut voxels = (self.voxel > 0.0).then(|| Voxels::new(self.voxel, points.len() / 16));
        let mut out = Vec::new();
        let mut passed = 0;
        for p in points {
            if !p.iter().all(|v| v.is_finite()) {
                counts.holes += 1;
                continue;
            }
            let v = Vector3::new(p[0] as Real, p[1] as Real, p[2] as Real);
            let d2 = v.norm_squared();
            if d2 < lo2 || d2 > hi2 {
                counts.range += 1;
                continue;
            }
            let w = sensor_pose.transform_point(&v.into()).coords;
            if let Some((lo, hi)) = &self.workspace {
                if (0..3).any(|k| w[k] < lo[k] || w[k] > hi[k]) {
                    counts.workspace += 1;
                    continue;
                }
            }
            passed += 1;
            match &mut voxels {
                Some(grid) => grid.add([w.x, w.y, w.z]),
                None => out.push([w.x, w.y, w.z]),
            }
        }
        if let Some(grid) = voxels {
            out = grid.means();
            counts.voxel += passed - out.len();
        }
        if let Some(o) = &self.outliers {
            let before = out.len();
            out = remove_outliers(out, o);
            counts.outliers += before - out.len();
        }
        counts.kept = out.len();
        Ok(out)
    }
}

/// One point per occupied voxel of edge `edge` (meters): the mean of the points in it, in the
/// order the voxels were first met.
pub fn voxel_grid(points: &[[Real; 3]], edge: Real) -> Vec<[Real; 3]> {
    let mut grid = Voxels::new(edge, points.len() / 4);
    for p in points {
        grid.add(*p);
    }
    grid.means()
}

/// A voxel grid being filled: each occupied voxel's sum and count, found by a hash map of the
/// voxel's integer coordinates. Consecutive points of a frame (a depth image's row, a
/// PointCloud2 in pixel order) mostly fall in the voxel of the one before, which is looked up
/// first, then in a voxel of the rows just before, which a small direct-mapped cache holds (the
/// hash map of a whole frame's voxels does not stay in the processor's caches).
struct Voxels {
    /// 1 / the voxel edge (1/m).
    inverse: Real,
    cells: HashMap<[i64; 3], u32, foldhash::fast::FixedState>,
    /// Recent voxels by a hash of their coordinates: (voxel, index in `sums`; `u32::MAX` empty).
    recent: Vec<([i64; 3], u32)>,
    sums: Vec<([Real; 3], u32)>,
    /// The voxel of the last point and its index in `sums` (`u32::MAX` before the first).
    last: ([i64; 3], u32),
}

/// Entries of [`Voxels`]' cache of recent voxels (a power of two; 128 KiB).
const RECENT: usize = 1 << 12;

/// The cache slot of a voxel: a multiplicative hash of its coordinates.
#[inline]
fn recent_slot(key: &[i64; 3]) -> usize {
    let h = (key[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (key[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (key[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    (h >> (64 - RECENT.trailing_zeros())) as usize
}

impl Voxels {
    fn new(edge: Real, capacity: usize) -> Self {
        Self {
            inverse: 1.0 / edge,
            cells: HashMap::with_capacity_and_hasher(capacity, Default::default()),
            recent: vec![([0; 3], u32::MAX); RECENT],
            sums: Vec::with_capacity(capacity),
            last: ([0; 3], u32::MAX),
        }
    }

    #[inline]
    fn add(&mut self, p: [Real; 3]) {
        // ⌊v / edge⌋ without a call to libm's floor (the cast saturates, and the cloud refuses
        // coordinates that large).
        let cell = |v: Real| {
            let t = v * self.inverse;
            let i = t as i64;
            i - i64::from((i as Real) > t)
        };
        let key = [cell(p[0]), cell(p[1]), cell(p[2])];
        // Compared coordinate by coordinate (an array compare reloads the key just stored).
        let same = (0..3).all(|i| self.last.0[i] == key[i]);
        let k = if same && self.last.1 != u32::MAX {
            self.last.1
        } else {
            let slot = recent_slot(&key);
            let (seen, k) = self.recent[slot];
            let k = if k != u32::MAX && (0..3).all(|i| seen[i] == key[i]) {
                k
            } else {
                let next = self.sums.len() as u32;
                let k = *self.cells.entry(key).or_insert(next);
                if k == next {
                    self.sums.push(([0.0; 3], 0));
                }
                self.recent[slot] = (key, k);
                k
            };
            self.last = (key, k);
            k
        };
        let (s, n) = &mut self.sums[k as usize];
        for i in 0..3 {
            s[i] += p[i];
        }
        *n += 1;
    }

    fn means(self) -> Vec<[Real; 3]> {
        self.sums.into_iter().map(|(s, n)| [s[0] / n as Real, s[1] / n as Real, s[2] / n as Real]).collect()
    }
}

/// Statistical outlier removal ([`OutlierFilter`]); fewer than k + 1 points are kept as they are.
pub fn remove_outliers(points: Vec<[Real; 3]>, filter: &OutlierFilter) -> Vec<[Real; 3]> {
    let k = filter.neighbors;
    if points.len() <= k {
        return points;
    }
    let Ok(tree) = ImmutableKdTree::<Real, 3>::new_from_slice(&points) else { return points };
    let n = NonZero::new(k + 1).expect("k + 1 ≥ 2");
    let means: Vec<Real> = points
        .iter()
        .map(|p| {
            let near = tree.query(p).nearest_n::<SquaredEuclidean<Real>>(n).execute();
            // The nearest is the point itself (distance 0).
            near.iter().map(|q| q.distance.sqrt()).sum::<Real>() / k as Real
        })
        .collect();
    let count = means.len() as Real;
    let mean = means.iter().sum::<Real>() / count;
    let var = means.iter().map(|m| (m - mean).powi(2)).sum::<Real>() / count;
    let cut = mean + filter.std_ratio * var.sqrt();
    points.into_iter().zip(means).filter(|(_, m)| *m <= cut).map(|(p, _)| p).collect()
}

/// The self filter: drops the points (world frame) whose ball of `radius` comes within
/// `padding` of the robot at joint configuration `q` with its root at `base` — the arm in the
/// sensor's view — by the contact rule of the checks ([`crate::cloud`]); returns how many.
///
/// # Errors
/// As [`crate::RobotModel::forward_kinematics`] (`q` of the wrong length or not finite);
/// [`Error::InvalidArgument`] naming `self_filter.padding` when it is negative or not finite.
pub fn self_filter(
    robot: &FittedRobot,
    q: &[Real],
    base: &Isometry3,
    radius: Real,
    padding: Real,
    points: &mut Vec<[Real; 3]>,
) -> Result<usize> {
    if !(padding.is_finite() && padding >= 0.0) {
        return Err(Error::invalid(
            "self_filter.padding",
            format!("must be finite and ≥ 0 m, got {}", show_real(padding)),
        ));
    }
    let mut link_poses = Vec::new();
    robot.model.forward_kinematics(q, base, &mut link_poses)?;
    let cloud = PointCloud::new(std::mem::take(points), radius)?;
    let mut drop = vec![false; cloud.len()];
    for g in &robot.geometries {
        let pose = link_poses[g.link] * g.origin;
        // Every contact of this geometry: search until no point ball is left within the padding.
        let (center, r) = g.sphere;
        let c = pose.transform_point(&center.into()).coords;
        let mut near = Vec::new();
        cloud.within(&c, r + radius + padding, &mut near);
        for i in near {
            if !drop[i] {
                let y = pose.inverse_transform_point(&cloud.point(i).into()).coords;
                drop[i] = point_to_geometry(&g.shape, &y).0 - radius <= padding;
            }
        }
    }
    let removed = drop.iter().filter(|d| **d).count();
    *points = cloud.points().iter().zip(&drop).filter(|(_, d)| !**d).map(|(p, _)| *p).collect();
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_grid_keeps_one_mean_per_voxel() {
        let pts = vec![[0.001, 0.001, 0.001], [0.009, 0.009, 0.009], [0.011, 0.0, 0.0], [-0.001, 0.0, 0.0]];
        let v = voxel_grid(&pts, 0.01);
        assert_eq!(v.len(), 3);
        assert!((v[0][0] - 0.005).abs() < 1e-15 && (v[0][2] - 0.005).abs() < 1e-15);
        assert_eq!(v[1], [0.011, 0.0, 0.0]);
        assert_eq!(v[2], [-0.001, 0.0, 0.0]);
    }

    #[test]
    fn voxel_grid_equals_grouping_by_floor() {
        // Random points of both signs, in runs (as a depth row gives them) and jumps: each
        // voxel's mean equals the mean of the points grouped by ⌊v / edge⌋ with libm's floor.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut pts: Vec<[Real; 3]> = Vec::new();
        for _ in 0..6000 {
            // A run from a fresh point, or (one in four) from an earlier one: more voxels than the
            // cache of recent voxels holds, and voxels met again after they left it.
            let mut p = match pts.len() {
                n if n > 0 && rng.random_range(0..4) == 0 => pts[rng.random_range(0..n)],
                _ => [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5)],
            };
            for _ in 0..rng.random_range(1..12) {
                p[0] += 0.003;
                pts.push(p);
            }
        }
        assert!(voxel_grid(&pts, 0.02).len() > RECENT);
        let edge = 0.02;
        let mut groups: std::collections::BTreeMap<[i64; 3], ([Real; 3], usize)> = Default::default();
        for p in &pts {
            let key = p.map(|v| (v / edge).floor() as i64);
            let (s, n) = groups.entry(key).or_insert(([0.0; 3], 0));
            for k in 0..3 {
                s[k] += p[k];
            }
            *n += 1;
        }
        let mut got = voxel_grid(&pts, edge);
        let mut want: Vec<[Real; 3]> = groups.values().map(|(s, n)| s.map(|v| v / *n as Real)).collect();
        let order = |a: &[Real; 3], b: &[Real; 3]| a.partial_cmp(b).expect("finite");
        got.sort_by(order);
        want.sort_by(order);
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert!((0..3).all(|k| (g[k] - w[k]).abs() < 1e-12), "{g:?} vs {w:?}");
        }
    }

    #[test]
    fn outliers_far_from_a_grid_are_dropped() {
        let mut pts: Vec<[Real; 3]> =
            (0..400).map(|i| [(i % 20) as Real * 0.01, (i / 20) as Real * 0.01, 0.0]).collect();
        pts.push([5.0, 5.0, 5.0]);
        pts.push([0.1, 0.1, 1.0]);
        let kept = remove_outliers(pts, &OutlierFilter::default());
        assert_eq!(kept.len(), 400);
        assert!(kept.iter().all(|p| p[2] == 0.0));
    }

    #[test]
    fn holes_range_and_workspace_are_counted() {
        let f = CloudFilter {
            voxel: 0.0,
            min_range: 0.2,
            max_range: 2.0,
            workspace: Some((Vector3::new(-1.0, -1.0, 0.5), Vector3::new(1.0, 1.0, 3.0))),
            ..CloudFilter::default()
        };
        let pts = [
            [0.0, 0.0, 1.0],
            [f32::NAN, 0.0, 1.0],
            [0.0, 0.0, 2.5],
            [0.0, 0.0, 0.1],
            [0.0, f32::INFINITY, 0.0],
            [1.5, 0.0, 0.5],
        ];
        let pose = Isometry3::translation(0.0, 0.0, 0.5);
        let mut counts = FilterCounts::default();
        let out = f.apply(&pts, &pose, &mut counts).unwrap();
        assert_eq!(out, vec![[0.0, 0.0, 1.5]]);
        assert_eq!((counts.input, counts.holes, counts.range, counts.workspace, counts.kept), (6, 2, 2, 1, 1));
    }

    #[test]
    fn bad_settings_name_the_field() {
        let bad = |f: CloudFilter| f.validate().unwrap_err().to_string();
        assert!(bad(CloudFilter { voxel: -1.0, ..Default::default() }).contains("filter.voxel"));
        assert!(bad(CloudFilter { max_range: 0.0, ..Default::default() }).contains("filter.max_range"));
        assert!(bad(CloudFilter { min_range: Real::NAN, ..Default::default() }).contains("filter.min_range"));
        let o = OutlierFilter { neighbors: 0, std_ratio: 1.0 };
        assert!(bad(CloudFilter { outliers: Some(o), ..Default::default() }).contains("neighbors"));
    }
}
