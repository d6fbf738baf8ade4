//! The robot model: links and joints of a URDF description as a tree, and the entries of a joint
//! configuration.
//!
//! A URDF (<http://wiki.ros.org/urdf/XML>) describes a tree: every joint names a parent and a child
//! link, every link but one (the root) is the child of exactly one joint. A joint's `origin`
//! (`xyz` in meters, `rpy` fixed-axis roll–pitch–yaw in radians, R = Rz(yaw)·Ry(pitch)·Rx(roll))
//! places the joint frame in the parent link's frame; the child link's frame is the joint frame
//! moved by the joint:
//!
//! ```text
//! revolute, continuous:  rotation by q about the unit axis      (q in radians)
//! prismatic:             translation by q along the unit axis   (q in meters)
//! fixed:                 identity
//! ```
//!
//! The configuration `q` has one entry per moving joint that is not a mimic joint, in the order
//! the URDF lists them ([`RobotModel::variable_names`]). A mimic joint follows its source:
//! `value = multiplier · q_source + offset` (a mimic of a mimic composes). A `mimic` tag on a fixed
//! joint has no effect. Floating, planar and spherical joints are refused: a robot's base pose is
//! given separately ([`crate::kinematics`]).

use crate::{Error, Result};
use nalgebra::{Translation3, Unit};
use std::collections::HashMap;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3, MAX_COORDINATE};

/// How far past a joint limit a value still counts as on it, relative to the bound's size: a
/// value `v` is within `[lo, hi]` when `lo − ε(lo) ≤ v ≤ hi + ε(hi)`, `ε(b) = LIMIT_ROUNDING ·
/// max(1, |b|)` (radians or meters). Floating-point rounding puts planners' states there: OMPL
/// and MoveIt interpolate and enforce bounds in double precision, and a UR5 state sampled on its
/// bound of ±3.14159265 arrives as −3.1415926500000007. Such a state is checked as sent; one past
/// the margin is refused as out of limits.
pub const LIMIT_ROUNDING: Real = 1e-9;

/// How a joint moves its child link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis, within limits (radians).
    Revolute,
    /// Rotation about the axis, unlimited (radians).
    Continuous,
    /// Translation along the axis, within limits (meters).
    Prismatic,
    /// No motion.
    Fixed,
}

/// Where a joint's value comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointValue {
    /// A fixed joint: no value.
    Fixed,
    /// Entry `k` of the configuration.
    Variable(usize),
    /// `multiplier · q[variable] + offset` (a URDF mimic joint, resolved to a configuration entry).
    Mimic {
        /// The configuration entry followed.
        variable: usize,
        /// Multiplier.
        multiplier: Real,
        /// Offset (radians or meters).
        offset: Real,
    },
}

/// The margin past bound `b` that [`LIMIT_ROUNDING`] allows.
fn rounding_margin(b: Real) -> Real {
    LIMIT_ROUNDING * b.abs().max(1.0)
}

/// A joint of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// Its URDF name.
    pub name: String,
    /// How it moves.
    pub kind: JointKind,
    /// The parent link's index in [`RobotModel::links`].
    pub parent: usize,
    /// The child link's index.
    pub child: usize,
    /// Joint frame in the parent link's frame (the URDF `origin`).
    pub origin: Isometry3,
    /// Unit axis in the joint frame (meaningless for a fixed joint).
    pub axis: Vector3,
    /// `(lower, upper)` limits of a revolute or prismatic joint (radians or meters).
    pub limits: Option<(Real, Real)>,
    /// Where its value comes from.
    pub value: JointValue,
    /// The URDF `<limit velocity>` of a revolute, continuous or prismatic joint (radians or
    /// meters per second), where it is given, finite and > 0.
    pub max_velocity: Option<Real>,
}

impl Joint {
    /// Whether `v` lies within the joint's limits, up to [`LIMIT_ROUNDING`] past either bound
    /// (always, for a continuous joint; never, for a value that is not finite).
    pub fn admits(&self, v: Real) -> bool {
        match self.limits {
            _ if !v.is_finite() => false,
            None => true,
            Some((lo, hi)) => lo - rounding_margin(lo) <= v && v <= hi + rounding_margin(hi),
        }
    }

    /// `v` moved into the joint's limits (unchanged for a continuous joint).
    pub fn clamp(&self, v: Real) -> Real {
        self.limits.map_or(v, |(lo, hi)| v.clamp(lo, hi))
    }

    /// The child link's frame in the parent link's frame at joint value `v`: `origin · motion(v)`.
    pub fn transform(&self, v: Real) -> Isometry3 {
        match self.kind {
            JointKind::Fixed => self.origin,
            JointKind::Revolute | JointKind::Continuous => {
                let rotation = UnitQuaternion::from_axis_angle(&Unit::new_unchecked(self.axis), v);
                self.origin * Isometry3::from_parts(Translation3::identity(), rotation)
            }
            JointKind::Prismatic => {
                self.origin * Isometry3::from_parts(Translation3::from(self.axis * v), UnitQuaternion::identity())
            }
        }
    }
}

/// Collision geometry of a link, in the link's frame (URDF `<collision>`).
#[derive(Clone, Debug, PartialEq)]
pub enum CollisionGeometry {
    /// A box of full side lengths `size`, centered at `origin`.
    Box {
        /// Its frame in the link's frame.
        origin: Isometry3,
        /// Full side lengths, meters.
        size: [Real; 3],
    },
    /// A cylinder along z of full `length`, centered at `origin`.
    Cylinder {
        /// Its frame in the link's frame.
        origin: Isometry3,
        /// Radius, meters.
        radius: Real,
        /// Full length, meters.
        length: Real,
    },
    /// A capsule along z: the points within `radius` of the segment of `length` centered at
    /// `origin`.
    Capsule {
        /// Its frame in the link's frame.
        origin: Isometry3,
        /// Radius, meters.
        radius: Real,
        /// Length of the axis segment, meters.
        length: Real,
    },
    /// A ball centered at `origin`.
    Sphere {
        /// Its frame in the link's frame.
        origin: Isometry3,
        /// Radius, meters.
        radius: Real,
    },
    /// A mesh file (`package://…` or a path relative to the URDF), scaled per axis.
    Mesh {
        /// Its frame in the link's frame.
        origin: Isometry3,
        /// The file name as written in the URDF.
        filename: String,
        /// Scale per axis.
        scale: [Real; 3],
    },
}

/// A link of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    /// Its URDF name.
    pub name: String,
    /// The joint whose child it is (`None` for the root).
    pub parent_joint: Option<usize>,
    /// Its collision geometry (empty when it has none).
    pub collision: Vec<CollisionGeometry>,
}

/// A robot: links and joints as a tree, in an order where every joint comes after the joint of its
/// parent link (so forward kinematics is one pass).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotModel {
    /// The URDF robot's name.
    pub name: String,
    links: Vec<Link>,
    /// Joints in tree order (parents first).
    joints: Vec<Joint>,
    /// The root link's index.
    root: usize,
    /// Configuration entry k → joint index.
    variables: Vec<usize>,
}

/// A pose of the URDF, validated: finite, within the coordinate range.
fn urdf_pose(field: &str, pose: &urdf_rs::Pose) -> Result<Isometry3> {
    let (xyz, rpy) = (*pose.xyz, *pose.rpy);
    if xyz.iter().chain(rpy.iter()).any(|v| !v.is_finite()) || xyz.iter().any(|v| v.abs() > MAX_COORDINATE) {
        return Err(Error::invalid(
            field,
            format!("origin xyz {xyz:?} rpy {rpy:?} must be finite (xyz within ±1e6 m)"),
        ));
    }
    let rotation = UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]);
    Ok(Isometry3::from_parts(Translation3::new(xyz[0], xyz[1], xyz[2]), rotation))
}

/// A positive finite length of the URDF.
fn length(field: &str, v: Real) -> Result<Real> {
    if v.is_finite() && v > 0.0 && v <= MAX_COORDINATE {
        Ok(v)
    } else {
        Err(Error::invalid(field, format!("must be a positive length in meters, got {v}")))
    }
}

fn collision(field: &str, c: &urdf_rs::Collision) -> Result<CollisionGeometry> {
    let origin = urdf_pose(&format!("{field}.origin"), &c.origin)?;
    Ok(match &c.geometry {
        urdf_rs::Geometry::Box { size } => {
            let f = format!("{field}.box.size");
            CollisionGeometry::Box { origin, size: [length(&f, size[0])?, length(&f, size[1])?, length(&f, size[2])?] }
        }
        urdf_rs::Geometry::Cylinder { radius, length: l } => CollisionGeometry::Cylinder {
            origin,
            radius: length(&format!("{field}.cylinder.radius"), *radius)?,
            length: length(&format!("{field}.cylinder.length"), *l)?,
        },
        urdf_rs::Geometry::Capsule { radius, length: l } => CollisionGeometry::Capsule {
            origin,
            radius: length(&format!("{field}.capsule.radius"), *radius)?,
            length: length(&format!("{field}.capsule.length"), *l)?,
        },
        urdf_rs::Geometry::Sphere { radius } => {
            CollisionGeometry::Sphere { origin, radius: length(&format!("{field}.sphere.radius"), *radius)? }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale.map_or([1.0; 3], |s| *s);
            if scale.iter().any(|v| !(v.is_finite() && *v != 0.0 && v.abs() <= MAX_COORDINATE)) {
                return Err(Error::invalid(
                    format!("{field}.mesh.scale"),
                    format!("must be finite and nonzero, got {scale:?} (a negative entry mirrors the mesh)"),
                ));
            }
            CollisionGeometry::Mesh { origin, filename: filename.clone(), scale }
        }
    })
}

impl RobotModel {
    /// Reads a robot from URDF text (see the module docs for what is accepted).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `urdf` for text the URDF parser refuses, or the element
    /// (`urdf.joint[NAME]…`, `urdf.link[NAME]…`) that does not validate: an unknown parent or
    /// child link, a link that is the child of two joints, no single root, a cycle, a floating,
    /// planar or spherical joint, a zero axis, limits with lower > upper, a mimic of an unknown or
    /// fixed joint, non-finite or out-of-range numbers.
    pub fn from_urdf_str(text: &str) -> Result<Self> {
        let robot = urdf_rs::read_from_string(text).map_err(|e| Error::invalid("urdf", e.to_string()))?;
        Self::from_urdf(&robot)
    }

    /// Reads a robot from a URDF file.
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be read; as [`RobotModel::from_urdf_str`].
    pub fn from_urdf_file(path: &std::path::Path) -> Result<Self> {
        Self::from_urdf_str(&std::fs::read_to_string(path)?)
    }

    fn from_urdf(robot: &urdf_rs::Robot) -> Result<Self> {
        crate::limits::check_urdf(
            robot.links.len(),
            robot.joints.len(),
            robot.joints.iter().filter(|j| !matches!(j.joint_type, urdf_rs::JointType::Fixed)).count(),
            robot.links.iter().map(|l| l.collision.len()).sum(),
        )?;
        let mut link_index = HashMap::new();
        let mut links = Vec::with_capacity(robot.links.len());
        for l in &robot.links {
            let field = format!("urdf.link[{}]", sublevel_core::error::clip(&l.name));
            if link_index.insert(l.name.clone(), links.len()).is_some() {
                return Err(Error::invalid(field, "a link of this name is defined twice"));
            }
            let collision = l
                .collision
                .iter()
                .enumerate()
                .map(|(k, c)| collision(&format!("{field}.collision[{k}]"), c))
                .collect::<Result<Vec<_>>>()?;
            links.push(Link { name: l.name.clone(), parent_joint: None, collision });
        }
        if links.is_empty() {
            return Err(Error::invalid("urdf", "the robot has no link"));
        }
        // Joints as read, before ordering.
        let mut raw = Vec::with_capacity(robot.joints.len());
        let mut joint_index = HashMap::new();
        for j in &robot.joints {
            let field = format!("urdf.joint[{}]", sublevel_core::error::clip(&j.name));
            if joint_index.insert(j.name.clone(), raw.len()).is_some() {
                return Err(Error::invalid(field, "a joint of this name is defined twice"));
            }
            let kind = match j.joint_type {
                urdf_rs::JointType::Revolute => JointKind::Revolute,
                urdf_rs::JointType::Continuous => JointKind::Continuous,
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                urdf_rs::JointType::Fixed => JointKind::Fixed,
                ref other => {
                    return Err(Error::invalid(
                        format!("{field}.type"),
                        format!("{other:?} joints are not supported: revolute, continuous, prismatic or fixed"),
                    ))
                }
            };
            let link = |which: &str, name: &str| {
                link_index.get(name).copied().ok_or_else(|| {
                    let shown = sublevel_core::error::clip(name);
                    Error::invalid(format!("{field}.{which}"), format!("link `{shown}` is not defined"))
                })
            };
            let (parent, child) = (link("parent", &j.parent.link)?, link("child", &j.child.link)?);
            if let Some(previous) = links[child].parent_joint {
                let other = &robot.joints[previous].name;
                return Err(Error::invalid(
                    format!("{field}.child"),
                    format!("link `{}` is already the child of joint `{other}`", links[child].name),
                ));
            }
            links[child].parent_joint = Some(raw.len());
            let origin = urdf_pose(&format!("{field}.origin"), &j.origin)?;
            let axis = Vector3::from(*j.axis.xyz);
            let norm = axis.norm();
            if kind != JointKind::Fixed && !(norm.is_finite() && norm > 1e-12) {
                return Err(Error::invalid(format!("{field}.axis"), "the axis must be a finite nonzero vector"));
            }
            let axis = if kind == JointKind::Fixed { Vector3::x() } else { axis / norm };
            let limits = match kind {
                JointKind::Revolute | JointKind::Prismatic => {
                    let (lo, hi) = (j.limit.lower, j.limit.upper);
                    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                        return Err(Error::invalid(
                            format!("{field}.limit"),
                            format!("lower {lo} and upper {hi} must be finite with lower ≤ upper"),
                        ));
                    }
                    Some((lo, hi))
                }
                _ => None,
            };
            let value = if kind == JointKind::Fixed { JointValue::Fixed } else { JointValue::Variable(usize::MAX) };
            let v = j.limit.velocity;
            let max_velocity = (kind != JointKind::Fixed && v.is_finite() && v > 0.0).then_some(v);
            raw.push(Joint { name: j.name.clone(), kind, parent, child, origin, axis, limits, value, max_velocity });
        }
        let roots: Vec<usize> = (0..links.len()).filter(|&l| links[l].parent_joint.is_none()).collect();
        let [root] = roots[..] else {
            let names: Vec<&str> = roots.iter().take(5).map(|&l| links[l].name.as_str()).collect();
            return Err(Error::invalid(
                "urdf",
                format!("a robot is a tree with one root link; {} links have no parent joint: {names:?}", roots.len()),
            ));
        };
        // Configuration entries: moving, non-mimic joints in URDF order.
        let mut variables = Vec::new();
        for (k, j) in robot.joints.iter().enumerate() {
            if raw[k].kind != JointKind::Fixed && j.mimic.is_none() {
                raw[k].value = JointValue::Variable(variables.len());
                variables.push(k);
            }
        }
        // Mimic joints, resolved to a configuration entry (following chains of mimics).
        for (k, j) in robot.joints.iter().enumerate() {
            let Some(m) = &j.mimic else { continue };
            if raw[k].kind == JointKind::Fixed {
                continue;
            }
            let field = format!("urdf.joint[{}].mimic", sublevel_core::error::clip(&j.name));
            let (mut multiplier, mut offset) = (m.multiplier.unwrap_or(1.0), m.offset.unwrap_or(0.0));
            if !(multiplier.is_finite() && offset.is_finite()) {
                return Err(Error::invalid(field, "multiplier and offset must be finite"));
            }
            let mut source = &m.joint;
            let mut steps = 0;
            let variable = loop {
                let Some(&s) = joint_index.get(source) else {
                    let shown = sublevel_core::error::clip(source);
                    return Err(Error::invalid(field, format!("joint `{shown}` is not defined")));
                };
                if raw[s].kind == JointKind::Fixed {
                    return Err(Error::invalid(field, format!("joint `{}` is fixed: nothing to follow", raw[s].name)));
                }
                match (&robot.joints[s].mimic, raw[s].value) {
                    (None, JointValue::Variable(v)) => break v,
                    (Some(next), _) if steps < robot.joints.len() => {
                        let (m2, o2) = (next.multiplier.unwrap_or(1.0), next.offset.unwrap_or(0.0));
                        // value = m·(m2·q + o2) + o
                        offset += multiplier * o2;
                        multiplier *= m2;
                        source = &next.joint;
                        steps += 1;
                    }
                    _ => return Err(Error::invalid(field, "mimic joints follow each other in a cycle")),
                }
            };
            raw[k].value = JointValue::Mimic { variable, multiplier, offset };
        }
        // Tree order: breadth first from the root (every link reachable, else a cycle).
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
        for (k, j) in raw.iter().enumerate() {
            children[j.parent].push(k);
        }
        let mut order = Vec::with_capacity(raw.len());
        let mut queue = std::collections::VecDeque::from([root]);
        while let Some(l) = queue.pop_front() {
            for &k in &children[l] {
                order.push(k);
                queue.push_back(raw[k].child);
            }
        }
        if order.len() != raw.len() {
            return Err(Error::invalid("urdf", "the joints form a cycle: some links are not reachable from the root"));
        }
        // Renumber joints in tree order.
        let mut new_index = vec![0; raw.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        for l in &mut links {
            l.parent_joint = l.parent_joint.map(|j| new_index[j]);
        }
        let variables = variables.iter().map(|&old| new_index[old]).collect();
        let joints = order.iter().map(|&old| raw[old].clone()).collect();
        Ok(Self { name: robot.name.clone(), links, joints, root, variables })
    }

    /// The links, indexed as [`crate::kinematics`] returns their poses.
    pub fn links(&self) -> &[Link] {
        &self.links
    }

    /// The joints, parents before children.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// The root link's index.
    pub fn root(&self) -> usize {
        self.root
    }

    /// Number of configuration entries (moving, non-mimic joints).
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// The joint of configuration entry `k`.
    pub fn variable_joint(&self, k: usize) -> &Joint {
        &self.joints[self.variables[k]]
    }

    /// The names of the configuration's entries, in order.
    pub fn variable_names(&self) -> Vec<&str> {
        self.variables.iter().map(|&j| self.joints[j].name.as_str()).collect()
    }

    /// The rigid body each link belongs to, by link index: links joined by fixed joints (a chain
    /// of them) share one, the index of the link nearest the root among them. No joint moves two
    /// links of one rigid body relative to each other, so their geometries keep one relative
    /// pose in every configuration.
    pub fn rigid_bodies(&self) -> Vec<usize> {
        let mut body: Vec<usize> = (0..self.links.len()).collect();
        for joint in &self.joints {
            if joint.kind == JointKind::Fixed {
                body[joint.child] = body[joint.parent];
            }
        }
        body
    }

    /// The pairs `(i, j)`, `i < j`, of links with collision geometry on one rigid body
    /// ([`RobotModel::rigid_bodies`]): their contact never changes, so self-collision checking
    /// leaves them out, as MoveIt's setup assistant disables them ("Adjacent" or "Always") and
    /// pinocchio never pairs geometries of one joint.
    pub fn rigid_pairs(&self) -> Vec<(usize, usize)> {
        let body = self.rigid_bodies();
        let with_geometry: Vec<usize> =
            (0..self.links.len()).filter(|&l| !self.links[l].collision.is_empty()).collect();
        let mut pairs = Vec::new();
        for (n, &i) in with_geometry.iter().enumerate() {
            for &j in &with_geometry[n + 1..] {
                if body[i] == body[j] {
                    pairs.push((i.min(j), i.max(j)));
                }
            }
        }
        pairs
    }

    /// The index of the link named `name`.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// Checks a configuration against the joint limits (revolute and prismatic joints; continuous
    /// joints have none), up to [`LIMIT_ROUNDING`] past a bound.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `field[k]` for the first entry outside its joint's limits
    /// (with the joint's name), or a configuration of the wrong length or with a non-finite entry.
    pub fn check_limits(&self, field: &str, q: &[Real]) -> Result<()> {
        self.check_configuration(field, q)?;
        for (k, (&v, &j)) in q.iter().zip(&self.variables).enumerate() {
            let joint = &self.joints[j];
            if let (false, Some((lo, hi))) = (joint.admits(v), joint.limits) {
                return Err(Error::invalid(
                    format!("{field}[{k}]"),
                    format!("joint `{}` at {v} is outside its limits [{lo}, {hi}]", joint.name),
                ));
            }
        }
        Ok(())
    }

    /// Full configurations from columns of named joints, as planners send them: `names` the
    /// joints given (each once; empty: every configuration entry, in
    /// [`RobotModel::variable_names`] order), `values` `len(names)` values per configuration
    /// (radians, meters), configuration-major. Entries not named take `defaults` (by joint name;
    /// names the robot lacks are ignored), else 0.
    ///
    /// Every value must lie within its joint's URDF limits, ends included, up to
    /// [`LIMIT_ROUNDING`] past them ([`Joint::admits`]; revolute and
    /// prismatic joints; continuous joints take any finite value, wrapped by the kinematics): a
    /// state outside them is not one a planner may take, so it is refused rather than answered.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `field.joint_names[c]` (a joint the robot lacks, a fixed
    /// or mimic joint, or a repeat), `field.values` (a length that is not a positive multiple of
    /// the columns) or `field.values[i]` (not finite, or outside its joint's limits).
    pub fn configurations(
        &self,
        field: &str,
        names: &[String],
        values: &[Real],
        defaults: &[(String, Real)],
    ) -> Result<Vec<Vec<Real>>> {
        self.columns(field, names, values, defaults, true)
    }

    /// As [`RobotModel::configurations`], with values outside the joint limits kept as given, for
    /// a caller that moves them into the limits itself and says so (a plan's start state, as
    /// MoveIt's `FixStartStateBounds` adapter does).
    ///
    /// # Errors
    /// As [`RobotModel::configurations`], less the limits.
    pub fn configurations_outside_limits(
        &self,
        field: &str,
        names: &[String],
        values: &[Real],
        defaults: &[(String, Real)],
    ) -> Result<Vec<Vec<Real>>> {
        self.columns(field, names, values, defaults, false)
    }

    /// [`RobotModel::configurations`], with the limits checked when `limits`.
    fn columns(
        &self,
        field: &str,
        names: &[String],
        values: &[Real],
        defaults: &[(String, Real)],
        limits: bool,
    ) -> Result<Vec<Vec<Real>>> {
        let all = self.variable_names();
        let columns: Vec<usize> = if names.is_empty() {
            (0..all.len()).collect()
        } else {
            let mut seen = vec![false; all.len()];
            names
                .iter()
                .enumerate()
                .map(|(c, n)| {
                    let k = all.iter().position(|v| v == n).ok_or_else(|| {
                        Error::invalid(
                            format!("{field}.joint_names[{c}]"),
                            format!(
                                "`{}` is not a moving joint of the robot; its joints: {all:?}",
                                sublevel_core::error::clip(n)
                            ),
                        )
                    })?;
                    if std::mem::replace(&mut seen[k], true) {
                        return Err(Error::invalid(format!("{field}.joint_names[{c}]"), format!("`{n}` is repeated")));
                    }
                    Ok(k)
                })
                .collect::<Result<_>>()?
        };
        let n = columns.len();
        if n == 0 || values.is_empty() || !values.len().is_multiple_of(n) {
            return Err(Error::invalid(
                format!("{field}.values"),
                format!("expected a positive multiple of the {n} columns, got {} values", values.len()),
            ));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("{field}.values[{i}]"), "joint values must be finite numbers"));
        }
        let mut base = vec![0.0; all.len()];
        for (name, v) in defaults {
            if let Some(k) = all.iter().position(|n| n == name) {
                base[k] = *v;
            }
        }
        for (i, &v) in values.iter().enumerate().filter(|_| limits) {
            let joint = &self.joints[self.variables[columns[i % n]]];
            if let (false, Some((lo, hi))) = (joint.admits(v), joint.limits) {
                return Err(Error::invalid(
                    format!("{field}.values[{i}]"),
                    format!(
                        "joint `{}` at {v} is outside its URDF limits [{lo}, {hi}] (a planner's state must lie \
                         within them, up to a rounding of {LIMIT_ROUNDING}·max(1, |bound|); continuous joints take \
                         any value)",
                        joint.name
                    ),
                ));
            }
        }
        Ok(values
            .chunks_exact(n)
            .map(|row| {
                let mut q = base.clone();
                for (c, &v) in row.iter().enumerate() {
                    q[columns[c]] = v;
                }
                q
            })
            .collect())
    }

    /// Checks a configuration's length and that its entries are finite.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `field` (wrong length) or `field[k]` (not finite).
    pub fn check_configuration(&self, field: &str, q: &[Real]) -> Result<()> {
        if q.len() != self.dof() {
            return Err(Error::invalid(
                field,
                format!("{} values for the {} joints {:?}", q.len(), self.dof(), self.variable_names()),
            ));
        }
        if let Some(k) = q.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("{field}[{k}]"), "joint values must be finite numbers"));
        }
        Ok(())
    }
}

/// The file a URDF mesh name refers to, resolved as ROS and pinocchio do:
///
/// - `package://NAME/PATH` → the first existing `DIR/NAME/PATH` over `package_dirs`;
/// - `file:///ABS` and absolute paths → themselves;
/// - a relative path → relative to the URDF's directory `urdf_dir`.
///
/// For the command line only: the service never resolves a name on its disk
/// ([`crate::fit::MeshSource::Memory`]).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` when no candidate file exists, listing the places
/// searched.
pub fn resolve_mesh_path(
    field: &str,
    filename: &str,
    urdf_dir: Option<&std::path::Path>,
    package_dirs: &[std::path::PathBuf],
) -> Result<std::path::PathBuf> {
    use std::path::{Path, PathBuf};
    let candidates: Vec<PathBuf> = if let Some(rest) = filename.strip_prefix("package://") {
        package_dirs.iter().map(|d| d.join(rest)).collect()
    } else if let Some(abs) = filename.strip_prefix("file://") {
        vec![PathBuf::from(abs)]
    } else if Path::new(filename).is_absolute() {
        vec![PathBuf::from(filename)]
    } else {
        vec![urdf_dir.unwrap_or(Path::new(".")).join(filename)]
    };
    if let Some(found) = candidates.iter().find(|p| p.is_file()) {
        return Ok(found.clone());
    }
    let shown = sublevel_core::error::clip(filename);
    let searched: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
    let hint = if filename.starts_with("package://") && package_dirs.is_empty() {
        " (give the directory holding the package with --package-dir)".to_owned()
    } else {
        String::new()
    };
    Err(Error::invalid(field, format!("mesh `{shown}` not found; searched {searched:?}{hint}")))
}
