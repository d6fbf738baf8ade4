//! Robots: summaries, configuration columns, and the answers of configuration and motion checks
//! in columns.

use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::Real;
use sublevel_robot::{ConfigurationAnswer, FittedRobot, MotionAnswer, MotionOptions, WorldObject};
use sublevel_scene::{AttachedRecord, PlacedRobot, RobotEntry, StoredPose};

/// Most configurations (or motions) one call may carry.
pub const MAX_CONFIGURATIONS_PER_CALL: usize = 100_000;

/// A stored robot's summary.
pub fn robot_summary(entry: &RobotEntry) -> pb::RobotSummary {
    let model = &entry.robot.model;
    let joints = || (0..model.dof()).map(|k| model.variable_joint(k));
    let mut link_names: Vec<String> = Vec::new();
    for g in &entry.robot.geometries {
        let name = &model.links()[g.link].name;
        if !link_names.contains(name) {
            link_names.push(name.clone());
        }
    }
    pb::RobotSummary {
        robot_id: entry.id.clone(),
        name: entry.name.clone(),
        joint_names: joints().map(|j| j.name.clone()).collect(),
        lower: joints().map(|j| j.limits.map_or(Real::NEG_INFINITY, |l| l.0)).collect(),
        upper: joints().map(|j| j.limits.map_or(Real::INFINITY, |l| l.1)).collect(),
        link_names,
        geometries: entry.robot.geometries.len() as u32,
        self_pairs: entry.robot.self_pairs.len() as u32,
        fit_warnings: entry.robot.file.report.warnings.clone(),
        rigid_pairs: model
            .rigid_pairs_not_in(&entry.robot.file.allowed_pairs)
            .iter()
            .map(|[a, b]| format!("{a} {b}"))
            .collect(),
    }
}

/// Full configurations of `robot` from columns (see [`sublevel_robot::RobotModel::configurations`]);
/// `field` names the columns in errors (`configurations`, `start`, `end`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` when absent, `field.values` beyond
/// [`MAX_CONFIGURATIONS_PER_CALL`] configurations, or as `configurations`.
pub fn configurations_from_proto(
    field: &str,
    columns: Option<&pb::ConfigurationColumns>,
    robot: &FittedRobot,
    defaults: &[(String, Real)],
) -> Result<Vec<Vec<Real>>> {
    let columns = columns.ok_or_else(|| Error::invalid(field, "required: joint names and values"))?;
    let width = if columns.joint_names.is_empty() { robot.model.dof() } else { columns.joint_names.len() };
    if columns.values.len() > MAX_CONFIGURATIONS_PER_CALL * width.max(1) {
        return Err(Error::invalid(
            format!("{field}.values"),
            format!("{} values: at most {MAX_CONFIGURATIONS_PER_CALL} configurations per call", columns.values.len()),
        ));
    }
    robot.model.configurations(field, &columns.joint_names, &columns.values, defaults)
}

/// The configurations of `robot` from columns, row by row in one vector (n × dof reals, the
/// robot's variable order): the request's own values, moved, when its columns are the robot's
/// joints in order (no names, or every name in order) and every value is finite and within its
/// joint's limits ([`sublevel_robot::Joint::admits`]); otherwise [`configurations_from_proto`]'s rows (and its errors), joined.
///
/// # Errors
/// As [`configurations_from_proto`].
pub fn configuration_rows(
    field: &str,
    columns: Option<pb::ConfigurationColumns>,
    robot: &FittedRobot,
    defaults: &[(String, Real)],
) -> Result<Vec<Real>> {
    let columns = columns.ok_or_else(|| Error::invalid(field, "required: joint names and values"))?;
    let model = &robot.model;
    let dof = model.dof();
    let in_order = columns.joint_names.is_empty()
        || (columns.joint_names.len() == dof
            && columns.joint_names.iter().zip(model.variable_names()).all(|(given, name)| given == name));
    let joints: Vec<&sublevel_robot::Joint> = (0..dof).map(|k| model.variable_joint(k)).collect();
    let fits = |(i, v): (usize, &Real)| joints[i % dof].admits(*v);
    if in_order
        && dof > 0
        && !columns.values.is_empty()
        && columns.values.len().is_multiple_of(dof)
        && columns.values.len() <= MAX_CONFIGURATIONS_PER_CALL * dof
        && columns.values.iter().enumerate().all(fits)
    {
        return Ok(columns.values);
    }
    Ok(configurations_from_proto(field, Some(&columns), robot, defaults)?.concat())
}

/// Most samples one motion of a sampled `CheckMotions` may take.
pub const MAX_SAMPLES_PER_MOTION: usize = 100_000;

/// Checks a sampled check's resolution (samples per unit of joint distance; finite, ≥ 0; 0: the
/// certified check).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `resolution`.
pub fn resolution(value: Real) -> Result<Real> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(Error::invalid("resolution", format!("must be finite and >= 0 (0: certified), got {value}")))
    }
}

/// The samples of motion `m` from `a` to `b` at `resolution` (> 0): `max(1, ⌈‖b − a‖ ·
/// resolution⌉)`, as [`sublevel_robot::RobotChecker::rake_motion`] takes them.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `resolution` beyond [`MAX_SAMPLES_PER_MOTION`].
pub fn motion_samples(m: usize, a: &[Real], b: &[Real], resolution: Real) -> Result<usize> {
    let length = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum::<Real>().sqrt();
    let samples = (length * resolution).ceil();
    if samples <= MAX_SAMPLES_PER_MOTION as Real {
        Ok((samples as usize).max(1))
    } else {
        Err(Error::invalid(
            "resolution",
            format!(
                "motion {m} ({length:.3} long in joint space) would take {samples} samples at resolution {resolution}; \
                 at most {MAX_SAMPLES_PER_MOTION} per motion"
            ),
        ))
    }
}

/// The fidelity level of a request's robot checks (`sublevel_robot::fidelity`); absent: mesh.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `fidelity.level` (unknown) or `fidelity.tolerance` (out of
/// range, or given for a level other than spheres).
pub fn fidelity(value: Option<&pb::Fidelity>) -> Result<sublevel_robot::Fidelity> {
    match value {
        Some(f) => sublevel_robot::Fidelity::parse("fidelity", &f.level, Some(f.tolerance)),
        None => Ok(sublevel_robot::Fidelity::Mesh),
    }
}

/// Checks padding (meters, finite, ≥ 0).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `padding`.
pub fn padding(value: Real) -> Result<Real> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(Error::invalid("padding", format!("must be finite and >= 0 m, got {value}")))
    }
}

/// The motion options of a request: `tolerance` 0 → 1 mm, `max_steps` 0 → the default.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `padding` or `tolerance`.
pub fn motion_options(pad: Real, tolerance: Real, max_steps: u32) -> Result<MotionOptions> {
    let defaults = MotionOptions::default();
    let options = MotionOptions {
        padding: padding(pad)?,
        tolerance: if tolerance == 0.0 { defaults.tolerance } else { tolerance },
        max_steps: if max_steps == 0 { defaults.max_steps } else { max_steps as usize },
    };
    options.validate()?;
    Ok(options)
}

/// The link name of geometry `g`.
fn link_of(robot: &FittedRobot, g: usize) -> String {
    robot.model.links()[robot.geometries[g].link].name.clone()
}

/// Appends the answers of configurations to the response columns.
pub fn push_configuration_answers(
    out: &mut pb::CheckConfigurationsResponse,
    answers: &[ConfigurationAnswer],
    robot: &FittedRobot,
    world: &[WorldObject],
    gradient: bool,
) {
    let dof = robot.model.dof();
    for a in answers {
        out.collides.push(a.collides);
        out.world.push(a.world);
        out.self_collision.push(a.self_collision);
        out.distance.push(a.distance);
        match a.pair {
            Some((g, o)) => {
                out.robot_link.push(link_of(robot, g));
                out.robot_geometry.push(robot.geometries[g].name.clone());
                out.world_object.push(world[o].name.clone());
            }
            None => {
                out.robot_link.push(String::new());
                out.robot_geometry.push(String::new());
                out.world_object.push(String::new());
            }
        }
        match a.witnesses {
            Some((x, y)) => out.witnesses.extend([x.x, x.y, x.z, y.x, y.y, y.z]),
            None => out.witnesses.extend([Real::NAN; 6]),
        }
        match a.self_pair.filter(|_| a.self_collision) {
            Some((x, y)) => {
                out.self_link_a.push(link_of(robot, x));
                out.self_link_b.push(link_of(robot, y));
            }
            None => {
                out.self_link_a.push(String::new());
                out.self_link_b.push(String::new());
            }
        }
        if gradient {
            match &a.gradient {
                Some(g) => out.gradient.extend_from_slice(g),
                None => out.gradient.extend(std::iter::repeat_n(Real::NAN, dof)),
            }
        }
        out.converged.push(a.converged);
        out.fidelity.push(a.fidelity.name().to_owned());
        out.pairs_pruned += (a.pairs_pruned + a.pairs_table + a.pairs_spheres) as u64;
        out.pairs_model += a.pairs_model as u64;
        out.pairs_exact += a.pairs_exact as u64;
    }
    out.count = out.collides.len() as u32;
}

/// Appends the answers of motions to the response columns: each motion's answer and the samples
/// its sampled check took (0: certified).
pub fn push_motion_answers(
    out: &mut pb::CheckMotionsResponse,
    answers: &[(MotionAnswer, usize)],
    robot: &FittedRobot,
    world: &[WorldObject],
) {
    let dof = robot.model.dof();
    for (a, samples) in answers {
        out.samples.push(u32::try_from(*samples).unwrap_or(u32::MAX));
        out.valid.push(a.valid);
        out.decided.push(a.decided);
        out.contact_t.push(a.contact.unwrap_or(Real::NAN));
        match &a.contact_q {
            Some(q) => out.contact_configuration.extend_from_slice(q),
            None => out.contact_configuration.extend(std::iter::repeat_n(Real::NAN, dof)),
        }
        let (link, other, self_contact) = match (a.pair, a.self_pair) {
            (Some((g, Some(o))), _) => (link_of(robot, g), world[o].name.clone(), false),
            (_, Some((x, y))) => (link_of(robot, x), link_of(robot, y), true),
            (Some((g, None)), None) => (link_of(robot, g), String::new(), true),
            (None, None) => (String::new(), String::new(), false),
        };
        out.robot_link.push(link);
        out.other.push(other);
        out.self_contact.push(self_contact);
        out.steps.push(u32::try_from(a.steps).unwrap_or(u32::MAX));
    }
    out.count = out.valid.len() as u32;
}

/// An attached object of a request as stored with a scene's robot (`field` names it in errors).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.primitive` (absent or invalid) or `field.origin`.
pub fn attached_record_from_proto(a: &pb::AttachedObject, field: &str, k: usize) -> Result<AttachedRecord> {
    let primitive = a.primitive.as_ref().ok_or_else(|| Error::invalid(format!("{field}.primitive"), "required"))?;
    let primitive = super::primitive_from_proto(primitive, &format!("{field}.primitive"))?;
    let origin = super::pose_from_proto(&format!("{field}.origin"), a.origin.as_ref())?;
    Ok(AttachedRecord {
        link: a.link.clone(),
        name: if a.name.is_empty() { format!("attached#{k}") } else { a.name.clone() },
        primitive: primitive.to_file(),
        origin: StoredPose::from_isometry(&origin),
    })
}

/// A scene's robot as the API shows it, with its joint positions from `joint_positions` (the
/// scene's, by name).
pub fn scene_robot_to_proto(placed: &PlacedRobot, joint_positions: &[(String, Real)]) -> pb::SceneRobot {
    let names = placed.robot.model.variable_names();
    let q = placed.configuration(joint_positions);
    pb::SceneRobot {
        robot_id: placed.robot_id.clone(),
        base: Some(super::pose_to_proto(&placed.base)),
        attached: placed
            .record
            .attached
            .iter()
            .map(|a| pb::AttachedObject {
                link: a.link.clone(),
                name: a.name.clone(),
                primitive: sublevel_core::primitive::Primitive::from_file(&a.primitive)
                    .ok()
                    .map(|p| super::primitive_to_proto(&p)),
                origin: a.origin.to_isometry("origin").ok().map(|o| super::pose_to_proto(&o)),
            })
            .collect(),
        link_padding: placed.link_padding.iter().cloned().collect(),
        joint_positions: names
            .iter()
            .zip(q)
            .map(|(name, position)| pb::JointPosition { name: (*name).to_owned(), position })
            .collect(),
    }
}
