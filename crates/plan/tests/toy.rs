//! The planner on a plane among disks, where every answer has a closed form: a configuration is
//! free when it is farther than a disk's radius from its center, and a segment when its closest
//! point to every center is (the projection onto the segment). The returned paths are checked
//! against that closed form, not against the planner's own checks.

use std::sync::atomic::AtomicBool;
use std::time::Duration;
use sublevel_core::math::Real;
use sublevel_plan::{
    plan, Certificate, CheckCounts, Goal, JointRegion, JointSpace, PlanSettings, PlanStatus, Validity,
};

/// Disks `(cx, cy, r)` in the box [−1, 1]²; `resolution_override` replaces the search's sampling
/// resolution (a coarse one lets sampled edges cross thin disks, for the certification to catch).
struct Disks {
    space: JointSpace,
    disks: Vec<(Real, Real, Real)>,
    coarse: Option<Real>,
    counts: CheckCounts,
}

impl Disks {
    fn new(disks: Vec<(Real, Real, Real)>) -> Self {
        Self { space: JointSpace::boxed(vec![(-1.0, 1.0); 2]), disks, coarse: None, counts: CheckCounts::default() }
    }
}

/// The distance from `(px, py)` to the segment `a → b`, and the segment parameter of the closest point.
fn segment_distance(a: &[Real], b: &[Real], (px, py): (Real, Real)) -> (Real, Real) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 == 0.0 { 0.0 } else { (((px - a[0]) * dx + (py - a[1]) * dy) / l2).clamp(0.0, 1.0) };
    let (x, y) = (a[0] + t * dx, a[1] + t * dy);
    (((x - px).powi(2) + (y - py).powi(2)).sqrt(), t)
}

/// Whether the segment `a → b` keeps clear of every disk (closed form).
fn segment_clear(disks: &[(Real, Real, Real)], a: &[Real], b: &[Real]) -> bool {
    disks.iter().all(|&(cx, cy, r)| segment_distance(a, b, (cx, cy)).0 > r)
}

impl Validity for Disks {
    fn space(&self) -> &JointSpace {
        &self.space
    }
    fn state_free(&mut self, q: &[Real]) -> sublevel_core::Result<bool> {
        self.counts.states += 1;
        Ok(self.disks.iter().all(|&(cx, cy, r)| (q[0] - cx).hypot(q[1] - cy) > r))
    }
    fn edge_free(&mut self, a: &[Real], b: &[Real], resolution: Real) -> sublevel_core::Result<bool> {
        self.counts.edges += 1;
        let n = ((self.space.distance(a, b) * self.coarse.unwrap_or(resolution)).ceil() as usize).max(1);
        let mut q = Vec::new();
        for i in 1..=n {
            self.space.interpolate(a, b, i as Real / n as Real, &mut q);
            if !self.state_free(&q)? {
                return Ok(false);
            }
        }
        Ok(true)
    }
    fn certify(&mut self, a: &[Real], b: &[Real], tolerance: Real) -> sublevel_core::Result<Certificate> {
        self.counts.edges_certified += 1;
        let first = self
            .disks
            .iter()
            .map(|&(cx, cy, _)| segment_distance(a, b, (cx, cy)))
            .zip(&self.disks)
            .filter(|((d, _), disk)| *d <= disk.2 + tolerance)
            .map(|((_, t), _)| t)
            .fold(Real::INFINITY, Real::min);
        Ok(if first.is_finite() { Certificate::Contact(first) } else { Certificate::Free })
    }
    fn counts(&self) -> CheckCounts {
        self.counts
    }
    fn collision(&mut self, q: &[Real]) -> sublevel_core::Result<Option<String>> {
        Ok(self.disks.iter().position(|&(cx, cy, r)| (q[0] - cx).hypot(q[1] - cy) <= r).map(|k| format!("disk {k}")))
    }
}

/// A wall of disks across x = 0 with one gap near y = 0.7.
fn wall() -> Vec<(Real, Real, Real)> {
    (0..=20).map(|k| -1.0 + 0.1 * k as Real).filter(|y| (y - 0.7).abs() > 0.15).map(|y| (0.0, y, 0.06)).collect()
}

fn settings() -> PlanSettings {
    PlanSettings { timeout: Duration::from_secs(5), range: 0.3, ..PlanSettings::default() }
}

/// Every edge clear by the closed form, the ends where they were asked to be.
fn assert_path_clear(disks: &[(Real, Real, Real)], path: &[Vec<Real>], start: &[Real], goal: &[Real]) {
    assert_eq!(path.first().map(Vec::as_slice), Some(start));
    assert_eq!(path.last().map(Vec::as_slice), Some(goal));
    for (i, w) in path.windows(2).enumerate() {
        assert!(segment_clear(disks, &w[0], &w[1]), "edge {i} {:?} → {:?} crosses a disk", w[0], w[1]);
    }
}

#[test]
fn a_path_through_the_gap_in_a_wall_is_clear_by_the_closed_form_and_reproducible() {
    let (start, goal) = (vec![-0.8, -0.8], vec![0.8, -0.8]);
    let mut checker = Disks::new(wall());
    let cancel = AtomicBool::new(false);
    let out = plan(&mut checker, &start, &Goal::Configurations(vec![goal.clone()]), &settings(), &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::Solved);
    assert!(out.certified && out.unproven.is_empty());
    assert_path_clear(&checker.disks, &out.path, &start, &goal);
    // Through the gap (y ≈ 0.7): at least the two legs up to it and down from it.
    let via_gap = ((0.8 as Real).hypot(1.5)) * 2.0;
    assert!(out.length >= via_gap - 0.05, "length {} shorter than the way through the gap {via_gap}", out.length);
    let sum: Real = out.path.windows(2).map(|w| checker.space.distance(&w[0], &w[1])).sum();
    assert!((sum - out.length).abs() < 1e-12);
    // Simplified: within 15 % of the shortest way round (the two legs to the gap's corner).
    assert!(out.length <= 1.15 * via_gap, "length {} vs {via_gap}", out.length);
    let again = plan(&mut Disks::new(wall()), &start, &Goal::Configurations(vec![goal]), &settings(), &cancel).unwrap();
    assert_eq!(again.path, out.path, "same seed, same path");
    assert!(out.counts.states > 0 && out.counts.edges_certified >= out.path.len() - 1);
}

#[test]
fn the_nearest_free_goal_of_several_is_reached_and_colliding_ends_are_named() {
    let (start, free_goal) = (vec![-0.8, -0.8], vec![-0.8, 0.8]);
    let blocked_goal = vec![0.0, 0.0];
    let mut checker = Disks::new(wall());
    let cancel = AtomicBool::new(false);
    let goals = Goal::Configurations(vec![blocked_goal.clone(), free_goal.clone()]);
    let out = plan(&mut checker, &start, &goals, &settings(), &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::Solved);
    assert_eq!(out.goal.as_deref(), Some(free_goal.as_slice()));
    assert_path_clear(&checker.disks, &out.path, &start, &free_goal);

    let out =
        plan(&mut checker, &[0.0, 0.0], &Goal::Configurations(vec![free_goal.clone()]), &settings(), &cancel).unwrap();
    assert!(matches!(out.status, PlanStatus::StartInCollision(ref why) if why.starts_with("disk")), "{:?}", out.status);
    assert!(out.path.is_empty());
    let out = plan(&mut checker, &start, &Goal::Configurations(vec![blocked_goal]), &settings(), &cancel).unwrap();
    assert!(matches!(out.status, PlanStatus::GoalInCollision(_)), "{:?}", out.status);
}

#[test]
fn an_enclosed_goal_times_out_and_a_set_cancel_flag_cancels() {
    // A ring of disks around (0.5, 0.5) with no gap.
    let ring: Vec<_> = (0..40)
        .map(|k| {
            let a = k as Real * std::f64::consts::TAU / 40.0;
            (0.5 + 0.3 * a.cos(), 0.5 + 0.3 * a.sin(), 0.04)
        })
        .collect();
    let mut checker = Disks::new(ring);
    let s = PlanSettings { timeout: Duration::from_millis(200), ..settings() };
    let cancel = AtomicBool::new(false);
    let goal = Goal::Configurations(vec![vec![0.5, 0.5]]);
    let out = plan(&mut checker, &[-0.8, -0.8], &goal, &s, &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::TimedOut);
    assert!(out.path.is_empty() && !out.certified);
    let cancel = AtomicBool::new(true);
    let out = plan(&mut checker, &[-0.8, -0.8], &goal, &s, &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::Cancelled);
}

#[test]
fn sampled_edges_that_cross_thin_obstacles_are_repaired_by_the_certification() {
    // Thin disks (radius 1 cm) and a search that samples edges every 0.5: its edges cross them;
    // the returned path must not.
    let disks: Vec<_> =
        (0..7).flat_map(|i| (0..7).map(move |j| (-0.6 + 0.2 * i as Real, -0.6 + 0.2 * j as Real, 0.01))).collect();
    let mut checker = Disks::new(disks);
    checker.coarse = Some(2.0);
    let (start, goal) = (vec![-0.95, -0.7], vec![0.95, 0.7]);
    let cancel = AtomicBool::new(false);
    let s = PlanSettings { simplify: false, ..settings() };
    let out = plan(&mut checker, &start, &Goal::Configurations(vec![goal.clone()]), &s, &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::Solved);
    assert!(out.repaired > 0, "the straight edge crosses a disk: something was repaired");
    assert_path_clear(&checker.disks, &out.path, &start, &goal);
}

#[test]
fn a_goal_region_is_reached_inside_its_tolerances() {
    let mut checker = Disks::new(wall());
    let cancel = AtomicBool::new(false);
    // The region's center sits in a disk of the wall; the region reaches free space beside it.
    let region = JointRegion { center: vec![0.0, -0.5], below: vec![0.2, 0.0], above: vec![0.2, 0.0] };
    let out = plan(&mut checker, &[-0.8, -0.8], &Goal::Region(region.clone()), &settings(), &cancel).unwrap();
    assert_eq!(out.status, PlanStatus::Solved);
    let end = out.path.last().unwrap();
    for (k, v) in end.iter().enumerate() {
        assert!(*v >= region.center[k] - region.below[k] - 1e-12 && *v <= region.center[k] + region.above[k] + 1e-12);
    }
    assert!(checker.disks.iter().all(|&(cx, cy, r)| (end[0] - cx).hypot(end[1] - cy) > r));
}

#[test]
fn bad_requests_name_their_field() {
    let mut checker = Disks::new(wall());
    let cancel = AtomicBool::new(false);
    let goal = Goal::Configurations(vec![vec![0.8, 0.8]]);
    let field = |e: sublevel_core::Error| match e {
        sublevel_core::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    let zero = PlanSettings { timeout: Duration::ZERO, ..settings() };
    assert_eq!(field(plan(&mut checker, &[0.8, -0.8], &goal, &zero, &cancel).unwrap_err()), "timeout");
    assert_eq!(field(plan(&mut checker, &[Real::NAN, 0.0], &goal, &settings(), &cancel).unwrap_err()), "start[0]");
    assert_eq!(field(plan(&mut checker, &[0.0], &goal, &settings(), &cancel).unwrap_err()), "start");
    assert_eq!(field(plan(&mut checker, &[0.0, 2.0], &goal, &settings(), &cancel).unwrap_err()), "start[1]");
    let bad_goal = Goal::Configurations(vec![vec![0.8, 0.8], vec![0.1]]);
    assert_eq!(
        field(plan(&mut checker, &[0.8, -0.8], &bad_goal, &settings(), &cancel).unwrap_err()),
        "goal.configurations[1]"
    );
    assert_eq!(
        field(plan(&mut checker, &[0.8, -0.8], &Goal::Configurations(vec![]), &settings(), &cancel).unwrap_err()),
        "goal"
    );
}
