//! Time-optimal parameterization of a [`BlendedPath`] (TOPP-RA through `copp`) and its sampling.

use super::path::{BlendedPath, Piece};
use super::{JointLimits, TimingSettings, MAX_STATIONS, MAX_TRAJECTORY_POINTS};
use copp::diag::PathError;
use copp::path::{Path, PathEvaluator2nd};
use copp::robot::Robot;
use copp::solver::topp2_ra::{topp2_ra, ReachSet2OptionsBuilder, Topp2ProblemBuilder};
use std::sync::Arc;
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

/// A timed trajectory: `positions[i]` reached at `time_from_start[i]` with `velocities[i]` and
/// `accelerations[i]` (MoveIt's `trajectory_msgs/JointTrajectory` points), at rest at both ends.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Seconds from the start, increasing, first 0.
    pub time_from_start: Vec<Real>,
    /// Configurations (radians or meters).
    pub positions: Vec<Vec<Real>>,
    /// Joint velocities (per second).
    pub velocities: Vec<Vec<Real>>,
    /// Joint accelerations (per second squared).
    pub accelerations: Vec<Vec<Real>>,
    /// Seconds from the start to the end.
    pub duration: Real,
}

/// The time-optimal parameterization of a [`BlendedPath`]: its stations and the path speed
/// there (module docs), from which any sampling is made ([`Timing::sample`]).
#[derive(Clone, Debug)]
pub struct Timing {
    path: BlendedPath,
    /// Per station: path parameter s, ṡ, time.
    s: Vec<Real>,
    speed: Vec<Real>,
    time: Vec<Real>,
    /// Piece start parameters.
    starts: Vec<Real>,
}

impl Timing {
    /// Seconds from rest at the start to rest at the end.
    pub fn duration(&self) -> Real {
        *self.time.last().unwrap_or(&0.0)
    }

    /// The path it times.
    pub fn path(&self) -> &BlendedPath {
        &self.path
    }

    /// The number of stations.
    pub fn stations(&self) -> usize {
        self.s.len()
    }

    /// The piece holding parameter `s` (the later one at a boundary) and the local parameter.
    fn locate(&self, s: Real) -> (usize, Real) {
        self.path.locate(&self.starts, s)
    }

    /// As [`Timing::locate`] for a point of the station interval starting at `from`: the piece
    /// that holds the interval (a station interval never spans two pieces).
    fn locate_in(&self, s: Real, from: Real) -> (usize, Real) {
        let (i, _) = self.locate(from);
        (i, (s - self.starts[i]).clamp(0.0, self.path.pieces[i].length()))
    }

    /// The state at time `t` (clamped to [0, duration]): position, velocity, acceleration.
    pub fn state(&self, t: Real, q: &mut [Real], qd: &mut [Real], qdd: &mut [Real]) {
        let mut scratch = vec![0.0; 2 * q.len()];
        self.state_at(t, q, qd, qdd, &mut scratch);
    }

    /// [`Timing::state`] with `scratch` (at least twice the robot's length) for the path's
    /// derivatives.
    fn state_at(&self, t: Real, q: &mut [Real], qd: &mut [Real], qdd: &mut [Real], scratch: &mut [Real]) {
        let t = t.clamp(0.0, self.duration());
        let k = self.time.partition_point(|&a| a <= t).saturating_sub(1).min(self.s.len() - 2);
        self.state_with(k, t, q, qd, qdd, scratch);
    }

    /// The state at time `t` by the motion of station interval `k` (its own constant s̈, so that
    /// `t` at the interval's end gives the limit from inside it), `scratch` at least twice the
    /// robot's length.
    fn state_with(&self, k: usize, t: Real, q: &mut [Real], qd: &mut [Real], qdd: &mut [Real], scratch: &mut [Real]) {
        let ds = self.s[k + 1] - self.s[k];
        let accel = (self.speed[k + 1].powi(2) - self.speed[k].powi(2)) / (2.0 * ds);
        let tau = t - self.time[k];
        let sd = (self.speed[k] + accel * tau).max(0.0);
        let s = (self.s[k] + self.speed[k] * tau + accel * tau * tau / 2.0).clamp(self.s[k], self.s[k + 1]);
        let (piece, u) = self.locate_in(s, self.s[k]);
        let n = q.len();
        let (dq, rest) = scratch.split_at_mut(n);
        let ddq = &mut rest[..n];
        self.path.pieces[piece].evaluate(u, q, dq, ddq);
        for j in 0..n {
            qd[j] = dq[j] * sd;
            qdd[j] = ddq[j] * sd * sd + dq[j] * accel;
        }
    }

    /// The trajectory sampled every `dt` seconds (> 0), its last point at the duration; `None`
    /// samples at the stations themselves.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `sample_dt` (not finite and > 0, or more than
    /// [`MAX_TRAJECTORY_POINTS`] points).
    pub fn sample(&self, dt: Option<Real>) -> Result<Trajectory> {
        let times: Vec<Real> = match dt {
            None => self.time.clone(),
            Some(dt) => {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(Error::invalid("sample_dt", format!("must be finite and > 0 s, got {dt}")));
                }
                let count = (self.duration() / dt).ceil();
                if count.is_nan() || count >= MAX_TRAJECTORY_POINTS as Real {
                    return Err(Error::invalid(
                        "sample_dt",
                        format!(
                            "{dt} s gives {count} points over {:.3} s, more than the limit of {MAX_TRAJECTORY_POINTS}",
                            self.duration()
                        ),
                    ));
                }
                let count = count as usize;
                let mut times: Vec<Real> = (0..count).map(|i| i as Real * dt).collect();
                times.push(self.duration());
                times
            }
        };
        let n = self.path.dof();
        let mut out = Trajectory { duration: self.duration(), ..Trajectory::default() };
        let mut scratch = vec![0.0; 2 * n];
        for &t in &times {
            let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            self.state_at(t, &mut q, &mut qd, &mut qdd, &mut scratch);
            out.time_from_start.push(t);
            out.positions.push(q);
            out.velocities.push(qd);
            out.accelerations.push(qdd);
        }
        // The ends exactly: the first and last waypoints, at rest.
        if let (Some(first), Some(last)) = (out.positions.first_mut(), self.path.waypoints.last()) {
            first.clone_from(&self.path.waypoints[0]);
            out.positions.last_mut().expect("two points at least").clone_from(last);
        }
        let last = out.velocities.len() - 1;
        for k in [0, last] {
            out.velocities[k].fill(0.0);
        }
        Ok(out)
    }

    /// Per station interval, the largest ratio of a speed and of an acceleration to its limit
    /// at its ends and, on an arc, at `between` points inside it: ≤ 1 within the limits.
    pub fn interval_ratios(&self, limits: &JointLimits, between: usize) -> Vec<(Real, Real)> {
        let n = self.path.dof();
        let mut scratch = vec![0.0; 5 * n];
        let mut out = Vec::with_capacity(self.s.len().saturating_sub(1));
        for k in 0..self.s.len() - 1 {
            let (piece, _) = self.locate(self.s[k]);
            let inner = if matches!(self.path.pieces[piece], Piece::Arc { .. }) { between } else { 0 };
            let (mut rv, mut ra): (Real, Real) = (0.0, 0.0);
            for i in 0..=inner + 1 {
                let t = self.time[k] + (self.time[k + 1] - self.time[k]) * i as Real / (inner + 1) as Real;
                let (q, rest) = scratch.split_at_mut(n);
                let (qd, rest) = rest.split_at_mut(n);
                let (qdd, rest) = rest.split_at_mut(n);
                self.state_with(k, t, q, qd, qdd, rest);
                for j in 0..n {
                    rv = rv.max(qd[j].abs() / limits.velocity[j]);
                    ra = ra.max(qdd[j].abs() / limits.acceleration[j]);
                }
            }
            out.push((rv, ra));
        }
        out
    }

    /// Slows the whole timing by `factor` ≥ 1: every time ×factor, every speed ÷factor.
    fn slow_down(&mut self, factor: Real) {
        for t in &mut self.time {
            *t *= factor;
        }
        for v in &mut self.speed {
            *v /= factor;
        }
    }
}

/// Evaluates a [`BlendedPath`] for `copp`.
struct Evaluator {
    path: BlendedPath,
    starts: Vec<Real>,
}

impl PathEvaluator2nd for Evaluator {
    fn dim(&self) -> usize {
        self.path.dof()
    }

    fn evaluate_up_to_2nd(
        &self,
        s: &[f64],
        q: &mut [f64],
        dq: &mut [f64],
        ddq: &mut [f64],
    ) -> std::result::Result<(), PathError> {
        let n = self.dim();
        for (c, &sc) in s.iter().enumerate() {
            let (i, u) = self.path.locate(&self.starts, sc);
            let r = c * n..(c + 1) * n;
            self.path.pieces[i].evaluate(u, &mut q[r.clone()], &mut dq[r.clone()], &mut ddq[r]);
        }
        Ok(())
    }
}

/// Times `path` time-optimally within `limits` scaled by `settings` (module docs), at rest at its
/// ends and stops.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `limits…` or a setting ([`JointLimits::validate`],
/// [`TimingSettings::validate`]); [`Error::Numerical`] when the parameterization finds no
/// feasible profile (it always exists for positive limits; a failure is the solver's).
pub fn time_path(path: &BlendedPath, limits: &JointLimits, settings: &TimingSettings) -> Result<Timing> {
    let n = path.dof();
    limits.validate(n)?;
    settings.validate()?;
    let scaled = JointLimits {
        velocity: limits.velocity.iter().map(|v| v * settings.velocity_scaling).collect(),
        acceleration: limits.acceleration.iter().map(|a| a * settings.acceleration_scaling).collect(),
    };
    let starts = path.starts();
    let total = starts.last().copied().unwrap_or(0.0) + path.pieces.last().map_or(0.0, Piece::length);
    let step = settings.station_step.max(total / MAX_STATIONS as Real);
    // Stations: every piece boundary, and points `step` apart within each piece (arcs at least 8
    // intervals, so that the curvature is seen).
    let mut s = vec![0.0];
    let mut stop_stations = vec![0usize];
    for (i, p) in path.pieces.iter().enumerate() {
        // An arc's derivatives turn between stations: at most ARC_STEP radians of it apart.
        let min = match p {
            Piece::Arc { angle, .. } => ((angle / ARC_STEP).ceil() as usize).max(8),
            // Two at least: the parameterization needs two intervals between stops.
            Piece::Line { .. } => 2,
        };
        let count = ((p.length() / step).ceil() as usize).max(min);
        for c in 1..count {
            s.push(starts[i] + p.length() * c as Real / count as Real);
        }
        // Exactly the next piece's start (as `starts` sums them), so that the station interval
        // after it is located on the next piece.
        s.push(starts[i] + p.length());
        if path.stop_after[i] {
            stop_stations.push(s.len() - 1);
        }
    }
    let evaluator = Evaluator { path: path.clone(), starts: starts.clone() };
    let copp_path = Path::from_shared_evaluator_2nd(Arc::new(evaluator), 0.0, total)
        .map_err(|e| Error::Numerical(format!("trajectory path: {e}")))?;
    let stations = s.len();
    let fail = |e: copp::diag::CoppError| Error::Numerical(format!("time parameterization: {e}"));
    let options = ReachSet2OptionsBuilder::new().build().map_err(fail)?;
    // Per station, factors on its velocity and acceleration limits: 1, then lowered where the
    // motion between it and the next station exceeds a limit (an arc's derivatives turn between
    // stations, which bound them only at their own points).
    let mut scale = vec![(1.0, 1.0); stations];
    let mut timing =
        Timing { path: path.clone(), s: s.clone(), speed: vec![0.0; stations], time: vec![0.0; stations], starts };
    // The limits of stations `k..k + run`, scaled by their factors.
    let set_limits = |robot: &mut Robot<usize>, k: usize, run: usize, (fv, fa): (Real, Real)| -> Result<()> {
        let v: Vec<Real> = scaled.velocity.iter().map(|x| x * fv).collect();
        let a: Vec<Real> = scaled.acceleration.iter().map(|x| x * fa).collect();
        let (lv, la): (Vec<Real>, Vec<Real>) = (v.iter().map(|x| -x).collect(), a.iter().map(|x| -x).collect());
        robot
            .with_axial_velocity((v.as_slice(), run), (lv.as_slice(), run), k)
            .map_err(|e| fail(e.into()))?
            .with_axial_acceleration((a.as_slice(), run), (la.as_slice(), run), k)
            .map_err(|e| fail(e.into()))?;
        Ok(())
    };
    for round in 0..=MAX_LIMIT_ROUNDS {
        // The constraints, built anew each round (a run of stations with the same factors in
        // one call: setting one station at a time costs more than the build).
        let mut robot = Robot::with_capacity(n, stations);
        robot
            .with_s(s.as_slice())
            .map_err(|e| fail(e.into()))?
            .with_q_from_path_2nd(&copp_path, 0, stations)
            .map_err(fail)?;
        let mut k = 0;
        while k < stations {
            let run = scale[k..].iter().take_while(|f| **f == scale[k]).count();
            set_limits(&mut robot, k, run, scale[k])?;
            k += run;
        }
        for w in stop_stations.windows(2) {
            let problem = Topp2ProblemBuilder::new(&robot, (w[0], w[1]), (0.0, 0.0)).build().map_err(fail)?;
            let a = topp2_ra(&problem, &options).map_err(fail)?;
            for (k, v) in a.iter().enumerate() {
                timing.speed[w[0] + k] = v.max(0.0).sqrt();
            }
        }
        for k in 1..stations {
            let v = timing.speed[k - 1] + timing.speed[k];
            timing.time[k] = timing.time[k - 1] + if v > 0.0 { 2.0 * (s[k] - s[k - 1]) / v } else { 0.0 };
        }
        let ratios = timing.interval_ratios(&scaled, ARC_CHECKS);
        let over: Vec<usize> = (0..ratios.len()).filter(|&k| ratios[k].0 > WITHIN || ratios[k].1 > WITHIN).collect();
        if over.is_empty() {
            break;
        }
        if round == MAX_LIMIT_ROUNDS {
            // What is left over: the whole timing slowed to the limits.
            let worst = ratios.iter().fold(0.0, |m: Real, r| m.max(r.0).max(r.1.sqrt()));
            timing.slow_down(worst / LIMIT_TARGET);
            break;
        }
        for k in over {
            let (rv, ra) = ratios[k];
            let f = &mut scale[k];
            if rv > WITHIN {
                f.0 *= LIMIT_TARGET / rv;
            }
            if ra > WITHIN {
                f.1 *= LIMIT_TARGET / ra;
            }
        }
    }
    Ok(timing)
}

/// Rounds of lowering the limits at the stations whose intervals exceed them before the rest is
/// taken by slowing the whole timing ([`time_path`]).
const MAX_LIMIT_ROUNDS: usize = 2;
/// Most angle (radians) of an arc between two stations.
const ARC_STEP: Real = 0.02;
/// The fraction of a limit the timed motion keeps within between stations: a margin for the
/// points between the ones checked.
const LIMIT_TARGET: Real = 1.0 - 1e-5;
/// A ratio to a limit taken as within it (the parameterization meets its limits to rounding).
const WITHIN: Real = 1.0 + 1e-9;
/// Points checked inside each station interval on an arc.
const ARC_CHECKS: usize = 8;
