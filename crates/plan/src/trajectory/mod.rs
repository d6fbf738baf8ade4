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
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

mod blend;
mod path;
mod timing;

pub use blend::{certify_blends, BlendCertificate};
pub use path::{BlendedPath, Piece};
pub use timing::{time_path, Timing, Trajectory};

/// The deviation (joint-space distance, radians or meters) a corner's blend may take from the
/// corner by default: MoveIt's time-optimal trajectory generation's `path_tolerance`.
pub const DEFAULT_MAX_DEVIATION: Real = 0.1;

/// Path length (joint-space distance) between two stations of the parameterization by default.
pub const DEFAULT_STATION_STEP: Real = 0.01;

/// Most points a sampled trajectory may hold (a `sample_dt` that would give more is refused).
pub const MAX_TRAJECTORY_POINTS: usize = 1_000_000;

/// Most stations one parameterization may use: a longer path takes longer steps.
pub const MAX_STATIONS: usize = 20_000;

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
mod tests;
