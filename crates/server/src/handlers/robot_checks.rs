//! The robot checks of `CheckConfigurations` and `CheckMotions` (and of a query stream's
//! requests): on prepared checkers ([`super::prepared`]), in chunks on the batch slots.
//!
//! Configurations are decoded once into one row-major vector and checked in blocks
//! ([`RobotChecker::check_block`]); motions are certified by conservative advancement
//! ([`MotionChecker`]) or, with a resolution, sampled ([`RobotChecker::rake_motion`]).

use super::prepared::{Asked, Prepared};
use super::robots::{chunks, RobotChecks};
use super::HandlerError;
use crate::convert as cv;
use crate::pb;
use crate::runtime::blocking;
use crate::{Error, Result};
use futures_util::future::try_join_all;
use std::ops::Range;
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{
    CheckOptions, ConfigurationAnswer, JointKind, MotionAnswer, MotionChecker, RobotChecker, RobotModel,
};

/// Most configurations whose verdicts (no distance) are answered inline on the async worker
/// (microseconds each on a prepared checker, as small query requests are), saving the two
/// hand-offs to the batch slots that would cost more than the check.
const INLINE_CONFIGURATIONS: usize = 4;

/// `e` with the index of a `configurations[i]` field moved on by `start` (a chunk's errors name
/// its own rows).
fn shift_configuration(e: Error, start: usize) -> Error {
    match e {
        Error::InvalidArgument { field, reason } if start > 0 => {
            let shifted = field
                .strip_prefix("configurations[")
                .and_then(|rest| rest.split_once(']'))
                .and_then(|(i, rest)| Some(format!("configurations[{}]{rest}", i.parse::<usize>().ok()? + start)));
            Error::InvalidArgument { field: shifted.unwrap_or(field), reason }
        }
        other => other,
    }
}

/// `b` moved by whole turns of its continuous joints to within half a turn of `a` (the shorter
/// way, as [`MotionChecker`] interpolates); the other entries are `b`'s own.
fn shorter_way(model: &RobotModel, a: &[Real], b: &[Real]) -> Vec<Real> {
    use std::f64::consts::PI;
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(k, (&x, &y))| {
            if model.variable_joint(k).kind == JointKind::Continuous {
                let w = (y - x).rem_euclid(2.0 * PI);
                x + if w > PI { w - 2.0 * PI } else { w }
            } else {
                y
            }
        })
        .collect()
}

/// The sampled check of the motion `a → b` at `resolution` (> 0): its answer (the colliding
/// sample's configuration and pair from a check of it) and the samples it took.
///
/// # Errors
/// As [`RobotChecker::rake_motion`] and [`RobotChecker::check`].
fn sampled(
    checker: &mut RobotChecker<'_>,
    a: &[Real],
    b: &[Real],
    resolution: Real,
    base: &Isometry3,
    padding: Real,
) -> Result<(MotionAnswer, usize)> {
    let b = shorter_way(&checker.robot().model, a, b);
    let rake = checker.rake_motion(a, &b, resolution, base, padding)?;
    let mut answer = MotionAnswer {
        valid: rake.collision.is_none(),
        decided: true,
        contact: rake.collision,
        contact_q: None,
        pair: None,
        self_pair: None,
        steps: 0,
    };
    if let Some(t) = rake.collision {
        // The sample's configuration, as the rake computed it, and its pair.
        let q: Vec<Real> = a.iter().zip(&b).map(|(x, y)| x + t * (y - x)).collect();
        let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        let check = checker.check(&q, base, &options)?;
        if check.world {
            answer.pair = check.pair.map(|(g, o)| (g, Some(o)));
        } else if check.self_collision {
            answer.self_pair = check.self_pair;
            answer.pair = check.self_pair.map(|(x, _)| (x, None));
        }
        answer.contact_q = Some(q);
    }
    Ok((answer, rake.samples))
}

impl RobotChecks {
    /// The prepared setting of `asked` ([`super::prepared::PreparedCheckers::get`]): read inline
    /// when the robot and the scene are in memory ([`RobotChecks::in_memory`]), else off the async
    /// workers.
    pub(super) async fn prepared(&self, asked: Asked) -> Result<Arc<Prepared>, HandlerError> {
        if self.in_memory() {
            Ok(self.prepared.get(&self.catalog, &asked)?)
        } else {
            let (prepared, catalog) = (self.prepared.clone(), self.catalog.clone());
            // The check's own error stays a core error (its field can still be prefixed).
            Ok(blocking(move || Ok(prepared.get(&catalog, &asked))).await??)
        }
    }

    /// Answers a `CheckConfigurationsRequest`, the scene's instances in `poses` moved there:
    /// configurations checked in blocks, in chunks on the batch slots (a few verdicts inline),
    /// answered in columns.
    pub(super) async fn configurations(
        &self,
        mut req: pb::CheckConfigurationsRequest,
        poses: Vec<(String, Isometry3)>,
    ) -> Result<pb::CheckConfigurationsResponse, HandlerError> {
        let padding = cv::padding(req.padding)?;
        let fidelity = cv::fidelity(req.fidelity.as_ref())?;
        let base = req.base.as_ref().map(|b| cv::pose_from_proto("base", Some(b))).transpose()?;
        let asked = Asked::taken(&mut req.robot_id, &mut req.scene_id, &mut req.attached, &mut req.link_padding, poses);
        let prepared = self.prepared(asked).await?;
        let base = base.unwrap_or(prepared.base);
        let configs = Arc::new(cv::configuration_rows(
            "configurations",
            req.configurations.take(),
            &prepared.robot,
            &prepared.world.planning.joint_positions,
        )?);
        let dof = prepared.robot.model.dof().max(1);
        let n = configs.len() / dof;
        let options = CheckOptions {
            padding,
            distance: req.distance || req.gradient,
            self_collision: !req.skip_self,
            gradient: req.gradient,
        };
        let stop = req.stop_at_first_collision;
        let check = move |prepared: &Prepared, configs: &[Real], range: Range<usize>| {
            let mut checker = prepared.take()?;
            let mut out = Vec::with_capacity(range.len());
            let rows = &configs[range.start * dof..range.end * dof];
            checker
                .with_dependent_mut(|_, c| {
                    c.set_fidelity(fidelity)?;
                    c.check_block(rows, &base, &options, stop, &mut out)
                })
                .map_err(|e| shift_configuration(e, range.start))?;
            prepared.put(checker);
            Ok::<Vec<ConfigurationAnswer>, Error>(out)
        };
        // A few verdicts are microseconds: answered inline, as small query requests are; the
        // rest (distances reach the meshes' distance searches) in chunks on the batch slots, or
        // in one chunk, in order, when the check stops at the first collision.
        let answers = if n <= INLINE_CONFIGURATIONS && !options.distance {
            vec![check(&prepared, &configs, 0..n)?]
        } else {
            let slots = if stop { 1 } else { self.slots };
            let work = chunks(n, slots).into_iter().map(|range| {
                let (prepared, configs) = (prepared.clone(), configs.clone());
                self.pools.batch.run(move || Ok(check(&prepared, &configs, range)))
            });
            try_join_all(work).await?.into_iter().collect::<Result<Vec<_>>>()?
        };
        let robot = &prepared.robot;
        let mut out = pb::CheckConfigurationsResponse {
            joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
            scene_version: prepared.world.scene_version,
            ..Default::default()
        };
        for chunk in &answers {
            cv::push_configuration_answers(&mut out, chunk, robot, &prepared.world.objects, req.gradient);
        }
        Ok(out)
    }

    /// Answers a `CheckMotionsRequest`, the scene's instances in `poses` moved there: motions
    /// certified by conservative advancement, or sampled at the request's resolution, in chunks
    /// on the batch slots, answered in columns.
    pub(super) async fn motions(
        &self,
        mut req: pb::CheckMotionsRequest,
        poses: Vec<(String, Isometry3)>,
    ) -> Result<pb::CheckMotionsResponse, HandlerError> {
        let options = cv::motion_options(req.padding, req.tolerance, req.max_steps)?;
        let resolution = cv::resolution(req.resolution)?;
        let base = req.base.as_ref().map(|b| cv::pose_from_proto("base", Some(b))).transpose()?;
        let asked = Asked::taken(&mut req.robot_id, &mut req.scene_id, &mut req.attached, &mut req.link_padding, poses);
        let prepared = self.prepared(asked).await?;
        let base = base.unwrap_or(prepared.base);
        let robot = prepared.robot.clone();
        let defaults = &prepared.world.planning.joint_positions;
        let names = |c: &Option<pb::ConfigurationColumns>| c.as_ref().map(|c| c.joint_names.clone());
        if let (Some(start), Some(end)) = (names(&req.start), names(&req.end)) {
            if start != end {
                return Err(Error::invalid(
                    "end.joint_names",
                    "names other joints than `start.joint_names`: a motion's end names the joints its start names, \
                     in the same order",
                )
                .into());
            }
        }
        let start = cv::configurations_from_proto("start", req.start.as_ref(), &robot, defaults)?;
        let end = cv::configurations_from_proto("end", req.end.as_ref(), &robot, defaults)?;
        if start.len() != end.len() {
            return Err(Error::invalid(
                "end.values",
                format!("{} end configurations for {} start configurations", end.len(), start.len()),
            )
            .into());
        }
        if resolution > 0.0 {
            // Bounded before any work: a resolution that would take too many samples is refused.
            for (m, (a, b)) in start.iter().zip(&end).enumerate() {
                cv::motion_samples(m, a, &shorter_way(&robot.model, a, b), resolution)?;
            }
        }
        let motions = Arc::new((start, end));
        let work = chunks(motions.0.len(), self.slots).into_iter().map(|range| {
            let (prepared, motions) = (prepared.clone(), motions.clone());
            self.pools.batch.run(move || {
                Ok((|| {
                    let mut checker = prepared.take()?;
                    let answers = checker.with_dependent_mut(|_, c| {
                        let at = |m: usize| move |e| cv::prefix_field(e, &format!("motions[{m}]"));
                        if resolution > 0.0 {
                            range
                                .map(|m| {
                                    sampled(c, &motions.0[m], &motions.1[m], resolution, &base, options.padding)
                                        .map_err(at(m))
                                })
                                .collect::<Result<Vec<_>>>()
                        } else {
                            let mut motion = MotionChecker::new(c)?;
                            range
                                .map(|m| {
                                    motion
                                        .check_motion(&motions.0[m], &motions.1[m], &base, &options)
                                        .map(|a| (a, 0))
                                        .map_err(at(m))
                                })
                                .collect::<Result<Vec<_>>>()
                        }
                    })?;
                    prepared.put(checker);
                    Ok(answers)
                })())
            })
        });
        let answers = try_join_all(work).await?.into_iter().collect::<Result<Vec<_>>>()?;
        let mut out = pb::CheckMotionsResponse {
            joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
            scene_version: prepared.world.scene_version,
            ..Default::default()
        };
        for chunk in &answers {
            cv::push_motion_answers(&mut out, chunk, &robot, &prepared.world.objects);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::shift_configuration;
    use crate::Error;

    #[test]
    fn chunk_errors_name_the_requests_rows() {
        let field = |e: Error| match e {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("{other:?}"),
        };
        let e = || Error::invalid("configurations[3].q[2]", "must be finite");
        assert_eq!(field(shift_configuration(e(), 0)), "configurations[3].q[2]");
        assert_eq!(field(shift_configuration(e(), 40)), "configurations[43].q[2]");
        assert_eq!(field(shift_configuration(Error::invalid("padding", "x"), 40)), "padding");
    }
}
