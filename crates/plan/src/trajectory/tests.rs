use super::blend::arc_free;
use super::*;
use std::f64::consts::PI;

fn limits(n: usize, v: Real, a: Real) -> JointLimits {
    JointLimits { velocity: vec![v; n], acceleration: vec![a; n] }
}

#[test]
fn a_straight_move_takes_the_bang_coast_bang_time() {
    // One joint, distance L, limits v and a: t = L/v + v/a when L ≥ v²/a, else 2√(L/a).
    for (l, v, a) in [(2.0, 1.0, 2.0), (0.1, 1.0, 2.0), (1.0, 0.5, 0.5)] {
        let path = BlendedPath::new(&[vec![0.0], vec![l]], 0.1).unwrap();
        let timing = time_path(&path, &limits(1, v, a), &TimingSettings::default()).unwrap();
        let exact = if l >= v * v / a { l / v + v / a } else { 2.0 * (l / a).sqrt() };
        assert!((timing.duration() - exact).abs() < 1e-6 * exact, "L={l}: {} vs {exact}", timing.duration());
    }
}

#[test]
fn a_blend_keeps_within_its_deviation_and_is_tangent_to_both_segments() {
    let w = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0, 1.0]];
    let path = BlendedPath::new(&w, 0.1).unwrap();
    assert_eq!(path.pieces.len(), 3);
    let Piece::Arc { radius, angle, .. } = &path.pieces[1] else { panic!("no arc") };
    assert!((angle - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    // Distance from the corner to the arc's middle is the deviation, 0.1.
    let mid = path.pieces[1].at(path.pieces[1].length() / 2.0);
    let d = ((mid[0] - 1.0).powi(2) + mid[1].powi(2)).sqrt();
    assert!((d - 0.1).abs() < 1e-12, "deviation {d}");
    assert!((radius - 0.1 / (std::f64::consts::SQRT_2 - 1.0)).abs() < 1e-12);
    // Continuity of position and direction at both ends of the arc.
    let (mut q, mut dq, mut ddq) = (vec![0.0; 2], vec![0.0; 2], vec![0.0; 2]);
    path.pieces[1].evaluate(0.0, &mut q, &mut dq, &mut ddq);
    let line_end = path.pieces[0].at(path.pieces[0].length());
    assert!((q[0] - line_end[0]).abs() < 1e-12 && (q[1] - line_end[1]).abs() < 1e-12);
    assert!((dq[0] - 1.0).abs() < 1e-12 && dq[1].abs() < 1e-12);
    path.pieces[1].evaluate(path.pieces[1].length(), &mut q, &mut dq, &mut ddq);
    let line_start = path.pieces[2].at(0.0);
    assert!((q[0] - line_start[0]).abs() < 1e-12 && (q[1] - line_start[1]).abs() < 1e-12);
    assert!(dq[0].abs() < 1e-12 && (dq[1] - 1.0).abs() < 1e-12);
    assert_eq!(path.stop_after, vec![false, false, true]);
}

#[test]
fn samples_respect_the_limits_and_end_at_rest_on_the_waypoints() {
    let w = vec![vec![0.0, 0.0, 0.0], vec![1.0, 0.3, -0.2], vec![1.2, 1.0, 0.4], vec![0.2, 1.5, 0.0]];
    let lim = JointLimits { velocity: vec![2.0, 1.0, 1.5], acceleration: vec![3.0, 2.0, 5.0] };
    for deviation in [0.0, 0.05, 0.3] {
        let path = BlendedPath::new(&w, deviation).unwrap();
        let timing = time_path(&path, &lim, &TimingSettings::default()).unwrap();
        let trajectory = timing.sample(Some(1e-3)).unwrap();
        for (i, (qd, qdd)) in trajectory.velocities.iter().zip(&trajectory.accelerations).enumerate() {
            for j in 0..3 {
                assert!(qd[j].abs() <= lim.velocity[j] * (1.0 + 1e-6), "deviation {deviation}, point {i}: v {qd:?}");
                assert!(qdd[j].abs() <= lim.acceleration[j] * (1.0 + 1e-6), "point {i}: a {qdd:?}");
            }
        }
        assert_eq!(trajectory.positions[0], w[0]);
        assert_eq!(trajectory.positions.last().unwrap(), &w[3]);
        assert!(trajectory.velocities.last().unwrap().iter().all(|v| *v == 0.0));
        // Samples move no faster than the velocity limits allow between them (no jumps).
        for k in 1..trajectory.positions.len() {
            let dt = trajectory.time_from_start[k] - trajectory.time_from_start[k - 1];
            for j in 0..3 {
                let dq = (trajectory.positions[k][j] - trajectory.positions[k - 1][j]).abs();
                assert!(dq <= lim.velocity[j] * dt * (1.0 + 1e-6) + 1e-12, "jump at {k}");
            }
        }
    }
}

#[test]
fn a_segment_shorter_than_a_station_step_between_two_stops_is_timed() {
    let w = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0, 0.001], vec![0.0, 0.001]];
    let path = BlendedPath::new(&w, 0.0).unwrap();
    let timing = time_path(&path, &limits(2, 1.0, 1.0), &TimingSettings::default()).unwrap();
    // Three rest-to-rest moves: 1 (coasting never reached: 2√(L/a)), 0.001, 1.
    let exact = 2.0 * 2.0 * 1.0f64.sqrt() + 2.0 * 0.001f64.sqrt();
    assert!((timing.duration() - exact).abs() < 1e-6 * exact, "{} vs {exact}", timing.duration());
}

#[test]
fn blending_is_faster_than_stopping_at_every_corner() {
    let w = vec![vec![0.0, 0.0], vec![1.0, 0.2], vec![1.5, 1.0], vec![2.5, 1.2]];
    let lim = limits(2, 1.0, 2.0);
    let stop = time_path(&BlendedPath::new(&w, 0.0).unwrap(), &lim, &TimingSettings::default()).unwrap();
    let blend = time_path(&BlendedPath::new(&w, 0.1).unwrap(), &lim, &TimingSettings::default()).unwrap();
    assert!(blend.duration() < 0.95 * stop.duration(), "{} vs {}", blend.duration(), stop.duration());
}

#[test]
fn bad_input_names_its_field() {
    let field = |e: Error| match e {
        Error::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(field(BlendedPath::new(&[vec![0.0]], 0.1).unwrap_err()), "path");
    assert_eq!(field(BlendedPath::new(&[vec![0.0], vec![0.0]], 0.1).unwrap_err()), "path");
    assert_eq!(field(BlendedPath::new(&[vec![0.0], vec![Real::NAN]], 0.1).unwrap_err()), "path[1][0]");
    assert_eq!(field(BlendedPath::new(&[vec![0.0], vec![1.0, 2.0]], 0.1).unwrap_err()), "path[1]");
    let path = BlendedPath::new(&[vec![0.0], vec![0.0], vec![1.0]], 0.1).unwrap();
    assert_eq!(path.waypoints.len(), 2);
    let bad = JointLimits { velocity: vec![0.0], acceleration: vec![1.0] };
    assert_eq!(field(time_path(&path, &bad, &TimingSettings::default()).unwrap_err()), "limits.velocity[0]");
    let bad = JointLimits { velocity: vec![1.0], acceleration: vec![Real::NAN] };
    assert_eq!(field(time_path(&path, &bad, &TimingSettings::default()).unwrap_err()), "limits.acceleration[0]");
    let settings = TimingSettings { velocity_scaling: 1.5, ..TimingSettings::default() };
    assert_eq!(field(time_path(&path, &limits(1, 1.0, 1.0), &settings).unwrap_err()), "velocity_scaling");
    let timing = time_path(&path, &limits(1, 1.0, 1.0), &TimingSettings::default()).unwrap();
    assert_eq!(field(timing.sample(Some(1e-9)).unwrap_err()), "sample_dt");
    assert_eq!(field(timing.sample(Some(0.0)).unwrap_err()), "sample_dt");
}

/// A point robot in the plane with a disc obstacle: a tube is free when every point of the
/// chord is farther than the disc's radius plus the tube's half-width from its center.
struct Disc {
    space: crate::space::JointSpace,
    center: [Real; 2],
    radius: Real,
    /// Answers every tube of nonzero width undecided (a checker that cannot prove tubes).
    refuse_tubes: bool,
}

impl Validity for Disc {
    fn space(&self) -> &crate::space::JointSpace {
        &self.space
    }
    fn state_free(&mut self, q: &[Real]) -> Result<bool> {
        Ok(((q[0] - self.center[0]).powi(2) + (q[1] - self.center[1]).powi(2)).sqrt() > self.radius)
    }
    fn certify(&mut self, a: &[Real], b: &[Real], tolerance: Real) -> Result<Certificate> {
        self.certify_tube(a, b, &[0.0, 0.0], tolerance)
    }
    fn certify_tube(&mut self, a: &[Real], b: &[Real], tube: &[Real], _: Real) -> Result<Certificate> {
        if self.refuse_tubes && tube.iter().any(|&w| w > 0.0) {
            return Ok(Certificate::Undecided);
        }
        // Distance from the center to the segment.
        let d = [b[0] - a[0], b[1] - a[1]];
        let t = (((self.center[0] - a[0]) * d[0] + (self.center[1] - a[1]) * d[1]) / (d[0] * d[0] + d[1] * d[1]))
            .clamp(0.0, 1.0);
        let p = [a[0] + t * d[0] - self.center[0], a[1] + t * d[1] - self.center[1]];
        let gap = (p[0] * p[0] + p[1] * p[1]).sqrt() - self.radius - (tube[0] * tube[0] + tube[1] * tube[1]).sqrt();
        Ok(if gap > 0.0 { Certificate::Free } else { Certificate::Contact(t) })
    }
    fn box_free(&mut self, center: &[Real], tube: &[Real]) -> Result<bool> {
        let d = ((center[0] - self.center[0]).powi(2) + (center[1] - self.center[1]).powi(2)).sqrt();
        Ok(!self.refuse_tubes && d > self.radius + (tube[0] * tube[0] + tube[1] * tube[1]).sqrt())
    }
    fn counts(&self) -> crate::validity::CheckCounts {
        crate::validity::CheckCounts::default()
    }
    fn collision(&mut self, _: &[Real]) -> Result<Option<String>> {
        Ok(None)
    }
}

#[test]
fn a_blend_that_would_cut_into_an_obstacle_is_tightened_until_it_is_proven() {
    // The corner (1, 0) turns up; a disc inside the turn on its bisector, 0.1 from the
    // corner, where the default blend's middle passes; the polyline clears it by 0.06.
    let w = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0, 1.0]];
    let inner = [1.0 - 0.1 / std::f64::consts::SQRT_2, 0.1 / std::f64::consts::SQRT_2];
    let space = crate::space::JointSpace::boxed(vec![(-10.0, 10.0); 2]);
    let mut disc = Disc { space: space.clone(), center: inner, radius: 0.01, refuse_tubes: false };
    let path = BlendedPath::new(&w, 0.1).unwrap();
    // The untightened arc's middle is the disc's center: it must not pass.
    assert!(!arc_free(&mut disc, &path.pieces[1], 1e-3).unwrap());
    let proven = certify_blends(&mut disc, &path, 1e-3).unwrap();
    assert_eq!((proven.arcs_certified, proven.tightened, proven.stops_added), (1, 1, 0));
    let d = proven.path.deviation[1];
    assert!((d - 0.025).abs() < 1e-12, "deviation {d}");
    // Dense samples of the tightened arc clear the disc.
    let arc = &proven.path.pieces[1];
    for i in 0..=1000 {
        let q = arc.at(arc.length() * i as Real / 1000.0);
        assert!(disc.state_free(&q).unwrap(), "sample {i}");
    }
    // A checker that proves no tube: no blend can be proven; the corner becomes a stop.
    let mut strict = Disc { space, center: [5.0, 5.0], radius: 0.01, refuse_tubes: true };
    let proven = certify_blends(&mut strict, &path, 1e-3).unwrap();
    assert_eq!((proven.arcs_certified, proven.stops_added), (0, 1));
    assert_eq!(proven.path.stop_after, vec![true, true]);
}

#[test]
fn a_continuous_joint_is_timed_the_shorter_way_round() {
    // Entry 0 wraps: 3.0 → −3.0 is 0.283 rad forward through π, as the edge was proven; the
    // trajectory goes that way (its values unwrapped past π), never 6 rad back.
    let space = crate::space::JointSpace { bounds: vec![(-PI, PI), (-10.0, 10.0)], wraps: vec![true, false] };
    let mut free = Disc { space, center: [100.0, 100.0], radius: 0.01, refuse_tubes: false };
    let ask = TrajectoryRequest {
        limits: limits(2, 1.0, 1.0),
        timing: TimingSettings::default(),
        sample_dt: 1e-3,
        max_deviation: 0.1,
    };
    let path = vec![vec![3.0, 0.0], vec![-3.0, 0.5], vec![-2.5, 0.5]];
    let timed = timed_trajectory(&mut free, &path, &ask, 1e-3).unwrap();
    let t = &timed.trajectory;
    let turn = 2.0 * PI - 6.0;
    assert_eq!(t.positions[0], path[0]);
    let last = t.positions.last().unwrap();
    assert!((last[0] - (3.0 + turn + 0.5)).abs() < 1e-12 && last[1] == 0.5, "{last:?}");
    assert!(t.positions.iter().all(|q| q[0] >= 3.0 - 1e-12 && q[0] <= 3.0 + turn + 0.5 + 1e-12));
    // The second edge runs on from the first (unwrapped): one blend, no stop.
    assert_eq!((timed.blends.arcs_certified, timed.stops), (1, 0));
}
