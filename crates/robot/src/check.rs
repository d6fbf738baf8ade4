//! Configuration checks: does the robot at joint configuration `q` collide with the world or with
//! itself, and how far is it from the world.
//!
//! ```text
//! q ──FK──► link poses ──► geometry poses (link pose · URDF collision origin)
//! world pairs (every geometry × every object, minus the allowed ones), by increasing ball gap:
//!   ball gap, then box gap (15 axes, stopped at the first that separates)
//!          > padding (verdict) or ≥ best distance so far (distance)          → decided, no solve
//!   inner balls (a closed link mesh against a primitive): a ball inside the mesh meets the
//!          object, which reaches outside the mesh's bounding ball      → collides, no mesh test
//!   sphere tree (a mesh link against a primitive object): the link's nested balls, every
//!          triangle piece inside a chain of them, descended against the object's closed form;
//!          every branch farther than the padding (verdict) or than best (distance) → decided;
//!          a node's whole ball within the padding                      → collides, no mesh test
//!   vertices (a mesh link against a primitive): a vertex within the padding → collides
//!   sos bound: the link's compound root body (contains every leaf, hence every triangle) against
//!              the object's exact primitive, or the body containing a mesh object (none: skipped),
//!              one Newton / active-set solve: d_sos ≤ d_mesh
//!   d_sos > padding (verdict) or ≥ best (distance)                           → decided
//!   mesh:  the link's triangles against the primitive or the object's triangles (parry's BVH):
//!          intersecting or within the padding → collides; else the exact mesh distance, the new
//!          best
//! self pairs (the SRDF's allowed pairs left out): ball gap, box gap, the pair's clearance table
//!   ([`crate::clearance`]), the two sphere trees' dual descent (a mesh and a primitive: the tree
//!   against the primitive), the contact proofs (two closed meshes' inner balls; a vertex or tree
//!   node inside the other's inner ball), root–root sos bound, then the two meshes' triangles;
//!   each stage over every pair still undecided before the next (a verdict stops at the first
//!   contact found, so a cheap proof on any pair spares the others' triangles)
//! ```
//!
//! **No false collision from the proofs.** The contact proofs ([`crate::inner`]) show that a
//! triangle meets the object (or the other link's triangles), so a pair they call colliding is
//! one the mesh checker calls colliding too. On the MotionBenchMaker labels they decide 0.26
//! colliding pairs per configuration and leave 0.10 to the meshes (0.36 without them).
//!
//! **No missed collision.** The sphere trees and the root body contain the mesh: a pair the
//! trees show farther than the padding has no triangle within it, and `d_sos` never exceeds the
//! mesh's distance, so a pair either calls free is free. A pair neither can call free (overlap,
//! within the padding, or a solve that did not converge) is decided on the mesh itself, exactly
//! as a mesh checker (coal, FCL) decides it: triangles against the primitive or the other mesh's
//! triangles (a shape wholly inside a closed mesh, touching no triangle, is not a contact for
//! either). So the verdict is the mesh's, and the trees and sos bodies decide, cheaply, what is
//! far.
//!
//! **Distance.** The minimum robot–world distance is the exact mesh distance of the closest pair:
//! pairs are taken by their ball gap, the sphere trees and the sos bound prune those that cannot
//! beat the best, and the rest get the mesh distance.
//!
//! **What each stage decides** (the MotionBenchMaker Panda, 1 400 labelled configurations,
//! `crates/lab/examples/check_profile.rs`): per configuration the ball and box gaps decide 142.6
//! pairs of the verdict, the sphere trees 0.89 (mostly the self pair link5–link7 at 2 cm), the
//! contact proofs 0.28; 0.08 reach the sos solve and 0.08 the mesh ([`crate::exact`]'s descents).
//!
//! **Why the root and not the leaves.** A 32-leaf tree's descent against a box costs tens of µs,
//! the root's sos solve 0.4–2 µs and the mesh stage a few µs; the sphere trees are another matter
//! (a ball against a primitive is a closed form of a few ns).

use crate::exact::{box_gap, box_gap_past, exact_collides, exact_pair, exact_pair_within, exact_primitive, parry_pose};
use crate::exact::{ExactShape, PairOutcome, PlacedBox};
use crate::exact::{PairHint, Slack};
use crate::fidelity::Fidelity;
use crate::fitted::{FittedRobot, LinkShape, RobotGeometry};
use crate::inner::{link_touches_primitive, link_vertex_touches};
use crate::spheres::{Sphere, TreeAnswer};
use crate::world::{WorldObject, WorldShape};
use crate::{Error, Result};
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_query::shape::{shape_distance, ShapeRef};

pub use crate::answer::{CheckOptions, ConfigurationAnswer};

pub mod block;
mod bounds;
mod cloud_pairs;
mod model_pairs;
mod self_pairs;

/// Most balls of one geometry's cut the block path's lanes test at [`Fidelity::Spheres`]: a
/// geometry whose cut at the tolerance needs more keeps the lanes' usual cut, and the pairs it
/// leaves go to the single path's descent of its sphere tree.
pub const MAX_CUT_BALLS: usize = 64;

/// A link shape as the sos bound sees it: the primitive, or the compound body's root (which
/// contains every leaf, hence every triangle).
fn root_shape(s: &LinkShape) -> ShapeRef<'_> {
    match s {
        LinkShape::Primitive(p) => ShapeRef::Primitive(p),
        LinkShape::Mesh { body, .. } => ShapeRef::Body(body),
    }
}

/// A robot geometry's exact shape for the mesh stage: its primitive, or its mesh's parry shape.
pub(crate) fn exact_shape(g: &RobotGeometry) -> ExactShape {
    match &g.shape {
        LinkShape::Primitive(p) => exact_primitive(p),
        LinkShape::Mesh { exact, .. } => ExactShape { shape: exact.clone(), offset: Isometry3::identity() },
    }
}

/// A world object's bound for the ball gaps, in the world frame.
#[derive(Clone, Copy, Debug)]
enum WorldBall {
    /// A ball containing the object (meters).
    Ball { center: Vector3, radius: Real },
    /// A halfspace {x : normal·x ≤ offset} (unit normal).
    Plane { normal: Vector3, offset: Real },
}

/// Checks configurations of one robot in one world (module docs). Holds the world's exact shapes
/// and scratch space; one checker per thread.
pub struct RobotChecker<'r> {
    robot: &'r FittedRobot,
    world: Vec<WorldObject>,
    world_exact: Vec<ExactShape>,
    /// Each world object's placed box (`None` for a halfspace).
    world_boxes: Vec<Option<PlacedBox>>,
    /// Each world object's ball in the world frame, or its plane (a halfspace).
    world_balls: Vec<WorldBall>,
    robot_exact: Vec<ExactShape>,
    /// Checked world pairs per geometry (objects not allowed to touch it).
    world_pairs: Vec<Vec<usize>>,
    /// Checked self pairs, as geometry indices.
    self_pairs: Vec<(usize, usize)>,
    /// Each self pair's closest triangles last found by [`RobotChecker::self_bound`] (a motion's
    /// warm start).
    self_hints: Vec<PairHint>,
    /// Each world pair's closest triangle last found by [`RobotChecker::world_bound`] (a motion's
    /// warm start), at `g · world.len() + o`.
    world_hints: Vec<PairHint>,
    /// Each self pair's clearance table in `robot.clearance`, if it has one.
    self_tables: Vec<Option<usize>>,
    /// The configuration last placed.
    q: Vec<Real>,
    link_poses: Vec<Isometry3>,
    poses: Vec<Isometry3>,
    centers: Vec<Vector3>,
    boxes: Vec<Option<PlacedBox>>,
    order: Vec<(Real, usize, usize)>,
    /// Self pairs left to the sphere trees, the sos bound and the meshes (scratch).
    pending: Vec<usize>,
    /// Extra padding per geometry (meters, ≥ 0): its link's ([`RobotChecker::set_link_padding`]).
    pad: Vec<Real>,
    /// The largest entry of `pad` (0 with none).
    pad_max: Real,
    /// Whether the outer sphere sets decide pairs before the sos solve
    /// ([`RobotChecker::set_sphere_stage`]).
    sphere_stage: bool,
    /// Whether the inner balls and the sphere trees prove pairs colliding
    /// ([`RobotChecker::set_contact_proofs`]).
    contact_proofs: bool,
    /// The block kernel's view of the robot and world, built at the first block check
    /// ([`block`]).
    block: Option<Box<block::BlockPlan>>,
    /// Configurations the block path checked, and those of them its lanes left to the single
    /// path's stages ([`RobotChecker::block_counts`]).
    block_counts: (u64, u64),
    /// The level of the checks ([`RobotChecker::set_fidelity`]).
    fidelity: Fidelity,
    /// At [`Fidelity::Spheres`], each mesh geometry's cut balls (its frame) for the lanes;
    /// empty otherwise ([`RobotChecker::sphere_cut`]).
    cuts: Vec<Vec<Sphere>>,
    /// At [`Fidelity::Spheres`], per geometry, which sphere-tree nodes the model's cut holds
    /// (the descents' leaves); empty otherwise.
    model_leaves: Vec<Vec<bool>>,
    /// The level set before the current one, with its cuts and block plan, restored without a
    /// rebuild when that level is set again.
    stash: Option<Stash>,
}

/// A level's cuts and block plan, kept across one switch of level.
type Stash = (Fidelity, Vec<Vec<Sphere>>, Vec<Vec<bool>>, Option<Box<block::BlockPlan>>);

impl<'r> RobotChecker<'r> {
    /// A checker of `robot` among `world`. `allowed(a, b)` overrides which pairs may touch, by
    /// link and object names (a scene's allowed-collision matrix): `Some(true)` allowed (never
    /// checked), `Some(false)` checked, `None` the default — self pairs as the robot's SRDF says,
    /// world pairs checked.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `world[k].pose` when a pose is not finite.
    pub fn new(
        robot: &'r FittedRobot,
        world: Vec<WorldObject>,
        allowed: &dyn Fn(&str, &str) -> Option<bool>,
    ) -> Result<Self> {
        for (k, o) in world.iter().enumerate() {
            let m = o.pose.to_homogeneous();
            if m.iter().any(|v| !v.is_finite()) {
                return Err(Error::invalid(format!("world[{k}].pose"), "must be finite"));
            }
        }
        let links = robot.model.links();
        let world_pairs = robot
            .geometries
            .iter()
            .map(|g| {
                let link = &links[g.link].name;
                // A cloud without points meets nothing.
                (0..world.len())
                    .filter(|&o| allowed(link, &world[o].name) != Some(true) && world[o].shape.ball().1 >= 0.0)
                    .collect()
            })
            .collect();
        let mut self_pairs = Vec::new();
        let n = robot.geometries.len();
        for a in 0..n {
            for b in a + 1..n {
                let (la, lb) = (robot.geometries[a].link, robot.geometries[b].link);
                if la == lb {
                    continue;
                }
                let default = robot.self_pairs.contains(&(la.min(lb), la.max(lb)));
                let check = match allowed(&links[la].name, &links[lb].name) {
                    Some(allow) => !allow,
                    None => default,
                };
                if check {
                    self_pairs.push((a, b));
                }
            }
        }
        let hints = robot.geometries.len() * world.len();
        let robot_exact = robot.geometries.iter().map(exact_shape).collect();
        let world_exact = world
            .iter()
            .map(|o| match &o.shape {
                WorldShape::Primitive(p) => exact_primitive(p),
                WorldShape::Mesh(m) => ExactShape { shape: m.exact.clone(), offset: Isometry3::identity() },
                WorldShape::Body(b) => ExactShape { shape: b.exact.clone(), offset: Isometry3::identity() },
                // Never used: a cloud's pairs go to its radius queries.
                WorldShape::Points(c) => exact_primitive(&Primitive::Sphere { radius: c.radius() }),
            })
            .collect();
        let world_boxes = world.iter().map(|o| o.shape.local_box().map(|b| PlacedBox::new(&o.pose, &b))).collect();
        let world_balls = world
            .iter()
            .map(|o| match o.shape {
                WorldShape::Primitive(Primitive::Halfspace { normal, offset }) => {
                    let n = o.pose.rotation * normal;
                    WorldBall::Plane { normal: n, offset: offset + n.dot(&o.pose.translation.vector) }
                }
                _ => {
                    let (center, radius) = o.shape.ball();
                    WorldBall::Ball { center: o.pose.transform_point(&center.into()).coords, radius }
                }
            })
            .collect();
        Ok(Self {
            robot,
            world,
            world_exact,
            world_boxes,
            world_balls,
            robot_exact,
            world_pairs,
            self_hints: self_pairs.iter().map(|_| PairHint::default()).collect(),
            world_hints: (0..hints).map(|_| PairHint::default()).collect(),
            self_tables: self_pairs.iter().map(|&p| robot.clearance.iter().position(|t| t.geometries == p)).collect(),
            q: Vec::new(),
            self_pairs,
            link_poses: Vec::new(),
            poses: Vec::new(),
            centers: Vec::new(),
            boxes: Vec::new(),
            order: Vec::new(),
            pending: Vec::new(),
            pad: vec![0.0; robot.geometries.len()],
            pad_max: 0.0,
            sphere_stage: true,
            contact_proofs: true,
            block: None,
            block_counts: (0, 0),
            fidelity: Fidelity::Mesh,
            cuts: Vec::new(),
            model_leaves: Vec::new(),
            stash: None,
        })
    }

    /// Sets per-link padding, as MoveIt's link padding: `padding[k] = (link, meters ≥ 0)` inflates
    /// every geometry of that link (attached objects included) for the checks that follow, on top of
    /// [`CheckOptions::padding`]. A world pair then collides within `padding + p(link)`, a self pair
    /// within `padding + p(a) + p(b)`; distances stay the unpadded ones. Links not listed get 0;
    /// each call replaces the previous padding.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `link_padding[LINK]` for a link the robot lacks or a
    /// padding that is negative or not finite (nothing changes then).
    pub fn set_link_padding(&mut self, padding: &[(String, Real)]) -> Result<()> {
        let robot = self.robot;
        let mut pad = vec![0.0; robot.geometries.len()];
        for (link, p) in padding {
            let field = || format!("link_padding[{}]", sublevel_core::error::clip(link));
            let index =
                robot.model.link_index(link).ok_or_else(|| Error::invalid(field(), "is not a link of the robot"))?;
            if !(p.is_finite() && *p >= 0.0) {
                return Err(Error::invalid(field(), format!("must be finite and ≥ 0 m, got {p}")));
            }
            for (g, geometry) in robot.geometries.iter().enumerate() {
                if geometry.link == index {
                    pad[g] = *p;
                }
            }
        }
        self.pad_max = pad.iter().copied().fold(0.0, Real::max);
        self.pad = pad;
        Ok(())
    }

    /// Turns the sphere stage on (the default) or off: with it, a pair the ball and box gaps
    /// leave undecided is tried against the link meshes' outer sphere sets before the sos solve
    /// ([`crate::spheres`]). The answers are the same either way (the stage only proves pairs
    /// free that the mesh calls free, and its distance bounds only prune); off, it is the
    /// reference the stage is measured and tested against.
    pub fn set_sphere_stage(&mut self, on: bool) {
        self.sphere_stage = on;
    }

    /// Turns the contact proofs on (the default) or off: with them, a pair the ball and box gaps
    /// leave undecided may be proved colliding by the link meshes' inner balls or by a sphere
    /// tree node wholly within the padding ([`crate::inner`], [`crate::spheres`]), where a mesh
    /// checker finds contact too, without the mesh. The verdicts are the same either way; off,
    /// it is the reference the proofs are tested against.
    pub fn set_contact_proofs(&mut self, on: bool) {
        self.contact_proofs = on;
    }

    /// The link padding of robot geometry `g` (meters).
    pub(crate) fn world_extra(&self, g: usize) -> Real {
        self.pad[g]
    }

    /// The link padding of checked self pair `k`: both geometries' (meters).
    pub(crate) fn self_extra(&self, k: usize) -> Real {
        let (a, b) = self.self_pairs[k];
        self.pad[a] + self.pad[b]
    }

    /// The world objects.
    pub fn world(&self) -> &[WorldObject] {
        &self.world
    }

    /// The checked self pairs, as geometry indices.
    pub fn self_pairs(&self) -> &[(usize, usize)] {
        &self.self_pairs
    }

    /// Checks configuration `q` (one entry per [`crate::RobotModel::variable_names`], radians /
    /// meters) with the robot's root at `base`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `q` or `q[k]` (wrong length, not finite) or `padding`
    /// (negative or not finite); [`Error::Numerical`] when a query fails outright.
    pub fn check(&mut self, q: &[Real], base: &Isometry3, options: &CheckOptions) -> Result<ConfigurationAnswer> {
        if !(options.padding.is_finite() && options.padding >= 0.0) {
            return Err(Error::invalid("padding", format!("must be finite and ≥ 0 m, got {}", options.padding)));
        }
        let robot = self.robot;
        self.place(q, base)?;
        let mut answer = ConfigurationAnswer::start(options.distance);
        self.world_check(options, &mut answer, None)?;
        if options.gradient && options.distance && !answer.world && answer.distance.is_finite() {
            if let (Some((x, y)), Some((g, _))) = (answer.witnesses, answer.pair) {
                let d = x - y;
                if d.norm() > 0.0 {
                    let n = d / d.norm();
                    let mut jacobian = Vec::new();
                    robot.model.point_jacobian(&self.link_poses, robot.geometries[g].link, &x, &mut jacobian);
                    answer.gradient = Some(jacobian.iter().map(|c| n.dot(c)).collect());
                }
            }
        }
        if options.self_collision {
            self.self_check(options, &mut answer, None)?;
        }
        answer.collides = answer.world || answer.self_collision;
        Ok(answer)
    }

    /// Places every geometry at configuration `q` (forward kinematics) for the pair bounds of
    /// [`RobotChecker::world_bound`] and [`RobotChecker::self_bound`].
    ///
    /// # Errors
    /// As [`crate::RobotModel::forward_kinematics`].
    pub(crate) fn place(&mut self, q: &[Real], base: &Isometry3) -> Result<()> {
        let robot = self.robot;
        robot.model.forward_kinematics(q, base, &mut self.link_poses)?;
        self.q.clear();
        self.q.extend_from_slice(q);
        self.poses.clear();
        self.centers.clear();
        self.boxes.clear();
        for g in &robot.geometries {
            let pose = self.link_poses[g.link] * g.origin;
            self.centers.push(pose.transform_point(&g.sphere.0.into()).coords);
            self.boxes.push(g.local_box.as_ref().map(|b| PlacedBox::new(&pose, b)));
            self.poses.push(pose);
        }
        Ok(())
    }

    /// The link poses of the configuration last placed ([`RobotChecker::place`]).
    pub(crate) fn link_poses(&self) -> &[Isometry3] {
        &self.link_poses
    }

    /// The center of robot geometry `g`'s bounding ball in the world frame, as last placed.
    pub(crate) fn geometry_center(&self, g: usize) -> &Vector3 {
        &self.centers[g]
    }

    /// The checked world pairs of geometry `g` (object indices).
    pub(crate) fn world_pairs_of(&self, g: usize) -> &[usize] {
        &self.world_pairs[g]
    }

    /// Whether robot geometry `g` and world object `o` are both exact primitives (their sos
    /// answer is then the exact one).
    fn both_primitive(&self, g: usize, o: usize) -> bool {
        matches!(
            (&self.robot.geometries[g].shape, &self.world[o].shape),
            (LinkShape::Primitive(_), WorldShape::Primitive(_))
        )
    }

    /// World object `o` as the sos bound sees it: the primitive, or the body containing the
    /// mesh; `None` for a mesh without one.
    fn world_sos_shape(&self, o: usize) -> Option<ShapeRef<'_>> {
        match &self.world[o].shape {
            WorldShape::Primitive(p) => Some(ShapeRef::Primitive(p)),
            WorldShape::Mesh(m) => m.body().map(ShapeRef::Body),
            WorldShape::Body(b) => Some(ShapeRef::Body(b.body())),
            WorldShape::Points(_) => None,
        }
    }

    /// The sos root bound of a world pair (its distance; 0 when overlapping, not converged, or
    /// for a mesh object without a body).
    fn sos_world_bound(&self, g: usize, o: usize) -> Result<Real> {
        let geometry = &self.robot.geometries[g];
        let obj = &self.world[o];
        let Some(shape) = self.world_sos_shape(o) else { return Ok(0.0) };
        let d = shape_distance(root_shape(&geometry.shape), &self.poses[g], shape, &obj.pose, None)?;
        Ok(if d.status.converged() && !d.overlapping { d.distance.max(0.0) } else { 0.0 })
    }

    /// The robot being checked.
    pub fn robot(&self) -> &FittedRobot {
        self.robot
    }

    /// Ball gap of robot geometry `g` and world object `o` (a lower bound of their distance).
    fn world_gap(&self, g: usize, o: usize) -> Real {
        let r = self.robot.geometries[g].sphere.1;
        match self.world_balls[o] {
            WorldBall::Plane { normal, offset } => normal.dot(&self.centers[g]) - offset - r,
            WorldBall::Ball { center, radius } => (self.centers[g] - center).norm() - r - radius,
        }
    }

    /// Whether the balls of robot geometry `g` and world object `o` are farther apart than
    /// `padding` ≥ 0: [`RobotChecker::world_gap`] `> padding`, with squared lengths (no root).
    fn world_apart(&self, g: usize, o: usize, padding: Real) -> bool {
        let r = self.robot.geometries[g].sphere.1;
        match self.world_balls[o] {
            WorldBall::Plane { normal, offset } => normal.dot(&self.centers[g]) - offset - r > padding,
            WorldBall::Ball { center, radius } => {
                let reach = r + radius + padding;
                (self.centers[g] - center).norm_squared() > reach * reach
            }
        }
    }

    /// Whether the inner balls of robot geometry `g` prove that it meets world object `o` (a
    /// primitive; [`crate::inner`]).
    fn inner_touches_world(&self, g: usize, o: usize) -> bool {
        let obj = &self.world[o];
        let WorldShape::Primitive(p) = &obj.shape else { return false };
        link_touches_primitive(&self.robot.geometries[g].shape, &self.poses[g], p, &obj.pose)
    }

    /// Whether a vertex of robot geometry `g` lies within `padding` of world object `o` (a
    /// primitive; [`crate::inner`]).
    fn vertex_touches_world(&self, g: usize, o: usize, padding: Real) -> bool {
        let obj = &self.world[o];
        let WorldShape::Primitive(p) = &obj.shape else { return false };
        link_vertex_touches(&self.robot.geometries[g].shape, &self.poses[g], p, &obj.pose, padding)
    }

    /// The sphere tree of robot geometry `g` against world object `o` ([`crate::spheres`]):
    /// apart past `threshold`, touching within `padding` (the inner stage's proofs from the
    /// outside), or unknown — also where the stage does not apply (a primitive geometry, whose
    /// sos answer is exact, or a mesh object). Against a body object it only proves apart.
    fn tree_against_world(&self, g: usize, o: usize, threshold: Real, padding: Real) -> TreeAnswer {
        let LinkShape::Mesh { spheres, .. } = &self.robot.geometries[g].shape else { return TreeAnswer::Unknown };
        let obj = &self.world[o];
        let rel = obj.pose.inv_mul(&self.poses[g]);
        let p = match &obj.shape {
            WorldShape::Primitive(p) => p,
            WorldShape::Body(b) if b.tree_apart(spheres, &rel, threshold) => return TreeAnswer::Apart,
            _ => return TreeAnswer::Unknown,
        };
        let padding = if self.contact_proofs { padding } else { Real::NEG_INFINITY };
        spheres.against_primitive(
            rel.rotation.to_rotation_matrix().matrix(),
            &rel.translation.vector,
            p,
            threshold,
            padding,
        )
    }

    /// The box gap of robot geometry `g` and world object `o` (a lower bound of their distance;
    /// −∞ without boxes), its search stopped at the first axis with a gap above `stop`.
    fn world_box_gap(&self, g: usize, o: usize, stop: Real) -> Real {
        match (&self.boxes[g], &self.world_boxes[o]) {
            (Some(a), Some(b)) => box_gap_past(a, b, stop),
            _ => Real::NEG_INFINITY,
        }
    }

    /// The world pairs of the configuration placed, or only the pairs `only` (geometry, object).
    fn world_check(
        &mut self,
        options: &CheckOptions,
        answer: &mut ConfigurationAnswer,
        only: Option<&[(usize, usize)]>,
    ) -> Result<()> {
        let mut order = std::mem::take(&mut self.order);
        order.clear();
        let most = options.padding + self.pad_max;
        if let Some(pairs) = only {
            order.extend(pairs.iter().map(|&(g, o)| (self.world_gap(g, o), g, o)));
        }
        for g in 0..self.robot.geometries.len() {
            if only.is_some() {
                break;
            }
            let padding = options.padding + self.pad[g];
            for &o in &self.world_pairs[g] {
                if !options.distance && self.world_apart(g, o, padding) {
                    // A verdict only: a pair apart by its balls is decided here, unsorted.
                    answer.pairs_pruned += 1;
                    continue;
                }
                order.push((self.world_gap(g, o), g, o));
            }
        }
        order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut best = Real::INFINITY;
        let mut result = Ok(());
        for (k, &(gap, g, o)) in order.iter().enumerate() {
            // Sorted by gap: past `best` (distance) and every pair's padding, nothing is left.
            if (!options.distance || gap >= best) && gap > most {
                answer.pairs_pruned += order.len() - k;
                break;
            }
            let padding = options.padding + self.pad[g];
            if gap > padding && (!options.distance || gap >= best) {
                answer.pairs_pruned += 1;
                continue;
            }
            let bound = if options.distance { best.max(padding) } else { padding };
            let box_gap = self.world_box_gap(g, o, bound);
            if box_gap > padding && box_gap >= bound {
                answer.pairs_pruned += 1;
                continue;
            }
            let outcome = if self.fidelity.is_mesh() {
                let tree = if self.contact_proofs && self.inner_touches_world(g, o) {
                    TreeAnswer::Touches
                } else if self.sphere_stage {
                    self.tree_against_world(g, o, bound, padding)
                } else {
                    TreeAnswer::Unknown
                };
                match tree {
                    TreeAnswer::Apart => {
                        answer.pairs_spheres += 1;
                        continue;
                    }
                    TreeAnswer::Touches => {
                        answer.pairs_proved += 1;
                        Ok(Some(PairOutcome::Collides))
                    }
                    TreeAnswer::Unknown if self.contact_proofs && self.vertex_touches_world(g, o, padding) => {
                        answer.pairs_proved += 1;
                        Ok(Some(PairOutcome::Collides))
                    }
                    TreeAnswer::Unknown => self.world_pair(g, o, bound, padding, answer),
                }
            } else {
                self.model_world_pair(g, o, bound, padding, answer)
            };
            match outcome {
                Ok(None) => {}
                Ok(Some(PairOutcome::Collides)) => {
                    answer.world = true;
                    answer.pair = Some((g, o));
                    answer.witnesses = None;
                    if options.distance {
                        answer.distance = 0.0;
                    }
                    break;
                }
                Ok(Some(PairOutcome::Free { distance, witnesses })) => {
                    if distance < best {
                        best = distance;
                        answer.pair = Some((g, o));
                        answer.witnesses = witnesses;
                    }
                }
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        if options.distance && !answer.world {
            answer.distance = best;
        }
        self.order = order;
        result
    }

    /// One world pair: `None` when the sos bound shows the pair is at least `bound` apart (and
    /// farther than the padding), else the mesh's answer.
    pub(super) fn world_pair(
        &self,
        g: usize,
        o: usize,
        bound: Real,
        padding: Real,
        answer: &mut ConfigurationAnswer,
    ) -> Result<Option<PairOutcome>> {
        let geometry = &self.robot.geometries[g];
        let obj = &self.world[o];
        let pose = &self.poses[g];
        if let Some(cloud) = self.cloud(o) {
            return Ok(self.cloud_pair(g, o, cloud, bound, padding, answer));
        }
        // A mesh object without a body has no sos bound: its pairs go to the triangles.
        let d = match self.world_sos_shape(o) {
            Some(shape) => {
                answer.pairs_model += 1;
                Some(shape_distance(root_shape(&geometry.shape), pose, shape, &obj.pose, None)?)
            }
            None => None,
        };
        let d = d.filter(|d| d.status.converged());
        if let Some(d) = &d {
            if self.both_primitive(g, o) {
                // Both exact: the primitive answer is the verdict and the distance.
                return Ok(Some(if d.overlapping || d.distance <= padding {
                    PairOutcome::Collides
                } else {
                    PairOutcome::Free { distance: d.distance, witnesses: Some((d.witness_a, d.witness_b)) }
                }));
            }
            if !d.overlapping && d.distance > padding && d.distance >= bound {
                return Ok(None);
            }
        }
        if bound <= padding {
            // A verdict only: no distance needed.
            answer.pairs_exact += 1;
            let (a, b) = (&self.robot_exact[g], &self.world_exact[o]);
            let collides = exact_collides(
                &parry_pose(&(self.poses[g] * a.offset)),
                a,
                &parry_pose(&(obj.pose * b.offset)),
                b,
                padding,
                &PairHint::default(),
            )?;
            return Ok(collides.then_some(PairOutcome::Collides));
        }
        // An upper bound of the mesh's distance: from the primitive's witness (a point of the
        // object; a mesh object's body witness is not one) to the link mesh's surface. The
        // search for the closest triangles stops a little beyond it (parry's GJK distances can
        // exceed the true one by a few µm), and where its answer is not below the bound, the
        // bound and its points are the answer.
        let mut upper = None;
        let primitive_object = matches!(obj.shape, WorldShape::Primitive(_));
        if let (Some(d), true, Some(mesh)) = (&d, primitive_object, self.robot_exact[g].shape.as_trimesh()) {
            use parry3d_f64::query::PointQuery;
            let y = pose.inverse_transform_point(&d.witness_b);
            let p = mesh.project_local_point(parry3d_f64::math::Vector::new(y.x, y.y, y.z), false).point;
            let x = pose.transform_point(&Point3::new(p.x, p.y, p.z));
            upper = Some(((x - d.witness_b).norm(), x, d.witness_b));
        }
        let max_dist = upper.map_or(bound, |(u, _, _)| bound.min(u * (1.0 + 1e-6) + 1e-6));
        let outcome = self.exact_world_pair(g, o, padding, max_dist, answer)?;
        Ok(Some(match (outcome, upper) {
            // The mesh is within `u` of the object: within the padding, a contact.
            (PairOutcome::Free { .. }, Some((u, _, _))) if u <= padding => PairOutcome::Collides,
            (PairOutcome::Free { distance, .. }, Some((u, x, y))) if u < distance && u < bound => {
                PairOutcome::Free { distance: u, witnesses: Some((x, y)) }
            }
            (outcome, _) => outcome,
        }))
    }

    /// A world pair on the mesh (exact; parry's triangle BVH).
    fn exact_world_pair(
        &self,
        g: usize,
        o: usize,
        padding: Real,
        max_dist: Real,
        answer: &mut ConfigurationAnswer,
    ) -> Result<PairOutcome> {
        answer.pairs_exact += 1;
        let (a, b) = (&self.robot_exact[g], &self.world_exact[o]);
        let pa = parry_pose(&(self.poses[g] * a.offset));
        let pb = parry_pose(&(self.world[o].pose * b.offset));
        exact_pair(&pa, a, &pb, b, padding, max_dist, &PairHint::default())
    }
}
