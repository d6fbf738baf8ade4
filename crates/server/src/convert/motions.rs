//! Rigid-body motions of scene instances (`CheckInstanceMotions`): the request's columns
//! validated into poses and options, and the answers back into columns.

use super::{require_id, MAX_CONFIGURATIONS_PER_CALL, MAX_ID_BYTES};
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::{pose_from_parts, pose_to_parts, Isometry3, Real};
use sublevel_scene::planner::{InstanceMotionAnswer, MotionOptions};

/// The motions of a `CheckInstanceMotions` request, validated: the moving instances' ids, the
/// start and end poses, and the options.
#[derive(Clone, Debug)]
pub struct InstanceMotions {
    /// The moving instance of each motion.
    pub instance_ids: Vec<String>,
    /// Start and end pose of each motion.
    pub poses: Vec<(Isometry3, Isometry3)>,
    /// Padding, tolerance and step limit.
    pub options: MotionOptions,
}

/// The motions of `request` (the scene id is checked by the handler).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `instance_ids` (none, or more than
/// [`MAX_CONFIGURATIONS_PER_CALL`]), `instance_ids[m]` (empty or too long), `start_poses` /
/// `end_poses` (not 7 numbers per motion), `start_poses[i]` / `end_poses[i]` (the first entry of
/// a pose that is not finite, off the supported range, or whose quaternion has no unit norm),
/// `padding` or `tolerance`.
pub fn instance_motions_from_proto(request: &pb::CheckInstanceMotionsRequest) -> Result<InstanceMotions> {
    let n = request.instance_ids.len();
    if n == 0 {
        return Err(Error::invalid("instance_ids", "must name at least one moving instance"));
    }
    if n > MAX_CONFIGURATIONS_PER_CALL {
        return Err(Error::invalid(
            "instance_ids",
            format!("{n} motions: at most {MAX_CONFIGURATIONS_PER_CALL} per call"),
        ));
    }
    for (m, id) in request.instance_ids.iter().enumerate() {
        require_id("id", id)
            .map_err(|_| Error::invalid(format!("instance_ids[{m}]"), format!("must be 1 to {MAX_ID_BYTES} bytes")))?;
    }
    let start = poses("start_poses", &request.start_poses, n)?;
    let end = poses("end_poses", &request.end_poses, n)?;
    let options = super::motion_options(request.padding, request.tolerance, request.max_steps)?;
    Ok(InstanceMotions {
        instance_ids: request.instance_ids.clone(),
        poses: start.into_iter().zip(end).collect(),
        options,
    })
}

/// The `n` poses of the column `field` (seven numbers each: w, x, y, z, tx, ty, tz).
fn poses(field: &str, numbers: &[Real], n: usize) -> Result<Vec<Isometry3>> {
    if numbers.len() != 7 * n {
        return Err(Error::invalid(
            field,
            format!("has {} numbers: expected 7 × {n} (w, x, y, z, tx, ty, tz per motion)", numbers.len()),
        ));
    }
    numbers
        .chunks_exact(7)
        .enumerate()
        .map(|(m, v)| {
            let parts = |name: &str| pose_from_parts(name, [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]);
            // The field is named only when the pose is refused (no string per pose).
            parts("").or_else(|_| parts(&format!("{field}[{}] (motion {m})", 7 * m)))
        })
        .collect()
}

/// The answers of the motions, in order, as the response's columns (NaN and empty strings where a
/// motion has no contact).
pub fn instance_motions_to_proto<'a>(
    answers: impl IntoIterator<Item = &'a InstanceMotionAnswer>,
) -> pb::CheckInstanceMotionsResponse {
    let mut out = pb::CheckInstanceMotionsResponse::default();
    for a in answers {
        out.valid.push(a.valid);
        out.decided.push(a.decided);
        out.contact_t.push(a.contact.unwrap_or(Real::NAN));
        match &a.contact_pose {
            Some(pose) => {
                let (q, t) = pose_to_parts(pose);
                out.contact_pose.extend(q.iter().chain(t.iter()));
            }
            None => out.contact_pose.extend([Real::NAN; 7]),
        }
        out.other.push(a.other.clone().unwrap_or_default());
        out.steps.push(u32::try_from(a.steps).unwrap_or(u32::MAX));
    }
    out.count = out.valid.len() as u32;
    out
}
