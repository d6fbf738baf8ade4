//! Timed trajectories: a path of waypoints turned into positions, velocities and accelerations
//! in time that a controller can execute, at rest at both ends, within the joints' velocity and
//! acceleration limits, on geometry proven free.
//!
//! ```text
//! waypoints    w₀ … w_m (joint space), consecutive repeats dropped
//! blend        every corner wᵢ replaced by a circular arc tangent to both segments, at most
//!              `max_deviation[i]` from the corner (joint-space distance) and using at most half
//!              of either segment (Kunz and Stilman, "Time-optimal trajectory generation for path
//!              following with bounded acceleration and velocity", RSS 2012, §IV); a corner of
//!              deviation 0 (or a reversal) is a stop: the robot comes to rest there
//! certify      every arc proven free with the path's straight pieces (sub-segments of edges
//!              already certified): the arc as chords, each proven free in a tube that holds the
//!              arc ([`Validity::certify_tube`]); an arc that cannot be proven is tightened
//!              (its deviation quartered), down to a stop                    [`certify_blends`]
//! time         time-optimal path parameterization by reachability analysis (TOPP-RA, Pham and
//!              Pham, IEEE T-RO 2018, through the `copp` crate) on stations along the path:
//!              |q'ⱼ(s) ṡ| ≤ vⱼ, |q'ⱼ(s) s̈ + q''ⱼ(s) ṡ²| ≤ aⱼ, ṡ = 0 at both ends and at every stop
//! sample       s(t) between stations with s̈ constant (the parameterization's own model), then
//!              q = q(s), q̇ = q'(s) ṡ, q̈ = q''(s) ṡ² + q'(s) s̈; where a sample on an arc exceeds a
//!              limit (the stations bound it only at their own points), the whole timing is slowed
//!              by the factor that brings it within (velocities scale as 1/k, accelerations 1/k²)
//! ```
//!
//! The trajectory follows the blended path exactly (`q(s(t))` stays on it), so the geometry it
//! sweeps is the path's, and every piece of the path is proven free before it is timed.

use crate::validity::{Certificate, Validity};
use copp::diag::PathError;
use copp::path::{Path, PathEvaluator2nd};
use copp::robot::Robot;
use copp::solver::topp2_ra::{topp2_ra, ReachSet2OptionsBuilder, Topp2ProblemBuilder};
use std::sync::Arc;
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

/// The deviation (joint-space distance, radians or meters) a corner's blend may take from the
/// corner by default: MoveIt's time-optimal trajectory generation's `path_tolerance`.
pub const DEFAULT_MAX_DEVIATION: Real = 0.1;

/// Path length (joint-space distance) between two stations of the parameterization by default.
pub const DEFAULT_STATION_STEP: Real = 0.01;

/// Most points a sampled trajectory may hold (a `sample_dt` that would give more is refused).
pub const MAX_TRAJECTORY_POINTS: usize = 1_000_000;

/// Most stations one parameterization may use: a longer path takes longer steps.
pub const MAX_STATIONS: usize = 20_000;

/// Angle (radians) below which two segments are taken as one straight line (no blend needed).
const STRAIGHT: Real = 1e-9;
/// Angle past which a corner is a reversal: the robot stops there (a blend would be a point).
const REVERSAL: Real = std::f64::consts::PI - 1e-6;
/// Segments shorter than this (joint-space distance) are dropped: repeated waypoints.
const REPEAT: Real = 1e-12;

/// Velocity and acceleration limits of the configuration entries (radians or meters per second,
/// per second squared), one per entry, each finite and > 0.
#[derive(Clone, Debug, PartialEq)]
pub struct JointLimits {
    /// Most speed of each entry.
    pub velocity: Vec<Real>,
    /// Most acceleration of each entry.
    pub acceleration: Vec<Real>,
}

impl JointLimits {
    /// Checks the limits for a configuration of `dof` entries.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `limits.velocity` / `limits.acceleration` (a length
    /// other than `dof`) or the entry (`limits.velocity[k]`) that is not finite and > 0.
    pub fn validate(&self, dof: usize) -> Result<()> {
        for (name, values) in [("velocity", &self.velocity), ("acceleration", &self.acceleration)] {
            if values.len() != dof {
                return Err(Error::invalid(
                    format!("limits.{name}"),
                    format!("{} values for {dof} configuration entries", values.len()),
                ));
            }
            if let Some(k) = values.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(Error::invalid(
                    format!("limits.{name}[{k}]"),
                    format!("must be finite and > 0, got {}", values[k]),
                ));
            }
        }
        Ok(())
    }
}

/// Settings of [`time_path`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimingSettings {
    /// Factor in (0, 1] on every velocity limit (MoveIt's `max_velocity_scaling_factor`).
    pub velocity_scaling: Real,
    /// Factor in (0, 1] on every acceleration limit (`max_acceleration_scaling_factor`).
    pub acceleration_scaling: Real,
    /// Path length between stations (joint-space distance, > 0); fewer stations on a long path
    /// past [`MAX_STATIONS`].
    pub station_step: Real,
}

impl Default for TimingSettings {
    fn default() -> Self {
        Self { velocity_scaling: 1.0, acceleration_scaling: 1.0, station_step: DEFAULT_STATION_STEP }
    }
}

impl TimingSettings {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `velocity_scaling` / `acceleration_scaling` (outside
    /// (0, 1]) or `station_step` (not finite and > 0).
    pub fn validate(&self) -> Result<()> {
        for (name, v) in
            [("velocity_scaling", self.velocity_scaling), ("acceleration_scaling", self.acceleration_scaling)]
        {
            if !(v > 0.0 && v <= 1.0) {
                return Err(Error::invalid(name, format!("must be in (0, 1], got {v}")));
            }
        }
        if !(self.station_step.is_finite() && self.station_step > 0.0) {
            return Err(Error::invalid("station_step", format!("must be finite and > 0, got {}", self.station_step)));
        }
        Ok(())
    }
}

/// One piece of a [`BlendedPath`], parameterized by arc length `u ∈ [0, length]`.
#[derive(Clone, Debug, PartialEq)]
pub enum Piece {
    /// `q(u) = from + u·direction`, `direction` a unit vector.
    Line {
        /// Its first configuration.
        from: Vec<Real>,
        /// Unit direction.
        direction: Vec<Real>,
        /// Its length.
        length: Real,
    },
    /// `q(u) = center + radius·(x cos θ + y sin θ)`, `θ = u / radius ∈ [0, angle]`, with `x`, `y`
    /// orthonormal: the blend of corner `corner` (the index of its waypoint).
    Arc {
        /// The arc's center.
        center: Vec<Real>,
        /// Unit vector from the center to the arc's first configuration.
        x: Vec<Real>,
        /// Unit tangent at the arc's first configuration (the incoming segment's direction).
        y: Vec<Real>,
        /// Radius (> 0).
        radius: Real,
        /// Angle turned (radians, in (0, π)).
        angle: Real,
        /// The waypoint whose corner it blends.
        corner: usize,
    },
}

impl Piece {
    /// Its arc length.
    pub fn length(&self) -> Real {
        match self {
            Piece::Line { length, .. } => *length,
            Piece::Arc { radius, angle, .. } => radius * angle,
        }
    }

    /// `q(u)`, `q'(u)` and `q''(u)` written into the three slices (the robot's length each).
    pub fn evaluate(&self, u: Real, q: &mut [Real], dq: &mut [Real], ddq: &mut [Real]) {
        match self {
            Piece::Line { from, direction, .. } => {
                for k in 0..from.len() {
                    q[k] = from[k] + u * direction[k];
                    dq[k] = direction[k];
                    ddq[k] = 0.0;
                }
            }
            Piece::Arc { center, x, y, radius, .. } => {
                let (sin, cos) = (u / radius).sin_cos();
                for k in 0..center.len() {
                    let radial = x[k] * cos + y[k] * sin;
                    q[k] = center[k] + radius * radial;
                    dq[k] = -x[k] * sin + y[k] * cos;
                    ddq[k] = -radial / radius;
                }
            }
        }
    }

    /// The configuration at `u`.
    pub fn at(&self, u: Real) -> Vec<Real> {
        let n = match self {
            Piece::Line { from, .. } => from.len(),
            Piece::Arc { center, .. } => center.len(),
        };
        let (mut q, mut dq, mut ddq) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        self.evaluate(u, &mut q, &mut dq, &mut ddq);
        q
    }
}

/// A path of straight pieces and circular blends, continuous in position and, except at its
/// stops, in direction (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct BlendedPath {
    /// Its pieces in order.
    pub pieces: Vec<Piece>,
    /// Per piece, whether the robot comes to rest at its end (always for the last piece).
    pub stop_after: Vec<bool>,
    /// The waypoints it was made from, consecutive repeats dropped.
    pub waypoints: Vec<Vec<Real>>,
    /// The deviation each waypoint's corner was given (0 at both ends and at stops).
    pub deviation: Vec<Real>,
}

impl BlendedPath {
    /// The path through `waypoints` with every interior corner blended within `max_deviation`
    /// (≥ 0; 0 stops at every waypoint).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `path` (fewer than two distinct waypoints), `path[i]`
    /// (a waypoint of another length than the first, or not finite), or `max_deviation`.
    pub fn new(waypoints: &[Vec<Real>], max_deviation: Real) -> Result<Self> {
        if !(max_deviation.is_finite() && max_deviation >= 0.0) {
            return Err(Error::invalid("max_deviation", format!("must be finite and ≥ 0, got {max_deviation}")));
        }
        let points = distinct(waypoints)?;
        let deviation = (0..points.len())
            .map(|i| if i == 0 || i + 1 == points.len() { 0.0 } else { max_deviation })
            .collect::<Vec<_>>();
        Ok(Self::with_deviations(points, deviation))
    }

    /// The path through `points` (distinct consecutive waypoints) with corner `i` blended within
    /// `deviation[i]`.
    fn with_deviations(points: Vec<Vec<Real>>, mut deviation: Vec<Real>) -> Self {
        let m = points.len();
        let n = points[0].len();
        let direction = |i: usize| -> (Vec<Real>, Real) {
            let d: Vec<Real> = (0..n).map(|k| points[i + 1][k] - points[i][k]).collect();
            let len = norm(&d);
            (d.iter().map(|v| v / len).collect(), len)
        };
        let segments: Vec<(Vec<Real>, Real)> = (0..m - 1).map(direction).collect();
        // Per corner: (blend distance ℓ along each segment, the arc), or a stop / straight.
        let mut blends: Vec<Option<(Real, Piece)>> = vec![None; m];
        let mut stop = vec![false; m];
        for i in 1..m - 1 {
            let (y1, len1) = &segments[i - 1];
            let (y2, len2) = &segments[i];
            let cos = dot(y1, y2).clamp(-1.0, 1.0);
            let alpha = cos.acos();
            if alpha < STRAIGHT {
                deviation[i] = 0.0;
                continue;
            }
            if deviation[i] <= 0.0 || alpha > REVERSAL {
                deviation[i] = 0.0;
                stop[i] = true;
                continue;
            }
            let half = alpha / 2.0;
            let ell = (len1 / 2.0).min(len2 / 2.0).min(deviation[i] * half.sin() / (1.0 - half.cos()));
            let radius = ell / half.tan();
            let bisector: Vec<Real> = (0..n).map(|k| y2[k] - y1[k]).collect();
            let bn = norm(&bisector);
            let center: Vec<Real> = (0..n).map(|k| points[i][k] + bisector[k] / bn * radius / half.cos()).collect();
            let start: Vec<Real> = (0..n).map(|k| points[i][k] - ell * y1[k]).collect();
            let x: Vec<Real> = (0..n).map(|k| (start[k] - center[k]) / radius).collect();
            // The deviation the blend actually takes (ℓ may be capped by half a segment).
            deviation[i] = radius * (1.0 / half.cos() - 1.0);
            blends[i] = Some((ell, Piece::Arc { center, x, y: y1.clone(), radius, angle: alpha, corner: i }));
        }
        let mut pieces = Vec::new();
        let mut stop_after = Vec::new();
        for (i, (y, len)) in segments.iter().enumerate() {
            let cut0 = blends[i].as_ref().map_or(0.0, |b| b.0);
            let cut1 = blends[i + 1].as_ref().map_or(0.0, |b| b.0);
            let length = len - cut0 - cut1;
            if length > REPEAT * len.max(1.0) {
                let from = (0..n).map(|k| points[i][k] + cut0 * y[k]).collect();
                pieces.push(Piece::Line { from, direction: y.clone(), length });
                stop_after.push(stop[i + 1] || i + 2 == m);
            } else if let Some(last) = stop_after.last_mut() {
                *last |= stop[i + 1] || i + 2 == m;
            }
            if let Some((_, arc)) = &blends[i + 1] {
                pieces.push(arc.clone());
                stop_after.push(false);
            }
        }
        if let Some(last) = stop_after.last_mut() {
            *last = true;
        }
        Self { pieces, stop_after, waypoints: points, deviation }
    }

    /// Its total length (joint-space distance).
    pub fn length(&self) -> Real {
        self.pieces.iter().map(Piece::length).sum()
    }

    /// The number of configuration entries.
    pub fn dof(&self) -> usize {
        self.waypoints[0].len()
    }

    /// The arcs (blends) of the path, with their index in [`BlendedPath::pieces`].
    pub fn arcs(&self) -> impl Iterator<Item = (usize, &Piece)> {
        self.pieces.iter().enumerate().filter(|(_, p)| matches!(p, Piece::Arc { .. }))
    }
}

/// `waypoints` with consecutive repeats dropped, checked.
fn distinct(waypoints: &[Vec<Real>]) -> Result<Vec<Vec<Real>>> {
    let Some(first) = waypoints.first() else {
        return Err(Error::invalid("path", "no waypoint: a path needs at least two"));
    };
    let n = first.len();
    if n == 0 {
        return Err(Error::invalid("path[0]", "a waypoint has no entry"));
    }
    let mut out: Vec<Vec<Real>> = Vec::with_capacity(waypoints.len());
    for (i, w) in waypoints.iter().enumerate() {
        if w.len() != n {
            return Err(Error::invalid(format!("path[{i}]"), format!("{} values where path[0] has {n}", w.len())));
        }
        if let Some(k) = w.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("path[{i}][{k}]"), format!("{} is not a finite number", w[k])));
        }
        let repeat = out.last().is_some_and(|last| {
            let d: Vec<Real> = (0..n).map(|k| w[k] - last[k]).collect();
            norm(&d) <= REPEAT * norm(last).max(1.0)
        });
        if !repeat {
            out.push(w.clone());
        }
    }
    if out.len() < 2 {
        return Err(Error::invalid(
            "path",
            format!("{} waypoints, all the same configuration: a path needs two distinct ones", waypoints.len()),
        ));
    }
    Ok(out)
}

fn dot(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[Real]) -> Real {
    dot(a, a).sqrt()
}

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
fn arc_free(checker: &mut dyn Validity, arc: &Piece, tolerance: Real) -> Result<bool> {
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
        let i = self.starts.partition_point(|&a| a <= s).saturating_sub(1).min(self.path.pieces.len() - 1);
        (i, (s - self.starts[i]).clamp(0.0, self.path.pieces[i].length()))
    }

    /// As [`Timing::locate`] for a point of the station interval starting at `from`: the piece
    /// that holds the interval (a station interval never spans two pieces).
    fn locate_in(&self, s: Real, from: Real) -> (usize, Real) {
        let (i, _) = self.locate(from);
        (i, (s - self.starts[i]).clamp(0.0, self.path.pieces[i].length()))
    }

    /// The state at time `t` (clamped to [0, duration]): position, velocity, acceleration.
    pub fn state(&self, t: Real, q: &mut [Real], qd: &mut [Real], qdd: &mut [Real]) {
        let t = t.clamp(0.0, self.duration());
        let k = self.time.partition_point(|&a| a <= t).saturating_sub(1).min(self.s.len() - 2);
        self.state_in(k, t, q, qd, qdd);
    }

    /// The state at time `t` by the motion of station interval `k` (its own constant s̈, so that
    /// `t` at the interval's end gives the limit from inside it).
    fn state_in(&self, k: usize, t: Real, q: &mut [Real], qd: &mut [Real], qdd: &mut [Real]) {
        let mut scratch = vec![0.0; 2 * q.len()];
        self.state_with(k, t, q, qd, qdd, &mut scratch);
    }

    /// [`Timing::state_in`] with `scratch` (at least twice the robot's length) for the path's
    /// derivatives.
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
        for &t in &times {
            let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            self.state(t, &mut q, &mut qd, &mut qdd);
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

    /// The largest ratio of a speed or acceleration to its limit over the stations and `between`
    /// points inside each station interval (≤ 1 within the limits): `(velocity, acceleration)`.
    pub fn worst_ratios(&self, limits: &JointLimits, between: usize) -> (Real, Real) {
        self.interval_ratios(limits, between).iter().fold((0.0, 0.0), |(v, a), r| (v.max(r.0), a.max(r.1)))
    }

    /// Per station interval, the largest ratio of a speed and of an acceleration to its limit
    /// at its ends and, on an arc, at `between` points inside it (as [`Timing::worst_ratios`]).
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
            let i = self.starts.partition_point(|&a| a <= sc).saturating_sub(1).min(self.path.pieces.len() - 1);
            let u = (sc - self.starts[i]).clamp(0.0, self.path.pieces[i].length());
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
    let mut starts = Vec::with_capacity(path.pieces.len());
    let mut total = 0.0;
    for p in &path.pieces {
        starts.push(total);
        total += p.length();
    }
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

/// The velocity and acceleration limits of `model`'s configuration entries: `velocity[name]` /
/// `acceleration[name]` (the request's and its `joint_limits.yaml`'s, merged by the caller),
/// else the URDF's `<limit velocity>`, else [`DEFAULT_VELOCITY_LIMIT`] and
/// [`DEFAULT_ACCELERATION_LIMIT`] (MoveIt's defaults), with one warning per joint of `moving`
/// that took a default. A mimic entry takes its own joint's limits.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `max_velocity[NAME]` / `max_acceleration[NAME]` for a value
/// that is not finite and > 0, or a name that is not a configuration entry.
pub fn joint_limits(
    model: &sublevel_robot::RobotModel,
    velocity: &std::collections::BTreeMap<String, Real>,
    acceleration: &std::collections::BTreeMap<String, Real>,
    moving: &[bool],
) -> Result<(JointLimits, Vec<String>)> {
    let names = model.variable_names();
    for (field, map) in [("max_velocity", velocity), ("max_acceleration", acceleration)] {
        for (name, &v) in map {
            let shown = sublevel_core::error::clip(name);
            if !names.contains(&name.as_str()) {
                return Err(Error::invalid(format!("{field}[{shown}]"), "not a moving joint of the robot"));
            }
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{field}[{shown}]"), format!("must be finite and > 0, got {v}")));
            }
        }
    }
    let mut limits = JointLimits { velocity: Vec::with_capacity(names.len()), acceleration: Vec::new() };
    let mut warnings = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let joint = model.variable_joint(k);
        let v = velocity.get(*name).copied().or(joint.max_velocity);
        let a = acceleration.get(*name).copied();
        let m = moving.get(k).copied().unwrap_or(true);
        if m && v.is_none() {
            warnings.push(format!(
                "limits.velocity[{name}]: the joint has no velocity limit (URDF or joint_limits); took {DEFAULT_VELOCITY_LIMIT} per second"
            ));
        }
        if m && a.is_none() {
            warnings.push(format!(
                "limits.acceleration[{name}]: the joint has no acceleration limit (joint_limits); took {DEFAULT_ACCELERATION_LIMIT} per second squared"
            ));
        }
        limits.velocity.push(v.unwrap_or(DEFAULT_VELOCITY_LIMIT));
        limits.acceleration.push(a.unwrap_or(DEFAULT_ACCELERATION_LIMIT));
    }
    Ok((limits, warnings))
}

/// The first edge `path[i] → path[i+1]` not proven free by `checker` at contact `tolerance`
/// (nor at a hundredth of it, as a plan's certificates: [`crate::certificate_tolerance`]), with
/// its certificate; `None` when every edge is proven. A path from another planner is checked so
/// before it is timed.
///
/// # Errors
/// The checker's errors (a malformed configuration names its field).
pub fn first_unproven_edge(
    checker: &mut dyn Validity,
    path: &[Vec<Real>],
    tolerance: Real,
) -> Result<Option<(usize, Certificate)>> {
    for (i, w) in path.windows(2).enumerate() {
        let first = checker.certify(&w[0], &w[1], tolerance)?;
        if first == Certificate::Free {
            continue;
        }
        let second = checker.certify(&w[0], &w[1], crate::certify::certificate_tolerance(tolerance))?;
        if second != Certificate::Free {
            return Ok(Some((i, second)));
        }
    }
    Ok(None)
}

/// Velocity limit of a joint that has none (radians or meters per second): MoveIt's default.
pub const DEFAULT_VELOCITY_LIMIT: Real = 1.0;
/// Acceleration limit of a joint that has none (per second squared): MoveIt's default.
pub const DEFAULT_ACCELERATION_LIMIT: Real = 1.0;

/// What [`timed_trajectory`] is asked.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryRequest {
    /// The limits (unscaled).
    pub limits: JointLimits,
    /// Scaling and stations.
    pub timing: TimingSettings,
    /// Seconds between points (> 0).
    pub sample_dt: Real,
    /// Most deviation of a blend from its corner (≥ 0; 0 stops at every waypoint).
    pub max_deviation: Real,
}

/// Seconds between a trajectory's points by default.
pub const DEFAULT_SAMPLE_DT: Real = 0.01;

/// A timed, certified trajectory of a path ([`timed_trajectory`]).
#[derive(Clone, Debug)]
pub struct TimedTrajectory {
    /// The sampled trajectory.
    pub trajectory: Trajectory,
    /// The limits it was timed within, scaling applied.
    pub limits: JointLimits,
    /// How its blends were proven.
    pub blends: BlendCertificate,
    /// Corners where it stops (reversals, unproven blends and deviation 0 included).
    pub stops: usize,
    /// Seconds the stage took.
    pub seconds: Real,
    /// Of which: blending and proving the blends, timing, sampling.
    pub stage_seconds: [Real; 3],
}

/// Blends `path`'s corners, proves the blends free with `checker` at contact `tolerance`
/// ([`certify_blends`]), times the result ([`time_path`]) and samples it every
/// `request.sample_dt` seconds. The straight pieces are parts of `path`'s edges: the timed
/// geometry is proven free when `path`'s edges are. A continuous joint moves the shorter way
/// round between waypoints, as the edges do, so its positions are unwrapped: they may leave
/// (−π, π] and end a whole turn from the last waypoint's value.
///
/// # Errors
/// As [`BlendedPath::new`], [`time_path`], [`Timing::sample`], and the checker's.
pub fn timed_trajectory(
    checker: &mut dyn Validity,
    path: &[Vec<Real>],
    request: &TrajectoryRequest,
    tolerance: Real,
) -> Result<TimedTrajectory> {
    let clock = std::time::Instant::now();
    request.limits.validate(path.first().map_or(0, Vec::len))?;
    request.timing.validate()?;
    if !(request.sample_dt.is_finite() && request.sample_dt > 0.0) {
        return Err(Error::invalid("sample_dt", format!("must be finite and > 0 s, got {}", request.sample_dt)));
    }
    // Continuous joints the shorter way round, as the path's edges were certified: each
    // waypoint's wrapped entries unwrapped from the one before.
    let space = checker.space().clone();
    let mut unwrapped: Vec<Vec<Real>> = Vec::with_capacity(path.len());
    for w in path {
        let mut w = w.clone();
        if let Some(previous) = unwrapped.last() {
            for (k, v) in w.iter_mut().enumerate() {
                if space.wraps.get(k).copied().unwrap_or(false) {
                    *v = previous[k] + space.delta(k, previous[k], *v);
                }
            }
        }
        unwrapped.push(w);
    }
    let blended = BlendedPath::new(&unwrapped, request.max_deviation)?;
    let blends = certify_blends(checker, &blended, tolerance)?;
    let certified = clock.elapsed().as_secs_f64();
    let timing = time_path(&blends.path, &request.limits, &request.timing)?;
    let timed = clock.elapsed().as_secs_f64();
    let trajectory = timing.sample(Some(request.sample_dt))?;
    let seconds = clock.elapsed().as_secs_f64();
    let stops = blends.path.stop_after.iter().filter(|&&s| s).count().saturating_sub(1);
    let limits = JointLimits {
        velocity: request.limits.velocity.iter().map(|v| v * request.timing.velocity_scaling).collect(),
        acceleration: request.limits.acceleration.iter().map(|a| a * request.timing.acceleration_scaling).collect(),
    };
    Ok(TimedTrajectory {
        trajectory,
        limits,
        blends,
        stops,
        seconds,
        stage_seconds: [certified, timed - certified, seconds - timed],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
                    assert!(
                        qd[j].abs() <= lim.velocity[j] * (1.0 + 1e-6),
                        "deviation {deviation}, point {i}: v {qd:?}"
                    );
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
}
