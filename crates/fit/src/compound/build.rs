//! Fitting a compound body to a triangle mesh: decomposition, one fit per part, the containment
//! tree, and the search over part counts.
//!
//! ```text
//! weld:  vertices within τ_w × the bounding-box diagonal merged, collapsed and repeated
//!        triangles dropped (mesh::weld_mesh; τ_w = weld_tolerance, default 1e-9)
//! T:     the excess tolerance, or with auto and none given T = relative_tolerance × the diagonal
//! for N in (fixed N) or (1, 2, 4, 8 until max leaf excess ≤ T):
//!     parts  = decompose(mesh, N)                                          (decompose.rs)
//!     leaf j = fit of the vertices of part j's triangles (paper §III-A, log det P):
//!              with T: the lowest candidate degree whose excess ≤ T (else the smallest excess)
//!              without: the degree `--degree auto` picks (fit::auto, volume tolerance τ)
//! auto, last N, still above T: refine — split the leaf of largest excess > T (VHACD on its own
//!       sub-mesh, else a median cut of its triangles; decompose::split_part) and fit the pieces,
//!       until every leaf ≤ T or max_parts leaves
//! tree: level by level, pair the nodes greedily by the diagonal of their union's bounding box;
//!       each pair gets a parent body containing both bodies (paper §V, S-procedure,
//!       fit::containment::contain_bodies), or the ellipsoid through the corners of the
//!       children's bounding box when that is tighter or the solver fails at every degree
//!       (box_ellipsoid); a node left out moves up alone; until one root
//! excess of every node: sampled one-sided Hausdorff excess over the mesh          (surface.rs)
//! certificate: every parent–child containment certified, a parent short of it rescaled; a
//!       parent shown not to contain a child (its fit checks samples only) replaced by the
//!       tighter of itself rescaled to a certified factor and the box ellipsoid, and certified
//!       (certify.rs, certify_tree_repairing)
//! check: every leaf of excess > T is a miss (CompoundReport::misses, met = no miss)
//! ```
//!
//! The tolerance is met or reported: a miss is not an error here (the body is still conservative
//! and usable), the caller decides (`sublevel fit --parts` exits non-zero on a miss unless told
//! otherwise).
//!
//! Each leaf contains the vertices of its triangles, hence (convexity) its triangles; each parent
//! contains its children's bodies; so every triangle lies in one body at every level of the tree
//! (checked by [`super::check::uncovered_triangles`]). A part whose own vertices are degenerate
//! (flat) is fitted with its VHACD hull points added (then it reaches up to about one voxel beyond
//! the mesh).

use super::decompose::{decompose, split_part, Part, DEFAULT_RESOLUTION, MAX_PARTS};
use super::surface::{MeshSurface, DEFAULT_EXCESS_SAMPLES};
use super::tree::{build_tree, set_depths};
use super::{CompoundBody, CompoundNode, CompoundReport, ToleranceMiss};
use crate::containment::ContainmentSettings;
use crate::mesh::{weld_mesh, TriangleMesh, DEFAULT_WELD_TOLERANCE};
use crate::{auto, fit_points, FitProgress, FitSettings, FitStage, PartProgress};
use crate::{Error, Result};
use std::time::Instant;
use sublevel_core::body::Body;
use sublevel_core::math::{Point3, Real};

/// Part counts `--parts auto` tries, in order (VHACD may return fewer than asked); the last
/// one is refined (its parts above the tolerance split again) up to
/// [`CompoundSettings::max_parts`]. Asking VHACD for more than 8 gains little: parry's VHACD
/// returns at most about 14 parts on the bundled meshes however many are asked.
pub const AUTO_PART_COUNTS: [usize; 4] = [1, 2, 4, 8];

/// Default cap on the part count reached by refinement.
pub const DEFAULT_MAX_PARTS: usize = 32;

/// Default excess tolerance of [`PartCount::Auto`] relative to the mesh's size: T = 0.01 × the
/// diagonal of the bounding box of the (welded) mesh, 1.9–3.3 mm on the Panda's links (0.19–0.33 m
/// diagonals): the millimeters a robot's collision model needs. It is a target, not a promise:
/// on those links the leaves reach 5.6–23 mm beyond the mesh at the default 32 parts (docs/paper.md,
/// compound bodies), so the fit reports every leaf above T ([`CompoundReport::misses`]) rather
/// than a looser default calling a 2 cm body a success.
pub const DEFAULT_RELATIVE_TOLERANCE: Real = 0.01;

/// How many parts to decompose into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PartCount {
    /// At most this many parts (VHACD may return fewer).
    Fixed(usize),
    /// The fewest of [`AUTO_PART_COUNTS`] whose max leaf excess is ≤ the excess tolerance T (or,
    /// above T at 8, those parts refined up to [`CompoundSettings::max_parts`]); T defaults to
    /// [`CompoundSettings::relative_tolerance`] × the mesh's bounding-box diagonal.
    Auto,
}

impl std::str::FromStr for PartCount {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(PartCount::Auto);
        }
        s.parse::<usize>()
            .map(PartCount::Fixed)
            .map_err(|_| Error::invalid("parts", format!("expected a part count or auto, got {s:?}")))
    }
}

/// Settings of [`fit_compound`].
#[derive(Clone, Debug)]
pub struct CompoundSettings {
    /// Settings of every leaf fit (its `degree` is ignored: see `degrees`).
    pub fit: FitSettings,
    /// Candidate leaf degrees 2d, strictly increasing (default 2, 4, 6).
    pub degrees: Vec<usize>,
    /// Relative volume tolerance τ of the degree choice when `excess_tolerance` is None (as
    /// `--degree auto`).
    pub volume_tolerance: Real,
    /// Leaf-excess tolerance T in meters: the lowest degree whose excess is ≤ T per part, and
    /// the fewest parts whose max leaf excess is ≤ T with [`PartCount::Auto`] (there, `None`
    /// means `relative_tolerance` × the mesh's bounding-box diagonal). With a tolerance, every
    /// leaf's excess is checked against it ([`CompoundReport::met`], [`CompoundReport::misses`]).
    pub excess_tolerance: Option<Real>,
    /// T relative to the bounding-box diagonal of the mesh, when [`PartCount::Auto`] has no
    /// `excess_tolerance` (default [`DEFAULT_RELATIVE_TOLERANCE`]).
    pub relative_tolerance: Real,
    /// Relative weld tolerance τ_w of [`weld_mesh`], applied before the decomposition (default
    /// [`DEFAULT_WELD_TOLERANCE`]; 0 merges equal coordinates only); `None` decomposes the
    /// triangles as given.
    pub weld_tolerance: Option<Real>,
    /// Degree 2d of the parent bodies (2, 4 or 6; lowered to (lowest child degree + 2) when the
    /// S-procedure multipliers would need a degree above 2).
    pub parent_degree: usize,
    /// Settings of the containment fits (degree and multiplier degree are set per parent).
    pub containment: ContainmentSettings,
    /// VHACD voxel resolution.
    pub resolution: u32,
    /// Boundary samples per node for the excess.
    pub excess_samples: usize,
    /// Most leaves refinement may reach with [`PartCount::Auto`] (2..=[`MAX_PARTS`]).
    pub max_parts: usize,
}

impl Default for CompoundSettings {
    fn default() -> Self {
        Self {
            fit: FitSettings { volume_samples: 50_000, ..FitSettings::default() },
            degrees: vec![2, 4, 6],
            volume_tolerance: 0.05,
            excess_tolerance: None,
            relative_tolerance: DEFAULT_RELATIVE_TOLERANCE,
            weld_tolerance: Some(DEFAULT_WELD_TOLERANCE),
            parent_degree: 4,
            containment: ContainmentSettings::default().with_volume_samples(50_000),
            resolution: DEFAULT_RESOLUTION,
            excess_samples: DEFAULT_EXCESS_SAMPLES,
            max_parts: DEFAULT_MAX_PARTS,
        }
    }
}

impl CompoundSettings {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degrees`, `volume_tolerance`, `tolerance` (the excess
    /// tolerance: finite, > 0), `relative_tolerance` (in (0, 1)), `weld_tolerance` (in [0, 1e-3]),
    /// `parent_degree`, `resolution` or `excess_samples`.
    pub fn validate(&self) -> Result<()> {
        auto::validate_auto(&self.degrees, self.volume_tolerance)?;
        if !(self.relative_tolerance > 0.0 && self.relative_tolerance < 1.0) {
            return Err(Error::invalid(
                "relative_tolerance",
                format!("must be in (0, 1), got {}", self.relative_tolerance),
            ));
        }
        if let Some(w) = self.weld_tolerance {
            if !(0.0..=1e-3).contains(&w) {
                return Err(Error::invalid("weld_tolerance", format!("must be in [0, 1e-3], got {w}")));
            }
        }
        if let Some(t) = self.excess_tolerance {
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::invalid("tolerance", format!("must be a finite number > 0 meters, got {t}")));
            }
        }
        if ![2, 4, 6].contains(&self.parent_degree) {
            return Err(Error::invalid("parent_degree", format!("must be 2, 4 or 6, got {}", self.parent_degree)));
        }
        if !(8..=512).contains(&self.resolution) {
            return Err(Error::invalid("resolution", format!("must be in 8..=512, got {}", self.resolution)));
        }
        if !(16..=100_000).contains(&self.excess_samples) {
            return Err(Error::invalid(
                "excess_samples",
                format!("must be in 16..=100000, got {}", self.excess_samples),
            ));
        }
        if !(2..=MAX_PARTS).contains(&self.max_parts) {
            return Err(Error::invalid("max_parts", format!("must be in 2..={MAX_PARTS}, got {}", self.max_parts)));
        }
        Ok(())
    }
}

/// Fits a compound body to a triangle mesh (meters; see the module docs): welded first (unless
/// `settings.weld_tolerance` is `None`), every leaf's excess checked against the tolerance at
/// the end. The body contains every triangle of `mesh` as given (merged vertices' original
/// positions are fitted too). Progress messages say which part / parent is being fitted
/// ("parts 8, part 3/8: degree 4: …"), stages and fractions as in [`crate::fit_points`].
/// `mesh_name` goes into the report, with the tolerance used, whether every leaf met it
/// (`met`), the leaves that missed it (`misses`), the weld counts and notes (why a part count
/// was kept, why refinement stopped).
///
/// # Errors
/// [`Error::InvalidArgument`] naming a settings field, `parts` (0 or too many) or `mesh` (no
/// triangles, bad indices, nothing left after welding); [`Error::Numerical`] when the
/// decomposition or a fit fails (naming the part); [`Error::Cancelled`] when cancelled
/// ([`crate::cancel`]). A leaf above the tolerance is not an error: it is reported.
pub fn fit_compound(
    mesh: &TriangleMesh,
    mesh_name: Option<&str>,
    parts: PartCount,
    settings: &CompoundSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<CompoundBody> {
    let start = Instant::now();
    settings.validate()?;
    let mut notes = Vec::new();
    let (welded, weld) = match settings.weld_tolerance {
        Some(tau) => {
            let w = weld_mesh(mesh, tau)?;
            let r = &w.report;
            if r.vertices_after < r.vertices_before || r.triangles_after < r.triangles_before {
                notes.push(format!(
                    "welded (ε = {:.1e} m): {} → {} vertices ({} merged, {} unused), {} → {} triangles ({} collapsed, {} repeated)",
                    r.tolerance,
                    r.vertices_before,
                    r.vertices_after,
                    r.merged_vertices,
                    r.unused_vertices,
                    r.triangles_before,
                    r.triangles_after,
                    r.degenerate_triangles,
                    r.duplicate_triangles
                ));
            }
            (Some(w.mesh.clone()), Some(w))
        }
        None => (None, None),
    };
    // Original positions merged into a welded vertex at another position: fitted with it, so the
    // body contains the mesh as given, not only the welded one.
    let extra = weld.as_ref().map(|w| merged_positions(mesh, w)).unwrap_or_default();
    let input_triangles = mesh.triangles.len();
    let weld = weld.map(|w| w.report);
    let mesh = welded.as_ref().unwrap_or(mesh);
    let mut settings = settings.clone();
    if parts == PartCount::Auto && settings.excess_tolerance.is_none() {
        let t = settings.relative_tolerance * bounding_diagonal(&mesh.vertices);
        if !(t.is_finite() && t > 0.0) {
            return Err(Error::invalid("mesh", "has no extent: its bounding box is a point"));
        }
        notes.push(format!(
            "excess tolerance {t:.4} m: the default {} × the bounding-box diagonal",
            settings.relative_tolerance
        ));
        settings.excess_tolerance = Some(t);
    }
    let settings = &settings;
    let counts: Vec<usize> = match parts {
        PartCount::Fixed(n) => vec![n],
        PartCount::Auto => AUTO_PART_COUNTS.to_vec(),
    };
    let surface = MeshSurface::new(&mesh.vertices, &mesh.triangles)?;
    // Overall fraction: the attempts (decomposition and part fits) up to `attempts_end`, the
    // refinement up to `leaves_end`, the tree (parents, the slowest stage) up to 1.
    let refining = parts == PartCount::Auto && settings.excess_tolerance.is_some();
    let (attempts_end, leaves_end) = if refining { (0.15, 0.4) } else { (0.4, 0.4) };
    let mut attempts = Vec::new();
    let mut best: Option<(Vec<CompoundNode>, Real, Real)> = None; // (leaves, decomposition s, max excess)
    for (a, &n) in counts.iter().enumerate() {
        let t0 = Instant::now();
        let frac = |f: Real| attempts_end * (a as Real + f) / counts.len() as Real;
        report(progress, FitStage::Hull, frac(0.0), format!("parts {n}: convex decomposition (VHACD)"));
        let decomposition = decompose(&mesh.vertices, &mesh.triangles, n, settings.resolution)?;
        let decomposition_seconds = t0.elapsed().as_secs_f64();
        let got = decomposition.len();
        let mut leaves = Vec::with_capacity(got);
        for (j, part) in decomposition.iter().enumerate() {
            let mut inner = |p: &FitProgress| {
                progress(&FitProgress {
                    stage: p.stage,
                    fraction: frac((j as Real + p.fraction) / got as Real).min(1.0),
                    message: format!("parts {n}, part {}/{got}: {}", j + 1, p.message),
                    part: Some(PartProgress { index: j + 1, count: got }),
                })
            };
            leaves.push(fit_leaf(mesh, &extra, part, j, &surface, settings, &mut inner)?);
        }
        if let (PartCount::Auto, Some(t)) = (parts, settings.excess_tolerance) {
            if a + 1 == counts.len() {
                let before = leaves.len();
                let source = Source { mesh, extra: &extra };
                let stop = refine(
                    source,
                    decomposition,
                    &mut leaves,
                    t,
                    &surface,
                    settings,
                    (attempts_end, leaves_end),
                    progress,
                )?;
                if leaves.len() > before {
                    notes.push(format!(
                        "{before} VHACD parts refined to {}: parts with excess above {t:.4} m split again",
                        leaves.len()
                    ));
                }
                let above = leaves.iter().filter(|l| l.excess > t).count();
                match stop {
                    _ if above == 0 => {}
                    RefineStop::MaxParts => notes.push(format!(
                        "refinement stopped at --max-parts {} leaves with {above} leaves still above {t:.4} m",
                        settings.max_parts
                    )),
                    RefineStop::Unsplittable => notes.push(format!(
                        "refinement stopped with {} leaves: the {above} leaves above {t:.4} m cannot be split further (one triangle, or a piece the solver fails on)",
                        leaves.len()
                    )),
                }
            }
        }
        let max_excess = leaves.iter().map(|l| l.excess).fold(0.0, Real::max);
        attempts.push((n, leaves.len(), max_excess, t0.elapsed().as_secs_f64()));
        let better = best.as_ref().is_none_or(|b| max_excess < b.2);
        if better {
            best = Some((leaves, decomposition_seconds, max_excess));
        }
        if let Some(t) = settings.excess_tolerance {
            if max_excess <= t {
                if parts == PartCount::Auto {
                    notes.push(format!(
                        "{} parts kept: the fewest tried whose max leaf excess {max_excess:.4} m is ≤ {t:.4} m",
                        leaves_len_of(&best)
                    ));
                }
                break;
            }
            if a + 1 == counts.len() {
                notes.push(format!(
                    "no part count tried reached the excess tolerance {t:.4} m; kept the smallest max leaf excess"
                ));
            }
        }
    }
    let Some((leaves, decomposition_seconds, _)) = best else {
        return Err(Error::invalid("parts", "no part count to try"));
    };
    let leaf_fit_seconds = leaves.iter().map(|l| l.fit_seconds).sum();
    let t_tree = Instant::now();
    let nodes = build_tree(leaves, &surface, settings, leaves_end, progress)?;
    let root = nodes.len() - 1;
    let mut nodes = nodes;
    set_depths(&mut nodes, root);
    // Every parent certified to contain its children (the fits check containment on samples; a
    // parent short of a certificate is rescaled, one shown to miss a child replaced: see
    // `certify`).
    report(progress, FitStage::Verify, 1.0, format!("certifying the containment of {} nodes", nodes.len()));
    let mut excess = |b: &Body| surface.excess(b, settings.excess_samples);
    let certified = super::certify::certify_tree_repairing(&mut nodes, &mut excess)?;
    // (A replaced parent's rescale, by more, has its own note.)
    let rescaled = certified
        .certificates
        .iter()
        .filter(|c| matches!(c.proof, super::certify::ContainmentProof::Rescaled { .. }))
        .filter(|c| certified.repairs.iter().all(|r| r.parent != c.parent))
        .count();
    if rescaled > 0 {
        notes.push(format!("{rescaled} parent–child containments certified after rescaling the parent (at most 10⁻³)"));
    }
    notes.extend(certified.repairs.iter().map(repair_note));
    let tree_fit_seconds = t_tree.elapsed().as_secs_f64();
    let misses = settings.excess_tolerance.map(|t| tolerance_misses(&nodes, t));
    let report = CompoundReport {
        mesh: mesh_name.map(str::to_owned),
        mesh_triangles: input_triangles,
        tolerance: settings.excess_tolerance,
        attempts,
        decomposition_seconds,
        leaf_fit_seconds,
        tree_fit_seconds,
        total_seconds: start.elapsed().as_secs_f64(),
        excess_samples: settings.excess_samples,
        notes,
        met: misses.as_ref().map(Vec::is_empty),
        misses: misses.unwrap_or_default(),
        weld,
    };
    let body = CompoundBody::new(nodes, root, report)?;
    report_done(progress, &body);
    Ok(body)
}

/// The report's note on a parent that [`super::certify::certify_tree_repairing`] replaced.
fn repair_note(r: &super::certify::Repair) -> String {
    let by = match r.replacement {
        super::certify::Replacement::Rescaled { factor } => format!("itself rescaled by {factor:.6}"),
        super::certify::Replacement::BoxEllipsoid => {
            "the ellipsoid through the corners of its children's bounding box".into()
        }
    };
    format!(
        "node {} did not contain its child node {} (p = {:.6} at ({:.6}, {:.6}, {:.6}) m): replaced by {by}, the tighter candidate (excess {:.4} m, was {:.4} m), and certified",
        r.parent, r.child, r.value, r.point.x, r.point.y, r.point.z, r.excess, r.excess_before
    )
}

/// The leaves (nodes without children) whose excess is above `t`, largest excess first.
fn tolerance_misses(nodes: &[CompoundNode], t: Real) -> Vec<ToleranceMiss> {
    let mut misses: Vec<ToleranceMiss> = nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| n.children.is_empty() && (n.excess > t || n.excess.is_nan()))
        .map(|(node, n)| ToleranceMiss { node, triangles: n.triangles, excess: n.excess })
        .collect();
    misses.sort_by(|a, b| b.excess.total_cmp(&a.excess));
    misses
}

/// Leaves of the kept attempt (for the note of an auto search that met its tolerance).
fn leaves_len_of(best: &Option<(Vec<CompoundNode>, Real, Real)>) -> usize {
    best.as_ref().map_or(0, |b| b.0.len())
}

/// Diagonal (meters) of the bounding box of `points`; 0 for none.
fn bounding_diagonal(points: &[Point3]) -> Real {
    let Some(first) = points.first() else { return 0.0 };
    let (lo, hi) = points.iter().fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    (hi - lo).norm()
}

/// For every welded vertex, the positions of the input vertices merged into it that differ from
/// its own (empty for a vertex merged only with exact copies).
fn merged_positions(input: &TriangleMesh, weld: &crate::mesh::WeldedMesh) -> Vec<Vec<Point3>> {
    let mut extra = vec![Vec::new(); weld.mesh.vertices.len()];
    for (v, w) in weld.source.iter().enumerate() {
        if let Some(w) = w {
            let p = input.vertices[v];
            let list: &mut Vec<Point3> = &mut extra[*w as usize];
            if p != weld.mesh.vertices[*w as usize] && !list.contains(&p) {
                list.push(p);
            }
        }
    }
    extra
}

/// The mesh the leaves are fitted to, with the merged positions of its welded vertices.
#[derive(Clone, Copy)]
struct Source<'a> {
    mesh: &'a TriangleMesh,
    extra: &'a [Vec<Point3>],
}

/// Why refinement stopped with leaves above the tolerance.
enum RefineStop {
    /// The leaf count reached [`CompoundSettings::max_parts`] (or the next split would pass it).
    MaxParts,
    /// No leaf above the tolerance can be split (one triangle, or the solver fails on a piece).
    Unsplittable,
}

fn report(progress: &mut dyn FnMut(&FitProgress), stage: FitStage, fraction: Real, message: String) {
    progress(&FitProgress { stage, fraction: fraction.min(1.0), message, part: None });
}

fn report_done(progress: &mut dyn FnMut(&FitProgress), body: &CompoundBody) {
    report(
        progress,
        FitStage::Done,
        1.0,
        format!(
            "{} parts, {} nodes, max leaf excess {:.4} m, root excess {:.4} m",
            body.leaf_count(),
            body.node_count(),
            body.max_leaf_excess(),
            body.node(body.root()).excess
        ),
    );
}

/// Fits one part (see the module docs) to its vertices and the positions merged into them
/// (`extra`, by vertex; may be empty); the node's depth is set later.
#[allow(clippy::too_many_arguments)]
fn fit_leaf(
    mesh: &TriangleMesh,
    extra: &[Vec<Point3>],
    part: &Part,
    index: usize,
    surface: &MeshSurface,
    settings: &CompoundSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<CompoundNode> {
    let t0 = Instant::now();
    let mut own: Vec<Point3> = part.vertices.iter().map(|&i| mesh.vertices[i as usize]).collect();
    for &i in &part.vertices {
        if let Some(more) = extra.get(i as usize) {
            own.extend_from_slice(more);
        }
    }
    let (body, excess) = match fit_leaf_points(&own, surface, settings, progress) {
        Err(Error::InvalidArgument { field, reason }) if field == "points" && !part.hull.is_empty() => {
            // A flat part: its VHACD hull gives it volume.
            let mut with_hull = own.clone();
            with_hull.extend_from_slice(&part.hull);
            let (mut b, e) =
                fit_leaf_points(&with_hull, surface, settings, progress).map_err(|e| name_part(e, index))?;
            b.report.notes.push(format!(
                "part {index}: its vertices alone were degenerate ({reason}); its VHACD hull points were added"
            ));
            (b, e)
        }
        other => other.map_err(|e| name_part(e, index))?,
    };
    Ok(CompoundNode {
        body,
        children: Vec::new(),
        depth: 0,
        excess,
        triangles: part.triangles.len(),
        fit_seconds: t0.elapsed().as_secs_f64(),
    })
}

fn name_part(e: Error, index: usize) -> Error {
    match e {
        Error::Numerical(m) => Error::Numerical(format!("part {index}: {m}")),
        other => other,
    }
}

/// Largest |coefficient| a leaf fit of degree above the lowest candidate may have (normalized
/// coordinates, where the body's boundary is p = 1): about 7 of the 16 digits of a value near the
/// boundary survive cancellation.
pub const MAX_LEAF_COEFFICIENT: Real = 1e9;

fn max_coefficient(body: &Body) -> Real {
    body.polynomial().coefficients().iter().fold(0.0, |m: Real, c| m.max(c.abs()))
}

/// The body of one part and its excess: the lowest degree within the excess tolerance, or the
/// `--degree auto` choice without one; with a tolerance, higher degrees whose coefficients exceed
/// [`MAX_LEAF_COEFFICIENT`] are not tried further.
fn fit_leaf_points(
    points: &[Point3],
    surface: &MeshSurface,
    settings: &CompoundSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(Body, Real)> {
    let Some(t) = settings.excess_tolerance else {
        let body = auto::fit_auto(points, &settings.fit, &settings.degrees, settings.volume_tolerance, progress)?;
        let e = surface.excess(&body, settings.excess_samples)?;
        return Ok((body, e));
    };
    let mut best: Option<(Body, Real)> = None;
    for &degree in &settings.degrees {
        let s = FitSettings { degree, ..settings.fit.clone() };
        let body = match fit_points(points, &s, progress) {
            Ok(b) => b,
            Err(Error::Numerical(_)) if best.is_some() => break,
            Err(e) => return Err(e),
        };
        // A nearly flat part can give a higher degree a polynomial of huge coefficients (1e15 on
        // chair_101's seat at 2d = 6): its values near the boundary lose most of their digits to
        // cancellation, so such a fit is not a candidate when a lower degree has one.
        if best.is_some() && max_coefficient(&body) > MAX_LEAF_COEFFICIENT {
            break;
        }
        let e = surface.excess(&body, settings.excess_samples)?;
        let done = e <= t;
        if best.as_ref().is_none_or(|b| e < b.1) {
            best = Some((body, e));
        }
        if done {
            break;
        }
    }
    let (mut body, e) = best.ok_or_else(|| Error::invalid("degrees", "need at least one candidate degree"))?;
    body.report.notes.push(format!("degree {} chosen by excess {e:.4} m against the tolerance {t} m", body.degree()));
    Ok((body, e))
}

/// Refinement: while a leaf's excess is above `t` and fewer than `settings.max_parts` leaves
/// exist, the leaf of largest excess is split ([`split_part`]) and its pieces fitted anew; a
/// leaf that cannot split (one triangle, or a piece the solver fails on) stays. `leaves[j]` is the fit of `parts[j]`.
/// Progress fractions run over `span` as the leaf count goes to `settings.max_parts`. Returns
/// why it stopped (meaningful when leaves above `t` remain).
#[allow(clippy::too_many_arguments)]
fn refine(
    source: Source<'_>,
    parts: Vec<Part>,
    leaves: &mut Vec<CompoundNode>,
    t: Real,
    surface: &MeshSurface,
    settings: &CompoundSettings,
    span: (Real, Real),
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<RefineStop> {
    let mesh = source.mesh;
    let first = leaves.len();
    let room = settings.max_parts.saturating_sub(first).max(1) as Real;
    let mut parts: Vec<(Part, bool)> = parts.into_iter().map(|p| (p, true)).collect();
    let mut capped = false;
    loop {
        if leaves.len() >= settings.max_parts {
            return Ok(RefineStop::MaxParts);
        }
        let worst = (0..leaves.len())
            .filter(|&j| parts[j].1 && leaves[j].excess > t)
            .max_by(|&a, &b| leaves[a].excess.total_cmp(&leaves[b].excess));
        let Some(j) = worst else {
            return Ok(if capped { RefineStop::MaxParts } else { RefineStop::Unsplittable });
        };
        let pieces = split_part(&mesh.vertices, &mesh.triangles, &parts[j].0, settings.resolution);
        if pieces.len() >= 2 && leaves.len() + pieces.len() - 1 > settings.max_parts {
            capped = true;
        }
        if pieces.len() < 2 || leaves.len() + pieces.len() - 1 > settings.max_parts {
            parts[j].1 = false;
            continue;
        }
        let n = leaves.len();
        let count = n + pieces.len() - 1;
        let mut fitted = Vec::with_capacity(pieces.len());
        for (k, piece) in pieces.iter().enumerate() {
            let mut inner = |p: &FitProgress| {
                let within = (k as Real + p.fraction) / pieces.len() as Real;
                let done = ((n - first) as Real + (pieces.len() - 1) as Real * within) / room;
                progress(&FitProgress {
                    stage: p.stage,
                    fraction: (span.0 + (span.1 - span.0) * done).min(span.1),
                    message: format!(
                        "refining ({n} parts), piece {}/{} of part {j}: {}",
                        k + 1,
                        pieces.len(),
                        p.message
                    ),
                    // The piece becomes leaf j (the first) or a new leaf after the others.
                    part: Some(PartProgress { index: if k == 0 { j + 1 } else { n + k }, count }),
                })
            };
            match fit_leaf(mesh, source.extra, piece, n + k, surface, settings, &mut inner) {
                Ok(leaf) => fitted.push(leaf),
                // A piece the solver cannot fit: the part stays whole (its fit is valid).
                Err(Error::Numerical(_)) => break,
                Err(e) => return Err(e),
            }
        }
        if fitted.len() < pieces.len() {
            parts[j].1 = false;
            continue;
        }
        let mut pieces = pieces.into_iter();
        let mut fitted = fitted.into_iter();
        if let (Some(p), Some(l)) = (pieces.next(), fitted.next()) {
            parts[j] = (p, true);
            leaves[j] = l;
        }
        parts.extend(pieces.map(|p| (p, true)));
        leaves.extend(fitted);
    }
}
