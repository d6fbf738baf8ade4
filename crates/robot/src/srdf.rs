//! SRDF: MoveIt's semantic robot description, the part of it collision checking uses.
//!
//! - `<disable_collisions link1="A" link2="B" reason="…"/>`: contacts between links A and B are
//!   allowed (adjacent links, links that can never touch, links always in contact). They become
//!   the robot's allowed-collision pairs ([`RobotModel::self_collision_pairs`]).
//! - `<group_state name="ready" group="arm"><joint name="j" value="0.5"/>…</group_state>`: named
//!   configurations of a group (radians or meters).
//! - `<virtual_joint name parent_frame child_link type/>`: how the root attaches to the world.
//!
//! Groups, end effectors and passive joints are not read yet. The XML is read with `quick-xml`
//! (already the URDF parser's XML reader); unknown elements are skipped.

use crate::model::RobotModel;
use crate::{Error, Result};
use quick_xml::events::{BytesStart, Event};
use std::collections::HashSet;
use sublevel_core::math::Real;

/// A pair of links whose contacts are allowed, with the SRDF's reason (`Adjacent`, `Never`, …).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DisabledPair {
    /// First link's name.
    pub link1: String,
    /// Second link's name.
    pub link2: String,
    /// The SRDF's `reason` (empty when absent).
    pub reason: String,
}

/// A named configuration of a group.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupState {
    /// The state's name (e.g. `ready`).
    pub name: String,
    /// The group it is a state of.
    pub group: String,
    /// Joint values by name (radians or meters).
    pub joints: Vec<(String, Real)>,
    /// Joints given several values (MoveIt's multi-DOF joints: a planar or floating root, e.g.
    /// `root_joint` at `0 0 1.02 0 0 0 1`), by name, kept as read: a robot model has no such
    /// joint, so [`Semantics::known_to`] skips them with a warning.
    pub multi_dof: Vec<(String, Vec<Real>)>,
}

/// The virtual joint attaching the root link to the world.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VirtualJoint {
    /// Its name.
    pub name: String,
    /// The world frame it hangs from.
    pub parent_frame: String,
    /// The robot link it carries.
    pub child_link: String,
    /// `fixed`, `floating` or `planar`.
    pub kind: String,
}

/// What an SRDF says, as read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Semantics {
    /// The robot's name.
    pub name: String,
    /// Link pairs whose contacts are allowed.
    pub disabled_pairs: Vec<DisabledPair>,
    /// Named configurations.
    pub group_states: Vec<GroupState>,
    /// Virtual joints.
    pub virtual_joints: Vec<VirtualJoint>,
}

/// The value of attribute `key` of `e`, unescaped.
fn attribute(field: &str, e: &BytesStart<'_>, key: &str) -> Result<Option<String>> {
    for a in e.attributes() {
        let a = a.map_err(|err| Error::invalid(field, format!("malformed attribute: {err}")))?;
        if a.key.local_name().as_ref() == key.as_bytes() {
            let v = a.unescape_value().map_err(|err| Error::invalid(field, format!("attribute `{key}`: {err}")))?;
            return Ok(Some(v.into_owned()));
        }
    }
    Ok(None)
}

/// A required attribute.
fn required(field: &str, e: &BytesStart<'_>, key: &str) -> Result<String> {
    attribute(field, e, key)?.ok_or_else(|| Error::invalid(field, format!("needs the attribute `{key}`")))
}

impl Semantics {
    /// Reads an SRDF document.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `srdf` for malformed XML (with its byte position), or
    /// `srdf.disable_collisions[k]` / `srdf.group_state[k]` / `srdf.virtual_joint[k]` for an element
    /// missing a required attribute or with a joint value that is not a finite number.
    pub fn from_srdf_str(text: &str) -> Result<Self> {
        let mut reader = quick_xml::Reader::from_str(text);
        let mut out = Semantics::default();
        let mut state: Option<GroupState> = None;
        loop {
            let position = reader.buffer_position();
            let event = reader
                .read_event()
                .map_err(|e| Error::invalid("srdf", format!("malformed XML near byte {position}: {e}")))?;
            let (e, empty) = match &event {
                Event::Start(e) => (e, false),
                Event::Empty(e) => (e, true),
                Event::End(e) => {
                    if e.local_name().as_ref() == b"group_state" {
                        out.group_states.extend(state.take());
                    }
                    continue;
                }
                Event::Eof => break,
                _ => continue,
            };
            match e.local_name().as_ref() {
                b"robot" => out.name = attribute("srdf.robot", e, "name")?.unwrap_or_default(),
                b"disable_collisions" => {
                    let field = format!("srdf.disable_collisions[{}]", out.disabled_pairs.len());
                    out.disabled_pairs.push(DisabledPair {
                        link1: required(&field, e, "link1")?,
                        link2: required(&field, e, "link2")?,
                        reason: attribute(&field, e, "reason")?.unwrap_or_default(),
                    });
                }
                b"group_state" => {
                    let field = format!("srdf.group_state[{}]", out.group_states.len());
                    let s = GroupState {
                        name: required(&field, e, "name")?,
                        group: required(&field, e, "group")?,
                        joints: Vec::new(),
                        multi_dof: Vec::new(),
                    };
                    if empty {
                        out.group_states.push(s);
                    } else {
                        state = Some(s);
                    }
                }
                b"joint" => {
                    if let Some(s) = state.as_mut() {
                        let k = s.joints.len() + s.multi_dof.len();
                        let field = format!("srdf.group_state[{}].joint[{k}]", out.group_states.len());
                        let name = required(&field, e, "name")?;
                        let text = required(&field, e, "value")?;
                        let values: Option<Vec<Real>> = text
                            .split_whitespace()
                            .map(|v| v.parse().ok().filter(|v: &Real| v.is_finite()))
                            .collect::<Option<_>>()
                            .filter(|v: &Vec<Real>| !v.is_empty());
                        let Some(values) = values else {
                            return Err(Error::invalid(
                                &field,
                                format!(
                                    "value `{}` is not a finite number (or several, for a multi-DOF joint)",
                                    sublevel_core::error::clip(&text)
                                ),
                            ));
                        };
                        if let [value] = values[..] {
                            s.joints.push((name, value));
                        } else {
                            s.multi_dof.push((name, values));
                        }
                    }
                }
                b"virtual_joint" => {
                    let field = format!("srdf.virtual_joint[{}]", out.virtual_joints.len());
                    out.virtual_joints.push(VirtualJoint {
                        name: required(&field, e, "name")?,
                        parent_frame: attribute(&field, e, "parent_frame")?.unwrap_or_default(),
                        child_link: required(&field, e, "child_link")?,
                        kind: attribute(&field, e, "type")?.unwrap_or_default(),
                    });
                }
                _ => {}
            }
        }
        Ok(out)
    }

    /// Reads an SRDF file.
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be read; as [`Semantics::from_srdf_str`].
    pub fn from_srdf_file(path: &std::path::Path) -> Result<Self> {
        Self::from_srdf_str(&std::fs::read_to_string(path)?)
    }
}

impl Semantics {
    /// The SRDF as MoveIt's SRDF loader keeps it for `model`: `disable_collisions` entries that
    /// name a link the URDF lacks, and group-state joints that are not joints of the URDF, are
    /// skipped, each with a warning naming its element (real SRDFs name links of other versions of
    /// their URDF: MoveIt warns and skips them). Also the warnings, in document order.
    pub fn known_to(&self, model: &RobotModel) -> (Semantics, Vec<String>) {
        let mut warnings = Vec::new();
        let mut kept = self.clone();
        kept.disabled_pairs.clear();
        for (k, p) in self.disabled_pairs.iter().enumerate() {
            let missing: Vec<&str> = [&p.link1, &p.link2]
                .into_iter()
                .filter(|l| model.link_index(l).is_none())
                .map(String::as_str)
                .collect();
            if missing.is_empty() {
                kept.disabled_pairs.push(p.clone());
            } else {
                let names: Vec<String> =
                    missing.iter().map(|l| format!("`{}`", sublevel_core::error::clip(l))).collect();
                warnings.push(format!(
                    "srdf.disable_collisions[{k}]: skipped, link {} is not in the robot",
                    names.join(" and ")
                ));
            }
        }
        for (g, state) in kept.group_states.iter_mut().enumerate() {
            let mut joints = Vec::with_capacity(state.joints.len());
            for (k, (name, value)) in state.joints.drain(..).enumerate() {
                if model.joints().iter().any(|j| j.name == name) {
                    joints.push((name, value));
                } else {
                    warnings.push(format!(
                        "srdf.group_state[{g}].joint[{k}]: skipped, joint `{}` is not in the robot",
                        sublevel_core::error::clip(&name)
                    ));
                }
            }
            state.joints = joints;
            for (name, values) in state.multi_dof.drain(..) {
                warnings.push(format!(
                    "srdf.group_state[{g}]: skipped joint `{}` of {} values, a planar or floating joint (the robot has \
                     none: its base pose is given apart)",
                    sublevel_core::error::clip(&name),
                    values.len()
                ));
            }
        }
        (kept, warnings)
    }
}

impl RobotModel {
    /// The pairs of links on one rigid body ([`RobotModel::rigid_pairs`]) that `allowed` (link
    /// names, either order) does not already allow, by name: left out of self-collision checking
    /// all the same, and listed in the fit report and the robot's summary.
    pub fn rigid_pairs_not_in(&self, allowed: &[[String; 2]]) -> Vec<[String; 2]> {
        let name = |l: usize| self.links()[l].name.clone();
        self.rigid_pairs()
            .into_iter()
            .map(|(i, j)| [name(i), name(j)])
            .filter(|[a, b]| !allowed.iter().any(|[c, d]| (a == c && b == d) || (a == d && b == c)))
            .collect()
    }

    /// The link pairs `(i, j)`, `i < j` (indices of [`RobotModel::links`]), that self-collision
    /// checking must test: both links have collision geometry and the pair is not among
    /// `allowed` (pairs of link names whose contacts are allowed, e.g. an SRDF's
    /// [`Semantics::disabled_pairs`], in either order) nor on one rigid body
    /// ([`RobotModel::rigid_pairs`]: no joint moves them relative to each other).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `srdf.disable_collisions[k]` when a pair names a link the
    /// robot does not have.
    pub fn self_collision_pairs(&self, allowed: &[DisabledPair]) -> Result<Vec<(usize, usize)>> {
        let mut skip = HashSet::new();
        for (k, p) in allowed.iter().enumerate() {
            let index = |name: &str| {
                self.link_index(name).ok_or_else(|| {
                    let shown = sublevel_core::error::clip(name);
                    Error::invalid(
                        format!("srdf.disable_collisions[{k}]"),
                        format!("link `{shown}` is not in the robot"),
                    )
                })
            };
            let (a, b) = (index(&p.link1)?, index(&p.link2)?);
            skip.insert((a.min(b), a.max(b)));
        }
        skip.extend(self.rigid_pairs());
        let with_geometry: Vec<usize> =
            (0..self.links().len()).filter(|&l| !self.links()[l].collision.is_empty()).collect();
        let mut pairs = Vec::new();
        for (n, &i) in with_geometry.iter().enumerate() {
            for &j in &with_geometry[n + 1..] {
                if !skip.contains(&(i, j)) {
                    pairs.push((i, j));
                }
            }
        }
        Ok(pairs)
    }
}
