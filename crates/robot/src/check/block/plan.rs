//! What the block kernel reads, built once per checker: forward kinematics compiled into a flat
//! program of joint steps, every geometry's balls in its link's frame, and the world's shapes in
//! closed form.

use crate::check::{RobotChecker, WorldBall};
use crate::cloud::PointCloud;
use crate::fitted::LinkShape;
use crate::model::{JointKind, JointValue, RobotModel};
use crate::spheres::SphereTree;
use crate::world::WorldShape;
use std::ops::Range;
use sublevel_core::math::{Isometry3, Matrix3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// Most balls of a link mesh's sphere tree the block kernel tests (the cut of
/// [`tree_cut`]).
pub(crate) const CUT_BALLS: usize = 8;

/// Balls of a link mesh's cut for point clouds ([`Geometry::cloud_cut`]): about 4 cm on the
/// Panda, so that a ball's query with a noise radius and padding of a few centimeters stays within
/// a cloud's grid reach.
pub(crate) const CLOUD_CUT_BALLS: usize = 24;

/// Where a joint's value comes from (a configuration entry, or a mimic of one).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Value {
    /// `q[k]`.
    Entry(usize),
    /// `m · q[k] + c`.
    Mimic(usize, Real, Real),
}

/// A joint's fixed rotation `origin`: a signed permutation of the parent's axes (column k of the
/// product is `sign[k]` times column `src[k]` of the parent's rotation: no arithmetic), or any
/// rotation (row-major).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Turn0 {
    Perm { src: [usize; 3], sign: [Real; 3] },
    General([Real; 9]),
}

/// A joint's motion after its origin.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Motion {
    Fixed,
    /// Rotation by the value about ±axis k: columns `i`, `j` (cyclic after k) mix, `sign` ±1.
    Turn {
        value: Value,
        i: usize,
        j: usize,
        sign: Real,
    },
    /// Rotation about a unit axis that is not a coordinate axis.
    TurnAxis {
        value: Value,
        axis: [Real; 3],
    },
    /// Translation by the value along a unit axis.
    Slide {
        value: Value,
        axis: [Real; 3],
    },
}

/// One step of the forward-kinematics program: `T(child) = T(parent) · origin · motion(value)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Step {
    pub parent: usize,
    pub child: usize,
    pub turn0: Turn0,
    pub t0: [Real; 3],
    pub motion: Motion,
}

/// A closed component's inner balls ([`crate::inner`]), link frame.
#[derive(Clone, Debug)]
pub(crate) struct Component {
    /// The component's bounding ball (center, radius).
    pub bound: [Real; 4],
    /// Its inner balls in [`BlockPlan::inner`].
    pub balls: Range<usize>,
    /// Its extreme vertices in [`BlockPlan::extremes`].
    pub extremes: Range<usize>,
}

/// A robot geometry's bounds, link frame.
#[derive(Clone, Debug)]
pub(crate) struct Geometry {
    pub link: usize,
    /// The ball containing the geometry (center, radius).
    pub ball: [Real; 4],
    /// Balls that together contain it, in [`BlockPlan::cut`] (the geometry's ball for a
    /// primitive).
    pub cut: Range<usize>,
    /// Smaller balls that together contain it, in [`BlockPlan::cloud_cut`]: the radius queries
    /// against point clouds, which their gap grids answer up to [`crate::cloud::GRID_REACH`].
    pub cloud_cut: Range<usize>,
    /// Its closed components' inner balls, in [`BlockPlan::components`] (none for a
    /// primitive).
    pub components: Range<usize>,
    /// Whether `cut` is the checker's [`crate::Fidelity::Spheres`] model of the geometry (a
    /// mesh's cut of at least two balls): a pair it leaves within the padding collides at that
    /// level.
    pub modelled: bool,
}

/// A world primitive in its own frame.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Shape {
    Box([Real; 3]),
    Sphere(Real),
    Cylinder(Real, Real),
    Capsule(Real, Real),
}

/// A world object as the kernel tests it.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Object {
    /// A ball containing the object (a mesh: bounds prove it free, nothing proves contact).
    Ball { c: [Real; 3], r: Real },
    /// The halfspace n·x ≤ d (world frame, unit n).
    Plane { n: [Real; 3], d: Real },
    /// A primitive: world → its frame is x ↦ rt · (x − t); `aabb` its world box (center, half
    /// extents).
    Shape { rt: [Real; 9], t: [Real; 3], shape: Shape, aabb: ([Real; 3], [Real; 3]) },
    /// A point cloud, [`BlockPlan::clouds`]`[index]`: its ball (world frame), and world → its
    /// frame as x ↦ rt · (x − t); the lanes ask its k-d tree one lane at a time.
    Cloud { c: [Real; 3], r: Real, rt: [Real; 9], t: [Real; 3], index: usize },
}

/// The block kernel's view of a checker's robot and world (module docs).
pub(crate) struct BlockPlan {
    pub steps: Vec<Step>,
    pub links: usize,
    pub root: usize,
    pub geometries: Vec<Geometry>,
    pub cut: Vec<[Real; 4]>,
    pub components: Vec<Component>,
    pub inner: Vec<[Real; 4]>,
    pub extremes: Vec<[Real; 3]>,
    pub objects: Vec<Object>,
    /// The balls of every geometry's [`Geometry::cloud_cut`].
    pub cloud_cut: Vec<[Real; 4]>,
    /// The point clouds of the [`Object::Cloud`] objects.
    pub clouds: Vec<std::sync::Arc<PointCloud>>,
    /// The inflation covering rounding at the base's origin (meters): scaled by the base's
    /// distance from the origin at check time ([`BlockPlan::inflation`]).
    pub eps0: Real,
}

/// Rounding margin of the lanes per meter of scale: a pose computed in lanes differs from the
/// single path's by a few units in the last place per joint (about 1e-15 m per meter of reach),
/// so bounds are required to clear the padding by this much more.
const EPS_PER_METER: Real = 1e-9;

fn arr(v: &Vector3) -> [Real; 3] {
    [v.x, v.y, v.z]
}

fn rows(m: &Matrix3) -> [Real; 9] {
    [m[(0, 0)], m[(0, 1)], m[(0, 2)], m[(1, 0)], m[(1, 1)], m[(1, 2)], m[(2, 0)], m[(2, 1)], m[(2, 2)]]
}

/// `pose` as the lanes take it: its rotation row by row, then its translation.
pub(crate) fn pose_rows(pose: &Isometry3) -> [Real; 12] {
    let r = rows(&pose.rotation.to_rotation_matrix().into_inner());
    let t = pose.translation.vector;
    [r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], t.x, t.y, t.z]
}

/// `m` as a signed permutation, when every entry is within 1e-14 of 0 or ±1 (a URDF `rpy` of
/// multiples of π/2): moving an entry by 1e-14 moves a point at 1 m by 1e-14 m, far inside the
/// rounding margin.
fn signed_permutation(m: &Matrix3) -> Option<([usize; 3], [Real; 3])> {
    let (mut src, mut sign) = ([0; 3], [0.0; 3]);
    for k in 0..3 {
        let col = m.column(k);
        let mut found = None;
        for r in 0..3 {
            let v = col[r];
            if (v.abs() - 1.0).abs() < 1e-14 {
                found = Some((r, v.signum()));
            } else if v.abs() >= 1e-14 {
                return None;
            }
        }
        let (r, s) = found?;
        (src[k], sign[k]) = (r, s);
    }
    Some((src, sign))
}

/// At most `count` nodes of `tree` whose balls together hold every piece: the root, split at its
/// largest ball while the count allows.
pub(crate) fn tree_cut(tree: &SphereTree, count: usize) -> Vec<usize> {
    if tree.nodes.is_empty() {
        return Vec::new();
    }
    let mut cut = vec![0usize];
    loop {
        let split = cut
            .iter()
            .enumerate()
            .filter(|(_, &n)| tree.nodes[n].children != 0)
            .max_by(|a, b| tree.nodes[*a.1].sphere.radius.total_cmp(&tree.nodes[*b.1].sphere.radius));
        let Some((i, &n)) = split else { break };
        if cut.len() + 1 > count {
            break;
        }
        let c = tree.nodes[n].children as usize;
        cut[i] = c;
        cut.push(c + 1);
    }
    cut
}

/// Forward kinematics of `model` as a flat program of joint steps, parents first, and a scale of
/// its reach (meters: 1 + the joint origins' offsets + the prismatic joints' travel).
pub(crate) fn program(model: &RobotModel) -> (Vec<Step>, Real) {
    let mut reach = 1.0;
    let steps = model
        .joints()
        .iter()
        .map(|j| {
            let r0 = j.origin.rotation.to_rotation_matrix().into_inner();
            let turn0 = match signed_permutation(&r0) {
                Some((src, sign)) => Turn0::Perm { src, sign },
                None => Turn0::General(rows(&r0)),
            };
            reach += j.origin.translation.vector.norm();
            let value = match j.value {
                JointValue::Fixed => None,
                JointValue::Variable(k) => Some(Value::Entry(k)),
                JointValue::Mimic { variable, multiplier, offset } => Some(Value::Mimic(variable, multiplier, offset)),
            };
            let axis = arr(&j.axis);
            let motion = match (j.kind, value) {
                (JointKind::Fixed, _) | (_, None) => Motion::Fixed,
                (JointKind::Prismatic, Some(value)) => {
                    if let Some((lo, hi)) = j.limits {
                        reach += lo.abs().max(hi.abs());
                    }
                    Motion::Slide { value, axis }
                }
                (_, Some(value)) => match (0..3).find(|&k| (axis[k].abs() - 1.0).abs() < 1e-15) {
                    Some(k) => Motion::Turn { value, i: (k + 1) % 3, j: (k + 2) % 3, sign: axis[k].signum() },
                    None => Motion::TurnAxis { value, axis },
                },
            };
            Step { parent: j.parent, child: j.child, turn0, t0: arr(&j.origin.translation.vector), motion }
        })
        .collect();
    (steps, reach)
}

impl BlockPlan {
    /// The plan of `checker`'s robot and world.
    pub(crate) fn new(checker: &RobotChecker<'_>) -> Self {
        let robot = checker.robot;
        let model = &robot.model;
        let (steps, mut reach) = program(model);
        let mut plan = BlockPlan {
            steps,
            links: model.links().len(),
            root: model.root(),
            geometries: Vec::new(),
            cut: Vec::new(),
            components: Vec::new(),
            inner: Vec::new(),
            extremes: Vec::new(),
            objects: Vec::new(),
            cloud_cut: Vec::new(),
            clouds: Vec::new(),
            eps0: 0.0,
        };
        for g in &robot.geometries {
            let o = &g.origin;
            let ball = |c: &Vector3, r: Real| {
                let p = o.transform_point(&(*c).into());
                [p.x, p.y, p.z, r]
            };
            let start = plan.cut.len();
            let cloud_start = plan.cloud_cut.len();
            let comps = plan.components.len();
            match &g.shape {
                LinkShape::Mesh { spheres, inner, .. } if !spheres.nodes.is_empty() => {
                    let model = checker.sphere_cut(plan.geometries.len());
                    if model.is_empty() {
                        for n in tree_cut(spheres, CUT_BALLS) {
                            let s = &spheres.nodes[n].sphere;
                            plan.cut.push(ball(&s.center, s.radius));
                        }
                    } else {
                        plan.cut.extend(model.iter().map(|s| ball(&s.center, s.radius)));
                    }
                    for n in tree_cut(spheres, CLOUD_CUT_BALLS) {
                        let s = &spheres.nodes[n].sphere;
                        plan.cloud_cut.push(ball(&s.center, s.radius));
                    }
                    for c in &inner.components {
                        let b0 = plan.inner.len();
                        plan.inner.extend(c.balls.iter().map(|s| ball(&s.center, s.radius)));
                        let e0 = plan.extremes.len();
                        plan.extremes.extend(c.extremes.iter().map(|v| arr(&o.transform_point(&(*v).into()).coords)));
                        plan.components.push(Component {
                            bound: ball(&c.bound.center, c.bound.radius),
                            balls: b0..plan.inner.len(),
                            extremes: e0..plan.extremes.len(),
                        });
                    }
                }
                _ => {
                    plan.cut.push(ball(&g.sphere.0, g.sphere.1));
                    plan.cloud_cut.push(ball(&g.sphere.0, g.sphere.1));
                }
            }
            reach = Real::max(reach, g.sphere.0.norm() + g.sphere.1 + 1.0);
            plan.geometries.push(Geometry {
                link: g.link,
                ball: ball(&g.sphere.0, g.sphere.1),
                cut: start..plan.cut.len(),
                cloud_cut: cloud_start..plan.cloud_cut.len(),
                components: comps..plan.components.len(),
                modelled: plan.cut.len() - start > 1 && !checker.sphere_cut(plan.geometries.len()).is_empty(),
            });
        }
        for (o, wb) in checker.world.iter().zip(&checker.world_balls) {
            plan.objects.push(match (*wb, &o.shape) {
                (WorldBall::Plane { normal, offset }, _) => Object::Plane { n: arr(&normal), d: offset },
                (WorldBall::Ball { .. }, WorldShape::Primitive(p)) => {
                    let shape = match *p {
                        Primitive::Box { half_extents: h } => Shape::Box(arr(&h)),
                        Primitive::Sphere { radius } => Shape::Sphere(radius),
                        Primitive::Cylinder { radius, half_height } => Shape::Cylinder(radius, half_height),
                        Primitive::Capsule { radius, half_height } => Shape::Capsule(radius, half_height),
                        Primitive::Halfspace { .. } => unreachable_plane(),
                    };
                    let r = o.pose.rotation.to_rotation_matrix().into_inner();
                    // The local box's half extents, turned into the world: |R| h, widened by a
                    // part in 1e-12 against rounding.
                    let h = match shape {
                        Shape::Box(h) => Vector3::from(h),
                        Shape::Sphere(r) => Vector3::repeat(r),
                        Shape::Cylinder(r, h) => Vector3::new(r, r, h),
                        Shape::Capsule(r, h) => Vector3::new(r, r, h + r),
                    };
                    let half = r.abs() * h * (1.0 + 1e-12);
                    Object::Shape {
                        rt: rows(&r.transpose()),
                        t: arr(&o.pose.translation.vector),
                        shape,
                        aabb: (arr(&o.pose.translation.vector), arr(&half)),
                    }
                }
                (WorldBall::Ball { center, radius }, WorldShape::Points(cloud)) => {
                    plan.clouds.push(cloud.clone());
                    let r = o.pose.rotation.to_rotation_matrix().into_inner();
                    Object::Cloud {
                        c: arr(&center),
                        r: radius,
                        rt: rows(&r.transpose()),
                        t: arr(&o.pose.translation.vector),
                        index: plan.clouds.len() - 1,
                    }
                }
                (WorldBall::Ball { center, radius }, WorldShape::Mesh(_) | WorldShape::Body(_)) => {
                    Object::Ball { c: arr(&center), r: radius }
                }
            });
        }
        plan.eps0 = EPS_PER_METER * reach;
        plan
    }

    /// The rounding margin with the robot's root at `base` (meters).
    pub(crate) fn inflation(&self, base: &Isometry3) -> Real {
        self.eps0 + EPS_PER_METER * base.translation.vector.norm()
    }
}

/// A halfspace always has a plane for its world ball ([`RobotChecker::new`]); a box of no size
/// stands in for the impossible case, which the bounds then never call free.
fn unreachable_plane() -> Shape {
    Shape::Box([Real::NAN; 3])
}
