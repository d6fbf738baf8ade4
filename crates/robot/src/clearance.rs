//! Clearance tables: a self pair whose relative pose depends on one or two joints gets a grid over
//! those joints' range holding the meshes' distance at every cell's center, so most
//! configurations decide the pair with one lookup instead of a tree descent.
//!
//! ```text
//! pair (a, b), common ancestor link C; the joints between C and a, and between C and b:
//!     one or two configuration entries q_i (no mimic joint), each with a finite range
//! grid: n_i cells of width h_i over [lower_i, upper_i]; cell centers c
//! stored: ⌊d(c) / unit⌋ (capped at 255), d the exact mesh distance at c (0 when touching)
//! at q:  d(q) ≥ stored · unit − Σ_i ρ_i |q_i − c_i|        (c the center of q's cell)
//!        > padding                                        → the pair is free, no other test
//! ```
//!
//! **Why the bound holds.** Turning a revolute joint by δ moves a point at distance r from its
//! axis by at most r·|δ| (the chord of the arc), and a prismatic joint by δ moves every point by
//! |δ|; the joints above C move both links together. `ρ_i` bounds the distance from joint i's axis
//! of every point of the link it moves (for a mesh, every vertex: the distance to a line is
//! convex, so a triangle's farthest point is a vertex), whatever the joints below it do, from the
//! joint origins along the chain ([`side_rates`]). The distance between two point sets changes by
//! at most how far their points move, and moving from c to q one entry at a time moves them by at
//! most `Σ ρ_i |q_i − c_i|`. The stored value is rounded down. So the bound never exceeds the
//! meshes' distance: a pair the table calls free, the mesh checker calls free too (the labels'
//! 0 misses are re-measured with the tables on).
//!
//! **Grid size.** `h_i = 2·max_loss / (k·ρ_i)` for `k` entries, so the Lipschitz term is at most
//! `max_loss` (4 mm by default) at a cell's corner; tables above `max_cells` are made coarser. On
//! the Panda the four pairs of link 5 with link 7, the hand and the fingers (joints 6 and 7) get
//! 28 000–41 000 cells each: link 5–link 7 reached the sphere trees in 79 % of uniform
//! configurations, at 2–5 cm, and with its table in 9 % (`docs/robots.md`).
//!
//! **Staleness.** Each table carries a SHA-256 key of everything its distances depend on: both
//! geometries (shape and origin), every joint between them, the grid and the unit. A robot file
//! whose table no longer matches its geometry or joints is refused, naming the table.

use crate::check::exact_shape;
use crate::exact::{exact_pair, meshes_touch, parry_pose, PairHint, PairOutcome};
use crate::fitted::{FittedRobot, LinkShape, RobotGeometry};
use crate::model::{Joint, JointKind, JointValue, RobotModel};
use crate::{Error, Result};
use base64::Engine;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};
use sublevel_core::math::{Isometry3, Real, Vector3};

mod cell;
use cell::{mesh_cell, stored};

/// Meters per stored step of a clearance table (values 0..=255: up to 5.1 cm).
pub const CLEARANCE_UNIT: Real = 2e-4;

/// Most cells one table may hold in a robot file.
pub const MAX_CLEARANCE_CELLS: usize = 1 << 22;

/// How clearance tables are built ([`build_clearance_tables`]).
#[derive(Clone, Debug)]
pub struct ClearanceSettings {
    /// Most the bound may lose at a cell's corner (meters, > 0): sets the cell widths.
    pub max_loss: Real,
    /// Most cells per table (≥ 1): a finer grid is made coarser to fit.
    pub max_cells: usize,
    /// Threads computing distances (0: one per available core).
    pub threads: usize,
}

impl Default for ClearanceSettings {
    fn default() -> Self {
        Self { max_loss: 0.004, max_cells: 1 << 17, threads: 0 }
    }
}

/// A clearance table as stored in a robot file (`"clearance": [...]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClearanceFile {
    /// The two geometries' names (`LINK` or `LINK#k`, [`RobotGeometry::name`]).
    pub geometries: [String; 2],
    /// The configuration entries the pair depends on (joint names; one or two).
    pub joints: Vec<String>,
    /// Each entry's lower end of the grid (radians or meters).
    pub lower: Vec<Real>,
    /// Each entry's upper end of the grid.
    pub upper: Vec<Real>,
    /// Cells along each entry (≥ 1).
    pub cells: Vec<usize>,
    /// Meters per stored step ([`CLEARANCE_UNIT`]).
    pub unit: Real,
    /// SHA-256 (hex) of the geometries, the joints between them, the grid and the unit.
    pub key: String,
    /// The cells' values (one byte each, the first entry's index slowest), base64.
    pub data: String,
    /// For two meshes, the cells that touch at their center with a touching triangle pair there:
    /// `(cell, triangle of the first, triangle of the second)` as little-endian `u32` triples,
    /// by increasing cell, base64. A check tests that pair first.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub contacts: String,
}

/// One entry of a table's grid.
#[derive(Clone, Copy, Debug)]
struct Axis {
    /// Configuration entry.
    variable: usize,
    lower: Real,
    width: Real,
    count: usize,
    /// Most any point of the pair moves relative to the other per unit of the entry (m/rad, or
    /// 1 for a prismatic joint).
    rate: Real,
    /// A continuous joint: values are taken modulo 2π into the grid's range.
    wrap: bool,
}

/// A clearance table as the checks use it (module docs).
#[derive(Clone, Debug)]
pub struct ClearanceTable {
    /// The pair, as geometry indices (smaller first).
    pub geometries: (usize, usize),
    axes: Vec<Axis>,
    unit: Real,
    cells: Vec<u8>,
    /// `(cell, triangle of a, triangle of b)` by increasing cell ([`ClearanceFile::contacts`]).
    contacts: Vec<(u32, u32, u32)>,
}

impl ClearanceTable {
    /// A lower bound of the pair's mesh distance at configuration `q` (meters; −∞ when an entry
    /// lies outside the grid).
    pub fn lower_bound(&self, q: &[Real]) -> Real {
        self.lookup(q).map_or(Real::NEG_INFINITY, |(_, bound)| bound)
    }

    /// The cell of `q` and [`ClearanceTable::lower_bound`] there; `None` outside the grid.
    pub fn lookup(&self, q: &[Real]) -> Option<(usize, Real)> {
        let mut index = 0;
        let mut loss = 0.0;
        for a in &self.axes {
            let mut v = q[a.variable];
            if a.wrap {
                v = a.lower + (v - a.lower).rem_euclid(2.0 * PI);
            }
            let s = (v - a.lower) / a.width;
            if !(0.0..=a.count as Real).contains(&s) {
                return None;
            }
            let i = (s as usize).min(a.count - 1);
            loss += a.rate * (v - center(a.lower, a.width, i)).abs();
            index = index * a.count + i;
        }
        Some((index, Real::from(self.cells[index]) * self.unit - loss))
    }

    /// The triangle pair (of the first geometry's mesh, of the second's) touching at the center
    /// of `cell`, if the table stored one.
    pub fn contact(&self, cell: usize) -> Option<(u32, u32)> {
        let k = self.contacts.binary_search_by_key(&cell, |c| c.0 as usize).ok()?;
        Some((self.contacts[k].1, self.contacts[k].2))
    }

    /// Cells in the table.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether the table has no cells (never, once validated).
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }
}

/// The center of cell `i` of an axis (the same expression when building and when reading).
fn center(lower: Real, width: Real, i: usize) -> Real {
    lower + (i as Real + 0.5) * width
}

/// The joints a self pair depends on: the configuration entries (joint index, entry) between the
/// two links and their common ancestor, with each entry's rate, and every joint on both paths
/// (for the key). `None` when the pair cannot have a table: a mimic joint on the path, no entry or
/// more than two, an entry without a finite range, or a halfspace.
struct PairChain {
    entries: Vec<(usize, usize, Real)>,
    path: Vec<usize>,
}

/// The joints from link `l` up to the root (child first).
fn chain_up(model: &RobotModel, mut l: usize) -> Vec<usize> {
    let mut out = Vec::new();
    while let Some(j) = model.links()[l].parent_joint {
        out.push(j);
        l = model.joints()[j].parent;
    }
    out
}

/// A geometry as balls in its link's frame: a mesh's vertices (radius 0), a primitive's
/// bounding ball; `None` for a halfspace.
fn link_balls(g: &RobotGeometry) -> Option<Vec<(Vector3, Real)>> {
    match &g.shape {
        LinkShape::Mesh { vertices, .. } => Some(vertices.iter().map(|v| ((g.origin * v).coords, 0.0)).collect()),
        LinkShape::Primitive(p) => {
            p.local_half_extents()?;
            Some(vec![(g.origin.translation.vector, p.bounding_radius())])
        }
    }
}

/// Points known as exact balls, or only as within `radius` of `anchor` (module docs).
enum Reach {
    Balls(Vec<(Vector3, Real)>),
    Bound { anchor: Vector3, radius: Real },
}

impl Reach {
    /// The largest distance of a point from the line through the origin along unit `axis`.
    fn axis_distance(&self, axis: &Vector3) -> Real {
        let off = |p: &Vector3| (p - axis * axis.dot(p)).norm();
        match self {
            Reach::Balls(b) => b.iter().map(|(c, r)| off(c) + r).fold(0.0, Real::max),
            Reach::Bound { anchor, radius } => off(anchor) + radius,
        }
    }

    /// A ball around an anchor on the axis holding every turn of the points about it.
    fn swept(&self, axis: &Vector3) -> (Vector3, Real) {
        match self {
            Reach::Balls(b) => {
                let along: Vec<Real> = b.iter().map(|(c, _)| axis.dot(c)).collect();
                let lo = along.iter().copied().fold(Real::INFINITY, Real::min);
                let hi = along.iter().copied().fold(Real::NEG_INFINITY, Real::max);
                let anchor = axis * (0.5 * (lo + hi));
                let radius = b.iter().map(|(c, r)| (c - anchor).norm() + r).fold(0.0, Real::max);
                (anchor, radius)
            }
            Reach::Bound { anchor, radius } => {
                let on = axis * axis.dot(anchor);
                (on, (anchor - on).norm() + radius)
            }
        }
    }

    /// The points in the frame `t` maps them into.
    fn transformed(self, t: &Isometry3) -> Self {
        match self {
            Reach::Balls(b) => {
                Reach::Balls(b.into_iter().map(|(c, r)| (t.transform_point(&c.into()).coords, r)).collect())
            }
            Reach::Bound { anchor, radius } => {
                Reach::Bound { anchor: t.transform_point(&anchor.into()).coords, radius }
            }
        }
    }
}

/// The entries moving the link of `balls` (its frame) relative to the frame above `path` (the
/// joints from the common ancestor down to the link, parents first), each with its rate: the most
/// any point moves per unit of the entry, whatever the joints below do (module docs). `None` for
/// a mimic joint on the path or a prismatic joint without limits.
fn side_rates(model: &RobotModel, path: &[usize], balls: Vec<(Vector3, Real)>) -> Option<Vec<(usize, usize, Real)>> {
    let mut reach = Reach::Balls(balls);
    let mut out = Vec::new();
    for &j in path.iter().rev() {
        let joint = &model.joints()[j];
        match (joint.kind, joint.value) {
            (JointKind::Fixed, _) | (_, JointValue::Fixed) => {}
            (_, JointValue::Mimic { .. }) => return None,
            (JointKind::Revolute | JointKind::Continuous, JointValue::Variable(k)) => {
                out.push((j, k, reach.axis_distance(&joint.axis)));
                let (anchor, radius) = reach.swept(&joint.axis);
                reach = Reach::Bound { anchor, radius };
            }
            (JointKind::Prismatic, JointValue::Variable(k)) => {
                let (lo, hi) = joint.limits?;
                out.push((j, k, 1.0));
                let (anchor, radius) = match reach {
                    Reach::Balls(b) => {
                        let anchor = b.iter().map(|(c, _)| c).sum::<Vector3>() / b.len().max(1) as Real;
                        (anchor, b.iter().map(|(c, r)| (c - anchor).norm() + r).fold(0.0, Real::max))
                    }
                    Reach::Bound { anchor, radius } => (anchor, radius),
                };
                reach =
                    Reach::Bound { anchor: anchor + joint.axis * (0.5 * (lo + hi)), radius: radius + 0.5 * (hi - lo) };
            }
        }
        reach = reach.transformed(&joint.origin);
    }
    Some(out)
}

/// The grid range of a joint: its limits, or one turn for a continuous joint (wrapped).
fn joint_range(joint: &Joint) -> Option<(Real, Real, bool)> {
    match joint.kind {
        JointKind::Continuous => Some((-PI, PI, true)),
        JointKind::Revolute | JointKind::Prismatic => {
            let (lo, hi) = joint.limits?;
            (lo.is_finite() && hi.is_finite() && hi > lo).then_some((lo, hi, false))
        }
        JointKind::Fixed => None,
    }
}

/// The chain of the pair of geometries `a`, `b` (see [`PairChain`]).
fn pair_chain(robot: &FittedRobot, a: usize, b: usize) -> Option<PairChain> {
    let model = &robot.model;
    let (ga, gb) = (&robot.geometries[a], &robot.geometries[b]);
    if ga.link == gb.link {
        return None;
    }
    let (ca, cb) = (chain_up(model, ga.link), chain_up(model, gb.link));
    let side_a: Vec<usize> = ca.iter().rev().filter(|j| !cb.contains(j)).copied().collect();
    let side_b: Vec<usize> = cb.iter().rev().filter(|j| !ca.contains(j)).copied().collect();
    let mut entries = side_rates(model, &side_a, link_balls(ga)?)?;
    entries.extend(side_rates(model, &side_b, link_balls(gb)?)?);
    if entries.is_empty() || entries.len() > 2 {
        return None;
    }
    if entries.iter().any(|&(j, _, rate)| joint_range(&model.joints()[j]).is_none() || !rate.is_finite()) {
        return None;
    }
    entries.sort_by_key(|e| e.1);
    Some(PairChain { entries, path: side_a.into_iter().chain(side_b).collect() })
}

/// The key of a table (module docs).
fn table_key(
    robot: &FittedRobot,
    a: usize,
    b: usize,
    chain: &PairChain,
    grid: &[(Real, Real, usize)],
    unit: Real,
) -> String {
    let mut h = Sha256::new();
    let reals = |h: &mut Sha256, v: &[Real]| v.iter().for_each(|x| h.update(x.to_le_bytes()));
    for g in [&robot.geometries[a], &robot.geometries[b]] {
        h.update(g.name.as_bytes());
        reals(&mut h, g.origin.translation.vector.as_slice());
        reals(&mut h, g.origin.rotation.coords.as_slice());
        match &g.shape {
            LinkShape::Primitive(p) => h.update(format!("{p:?}").as_bytes()),
            LinkShape::Mesh { vertices, triangles, .. } => {
                vertices.iter().for_each(|v| reals(&mut h, v.coords.as_slice()));
                triangles.iter().flatten().for_each(|i| h.update(i.to_le_bytes()));
            }
        }
    }
    for &j in &chain.path {
        let joint = &robot.model.joints()[j];
        h.update(format!("{}|{:?}|{:?}", joint.name, joint.kind, joint.value).as_bytes());
        reals(&mut h, joint.origin.translation.vector.as_slice());
        reals(&mut h, joint.origin.rotation.coords.as_slice());
        reals(&mut h, joint.axis.as_slice());
    }
    for &(lo, hi, n) in grid {
        reals(&mut h, &[lo, hi]);
        h.update((n as u64).to_le_bytes());
    }
    reals(&mut h, &[unit]);
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Builds a clearance table for every geometry pair of the robot's checked self pairs that can
/// have one (module docs), computing the meshes' distance at every cell center on
/// `settings.threads` threads; `progress` receives a line per table.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `max_loss` (not finite and > 0) or `max_cells` (0);
/// [`Error::ResourceExhausted`] for more than [`crate::limits::MAX_CLEARANCE_TABLES`] tables;
/// [`Error::Numerical`] when a distance fails; [`Error::Cancelled`] once this thread's
/// [`sublevel_core::cancel`] scope is cancelled (checked between blocks of 256 cells on every
/// thread).
pub fn build_clearance_tables(
    robot: &FittedRobot,
    settings: &ClearanceSettings,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<ClearanceFile>> {
    if !(settings.max_loss.is_finite() && settings.max_loss > 0.0) {
        return Err(Error::invalid("max_loss", format!("must be finite and > 0 m, got {}", settings.max_loss)));
    }
    if settings.max_cells == 0 || settings.max_cells > MAX_CLEARANCE_CELLS {
        return Err(Error::invalid("max_cells", format!("must be 1 to {MAX_CLEARANCE_CELLS}")));
    }
    let threads = match settings.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    };
    let mut pairs = Vec::new();
    let n = robot.geometries.len();
    let self_pairs: std::collections::HashSet<(usize, usize)> = robot.self_pairs.iter().copied().collect();
    for a in 0..n {
        for b in a + 1..n {
            let (la, lb) = (robot.geometries[a].link, robot.geometries[b].link);
            if !self_pairs.contains(&(la.min(lb), la.max(lb))) {
                continue;
            }
            sublevel_core::cancel::check()?;
            if let Some(chain) = pair_chain(robot, a, b) {
                pairs.push((a, b, chain));
            }
        }
    }
    if pairs.len() > crate::limits::MAX_CLEARANCE_TABLES {
        return Err(crate::limits::exceeded("clearance tables", pairs.len(), crate::limits::MAX_CLEARANCE_TABLES));
    }
    let count = pairs.len();
    let mut files = Vec::with_capacity(count);
    for (k, (a, b, chain)) in pairs.into_iter().enumerate() {
        sublevel_core::cancel::check()?;
        let start = std::time::Instant::now();
        let file = build_table(robot, a, b, &chain, settings, threads)?;
        progress(&format!(
            "clearance table {}/{count} {}–{}: {:?} cells over {:?}, {:.1} s",
            k + 1,
            robot.geometries[a].name,
            robot.geometries[b].name,
            file.cells,
            file.joints,
            start.elapsed().as_secs_f64()
        ));
        files.push(file);
    }
    Ok(files)
}

/// One table (see [`build_clearance_tables`]).
fn build_table(
    robot: &FittedRobot,
    a: usize,
    b: usize,
    chain: &PairChain,
    settings: &ClearanceSettings,
    threads: usize,
) -> Result<ClearanceFile> {
    let model = &robot.model;
    let k = chain.entries.len() as Real;
    let mut grid: Vec<(Real, Real, usize)> = Vec::new();
    for &(j, _, rate) in &chain.entries {
        let (lo, hi, _) = joint_range(&model.joints()[j]).unwrap_or((0.0, 0.0, false));
        let n = ((hi - lo) * rate * k / (2.0 * settings.max_loss)).ceil().clamp(1.0, 1e7) as usize;
        grid.push((lo, hi, n));
    }
    let total: usize = grid.iter().map(|g| g.2).product();
    if total > settings.max_cells {
        let f = (settings.max_cells as Real / total as Real).powf(1.0 / k);
        grid.iter_mut().for_each(|g| g.2 = ((g.2 as Real * f).floor() as usize).max(1));
    }
    let counts: Vec<usize> = grid.iter().map(|g| g.2).collect();
    let total: usize = counts.iter().product();
    let (ga, gb) = (&robot.geometries[a], &robot.geometries[b]);
    let (ea, eb) = (exact_shape(ga), exact_shape(gb));
    let unit = CLEARANCE_UNIT;
    let cap = 255.0 * unit;
    let next = AtomicUsize::new(0);
    const BLOCK: usize = 256;
    let blocks: std::sync::Mutex<Vec<(usize, Vec<u8>)>> = std::sync::Mutex::new(Vec::new());
    let contacts: std::sync::Mutex<Vec<(u32, u32, u32)>> = std::sync::Mutex::new(Vec::new());
    let meshes = ea.shape.as_trimesh().zip(eb.shape.as_trimesh());
    let failed: std::sync::Mutex<Option<Error>> = std::sync::Mutex::new(None);
    let cancelled = sublevel_core::cancel::current();
    let stop = || cancelled.as_ref().is_some_and(|f| f.load(Ordering::Relaxed));
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, total.div_ceil(BLOCK)) {
            s.spawn(|| {
                let mut q = vec![0.0; model.dof()];
                let mut poses = Vec::new();
                let hint = PairHint::default();
                let mut out = Vec::with_capacity(BLOCK);
                let mut found = Vec::new();
                loop {
                    let first = next.fetch_add(BLOCK, Ordering::Relaxed);
                    if first >= total || stop() {
                        break;
                    }
                    out.clear();
                    found.clear();
                    for idx in first..(first + BLOCK).min(total) {
                        let mut rest = idx;
                        for (e, &(lo, hi, n)) in chain.entries.iter().zip(&grid).rev() {
                            q[e.1] = center(lo, (hi - lo) / n as Real, rest % n);
                            rest /= n;
                        }
                        if let Err(e) = model.forward_kinematics(&q, &Isometry3::identity(), &mut poses) {
                            if let Ok(mut f) = failed.lock() {
                                *f = Some(e);
                            }
                            return;
                        }
                        let pa = parry_pose(&(poses[ga.link] * ga.origin * ea.offset));
                        let pb = parry_pose(&(poses[gb.link] * gb.origin * eb.offset));
                        // Two meshes: only what can lower the stored value is searched
                        // (`mesh_cell`); other pairs: the exact distance, capped.
                        let (value, touching) = match meshes {
                            Some((ma, mb)) => mesh_cell(ma, &pa, mb, &pb, unit, &hint),
                            None => match exact_pair(&pa, &ea, &pb, &eb, 0.0, cap, &hint) {
                                Ok(PairOutcome::Collides) => (0, true),
                                Ok(PairOutcome::Free { distance, .. }) => (stored(distance, unit), false),
                                Err(e) => {
                                    if let Ok(mut f) = failed.lock() {
                                        *f = Some(e);
                                    }
                                    return;
                                }
                            },
                        };
                        out.push(value);
                        if let (true, Some((ma, mb))) = (touching, meshes) {
                            let touch = PairHint::default();
                            if meshes_touch(ma, &pa, mb, &pb, 0.0, &touch) {
                                if let Some((i, j)) = touch.get() {
                                    found.push((idx as u32, i, j));
                                }
                            }
                        }
                    }
                    if let Ok(mut bl) = blocks.lock() {
                        bl.push((first, out.clone()));
                    }
                    if let Ok(mut c) = contacts.lock() {
                        c.extend_from_slice(&found);
                    }
                }
            });
        }
    });
    if let Some(e) = failed.into_inner().ok().flatten() {
        return Err(e);
    }
    sublevel_core::cancel::check()?;
    let mut blocks = blocks.into_inner().map_err(|_| Error::Numerical("a clearance thread panicked".into()))?;
    blocks.sort_by_key(|b| b.0);
    let cells: Vec<u8> = blocks.into_iter().flat_map(|b| b.1).collect();
    if cells.len() != total {
        return Err(Error::Numerical("a clearance table did not finish".into()));
    }
    let mut contacts = contacts.into_inner().unwrap_or_default();
    contacts.sort_unstable();
    let packed: Vec<u8> = contacts.iter().flat_map(|&(c, i, j)| [c, i, j]).flat_map(u32::to_le_bytes).collect();
    Ok(ClearanceFile {
        geometries: [ga.name.clone(), gb.name.clone()],
        joints: chain.entries.iter().map(|e| model.joints()[e.0].name.clone()).collect(),
        lower: grid.iter().map(|g| g.0).collect(),
        upper: grid.iter().map(|g| g.1).collect(),
        cells: counts,
        unit,
        key: table_key(robot, a, b, chain, &grid, unit),
        data: base64::engine::general_purpose::STANDARD.encode(&cells),
        contacts: base64::engine::general_purpose::STANDARD.encode(&packed),
    })
}

/// Validates a robot file's tables against the robot (field `clearance[k]…`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `clearance[k].geometries` (unknown names, one link, or a
/// pair that cannot have a table), `.joints` (not the entries the pair depends on), `.cells`,
/// `.lower`, `.unit`, `.data` (not base64, or the wrong length) or `.key` (the table does not
/// match the robot's geometry and joints: it is stale).
pub(crate) fn load_tables(robot: &FittedRobot, files: &[ClearanceFile]) -> Result<Vec<ClearanceTable>> {
    let mut out = Vec::with_capacity(files.len());
    for (k, f) in files.iter().enumerate() {
        let field = |name: &str| format!("clearance[{k}].{name}");
        let index = |name: &String| robot.geometries.iter().position(|g| &g.name == name);
        let (Some(a), Some(b)) = (index(&f.geometries[0]), index(&f.geometries[1])) else {
            return Err(Error::invalid(field("geometries"), "names a geometry the robot does not have"));
        };
        let (a, b) = (a.min(b), a.max(b));
        let chain = pair_chain(robot, a, b).ok_or_else(|| {
            Error::invalid(field("geometries"), "this pair does not depend on one or two joints with finite ranges")
        })?;
        let names: Vec<&str> = chain.entries.iter().map(|e| robot.model.joints()[e.0].name.as_str()).collect();
        if f.joints.iter().map(String::as_str).ne(names.iter().copied()) {
            return Err(Error::invalid(field("joints"), format!("the pair depends on {names:?}")));
        }
        let m = names.len();
        if f.cells.len() != m || f.lower.len() != m || f.upper.len() != m {
            return Err(Error::invalid(field("cells"), format!("lower, upper and cells need {m} entries each")));
        }
        let total = f.cells.iter().try_fold(1usize, |t, &n| t.checked_mul(n).filter(|_| n > 0));
        let Some(total) = total.filter(|&t| t <= MAX_CLEARANCE_CELLS) else {
            return Err(Error::invalid(field("cells"), format!("each ≥ 1, at most {MAX_CLEARANCE_CELLS} in all")));
        };
        if f.lower.iter().zip(&f.upper).any(|(lo, hi)| !(lo.is_finite() && hi.is_finite() && lo < hi)) {
            return Err(Error::invalid(field("lower"), "each lower end must be finite and below its upper end"));
        }
        if !(f.unit.is_finite() && f.unit > 0.0) {
            return Err(Error::invalid(field("unit"), "must be finite and > 0 m"));
        }
        let cells = base64::engine::general_purpose::STANDARD
            .decode(&f.data)
            .map_err(|e| Error::invalid(field("data"), format!("not base64: {e}")))?;
        if cells.len() != total {
            return Err(Error::invalid(field("data"), format!("holds {} cells, expected {total}", cells.len())));
        }
        let grid: Vec<(Real, Real, usize)> = (0..m).map(|i| (f.lower[i], f.upper[i], f.cells[i])).collect();
        if table_key(robot, a, b, &chain, &grid, f.unit) != f.key {
            return Err(Error::invalid(
                field("key"),
                "the table does not match the robot's geometry and joints: rebuild it (`sublevel robot tables`)",
            ));
        }
        let contacts = load_contacts(robot, a, b, total, &f.contacts)
            .map_err(|reason| Error::invalid(field("contacts"), reason))?;
        let axes = chain
            .entries
            .iter()
            .zip(&grid)
            .map(|(&(j, variable, rate), &(lower, upper, count))| Axis {
                variable,
                lower,
                width: (upper - lower) / count as Real,
                count,
                rate,
                wrap: robot.model.joints()[j].kind == JointKind::Continuous,
            })
            .collect();
        out.push(ClearanceTable { geometries: (a, b), axes, unit: f.unit, cells, contacts });
    }
    Ok(out)
}

/// Decodes a table's contacts (see [`ClearanceFile::contacts`]) for geometries `a`, `b` and
/// `total` cells; the reason when they do not validate.
fn load_contacts(
    robot: &FittedRobot,
    a: usize,
    b: usize,
    total: usize,
    text: &str,
) -> std::result::Result<Vec<(u32, u32, u32)>, String> {
    if text.is_empty() {
        return Ok(Vec::new());
    }
    let triangles = |g: usize| match &robot.geometries[g].shape {
        LinkShape::Mesh { triangles, .. } => Some(triangles.len()),
        LinkShape::Primitive(_) => None,
    };
    let (Some(na), Some(nb)) = (triangles(a), triangles(b)) else {
        return Err("only a pair of two meshes has contacts".into());
    };
    let bytes = base64::engine::general_purpose::STANDARD.decode(text).map_err(|e| format!("not base64: {e}"))?;
    if bytes.len() % 12 != 0 {
        return Err(format!("{} bytes is not a whole number of (cell, triangle, triangle) triples", bytes.len()));
    }
    let word = |k: usize| u32::from_le_bytes([bytes[k], bytes[k + 1], bytes[k + 2], bytes[k + 3]]);
    let contacts: Vec<(u32, u32, u32)> =
        (0..bytes.len() / 12).map(|k| (word(12 * k), word(12 * k + 4), word(12 * k + 8))).collect();
    if let Some(k) = contacts.iter().position(|&(c, i, j)| c as usize >= total || i as usize >= na || j as usize >= nb)
    {
        return Err(format!("entry {k} names a cell or triangle out of range"));
    }
    if contacts.windows(2).any(|w| w[0].0 >= w[1].0) {
        return Err("cells must be strictly increasing".into());
    }
    Ok(contacts)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value search (`mesh_cell`) against the Panda's stored tables, which the exact stage's
    /// whole distance built cell by cell: every sampled cell gets the stored value, and the cells
    /// stored with a contact are the ones found touching.
    #[test]
    fn the_value_search_gives_the_pandas_stored_values() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
        let robot = FittedRobot::load(&path).unwrap();
        assert_eq!(robot.clearance.len(), 4);
        let mut q = vec![0.0; robot.model.dof()];
        let mut poses = Vec::new();
        let (mut compared, mut touching_cells) = (0, 0);
        for table in &robot.clearance {
            let (ga, gb) = (&robot.geometries[table.geometries.0], &robot.geometries[table.geometries.1]);
            let (ea, eb) = (exact_shape(ga), exact_shape(gb));
            let (ma, mb) = (ea.shape.as_trimesh().unwrap(), eb.shape.as_trimesh().unwrap());
            let hint = PairHint::default();
            // Every 97th cell, and every cell stored with a contact.
            let contact_cells: Vec<usize> = table.contacts.iter().map(|c| c.0 as usize).collect();
            let mut cells: Vec<usize> =
                (0..table.len()).step_by(97).chain(contact_cells.iter().copied().step_by(7)).collect();
            cells.sort_unstable();
            cells.dedup();
            for cell in cells {
                let mut rest = cell;
                for a in table.axes.iter().rev() {
                    q[a.variable] = center(a.lower, a.width, rest % a.count);
                    rest /= a.count;
                }
                robot.model.forward_kinematics(&q, &Isometry3::identity(), &mut poses).unwrap();
                let pa = parry_pose(&(poses[ga.link] * ga.origin));
                let pb = parry_pose(&(poses[gb.link] * gb.origin));
                let (value, touching) = mesh_cell(ma, &pa, mb, &pb, table.unit, &hint);
                assert_eq!(value, table.cells[cell], "{} – {} cell {cell}", ga.name, gb.name);
                assert_eq!(touching, table.contact(cell).is_some(), "{} – {} cell {cell}", ga.name, gb.name);
                compared += 1;
                touching_cells += usize::from(touching);
            }
        }
        assert!(compared > 1000 && touching_cells > 50, "{compared} cells compared, {touching_cells} touching");
    }
}
