//! The catalog's query methods. Every query path ends in [`Catalog::answer_snapshot`], which
//! copies the posed instances and warm starts under the scene's lock, solves outside it
//! ([`crate::planner::answer_pair`]) and writes the new warm starts back.

use super::{instance, lock, posed, BodyEntry, Catalog, SceneState};
use crate::answer::{
    self, warm_kind, DistanceReply, GrowthReply, PairRef, Posed, QueryAnswer, QueryKind, QueryOptions, QueryPair,
};
use crate::cache::WarmStartCache;
use crate::{Error, Result};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use sublevel_core::math::Isometry3;
use sublevel_query::{CertifyMode, CertifyParams, DistanceResult, GrowthResult};

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

    /// [`Catalog::distance`] with options: the certified answer ([`sublevel_query::certified_distance`]) and, on
    /// request, its pose gradients. Solves outside the scene's lock ([`Catalog::batch`]), so a
    /// certificate (milliseconds to seconds with [`CertifyMode::Certify`]) holds up no other
    /// request of the scene.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance; [`Error::InvalidArgument`] naming
    /// `instance_b` for two halfspaces (no finite distance).
    pub fn distance_with(&self, scene_id: &str, a: &str, b: &str, options: &QueryOptions) -> Result<DistanceReply> {
        let pair = PairRef { kind: QueryKind::Distance, first: a, second: b, options: *options, margin: 0.0 };
        let field = |_: usize, second: bool| if second { "instance_b" } else { "instance_a" }.to_owned();
        match self.answer_snapshot(scene_id, &[pair], &field)?.pop() {
            Some(QueryAnswer::Distance(d)) => Ok(d),
            _ => Err(Error::Numerical("a distance query answered with another kind".into())),
        }
    }

    /// [`Catalog::growth`] with options, like [`Catalog::distance_with`].
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance; [`Error::InvalidArgument`] naming
    /// `instance_1` or `instance_2` when it is a primitive (growth is defined for sos-convex
    /// bodies).
    pub fn growth_with(&self, scene_id: &str, p1: &str, p2: &str, options: &QueryOptions) -> Result<GrowthReply> {
        let pair = PairRef { kind: QueryKind::Growth, first: p1, second: p2, options: *options, margin: 0.0 };
        let field = |_: usize, second: bool| if second { "instance_2" } else { "instance_1" }.to_owned();
        match self.answer_snapshot(scene_id, &[pair], &field)?.pop() {
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
    /// `Catalog::answer_snapshot`), so batches of one scene run in parallel.
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
        let field = |k: usize, second: bool| format!("pairs[{k}].{}", if second { "second" } else { "first" });
        self.answer_snapshot(scene_id, &views, &field)
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
        margin: sublevel_core::math::Real,
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
        let field = |k: usize, second: bool| format!("columns.{}[{k}]", if second { "second" } else { "first" });
        self.answer_snapshot(scene_id, &views, &field)
    }

    /// Answers `pairs` on a snapshot of the scene, solving outside its lock:
    ///
    /// ```text
    /// lock:    posed instances (body Arc + pose) of every id, warm starts of every pair → scratch
    /// unlock:  build the bodies not built yet (first uses only, see `BodyEntry::built`); solve
    ///          every pair in order with the scratch warm starts (repeated pairs warm-start each
    ///          other as before)
    /// lock:    write the new warm starts back (those of instances still in the scene)
    /// ```
    ///
    /// Inside a cancelled [`sublevel_core::cancel::cancellable`] scope it stops before the next pair
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
    /// [`Error::NotFound`] for the scene or an instance; [`Error::FailedPrecondition`] naming a
    /// body that does not validate (quarantined when it was built); [`Error::InvalidArgument`]
    /// naming `field(k, second)` (query k's first or second instance) for a query that cannot be
    /// answered (growth with a primitive, the distance of two halfspaces), before any is solved.
    fn answer_snapshot(
        &self,
        scene_id: &str,
        pairs: &[PairRef<'_>],
        field: &dyn Fn(usize, bool) -> String,
    ) -> Result<Vec<QueryAnswer>> {
        let scene = self.scene(scene_id)?;
        // Instances whose body is not built yet, built after the lock is released.
        let mut unbuilt: BTreeMap<&str, (Arc<BodyEntry>, Isometry3)> = BTreeMap::new();
        let (mut posed_by_id, mut scratch) = {
            let s = lock(&scene);
            if s.deleted {
                return Err(Error::not_found("scene", scene_id));
            }
            let mut posed_by_id: HashMap<&str, Posed, foldhash::fast::RandomState> = HashMap::default();
            let mut scratch = WarmStartCache::default();
            for p in pairs {
                for id in [p.first, p.second] {
                    if !posed_by_id.contains_key(id) && !unbuilt.contains_key(id) {
                        let inst = instance(&s, id)?;
                        match inst.entry.ready() {
                            Some(built) => _ = posed_by_id.insert(id, posed(built, inst.pose)),
                            None => _ = unbuilt.insert(id, (inst.entry.clone(), inst.pose)),
                        }
                    }
                }
                if !p.options.cold {
                    s.cache.copy_pair(&mut scratch, warm_kind(p.kind), p.first, p.second);
                }
            }
            (posed_by_id, scratch)
        };
        for (id, (entry, pose)) in unbuilt {
            posed_by_id.insert(id, posed(entry.built()?, pose));
        }
        for (k, p) in pairs.iter().enumerate() {
            answer::check_pair(p, &posed_by_id[p.first], &posed_by_id[p.second], |second| field(k, second))?;
        }
        let params = self.certify_params();
        // Cold distance solves of one body pair on the batch solver's lanes, collide queries the
        // cheap tests decide (see `sublevel_query::dispatch::lane_distances`).
        let mut newton = answer::lane_distances(
            pairs,
            |k| Some((posed_by_id[pairs[k].first].borrowed(), posed_by_id[pairs[k].second].borrowed())),
            &params,
            false,
        );
        let mut answers = Vec::with_capacity(pairs.len());
        for (k, p) in pairs.iter().enumerate() {
            if sublevel_core::cancel::is_cancelled() {
                // The caller abandoned the request (its deadline passed): stop before the next
                // pair and leave the warm starts as they were.
                return Err(Error::Cancelled(format!("query of scene `{scene_id}` abandoned by its caller")));
            }
            let (a, b) = (&posed_by_id[p.first], &posed_by_id[p.second]);
            answers.push(answer::answer_pair_with(*p, a, b, &mut scratch, &params, newton.take(k)));
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
