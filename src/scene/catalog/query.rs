//! Queries between two instances of a scene: which query ([`QueryKind`]) with which options
//! ([`QueryOptions`]), the replies, and the catalog's query methods. Every query path ends in
//! [`Catalog::answer_snapshot`], which copies the posed instances and warm starts under the
//! scene's lock, solves outside it ([`crate::scene::planner::answer_pair`]) and writes the new warm
//! starts back.

use super::{lock, posed, Catalog, SceneState};
use crate::body::Body;
use crate::math::Isometry3;
use crate::query::{
    CertifiedDistance, CertifiedGrowth, CertifyMode, CertifyParams, DistanceResult, GrowthResult, PoseGradient,
};
use crate::scene::cache::{WarmKind, WarmStartCache};
use crate::scene::planner::{self, CollideReply, Posed};
use crate::{Error, Result};
use std::collections::HashMap;

/// Which query to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QueryKind {
    /// Euclidean distance between `first` and `second` (eq. "distance").
    Distance,
    /// Growth measure d(first ‖ second) (eq. "overlap").
    Growth,
    /// Collide-with-margin: is the distance below [`QueryPair::margin`]? (see
    /// [`planner::answer_pair`]).
    Collide,
}

/// Per-query options: certification mode and pose gradients.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct QueryOptions {
    /// [`CertifyMode::Newton`] (default: the SDP only as a fallback) or [`CertifyMode::Certify`]
    /// (always attach the level-0 certificate); see [`crate::query::certified`].
    pub mode: CertifyMode,
    /// Also return the gradients of the value with respect to both poses
    /// ([`crate::query::gradient`]).
    pub with_gradient: bool,
    /// Solve cold: ignore the pair's warm start and leave none behind.
    pub cold: bool,
    /// Distance queries: also the penetration depth when overlapping (signed distance,
    /// [`crate::query::penetration`]).
    pub signed: bool,
    /// Distance queries of pairs with a compound body: stop refining once the bounds are within
    /// this many meters (upper − lower ≤ tolerance; [`crate::query::tree::TreeQueryParams`]).
    /// 0 (default): the exact distance of the two models. Finite and ≥ 0 (checked by the
    /// callers that take it from outside). Ignored by single-body pairs.
    pub tolerance: crate::math::Real,
}

/// What a query between a compound body and another body (issue 14) adds to its answer: the
/// branch and bound's bounds and cost ([`crate::query::tree`]). `None` on single-body pairs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeInfo {
    /// Lower bound of the models' distance (meters; distance and collide queries; the answer's
    /// distance). Growth queries: the answer's d.
    pub lower: crate::math::Real,
    /// Upper bound of the models' distance (meters): the best leaf pair's distance (+∞ when no
    /// leaf pair was resolved). Growth and collide queries: equal to `lower`.
    pub upper: crate::math::Real,
    /// The deepest tree level reached (0: decided by the root pair).
    pub level: usize,
    /// The active leaf pair (node of the first body's tree, node of the second's), when one
    /// decided (a single body is node 0 of its one-node tree).
    pub leaves: Option<(usize, usize)>,
    /// Node pairs solved (Newton solves, leaf pairs included).
    pub pairs_evaluated: usize,
    /// Node pairs decided by their bounding spheres alone (no solve).
    pub pairs_pruned_by_spheres: usize,
    /// Distance: upper − lower ≤ the tolerance asked for (and no leaf pair stayed unresolved).
    pub within_tolerance: bool,
    /// [`CertifyMode::NewtonOnly`] only: a leaf pair needs the SDP that mode does not solve.
    pub needs_sdp: bool,
}

/// One query of a batch: a kind, an ordered pair of instance ids and its options.
#[derive(Clone, Debug)]
pub struct QueryPair {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: String,
    /// Second instance (B, or p₂).
    pub second: String,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: crate::math::Real,
}

impl QueryPair {
    /// This query by reference ([`PairRef`]).
    pub fn view(&self) -> PairRef<'_> {
        PairRef {
            kind: self.kind,
            first: &self.first,
            second: &self.second,
            options: self.options,
            margin: self.margin,
        }
    }
}

/// One query with borrowed instance ids: what [`planner::answer_pair`] needs (the ids key
/// the warm starts). Built from a [`QueryPair`] ([`QueryPair::view`]) or from columns
/// ([`Catalog::batch_columns`]) without allocating.
#[derive(Clone, Copy, Debug)]
pub struct PairRef<'a> {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: &'a str,
    /// Second instance (B, or p₂).
    pub second: &'a str,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: crate::math::Real,
}

/// A certified distance answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct DistanceReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedDistance,
    /// (∂D/∂ξ_a, ∂D/∂ξ_b) when asked for and the answer is not a lower bound (twists, see
    /// [`crate::query::gradient`]).
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
    /// The signed distance was asked for ([`QueryOptions::signed`]).
    pub signed: bool,
    /// With [`QueryOptions::signed`] on an overlapping answer of convex bodies: the penetration
    /// (not computed for compound pairs).
    pub penetration: Option<crate::query::penetration::Penetration>,
    /// Compound pairs: the bounds and cost of the tree query ([`TreeInfo`]).
    pub tree: Option<TreeInfo>,
}

/// A certified growth answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct GrowthReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedGrowth,
    /// (∂d/∂ξ₁, ∂d/∂ξ₂) when asked for and the answer is not a lower bound.
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
    /// Compound pairs: the tree query's level and cost ([`TreeInfo`]).
    pub tree: Option<TreeInfo>,
}

/// Relative precision in a body's normalized coordinates below which an answer is flagged as
/// limited by its inputs: 1e-9, ten times the Newton KKT tolerance's square root region.
pub const PRECISION_LIMIT: crate::math::Real = 1e-9;

/// True when one unit in the last place of the largest coordinate involved (the two poses'
/// translations and the bodies' centers, meters) exceeds [`PRECISION_LIMIT`] of the smaller
/// body's scale: the query's inputs already carry that error in normalized coordinates, before
/// any solver runs (e.g. a 1 mm body 500 km from the origin).
pub fn precision_limited(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> bool {
    let mag = [
        pose_a.translation.vector.amax(),
        pose_b.translation.vector.amax(),
        a.center().amax() + a.scale(),
        b.center().amax() + b.scale(),
    ]
    .into_iter()
    .fold(0.0, crate::math::Real::max);
    mag * crate::math::Real::EPSILON > PRECISION_LIMIT * a.scale().min(b.scale())
}

/// The answer of one query of a batch.
///
/// The distance variant is larger (its warm start carries earlier answers for the motion
/// predictor); answers are built once per query and moved, so boxing it would only add an
/// allocation to every query.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
pub enum QueryAnswer {
    /// A distance answer.
    Distance(DistanceReply),
    /// A growth answer.
    Growth(GrowthReply),
    /// A collide-with-margin answer.
    Collide(CollideReply),
}

impl QueryAnswer {
    /// Whether this answer of a [`CertifyMode::NewtonOnly`] query needs the SDP that mode does not
    /// solve ([`crate::query::Certified::needs_sdp`]): ask again in [`CertifyMode::Newton`].
    pub fn needs_sdp(&self) -> bool {
        match self {
            QueryAnswer::Distance(d) => d.answer.needs_sdp,
            QueryAnswer::Growth(g) => g.answer.needs_sdp,
            QueryAnswer::Collide(c) => {
                c.solve.as_ref().is_some_and(|d| d.answer.needs_sdp) || c.tree.is_some_and(|t| t.needs_sdp)
            }
        }
    }
}

impl Catalog {
    /// Distance between instances `a` and `b` of a scene (eq. "distance"), warm-started from the
    /// previous answer of the same ordered pair; the new answer's warm start replaces it. The
    /// default path of [`Catalog::distance_with`] (SDP only as a fallback; a lower bound for
    /// nonconvex bodies — use `distance_with` to see which).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn distance(&self, scene_id: &str, a: &str, b: &str) -> Result<DistanceResult> {
        Ok(self.distance_with(scene_id, a, b, &QueryOptions::default())?.answer.result)
    }

    /// Growth measure d(p₁‖p₂) between instances `p1` and `p2` (eq. "overlap"), warm-started
    /// like [`Catalog::distance`].
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn growth(&self, scene_id: &str, p1: &str, p2: &str) -> Result<GrowthResult> {
        Ok(self.growth_with(scene_id, p1, p2, &QueryOptions::default())?.answer.result)
    }

    /// [`Catalog::distance`] with options: the certified answer ([`crate::query::certified_distance`]) and, on
    /// request, its pose gradients. Solves outside the scene's lock ([`Catalog::batch`]), so a
    /// certificate (milliseconds to seconds with [`CertifyMode::Certify`]) holds up no other
    /// request of the scene.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn distance_with(&self, scene_id: &str, a: &str, b: &str, options: &QueryOptions) -> Result<DistanceReply> {
        let pair = PairRef { kind: QueryKind::Distance, first: a, second: b, options: *options, margin: 0.0 };
        match self.answer_snapshot(scene_id, &[pair])?.pop() {
            Some(QueryAnswer::Distance(d)) => Ok(d),
            _ => Err(Error::Numerical("a distance query answered with another kind".into())),
        }
    }

    /// [`Catalog::growth`] with options, like [`Catalog::distance_with`].
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn growth_with(&self, scene_id: &str, p1: &str, p2: &str, options: &QueryOptions) -> Result<GrowthReply> {
        let pair = PairRef { kind: QueryKind::Growth, first: p1, second: p2, options: *options, margin: 0.0 };
        match self.answer_snapshot(scene_id, &[pair])?.pop() {
            Some(QueryAnswer::Growth(g)) => Ok(g),
            _ => Err(Error::Numerical("a growth query answered with another kind".into())),
        }
    }

    /// The certification parameters of every query (the catalog's Newton parameters).
    pub(crate) fn certify_params(&self) -> CertifyParams {
        CertifyParams { newton: self.params, ..CertifyParams::default() }
    }

    /// Many queries of one scene, all at the poses of one moment; answers in order. Each instance
    /// is looked up once; the solves run outside the scene's lock (see
    /// [`Catalog::answer_snapshot`]), so batches of one scene run in parallel.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or any instance (checked before any query runs).
    pub fn batch(&self, scene_id: &str, pairs: &[QueryPair]) -> Result<Vec<QueryAnswer>> {
        self.batch_with(scene_id, pairs, None)
    }

    /// [`Catalog::batch`] with every query's certification mode replaced by `mode` when given
    /// (e.g. [`CertifyMode::NewtonOnly`] on an async worker).
    ///
    /// # Errors
    /// As [`Catalog::batch`].
    pub fn batch_with(
        &self,
        scene_id: &str,
        pairs: &[QueryPair],
        mode: Option<CertifyMode>,
    ) -> Result<Vec<QueryAnswer>> {
        let views: Vec<PairRef<'_>> = pairs
            .iter()
            .map(|p| {
                let mut v = p.view();
                if let Some(mode) = mode {
                    v.options.mode = mode;
                }
                v
            })
            .collect();
        self.answer_snapshot(scene_id, &views)
    }

    /// Queries of one kind given in columns: pair k asks about `ids[first[k]]` and
    /// `ids[second[k]]` (the form of `BatchQueryRequest.columns`), like [`Catalog::batch`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `first` and `second` of different lengths or an index
    /// outside `ids`; [`Error::NotFound`] for the scene or an instance (checked before any query
    /// runs).
    pub fn batch_columns(
        &self,
        scene_id: &str,
        ids: &[String],
        (first, second): (&[u32], &[u32]),
        kind: QueryKind,
        options: QueryOptions,
        margin: crate::math::Real,
    ) -> Result<Vec<QueryAnswer>> {
        if first.len() != second.len() {
            return Err(Error::invalid(
                "columns.second",
                format!("has {} entries, `first` has {}", second.len(), first.len()),
            ));
        }
        for (field, column) in [("columns.first", first), ("columns.second", second)] {
            if let Some((k, i)) = column.iter().enumerate().find(|(_, &i)| i as usize >= ids.len()) {
                return Err(Error::invalid(
                    format!("{field}[{k}]"),
                    format!("index {i} is outside instance_ids (length {})", ids.len()),
                ));
            }
        }
        let views: Vec<PairRef<'_>> = first
            .iter()
            .zip(second)
            .map(|(&i, &j)| PairRef { kind, first: &ids[i as usize], second: &ids[j as usize], options, margin })
            .collect();
        self.answer_snapshot(scene_id, &views)
    }

    /// Answers `pairs` on a snapshot of the scene, solving outside its lock:
    ///
    /// ```text
    /// lock:    posed instances (body Arc + pose) of every id, warm starts of every pair → scratch
    /// unlock:  solve every pair in order with the scratch warm starts (repeated pairs warm-start
    ///          each other as before)
    /// lock:    write the new warm starts back (those of instances still in the scene)
    /// ```
    ///
    /// Inside a cancelled [`crate::fit::cancel::cancellable`] scope it stops before the next pair
    /// with [`Error::Cancelled`] (a running certificate SDP stops at its next iteration).
    ///
    /// When an answer needs the SDP ([`QueryAnswer::needs_sdp`], [`CertifyMode::NewtonOnly`]
    /// queries) no warm start is written back, so asking again in [`CertifyMode::Newton`] gives
    /// exactly the answers a first ask in that mode would have given.
    ///
    /// Two requests of one scene solve in parallel; a concurrent pose change is seen by the next
    /// request, never halfway through this one. Warm starts are copied as `Arc`s (no 1 KB copies).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    fn answer_snapshot(&self, scene_id: &str, pairs: &[PairRef<'_>]) -> Result<Vec<QueryAnswer>> {
        let scene = self.scene(scene_id)?;
        let (posed_by_id, mut scratch) = {
            let s = lock(&scene);
            if s.deleted {
                return Err(Error::not_found("scene", scene_id));
            }
            let mut posed_by_id: HashMap<&str, Posed, foldhash::fast::RandomState> = HashMap::default();
            let mut scratch = WarmStartCache::default();
            for p in pairs {
                for id in [p.first, p.second] {
                    if !posed_by_id.contains_key(id) {
                        posed_by_id.insert(id, posed(&s, id)?);
                    }
                }
                if !p.options.cold {
                    s.cache.copy_pair(&mut scratch, warm_kind(p.kind), p.first, p.second);
                }
            }
            (posed_by_id, scratch)
        };
        let params = self.certify_params();
        // Cold distance solves of one body pair on the batch solver's lanes (see
        // `planner::lane_distances`).
        let mut newton = planner::lane_distances(
            pairs,
            |k| Some((posed_by_id[pairs[k].first].borrowed(), posed_by_id[pairs[k].second].borrowed())),
            &params,
            false,
        );
        let mut answers = Vec::with_capacity(pairs.len());
        for (k, p) in pairs.iter().enumerate() {
            if crate::fit::cancel::is_cancelled() {
                // The caller abandoned the request (its deadline passed): stop before the next
                // pair and leave the warm starts as they were.
                return Err(Error::Cancelled(format!("query of scene `{scene_id}` abandoned by its caller")));
            }
            let (a, b) = (&posed_by_id[p.first], &posed_by_id[p.second]);
            answers.push(planner::answer_pair_with(*p, a, b, &mut scratch, &params, newton.take(k)));
        }
        if !scratch.is_empty() && !answers.iter().any(QueryAnswer::needs_sdp) {
            let mut s = lock(&scene);
            if !s.deleted {
                let SceneState { instances, cache, .. } = &mut *s;
                cache.merge(scratch, |id| instances.contains_key(id));
            }
        }
        Ok(answers)
    }
}

/// The warm-start table a query kind uses (collide queries solve distances).
pub(crate) fn warm_kind(kind: QueryKind) -> WarmKind {
    match kind {
        QueryKind::Distance | QueryKind::Collide => WarmKind::Distance,
        QueryKind::Growth => WarmKind::Growth,
    }
}
