//! Point-cloud obstacles as bodies: the cloud's Euclidean clusters, each fitted by a sos-convex
//! body (paper §III) that contains the noise ball of every one of its points, kept from frame to
//! frame while it still contains them.
//!
//! ```text
//! cluster   chains of points with steps ≤ `tolerance` (PCL's EuclideanClusterExtraction), by
//!           union-find over a grid of cubes of side `tolerance`; clusters under `min_points` are
//!           outliers and dropped;
//!           clusters over `max_points` are split at the median of their longest box axis until
//!           every part fits                                         [`euclidean_clusters`]
//! cover     every point's ball B(p, r) is replaced by a polytope that contains it, the cube
//!           p + r·[−1, 1]³ (8 vertices, reach r√3) or the circumscribed icosahedron (12
//!           vertices, reach 1.26 r)                                 [`BallCover`]
//! fit       sublevel-fit on the cover's vertices (its hull stage keeps the hull vertices as the
//!           SDP's containment rows): a convex body containing every vertex of a polytope
//!           contains the polytope, hence the ball; a fit that fails gets a bounding ball
//!                                                                   [`fit_cluster`]
//! verify    p ≤ 1 at every cover vertex, with the same evaluation as every later check; a
//!           body over 1 somewhere (rounding) is rescaled until it is not
//! reuse     a new frame's cluster matched to one of the last frame's (same fingerprint, or
//!           centroid, box and size alike) keeps the old body unchanged when p ≤ 1 at the cover
//!           vertices of every new point                                 [`CloudBodies::update`]
//! rescale   a matched cluster the old body no longer contains, whose largest cover value v
//!           keeps the body's growth since its last fit (the product of its rescales) within
//!           `rescale_limit`, gets the old body's p / v: convex, containing every new ball, no
//!           SDP (the previous frame's fit is the warm start)
//! fit       the rest, on `threads` threads at once, largest clusters first
//! ```
//!
//! Only convex fits are accepted (sos-convex p, `LogDetP` / `TraceP` / `LogDetH` / `TraceH`
//! with no convexity relaxation): the vertex argument needs convexity. Clarabel starts every
//! solve cold, so the warm start is the old body itself: kept (reuse) or rescaled, which costs
//! one pass over the cover vertices and the body's tables instead of an SDP. The sdsos / dsos
//! cones of paper §VI (`FitSettings::convexity_cone`) are accepted too: each fit's Clarabel time
//! falls by about a sixth and a fifth, and the bodies grow by about a fifth and a third
//! (docs/point_clouds.md), so the psd cone stays the default.
//!
//! Cost (release, a loaded 2-core machine; the ignored tests of `tests/cloud_bodies.rs`): the
//! cover of 50–2000 points has 40–170 hull vertices, so a fit hardly depends on n: 20–50 ms at
//! 2d = 2 (Clarabel 2–9 ms, the body's query tables most of the rest) and 45–120 ms at 2d = 4
//! (Clarabel 25–85 ms); a reuse check is 0.01–2 ms. Degree 4 buys tightness: body volume over the
//! hull of the balls 1.2–2.1 against 1.25–3.2 at 2d = 2 (box-like clusters gain most).

mod cluster;
mod cover;

pub use cluster::euclidean_clusters;
pub use cover::{ball_hull_volume, max_cover_value, BallCover, COVER_SLACK};

use super::MAX_NOISE_RADIUS;
use crate::{Error, Result};
use cluster::{index_box, validate_clustering};
use std::hash::{Hash, Hasher};
use std::sync::Arc;
use std::time::Instant;
use sublevel_core::body::Body;
use sublevel_core::error::show_real;
use sublevel_core::math::{Real, Vector3, MAX_COORDINATE};
use sublevel_fit::{FitMethod, FitSettings};

/// Largest clustering `tolerance` (meters): a chain step of a meter already joins a room's
/// furniture into one cluster, and the clustering grid's cubes have this side.
pub const MAX_TOLERANCE: Real = 1.0;

/// The default most clusters of one frame ([`CloudBodySettings::max_clusters`]): the
/// MotionBenchMaker scenes' frames have 5–20 clusters and a room's 42 (docs/point_clouds.md);
/// 256 fits at 20–100 ms each are seconds of work, about the most one sensor frame should take.
pub const DEFAULT_MAX_CLUSTERS: usize = 256;

/// The largest [`CloudBodySettings::max_clusters`] a caller may ask for.
pub const MAX_CLUSTERS: usize = 4096;

/// Settings of [`CloudBodies::update`] and [`fit_cluster`].
#[derive(Clone, Debug)]
pub struct CloudBodySettings {
    /// Largest step of a chain of points within one cluster (meters, in (0,
    /// [`MAX_TOLERANCE`]]; default 0.05, 2.5 voxels of the default 2 cm grid).
    pub tolerance: Real,
    /// Clusters with fewer points are outliers, dropped (1 to `max_points`; default 10).
    pub min_points: usize,
    /// Clusters with more points are split until every part has at most this many (≥ 4;
    /// default 2000).
    pub max_points: usize,
    /// Most clusters one frame may have (1 to [`MAX_CLUSTERS`]; default
    /// [`DEFAULT_MAX_CLUSTERS`]): a frame with more is refused after clustering, before any
    /// body is checked or fitted, since each cluster may cost a fit of tens of milliseconds.
    pub max_clusters: usize,
    /// The polytope standing in for each point's ball (default the cube).
    pub cover: BallCover,
    /// Extra radius the fits use (meters, 0 to [`MAX_NOISE_RADIUS`]; default 0): a body fitted
    /// to balls of radius r + `slack` still contains the balls of the next frame's points when
    /// they moved by less than `slack`, so it is reused rather than refitted. The reuse check itself uses r.
    pub slack: Real,
    /// Largest centroid shift, and largest change of any half extent of the bounding box, of a
    /// cluster matched to the last frame's (meters, ≥ 0; default 0.05).
    pub match_distance: Real,
    /// Largest relative change of a matched cluster's point count: |n − n'| ≤ this × max(n, n')
    /// (in [0, 1]; default 0.5).
    pub match_count_change: Real,
    /// Largest growth of a body by rescaling since its last fit (≥ 1; default 1.25; 1: never
    /// rescale): a matched cluster whose old body has p = v > 1 at some cover vertex of the
    /// new balls of radius r + `slack` takes p / v when the body's rescales since its last fit,
    /// v included, multiply to at most this; else it is fitted again. For a p homogeneous about
    /// its center, 1.25 at 2d = 4 is 5.7 % in every direction.
    pub rescale_limit: Real,
    /// Threads fitting at once (0, the default: the machine's available parallelism).
    pub threads: usize,
    /// The fit of every cluster (paper §III): a convex method with no convexity relaxation.
    /// Default: degree 4, log det P, 4096 volume samples (the volume is only reported).
    pub fit: FitSettings,
}

impl Default for CloudBodySettings {
    fn default() -> Self {
        Self {
            tolerance: 0.05,
            min_points: 10,
            max_points: 2000,
            max_clusters: DEFAULT_MAX_CLUSTERS,
            cover: BallCover::Cube,
            slack: 0.0,
            match_distance: 0.05,
            match_count_change: 0.5,
            rescale_limit: 1.25,
            threads: 0,
            fit: FitSettings::default().with_degree(4).with_volume_samples(4096),
        }
    }
}

impl CloudBodySettings {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `tolerance`, `min_points`, `max_points`,
    /// `max_clusters`, `slack`, `match_distance`, `match_count_change`, `rescale_limit`,
    /// `fit.method` (the inverse moment, not convex),
    /// `fit.convexity_relaxation` (> 0: the body may be nonconvex) or another `fit.` field
    /// ([`FitSettings::validate`]).
    pub fn validate(&self) -> Result<()> {
        validate_clustering(self.tolerance, self.min_points, self.max_points)?;
        if !(1..=MAX_CLUSTERS).contains(&self.max_clusters) {
            return Err(Error::invalid(
                "max_clusters",
                format!("must be 1 to {MAX_CLUSTERS}, got {}", self.max_clusters),
            ));
        }
        for (field, v, most) in
            [("slack", self.slack, MAX_NOISE_RADIUS), ("match_distance", self.match_distance, MAX_COORDINATE)]
        {
            if !(v.is_finite() && (0.0..=most).contains(&v)) {
                return Err(Error::invalid(
                    field,
                    format!("must be finite and in [0, {}] m, got {}", show_real(most), show_real(v)),
                ));
            }
        }
        let c = self.match_count_change;
        if !(0.0..=1.0).contains(&c) {
            return Err(Error::invalid("match_count_change", format!("must be in [0, 1], got {}", show_real(c))));
        }
        let g = self.rescale_limit;
        if !(g.is_finite() && g >= 1.0) {
            return Err(Error::invalid("rescale_limit", format!("must be finite and ≥ 1, got {}", show_real(g))));
        }
        self.fit.validate().map_err(|e| match e {
            Error::InvalidArgument { field, reason } => Error::invalid(format!("fit.{field}"), reason),
            other => other,
        })?;
        if self.fit.method == FitMethod::InverseMoment {
            return Err(Error::invalid(
                "fit.method",
                "the inverse moment body is not convex; a cloud body must contain the hull of its cover vertices",
            ));
        }
        if self.fit.convexity_relaxation != 0.0 {
            return Err(Error::invalid(
                "fit.convexity_relaxation",
                "must be 0: a relaxed (possibly nonconvex) body need not contain the hull of its cover vertices",
            ));
        }
        Ok(())
    }
}

/// A cluster's body and how it was obtained ([`fit_cluster`]).
#[derive(Clone, Debug)]
pub struct ClusterFit {
    /// The body: contains every ball B(p_i, r + slack) of the cluster's points.
    pub body: Body,
    /// Largest p at the cover vertices (≤ 1).
    pub max_value: Real,
    /// Why the fit failed, when the body is the bounding ball instead.
    pub fallback: Option<String>,
    /// Seconds the fit took (cover, fit, verification).
    pub seconds: Real,
}

/// Fits a body to the cluster `points[indices]` (meters) whose every point is a ball of
/// `radius` (meters): sublevel-fit's [`sublevel_fit::fit_points`] on the cover vertices of the
/// balls of radius `radius + settings.slack` ([`BallCover::vertices`]; the fit keeps their hull's
/// vertices as containment rows), then p ≤ 1 checked at every cover vertex with
/// [`Body::value_at`] and the body rescaled where rounding left a value above 1. A fit that fails
/// (too few points for a volume with r = 0, a solver failure) is replaced by a ball about the
/// points' box center containing every ball, and says why in [`ClusterFit::fallback`].
///
/// # Errors
/// [`Error::Cancelled`] when the fit runs in a cancelled [`sublevel_core::cancel::cancellable`]
/// scope; [`Error::InvalidArgument`] naming `indices` (empty or out of range) or a settings field
/// ([`CloudBodySettings::validate`] is not run here; run it first).
pub fn fit_cluster(
    points: &[[Real; 3]],
    indices: &[usize],
    radius: Real,
    settings: &CloudBodySettings,
) -> Result<ClusterFit> {
    let start = Instant::now();
    if indices.is_empty() || indices.iter().any(|&i| i >= points.len()) {
        return Err(Error::invalid("indices", format!("must be non-empty and below {}", points.len())));
    }
    let r = radius + settings.slack;
    let cover = settings.cover.vertices(points, indices, r);
    let fitted = match sublevel_fit::fit_points(&cover, &settings.fit, &mut |_| {}) {
        Ok(body) => contain(body, points, indices, r, settings.cover, None),
        Err(e @ Error::Cancelled(_)) => return Err(e),
        Err(e) => Err(e.to_string()),
    };
    let (body, max_value, fallback) = match fitted {
        Ok((body, m)) => (body, m, None),
        Err(why) => {
            let body = bounding_ball_body(points, indices, r)?;
            let m = max_cover_value(&body, points, indices, r, settings.cover, None);
            (body, m, Some(why))
        }
    };
    Ok(ClusterFit { body, max_value, fallback, seconds: start.elapsed().as_secs_f64() })
}

/// `body` with p ≤ 1 at every cover vertex of `points[indices]` (radius `r`), evaluated as every
/// later check evaluates it: divided by its largest value there (and a hair more) when that is
/// above 1. `known`: that largest value when the caller has just computed it (saves one pass).
/// Err names why not (a rescaled polynomial refused as a body).
fn contain(
    mut body: Body,
    points: &[[Real; 3]],
    indices: &[usize],
    r: Real,
    cover: BallCover,
    known: Option<Real>,
) -> std::result::Result<(Body, Real), String> {
    let mut known = known;
    for _ in 0..4 {
        let m = known.take().unwrap_or_else(|| max_cover_value(&body, points, indices, r, cover, None));
        if m <= 1.0 {
            return Ok((body, m));
        }
        let mut poly = body.polynomial().clone();
        poly.scale(1.0 / (m * (1.0 + 4.0 * Real::EPSILON)));
        let c = body.center();
        let mut report = body.report.clone();
        report.containment_rescale *= m;
        report.notes.push(format!("rescaled by {m:.17} for p ≤ 1 at every cover vertex"));
        body = Body::new(poly, [c.x, c.y, c.z], body.scale(), report).map_err(|e| e.to_string())?;
    }
    Err("p stayed above 1 at a cover vertex after 4 rescales".into())
}

/// A ball containing every ball B(p_i, r): about the points' box center, radius the farthest
/// point's distance plus r, pushed out by 10⁻⁹ relatively (and at least 1 µm, a body's smallest
/// scale).
fn bounding_ball_body(points: &[[Real; 3]], indices: &[usize], r: Real) -> Result<Body> {
    let (lo, hi) = index_box(points, indices);
    let c = (lo + hi) * 0.5;
    let far = indices.iter().map(|&i| (Vector3::from(points[i]) - c).norm()).fold(0.0, Real::max);
    let radius = ((far + r) * (1.0 + 1e-9)).max(1e-6);
    let mut body = sublevel_core::body::ellipsoid([c.x, c.y, c.z], [radius; 3])?;
    body.report.volume = 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3);
    body.report.notes.push("bounding ball of the cluster's point balls (the fit failed)".into());
    Ok(body)
}

/// One cluster of the last frame and its body ([`CloudBodies`]).
#[derive(Clone, Debug)]
pub struct ClusterBody {
    /// The body (meters): contains the ball B(p, r) of every point in `indices` (radius r of the
    /// last update). Shared: a reused body is the same allocation frame after frame.
    pub body: Arc<Body>,
    /// The cluster's points: indices into the last frame's points, ascending.
    pub indices: Vec<usize>,
    /// Mean of the points (meters).
    pub centroid: Vector3,
    /// Bounding box of the points (not of their balls): center and half extents (meters).
    pub bounds: (Vector3, Vector3),
    /// Hash of the points' coordinates (exact bits, order-independent): equal for the same point
    /// set.
    pub fingerprint: u64,
    /// Consecutive updates the body was reused or rescaled in (0: fitted in the last one).
    pub reused_for: usize,
    /// Product of the body's rescales since its last fit (1: as fitted; at most the settings'
    /// `rescale_limit`).
    pub growth: Real,
    /// Why the fit failed, when the body is a bounding ball ([`fit_cluster`]).
    pub fallback: Option<String>,
}

/// What [`CloudBodies::update`] did with one cluster of the new frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClusterOutcome {
    /// Matched to last frame's cluster `previous`, whose body contains every new ball: kept.
    /// `unchanged` when the point set is the same (equal fingerprint).
    Reused {
        /// Index of the matched cluster in the last frame's list.
        previous: usize,
        /// The same points as before.
        unchanged: bool,
    },
    /// Matched to `previous`, whose body leaves some new ball: its p divided by `factor` (> 1,
    /// the largest p at the new cover vertices of radius r + slack, within the rescale limit).
    Rescaled {
        /// Index of the matched cluster in the last frame's list.
        previous: usize,
        /// The divisor of p.
        factor: Real,
    },
    /// Matched to `previous`, whose body leaves some new ball (p = `max_value` > 1 at a cover
    /// vertex) by more than a rescale allows: fitted again.
    Refitted {
        /// Index of the matched cluster in the last frame's list.
        previous: usize,
        /// The old body's largest p at the new cover vertices.
        max_value: Real,
    },
    /// No cluster of the last frame matched (or the fit settings changed): fitted.
    Added,
}

/// What one [`CloudBodies::update`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UpdateReport {
    /// Points of the frame.
    pub points: usize,
    /// Clusters of the frame (after splitting), each with a body.
    pub clusters: usize,
    /// Points dropped as outliers (in clusters under `min_points`).
    pub outliers: usize,
    /// Clusters whose body was kept (`reused + rescaled + refitted == clusters`).
    pub reused: usize,
    /// Of the reused, those with the very same points.
    pub unchanged: usize,
    /// Clusters whose old body was rescaled to contain the new balls, with no fit.
    pub rescaled: usize,
    /// Clusters fitted in this update (matched but no longer contained, or new).
    pub refitted: usize,
    /// Of the refitted, those with no match in the last frame.
    pub added: usize,
    /// Clusters of the last frame no new cluster matched.
    pub removed: usize,
    /// Of the refitted, those whose fit failed and got a bounding ball.
    pub fallbacks: usize,
    /// Per new cluster, in the order of [`CloudBodies::clusters`].
    pub outcomes: Vec<ClusterOutcome>,
    /// Seconds clustering took.
    pub cluster_seconds: Real,
    /// Seconds the reuse checks took.
    pub check_seconds: Real,
    /// Seconds the rescales and fits took (wall time: the fits run on several threads).
    pub fit_seconds: Real,
    /// Seconds in all.
    pub total_seconds: Real,
}

/// A point cloud as bodies, kept across frames: one body per Euclidean cluster, each containing
/// the noise ball of every point of its cluster (module docs).
#[derive(Clone, Debug, Default)]
pub struct CloudBodies {
    clusters: Vec<ClusterBody>,
    /// Degree, method and cover of the bodies; a change refits every cluster.
    key: Option<(usize, FitMethod, BallCover)>,
}

/// A cluster of the new frame before it has a body.
struct Candidate {
    indices: Vec<usize>,
    centroid: Vector3,
    bounds: (Vector3, Vector3),
    fingerprint: u64,
}

impl Candidate {
    fn new(points: &[[Real; 3]], indices: Vec<usize>) -> Self {
        let n = indices.len() as Real;
        let centroid = indices.iter().fold(Vector3::zeros(), |a, &i| a + Vector3::from(points[i])) / n;
        let (lo, hi) = index_box(points, &indices);
        let mut sum = 0u64;
        let mut mix = 0u64;
        for &i in &indices {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            points[i].map(Real::to_bits).hash(&mut h);
            let h = h.finish();
            sum = sum.wrapping_add(h);
            mix ^= h.rotate_left(17).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
        let fingerprint = sum ^ mix.rotate_left(32) ^ (indices.len() as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        Self { indices, centroid, bounds: ((lo + hi) * 0.5, (hi - lo) * 0.5), fingerprint }
    }
}

impl CloudBodies {
    /// No clusters yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The clusters of the last frame, each with its body.
    pub fn clusters(&self) -> &[ClusterBody] {
        &self.clusters
    }

    /// The bodies of the last frame (meters, the cloud's frame).
    pub fn bodies(&self) -> impl Iterator<Item = &Body> {
        self.clusters.iter().map(|c| c.body.as_ref())
    }

    /// How many clusters.
    pub fn len(&self) -> usize {
        self.clusters.len()
    }

    /// Whether there are no clusters.
    pub fn is_empty(&self) -> bool {
        self.clusters.is_empty()
    }

    /// Takes a new frame: `points` (meters, filtered; [`super::filter`]), each a ball of `radius`
    /// meters. Clusters it ([`euclidean_clusters`]), matches each cluster to one of the last
    /// frame's (the same fingerprint first; otherwise the nearest centroid within
    /// `match_distance` whose box half extents differ by at most `match_distance` and whose point
    /// count by at most `match_count_change` relatively; each old cluster matches once), keeps a
    /// matched body unchanged when p ≤ 1 at the cover vertices of every new point's ball
    /// ([`max_cover_value`]), rescales a matched body within `rescale_limit` of its last fit
    /// ([`ClusterOutcome::Rescaled`]), and fits the rest ([`fit_cluster`]) on `threads`
    /// threads, each in the caller's cancellation scope. An empty frame leaves no clusters. On an
    /// error the previous clusters are kept.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `radius` (not in [0, 1] m), `points[k]`, a settings
    /// field ([`CloudBodySettings::validate`]), or `max_clusters` when the frame has more
    /// clusters than it (checked before any body is checked or fitted);
    /// [`Error::ResourceExhausted`] naming `points` past [`super::MAX_CLOUD_POINTS`];
    /// [`Error::Cancelled`] when the caller's cancellation scope ([`sublevel_core::cancel`]) is
    /// cancelled: it is looked at after clustering, after the reuse checks and before every
    /// rescale or fit, and a running fit's solver stops at its next iteration.
    pub fn update(&mut self, points: &[[Real; 3]], radius: Real, settings: &CloudBodySettings) -> Result<UpdateReport> {
        let start = Instant::now();
        settings.validate()?;
        if !(radius.is_finite() && (0.0..=MAX_NOISE_RADIUS).contains(&radius)) {
            return Err(Error::invalid(
                "radius",
                format!("must be finite, in [0, {MAX_NOISE_RADIUS}] m, got {radius}"),
            ));
        }
        let clusters = euclidean_clusters(points, settings.tolerance, settings.min_points, settings.max_points)?;
        if clusters.len() > settings.max_clusters {
            return Err(Error::invalid(
                "max_clusters",
                format!(
                    "the frame has {} clusters of at least min_points ({}) points, more than the {} one frame may \
                     have; raise min_points or tolerance, crop the frame, or raise max_clusters (at most \
                     {MAX_CLUSTERS})",
                    clusters.len(),
                    settings.min_points,
                    settings.max_clusters
                ),
            ));
        }
        cancelled()?;
        let candidates: Vec<Candidate> = clusters.into_iter().map(|c| Candidate::new(points, c)).collect();
        let cluster_seconds = start.elapsed().as_secs_f64();

        let key = (settings.fit.degree, settings.fit.method, settings.cover);
        let old = if self.key == Some(key) { self.clusters.as_slice() } else { &[] };
        let matches = match_clusters(old, &candidates, settings);

        // The reuse checks, on the fit threads too (a pass over every matched point's cover).
        let checks = Instant::now();
        let all: Vec<usize> = (0..candidates.len()).collect();
        let mut outcomes = in_parallel(
            &all,
            |i| if matches[i].is_some() { candidates[i].indices.len() } else { 0 },
            settings.threads,
            |i| match matches[i] {
                None => ClusterOutcome::Added,
                Some(j) => {
                    let c = &candidates[i];
                    let v = max_cover_value(&old[j].body, points, &c.indices, radius, settings.cover, Some(1.0));
                    if v <= 1.0 {
                        ClusterOutcome::Reused { previous: j, unchanged: old[j].fingerprint == c.fingerprint }
                    } else {
                        ClusterOutcome::Refitted { previous: j, max_value: v }
                    }
                }
            },
        );
        let check_seconds = checks.elapsed().as_secs_f64();
        cancelled()?;

        // Every rescale and fit first: a cancelled fit leaves `self` as it was.
        let fits = Instant::now();
        let todo: Vec<usize> =
            (0..candidates.len()).filter(|&i| !matches!(outcomes[i], ClusterOutcome::Reused { .. })).collect();
        let renewed = in_parallel(
            &todo,
            |i| candidates[i].indices.len(),
            settings.threads,
            |i| {
                // Looked at before every cluster: an abandoned update stops within one fit.
                cancelled()?;
                let previous = match outcomes[i] {
                    ClusterOutcome::Refitted { previous, .. } => Some(&old[previous]),
                    _ => None,
                };
                renew(previous, points, &candidates[i].indices, radius, settings)
            },
        );
        let mut fitted: Vec<Option<(ClusterFit, Real)>> = (0..candidates.len()).map(|_| None).collect();
        for (i, r) in todo.into_iter().zip(renewed) {
            let (fit, factor) = r?;
            let growth = match (outcomes[i], factor) {
                (ClusterOutcome::Refitted { previous, .. }, Some(factor)) => {
                    outcomes[i] = ClusterOutcome::Rescaled { previous, factor };
                    old[previous].growth * factor
                }
                _ => 1.0,
            };
            fitted[i] = Some((fit, growth));
        }
        let fit_seconds = fits.elapsed().as_secs_f64();

        let mut report = UpdateReport {
            points: points.len(),
            clusters: candidates.len(),
            outliers: points.len() - candidates.iter().map(|c| c.indices.len()).sum::<usize>(),
            cluster_seconds,
            check_seconds,
            fit_seconds,
            ..Default::default()
        };
        report.removed = old.len() - matches.iter().flatten().count();
        let mut next = Vec::with_capacity(candidates.len());
        for ((c, o), fit) in candidates.into_iter().zip(&outcomes).zip(fitted) {
            let Candidate { indices, centroid, bounds, fingerprint } = c;
            let (body, reused_for, growth, fallback) = match (o, fit) {
                (ClusterOutcome::Rescaled { previous: j, .. }, Some((fit, growth))) => {
                    report.rescaled += 1;
                    let kept = &old[*j];
                    (Arc::new(fit.body), kept.reused_for + 1, growth, kept.fallback.clone())
                }
                (_, Some((fit, _))) => {
                    report.refitted += 1;
                    report.added += usize::from(*o == ClusterOutcome::Added);
                    report.fallbacks += usize::from(fit.fallback.is_some());
                    (Arc::new(fit.body), 0, 1.0, fit.fallback)
                }
                (ClusterOutcome::Reused { previous: j, unchanged }, None) => {
                    report.reused += 1;
                    report.unchanged += usize::from(*unchanged);
                    let kept = &old[*j];
                    (Arc::clone(&kept.body), kept.reused_for + 1, kept.growth, kept.fallback.clone())
                }
                // A cluster that is not reused was renewed above.
                (_, None) => continue,
            };
            next.push(ClusterBody { body, indices, centroid, bounds, fingerprint, reused_for, growth, fallback });
        }
        self.clusters = next;
        self.key = Some(key);
        report.outcomes = outcomes;
        report.total_seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }
}

/// [`Error::Cancelled`] when the caller's cancellation scope is cancelled.
fn cancelled() -> Result<()> {
    if sublevel_core::cancel::is_cancelled() {
        return Err(Error::Cancelled("the cloud's bodies update was cancelled".into()));
    }
    Ok(())
}

/// A new body for the cluster `points[indices]`: the old cluster's body rescaled when that keeps
/// its growth since its last fit within `settings.rescale_limit` (its p divided by the largest
/// p at the cover vertices of radius `radius + slack`, [`contain`]), else a fit
/// ([`fit_cluster`]). Returns the body and, when it was rescaled, the divisor of p.
fn renew(
    old: Option<&ClusterBody>,
    points: &[[Real; 3]],
    indices: &[usize],
    radius: Real,
    settings: &CloudBodySettings,
) -> Result<(ClusterFit, Option<Real>)> {
    if let Some(old) = old.filter(|o| o.fallback.is_none() && settings.rescale_limit > o.growth) {
        let start = Instant::now();
        let r = radius + settings.slack;
        let allowed = settings.rescale_limit / old.growth;
        let v = max_cover_value(&old.body, points, indices, r, settings.cover, Some(allowed));
        if v <= allowed {
            let rescaled = contain(old.body.as_ref().clone(), points, indices, r, settings.cover, Some(v));
            if let Ok((mut body, max_value)) = rescaled {
                let factor = v.max(1.0);
                let growth = old.growth * factor;
                body.report.notes.retain(|n| !n.starts_with("rescaled"));
                body.report
                    .notes
                    .push(format!("rescaled by {growth:.6} in all since its fit, for p ≤ 1 at every cover vertex"));
                let seconds = start.elapsed().as_secs_f64();
                return Ok((ClusterFit { body, max_value, fallback: None, seconds }, Some(factor)));
            }
        }
    }
    Ok((fit_cluster(points, indices, radius, settings)?, None))
}

/// `f` of every item of `items`, in their order, on up to `threads` scoped threads (0: the
/// machine's available parallelism), the items of largest `size` started first; every thread
/// runs in the caller's cancellation scope ([`sublevel_core::cancel`]).
fn in_parallel<T: Send>(
    items: &[usize],
    size: impl Fn(usize) -> usize,
    threads: usize,
    f: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    let threads = match threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
    .clamp(1, items.len().max(1));
    if threads == 1 {
        return items.iter().map(|&i| f(i)).collect();
    }
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&k| std::cmp::Reverse(size(items[k])));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let flag = sublevel_core::cancel::current();
    let mut done: Vec<(usize, T)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    sublevel_core::cancel::within(flag.clone(), || {
                        let mut out = Vec::new();
                        loop {
                            let n = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            let Some(&k) = order.get(n) else { break out };
                            out.push((k, f(items[k])));
                        }
                    })
                })
            })
            .collect();
        workers.into_iter().flat_map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).collect()
    });
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, t)| t).collect()
}

/// For each candidate, the index of the old cluster it matches, if any: equal fingerprints
/// first, then the remaining pairs within the settings' limits by increasing centroid distance;
/// every old cluster matches at most one candidate.
fn match_clusters(old: &[ClusterBody], candidates: &[Candidate], s: &CloudBodySettings) -> Vec<Option<usize>> {
    let mut matched = vec![None; candidates.len()];
    let mut taken = vec![false; old.len()];
    for (i, c) in candidates.iter().enumerate() {
        if let Some(j) = (0..old.len()).find(|&j| !taken[j] && old[j].fingerprint == c.fingerprint) {
            matched[i] = Some(j);
            taken[j] = true;
        }
    }
    let mut pairs = Vec::new();
    for (i, c) in candidates.iter().enumerate() {
        if matched[i].is_some() {
            continue;
        }
        for (j, o) in old.iter().enumerate() {
            let d = (c.centroid - o.centroid).norm();
            let boxes = (c.bounds.1 - o.bounds.1).abs().max() <= s.match_distance;
            let (n, m) = (c.indices.len() as Real, o.indices.len() as Real);
            let counts = (n - m).abs() <= s.match_count_change * n.max(m);
            if !taken[j] && d <= s.match_distance && boxes && counts {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (_, i, j) in pairs {
        if matched[i].is_none() && !taken[j] {
            matched[i] = Some(j);
            taken[j] = true;
        }
    }
    matched
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_names_the_field() {
        let field = |e: Error| match e {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("expected InvalidArgument, got {other}"),
        };
        let p = [[0.0; 3]];
        assert_eq!(field(euclidean_clusters(&p, 0.0, 1, 10).unwrap_err()), "tolerance");
        assert_eq!(field(euclidean_clusters(&p, Real::NAN, 1, 10).unwrap_err()), "tolerance");
        assert_eq!(field(euclidean_clusters(&p, 0.1, 0, 10).unwrap_err()), "min_points");
        assert_eq!(field(euclidean_clusters(&p, 0.1, 20, 10).unwrap_err()), "min_points");
        assert_eq!(field(euclidean_clusters(&p, 0.1, 1, 3).unwrap_err()), "max_points");
        assert_eq!(field(euclidean_clusters(&p, 1.5, 1, 10).unwrap_err()), "tolerance");
        let huge = euclidean_clusters(&p, 1e300, 1, 10).unwrap_err().to_string();
        assert!(huge.contains("tolerance") && huge.contains("1e300") && huge.len() < 200, "{huge}");
        assert_eq!(field(euclidean_clusters(&[[0.0, Real::INFINITY, 0.0]], 0.1, 1, 10).unwrap_err()), "points[0]");
        let mut bodies = CloudBodies::new();
        let s = CloudBodySettings::default();
        assert_eq!(field(bodies.update(&p, -1.0, &s).unwrap_err()), "radius");
        let bad = CloudBodySettings { fit: s.fit.clone().with_method(FitMethod::InverseMoment), ..s.clone() };
        assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "fit.method");
        let bad = CloudBodySettings { fit: s.fit.clone().with_relaxation(0.1), ..s.clone() };
        assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "fit.convexity_relaxation");
        let bad = CloudBodySettings { fit: s.fit.clone().with_degree(3), ..s.clone() };
        assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "fit.degree");
        let bad = CloudBodySettings { match_count_change: 2.0, ..s.clone() };
        assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "match_count_change");
        for bad in [
            CloudBodySettings { max_clusters: 0, ..s.clone() },
            CloudBodySettings { max_clusters: MAX_CLUSTERS + 1, ..s.clone() },
        ] {
            assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "max_clusters");
        }
        let bad = CloudBodySettings { slack: 1e300, ..s.clone() };
        assert_eq!(field(bodies.update(&p, 0.01, &bad).unwrap_err()), "slack");
        let report = bodies.update(&[], 0.01, &s).unwrap();
        assert_eq!((report.clusters, bodies.len()), (0, 0));
    }

    /// Five points 1 m apart, each its own cluster at `min_points` 1: refused past
    /// `max_clusters` before any fit, and a cancelled scope stops the update with nothing kept.
    #[test]
    fn clusters_are_bounded_and_updates_cancellable() {
        let pts: Vec<[Real; 3]> = (0..5).map(|i| [i as Real, 0.0, 0.0]).collect();
        let s = CloudBodySettings { min_points: 1, max_clusters: 4, threads: 1, ..Default::default() };
        let mut bodies = CloudBodies::new();
        let e = bodies.update(&pts, 0.01, &s).unwrap_err();
        assert!(e.to_string().contains("5 clusters"), "{e}");
        assert!(matches!(e, Error::InvalidArgument { ref field, .. } if field == "max_clusters"));
        let flag = Arc::new(std::sync::atomic::AtomicBool::new(true));
        let s = CloudBodySettings { max_clusters: 5, ..s };
        let e = sublevel_core::cancel::cancellable(flag, || bodies.update(&pts, 0.01, &s)).unwrap_err();
        assert!(matches!(e, Error::Cancelled(_)), "{e}");
        assert!(bodies.is_empty());
    }

    #[test]
    fn a_failed_fit_falls_back_to_a_bounding_ball() {
        // Three collinear points with r = 0: no volume to fit; the ball contains them.
        let pts = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0]];
        let s = CloudBodySettings { min_points: 1, ..Default::default() };
        let fit = fit_cluster(&pts, &[0, 1, 2], 0.0, &s).unwrap();
        assert!(fit.fallback.is_some() && fit.max_value <= 1.0);
        assert!(fit_cluster(&pts, &[3], 0.0, &s).is_err());
    }
}
