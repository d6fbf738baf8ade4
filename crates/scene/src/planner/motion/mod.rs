//! Rigid-body motions of scene instances certified by conservative advancement: one instance
//! moves from a start pose to an end pose while every other instance of the scene stays where it
//! is; the motion is proven free, or its first contact parameter is found, with no sampling
//! resolution to choose (Schwarzer, Saha and Latombe, IEEE T-RO 2005).
//!
//! **The motion.** Translation along the segment, rotation along the shorter great arc (slerp),
//! both at constant speed in the parameter `s ∈ [0, 1]`:
//!
//! ```text
//! pose(s) = (R(s), t(s)),   t(s) = t₀ + s·(t₁ − t₀),   R(s) = R₀ · Rot(a, s·θ)
//! q₀⁻¹ q₁ = (cos θ/2, a sin θ/2)        q₁'s sign flipped first when q₀·q₁ < 0, so θ ∈ [0, π]
//! ```
//!
//! **The motion bound.** A point x of the body (its own frame) is at `p(s) = R(s) x + t(s)` and
//! moves with velocity `dp/ds = ω(s) × R(s) x + (t₁ − t₀)`, `‖ω‖ = θ` (constant angular speed). With
//! `r ≥ ‖x‖` for every point of the body (its *reach*: the bounding radius about its frame's
//! origin, [`bounds::reach`]), the path of every point over a step `Δs` is at most
//!
//! ```text
//! ‖p(s + Δs) − p(s)‖ ≤ ∫ ‖dp/ds‖ ds ≤ (‖t₁ − t₀‖ + r·θ) · Δs = v · Δs        (chord ≤ arc)
//! ```
//!
//! so a body at distance `d` from a static obstacle cannot come within `padding` of it before
//! moving `d − padding`: no point of it moves that far within `Δs = (d − padding) / v`.
//!
//! **The advancement.**
//!
//! ```text
//! s ← 0
//! loop:  place the body at pose(s); every obstacle o gets a cheap lower bound b_o of its distance
//!          (bounding spheres, separating axis); obstacles with b_o − padding > v·(1 − s) are out of
//!          reach for the rest of the motion and dropped
//!        take obstacles by b_o, smallest first; refine the one taken (the exact or proven
//!          distance of its kind, bounds module) until the smallest is refined: every other
//!          obstacle's distance is at least its cheap bound, hence at least the smallest
//!        smallest ≤ padding + tolerance   → contact at s (only on a bound within a quarter of the
//!                                           tolerance of the pair's distance; else undecided)
//!        s = 1                            → the motion is free
//!        s ← min(1, s + (smallest − padding) / v)
//! ```
//!
//! Every step is proven free by the motion bound, and the steps cover `[0, s]` with no gap. A
//! contact answer says the body is free (farther than `padding`) before `s`, and at `s` a
//! certified lower bound of its distance to the other instance is at most `padding + tolerance`
//! and within `tolerance / 4` ([`EXACT_FRACTION`]) of the solver's distance; for an approach whose
//! distance closes at speed `w` per unit of s, the true first contact `t*` lies within
//! `1.25 · tolerance / w` after the reported parameter, never before it. Every
//! bound a step rests on is proven (bounds module): exact distances and separating-plane
//! certificates of primitives, tangent-plane bounds at Newton's witnesses for sos-convex bodies,
//! verified SDP bounds for what Newton does not prove, and the tree search's lower bound for
//! compound bodies. The refined bounds keep their warm starts along the motion, so a step costs
//! about one warm solve of the limiting pair. Rounding: the speed is inflated by 10⁻⁹ of itself.
//!
//! A halfspace cannot move (no bounded reach), nor can a body with no proven bounding volume (a
//! nonconvex body).

mod bounds;
#[cfg(test)]
mod tests;

pub use bounds::EXACT_FRACTION;

use crate::answer::Posed;
use crate::catalog::{Catalog, PosedInstance};
use crate::{Error, Result};
use bounds::Obstacle;
use nalgebra::Translation3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::collections::HashMap;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_query::dispatch::PosedRef;
use sublevel_query::CertifyParams;

/// Settings of [`MotionScene::check_motion`]: those of the robot motions (padding around the
/// moving body, contact tolerance, most steps), validated as they are.
pub use sublevel_robot::MotionOptions;

/// The answer for one motion.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceMotionAnswer {
    /// Whether the whole motion is proven free.
    pub valid: bool,
    /// Whether the answer is decided (false: `max_steps` was reached, or the limiting pair's
    /// bound fell to the contact threshold without being within the tolerance of its distance;
    /// then `valid` is false and there is no contact).
    pub decided: bool,
    /// The first contact parameter in [0, 1] (within the tolerance), when there is one.
    pub contact: Option<Real>,
    /// The moving instance's pose at `contact`.
    pub contact_pose: Option<Isometry3>,
    /// The instance it comes into contact with (its id).
    pub other: Option<String>,
    /// Advancement steps taken (poses bounded).
    pub steps: usize,
}

/// The moving instance of a motion, resolved ([`MotionScene::moving`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Moving {
    /// Its index among the scene's instances.
    index: usize,
    /// Its reach (meters): how far its farthest point lies from its frame's origin.
    reach: Real,
}

/// A scene's instances at the poses of one moment, for motion checks: every instance but the
/// moving one is a static obstacle.
pub struct MotionScene {
    instances: Vec<(String, Posed)>,
    index: HashMap<String, usize>,
    params: CertifyParams,
}

impl MotionScene {
    /// The scene's instances (ids, bodies and poses, [`Catalog::posed_instances`]) with the
    /// catalog's solver settings.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene; [`Error::FailedPrecondition`] naming a body that does
    /// not validate.
    pub fn read(catalog: &Catalog, scene_id: &str) -> Result<Self> {
        Self::read_at(catalog, scene_id, &[])
    }

    /// [`MotionScene::read`] with the instances `poses` names (instance id, pose) moved there,
    /// e.g. a planner stream's view; ids the scene lacks are ignored.
    ///
    /// # Errors
    /// As [`MotionScene::read`].
    pub fn read_at(catalog: &Catalog, scene_id: &str, poses: &[(String, Isometry3)]) -> Result<Self> {
        let mut instances = catalog.posed_instances(scene_id, &[])?;
        for (id, pose) in poses {
            if let Some(i) = instances.iter_mut().find(|i| i.id == *id) {
                i.pose = *pose;
            }
        }
        Ok(Self::new(instances, catalog.certify_params()))
    }

    /// Motion checks among `instances` (ids unique; a repeated id keeps its last entry), solved
    /// with `params`.
    pub fn new(instances: Vec<PosedInstance>, params: CertifyParams) -> Self {
        let instances: Vec<(String, Posed)> = instances
            .into_iter()
            .map(|i| (i.id, Posed { body: i.body, tree: i.tree, primitive: i.primitive, pose: i.pose }))
            .collect();
        let index = instances.iter().enumerate().map(|(k, (id, _))| (id.clone(), k)).collect();
        Self { instances, index, params }
    }

    /// Number of instances.
    pub fn len(&self) -> usize {
        self.instances.len()
    }

    /// Whether the scene has no instance.
    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }

    /// Instance `id` as the moving instance of a motion; `field` names it in errors (e.g.
    /// `instance_ids[3]`).
    ///
    /// # Errors
    /// [`Error::NotFound`] naming `field` for an unknown instance; [`Error::InvalidArgument`]
    /// naming `field` for a halfspace or a body with no proven bounding volume (nonconvex).
    pub fn moving(&self, field: &str, id: &str) -> Result<Moving> {
        let index = *self.index.get(id).ok_or_else(|| Error::not_found_at(field, "instance", id))?;
        let posed = &self.instances[index].1;
        let reach = bounds::reach(posed).filter(|r| r.is_finite()).ok_or_else(|| {
            let what = match &posed.primitive {
                Some(p) => format!("is a {} primitive: it has no bounded extent to move", p.kind()),
                None => "has no proven bounding volume (a nonconvex body): it cannot move".to_owned(),
            };
            Error::invalid(field, format!("instance `{}` {what}", sublevel_core::error::clip(id)))
        })?;
        Ok(Moving { index, reach })
    }

    /// Checks the motion of `moving` from pose `start` to pose `end` (module docs) among the other
    /// instances at their poses.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] as [`MotionOptions::validate`]; [`Error::Cancelled`]
    /// when the calling request was abandoned ([`sublevel_core::cancel`]).
    pub fn check_motion(
        &self,
        moving: &Moving,
        start: &Isometry3,
        end: &Isometry3,
        options: &MotionOptions,
    ) -> Result<InstanceMotionAnswer> {
        options.validate()?;
        let path = Slerp::new(start, end);
        let speed = (path.shift.norm() + moving.reach * path.angle) * (1.0 + 1e-9);
        let body = &self.instances[moving.index].1;
        let at = |pose: Isometry3| PosedRef {
            body: &body.body,
            tree: body.tree.as_deref(),
            primitive: body.primitive.as_ref(),
            pose,
        };
        let first = at(*start);
        let mut obstacles: Vec<Obstacle> = (0..self.instances.len())
            .filter(|&k| k != moving.index)
            .map(|k| Obstacle::new(k, &first, &self.instances[k].1.borrowed()))
            .collect();
        let (padding, threshold) = (options.padding, options.padding + options.tolerance);
        let mut answer = InstanceMotionAnswer {
            valid: false,
            decided: true,
            contact: None,
            contact_pose: None,
            other: None,
            steps: 0,
        };
        let mut s: Real = 0.0;
        let mut heap = BinaryHeap::with_capacity(obstacles.len());
        let mut kept = Vec::with_capacity(obstacles.len());
        loop {
            // An abandoned request (deadline passed) stops here, as `Catalog::batch` does.
            sublevel_core::cancel::check()?;
            answer.steps += 1;
            let pose = path.at(s);
            let m = at(pose);
            let left = speed * (1.0 - s);
            heap.clear();
            for o in obstacles.drain(..) {
                let bound = o.cheap(&m, &self.instances[o.index].1.borrowed());
                // Out of reach for the rest of the motion: dropped for good.
                if bound - padding <= left {
                    heap.push(Queued { bound, refined: false, exact: false, obstacle: kept.len() });
                    kept.push(o);
                }
            }
            std::mem::swap(&mut obstacles, &mut kept);
            let limiting = loop {
                let Some(mut top) = heap.pop() else { break None };
                if top.refined {
                    break Some(top);
                }
                let o = &mut obstacles[top.obstacle];
                let b =
                    o.refined(&m, &self.instances[o.index].1.borrowed(), &self.params, options.tolerance, top.bound);
                (top.bound, top.exact, top.refined) = (b.lower, b.exact, true);
                heap.push(top);
            };
            let Some(limit) = limiting else {
                answer.valid = true;
                return Ok(answer);
            };
            if limit.bound <= threshold {
                if limit.exact {
                    answer.contact = Some(s);
                    answer.contact_pose = Some(pose);
                    answer.other = Some(self.instances[obstacles[limit.obstacle].index].0.clone());
                } else {
                    answer.decided = false;
                }
                return Ok(answer);
            }
            if s >= 1.0 || speed == 0.0 {
                answer.valid = true;
                return Ok(answer);
            }
            if answer.steps >= options.max_steps {
                answer.decided = false;
                return Ok(answer);
            }
            s = (s + (limit.bound - padding) / speed).min(1.0);
        }
    }
}

/// A pose path: translation along the segment, rotation along the shorter arc (module docs).
#[derive(Clone, Copy, Debug)]
pub struct Slerp {
    start: Isometry3,
    /// t₁ − t₀ (meters).
    shift: Vector3,
    /// The rotation axis in the start pose's frame (unit).
    axis: nalgebra::Unit<Vector3>,
    /// The rotation angle θ ∈ [0, π] (radians).
    angle: Real,
}

impl Slerp {
    /// The path from `start` to `end`.
    pub fn new(start: &Isometry3, end: &Isometry3) -> Self {
        let (q0, mut q1) = (*start.rotation.quaternion(), *end.rotation.quaternion());
        if q0.dot(&q1) < 0.0 {
            q1 = -q1;
        }
        let rel = q0.conjugate() * q1;
        let sin_half = rel.imag().norm();
        let angle = 2.0 * sin_half.atan2(rel.w.max(0.0));
        let axis = rel.imag().try_normalize(0.0).map_or(Vector3::x_axis(), nalgebra::Unit::new_unchecked);
        Self { start: *start, shift: end.translation.vector - start.translation.vector, axis, angle }
    }

    /// The pose at parameter `s ∈ [0, 1]`.
    pub fn at(&self, s: Real) -> Isometry3 {
        let turn = UnitQuaternion::from_axis_angle(&self.axis, s * self.angle);
        let t = self.start.translation.vector + self.shift * s;
        Isometry3::from_parts(Translation3::from(t), self.start.rotation * turn)
    }

    /// The rotation angle θ (radians, [0, π]).
    pub fn angle(&self) -> Real {
        self.angle
    }

    /// The translation's length ‖t₁ − t₀‖ (meters).
    pub fn travel(&self) -> Real {
        self.shift.norm()
    }
}

/// An obstacle in the step's queue: smallest bound first.
struct Queued {
    bound: Real,
    refined: bool,
    exact: bool,
    obstacle: usize,
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Queued {
    /// Reversed on the bound (a min-queue on `BinaryHeap`); refined entries first among equal
    /// bounds, so a refined bound ends the search before an equal cheap one is refined.
    fn cmp(&self, other: &Self) -> Ordering {
        other.bound.total_cmp(&self.bound).then_with(|| self.refined.cmp(&other.refined))
    }
}
