//! [`QueryView`]: a client's private view of a scene, answering planner requests.

use super::{check_unique, ids_of, AnswerSink, CandidateStates, PlannerAnswers, PlannerRequest};
use crate::answer::{self, answer_pair_with, warm_kind, PairRef, Posed, QueryPair};
use crate::cache::WarmStartCache;
use crate::catalog::Catalog;
use crate::{Error, Result};
use std::collections::HashMap;
use sublevel_core::math::Isometry3;
use sublevel_query::dispatch::{self, LaneAnswers, PairAsk, PosedRef, StateRoute};
use sublevel_query::{CertifyMode, CertifyParams};

/// The posed instances of one request, by id.
type PosedMap<'a> = HashMap<&'a str, Posed, foldhash::fast::RandomState>;

/// A client's private view of a scene: pose overrides and warm starts of its own (see the module
/// docs). A QueryStream holds one for its lifetime; a unary Query uses a fresh one.
#[derive(Debug)]
pub struct QueryView {
    scene_id: String,
    overrides: HashMap<String, Isometry3, foldhash::fast::RandomState>,
    cache: WarmStartCache,
}

impl QueryView {
    /// An empty view of `scene_id` (stored poses, no warm starts).
    pub fn new(scene_id: &str) -> Self {
        Self { scene_id: scene_id.to_owned(), overrides: HashMap::default(), cache: WarmStartCache::default() }
    }

    /// The scene this view looks at.
    pub fn scene_id(&self) -> &str {
        &self.scene_id
    }

    /// The view's pose overrides (instance id, pose), in no particular order: the poses its
    /// requests set, which the stored scene does not see.
    pub fn pose_overrides(&self) -> Vec<(String, Isometry3)> {
        self.overrides.iter().map(|(id, pose)| (id.clone(), *pose)).collect()
    }

    /// Number of warm starts this view holds.
    pub fn warm_starts(&self) -> usize {
        self.cache.len()
    }

    /// Applies `request.poses`, then answers its queries (see the module docs).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance a query names; [`Error::InvalidArgument`]
    /// naming `poses[k].instance_id` / `states[s].poses[k].instance_id` for an unknown or repeated
    /// instance (the view is then unchanged), or `queries[k].first` / `queries[k].second` for a
    /// query that cannot be answered (growth with a primitive, two halfspaces).
    pub fn run(&mut self, catalog: &Catalog, request: &PlannerRequest) -> Result<PlannerAnswers> {
        let mut answers = PlannerAnswers::for_request(request);
        self.run_into(catalog, request, &mut answers)?;
        Ok(answers)
    }

    /// [`QueryView::run`] with each answer handed to `sink` as it is solved.
    ///
    /// # Errors
    /// As [`QueryView::run`] (`sink` then holds no answer).
    pub fn run_into(&mut self, catalog: &Catalog, request: &PlannerRequest, sink: &mut dyn AnswerSink) -> Result<()> {
        if self.run_with(catalog, request, false, sink)? {
            Ok(())
        } else {
            Err(Error::Numerical("an answer needs the SDP outside CertifyMode::NewtonOnly".into()))
        }
    }

    /// [`QueryView::run`] without any SDP (for an async worker): every query is answered in
    /// [`CertifyMode::NewtonOnly`] (a request asking for a certificate must not come here). When an
    /// answer needs the SDP ([`crate::QueryAnswer::needs_sdp`]) it returns `None` and keeps none of the
    /// request's warm starts, so [`QueryView::run`] then gives exactly the answers it would have
    /// given first (the pose updates, already applied, are applied again to the same values).
    ///
    /// # Errors
    /// As [`QueryView::run`].
    pub fn run_newton_only(&mut self, catalog: &Catalog, request: &PlannerRequest) -> Result<Option<PlannerAnswers>> {
        let mut answers = PlannerAnswers::for_request(request);
        Ok(self.run_newton_only_into(catalog, request, &mut answers)?.then_some(answers))
    }

    /// [`QueryView::run_newton_only`] with each answer handed to `sink` as it is solved. Returns
    /// false, with `sink` cleared ([`AnswerSink::clear`]), at the first answer that needs the SDP
    /// (none of the request's warm starts is kept then).
    ///
    /// # Errors
    /// As [`QueryView::run`].
    pub fn run_newton_only_into(
        &mut self,
        catalog: &Catalog,
        request: &PlannerRequest,
        sink: &mut dyn AnswerSink,
    ) -> Result<bool> {
        self.run_with(catalog, request, true, sink)
    }

    /// Validates and resolves `request`, then answers it into `sink`; false (and `sink` cleared)
    /// when `newton_only` and an answer needs the SDP.
    fn run_with(
        &mut self,
        catalog: &Catalog,
        request: &PlannerRequest,
        newton_only: bool,
        sink: &mut dyn AnswerSink,
    ) -> Result<bool> {
        check_unique(|k| format!("poses[{k}].instance_id"), ids_of(&request.poses))?;
        let mut ids: Vec<&str> = ids_of(&request.poses).collect();
        match &request.states {
            CandidateStates::Lists(states) => {
                for (s, state) in states.iter().enumerate() {
                    check_unique(|k| format!("states[{s}].poses[{k}].instance_id"), ids_of(state))?;
                }
                ids.extend(states.iter().flat_map(|s| ids_of(s)));
            }
            CandidateStates::Columns { instance_ids, poses } => {
                let n = instance_ids.len();
                if n == 0 || !poses.len().is_multiple_of(n) {
                    return Err(Error::invalid(
                        "state_columns.poses",
                        format!(
                            "has {} poses: expected a multiple of the {n} instances of `state_columns.instance_ids`",
                            poses.len()
                        ),
                    ));
                }
                let names = instance_ids.iter().map(String::as_str);
                check_unique(|k| format!("state_columns.instance_ids[{k}]"), names.clone())?;
                ids.extend(names);
            }
        }
        ids.extend(request.queries.iter().flat_map(|q| [q.first.as_str(), q.second.as_str()]));
        ids.sort_unstable();
        ids.dedup();
        let stored = catalog.posed_by_ids(&self.scene_id, &ids).map_err(|e| match e {
            Error::NotFound { kind: "instance", id, .. } => {
                let field = request
                    .poses
                    .iter()
                    .position(|(p, _)| *p == id)
                    .map(|k| format!("poses[{k}].instance_id"))
                    .or_else(|| match &request.states {
                        CandidateStates::Lists(states) => states.iter().enumerate().find_map(|(s, st)| {
                            let k = st.iter().position(|(p, _)| *p == id)?;
                            Some(format!("states[{s}].poses[{k}].instance_id"))
                        }),
                        CandidateStates::Columns { instance_ids, .. } => instance_ids
                            .iter()
                            .position(|p| *p == id)
                            .map(|k| format!("state_columns.instance_ids[{k}]")),
                    });
                match field {
                    Some(f) => Error::not_found_at(f, "instance", id),
                    None => Error::not_found("instance", id),
                }
            }
            other => other,
        })?;
        // Queries that cannot be answered are refused before the view changes (`ids` is sorted).
        let at = |id: &str| ids.binary_search(&id).ok().map(|i| &stored[i]);
        for (k, q) in request.queries.iter().enumerate() {
            if let (Some(a), Some(b)) = (at(&q.first), at(&q.second)) {
                answer::check_pair(&q.view(), a, b, |second| {
                    format!("queries[{k}].{}", if second { "second" } else { "first" })
                })?;
            }
        }
        for (id, pose) in &request.poses {
            match self.overrides.get_mut(id) {
                Some(p) => *p = *pose,
                None => {
                    self.overrides.insert(id.clone(), *pose);
                }
            }
        }
        let mut posed: PosedMap<'_> = HashMap::with_capacity_and_hasher(ids.len(), Default::default());
        for (id, mut p) in ids.into_iter().zip(stored) {
            if let Some(pose) = self.overrides.get(id) {
                p.pose = *pose;
            }
            posed.insert(id, p);
        }

        let params = catalog.certify_params();
        if !newton_only {
            return Ok(self.answer_states(request, &mut posed, &params, None, sink));
        }
        // The request's warm starts go to a scratch cache, kept only when no answer needs the SDP.
        let mut scratch = WarmStartCache::default();
        for q in request.queries.iter().filter(|q| !q.options.cold) {
            self.cache.copy_pair(&mut scratch, warm_kind(q.kind), &q.first, &q.second);
        }
        let saved = std::mem::replace(&mut self.cache, scratch);
        let done = self.answer_states(request, &mut posed, &params, Some(CertifyMode::NewtonOnly), sink);
        let scratch = std::mem::replace(&mut self.cache, saved);
        if !done {
            sink.clear();
            return Ok(false);
        }
        self.cache.merge(scratch, |_| true);
        Ok(true)
    }

    /// The queries answered once, or once per candidate state, into `sink`; `mode` overrides each
    /// query's. Takes the instances out of `posed`. With `mode` [`CertifyMode::NewtonOnly`] it
    /// stops at the first answer that needs the SDP and returns false.
    fn answer_states(
        &mut self,
        request: &PlannerRequest,
        posed: &mut PosedMap<'_>,
        params: &CertifyParams,
        mode: Option<CertifyMode>,
        sink: &mut dyn AnswerSink,
    ) -> bool {
        let nq = request.queries.len();
        // The request's instances by slot, each query's two slots and each state's posed slots
        // resolved once (by name only for states given as lists), so that no state hashes an id
        // or touches a reference count.
        let (ids, mut slots): (Vec<&str>, Vec<Posed>) = posed.drain().unzip();
        let slot_of: HashMap<&str, usize, foldhash::fast::RandomState> =
            ids.iter().enumerate().map(|(i, id)| (*id, i)).collect();
        let slot = |id: &str| slot_of.get(id).copied();
        let pairs: Vec<Option<(usize, usize)>> =
            request.queries.iter().map(|q| slot(&q.first).zip(slot(&q.second))).collect();
        if request.states.is_empty() {
            // Cold queries of one body pair among the request's queries: on the batch solver's lanes.
            let mut newton = LaneAnswers::default();
            if dispatch::enough_lane_candidates(
                request.queries.iter().map(|q| q.view().ask()),
                params.newton.batch.min_lane_batch,
            ) {
                let views: Vec<PairRef<'_>> = request.queries.iter().map(|q| with_mode(q.view(), mode)).collect();
                let at = |k: usize| pairs[k].map(|(i, j)| (slots[i].borrowed(), slots[j].borrowed()));
                newton = answer::lane_distances(&views, at, params, false);
            }
            return self.answer_slots(&request.queries, &pairs, &slots, params, mode, (&mut newton, 0, 0), sink);
        }
        // States in columns: the slots of their instances, resolved once.
        let columns: Vec<Option<usize>> = match &request.states {
            CandidateStates::Lists(_) => Vec::new(),
            CandidateStates::Columns { instance_ids, .. } => instance_ids.iter().map(|id| slot(id)).collect(),
        };
        let state_slots = |s: usize, buf: &mut Vec<(usize, Isometry3)>| {
            buf.clear();
            match &request.states {
                CandidateStates::Lists(states) => {
                    buf.extend(states[s].iter().filter_map(|(id, pose)| Some((slot(id)?, *pose))));
                }
                CandidateStates::Columns { poses, .. } => {
                    let state = &poses[s * columns.len()..(s + 1) * columns.len()];
                    buf.extend(columns.iter().zip(state).filter_map(|(c, pose)| Some(((*c)?, *pose))));
                }
            }
        };
        let states = request.states.len();
        let mut buf = Vec::new();
        let mut newton = state_lane_distances(request, &slots, &pairs, state_slots, params, mode, &self.cache);
        // The poses a state replaces, restored after it.
        let mut saved: Vec<(usize, Isometry3)> = Vec::new();
        for s in 0..states {
            state_slots(s, &mut buf);
            saved.extend(buf.iter().map(|&(i, pose)| (i, std::mem::replace(&mut slots[i].pose, pose))));
            if !self.answer_slots(&request.queries, &pairs, &slots, params, mode, (&mut newton, s * nq, s), sink) {
                return false;
            }
            for (i, pose) in saved.drain(..).rev() {
                slots[i].pose = pose;
            }
        }
        true
    }

    /// The queries answered at the poses of the request's instances `slots`, into `sink` as
    /// candidate state `newton.2` (0 without states): query q between `slots[pairs[q].0]` and
    /// `slots[pairs[q].1]` (skipped when `None`), with what was settled ahead (Newton's answers,
    /// collide bounds) where `newton.0` has it (query q at index `newton.1 + q`, taken from it).
    /// With `mode` [`CertifyMode::NewtonOnly`] it stops at the first answer that needs the SDP and
    /// returns false.
    #[allow(clippy::too_many_arguments)]
    fn answer_slots(
        &mut self,
        queries: &[QueryPair],
        pairs: &[Option<(usize, usize)>],
        slots: &[Posed],
        params: &CertifyParams,
        mode: Option<CertifyMode>,
        newton: (&mut LaneAnswers, usize, usize),
        sink: &mut dyn AnswerSink,
    ) -> bool {
        let (newton, offset, state) = newton;
        for (q, (query, ij)) in queries.iter().zip(pairs).enumerate() {
            let Some((i, j)) = *ij else { continue };
            let pair = with_mode(query.view(), mode);
            let answer = answer_pair_with(pair, &slots[i], &slots[j], &mut self.cache, params, newton.take(offset + q));
            if mode.is_some() && answer.needs_sdp() {
                return false;
            }
            sink.push(state, q, answer);
        }
        true
    }
}

/// `pair` with its certification mode replaced by `mode` when given.
fn with_mode(mut pair: PairRef<'_>, mode: Option<CertifyMode>) -> PairRef<'_> {
    if let Some(mode) = mode {
        pair.options.mode = mode;
    }
    pair
}

/// Newton's answers of a request's distance and collide queries across its candidate states from
/// the batch solver's lanes ([`sublevel_query::dispatch::lane_distances`]: each query's pair in
/// every state is one column of one body pair), entry `s · queries + q` for state s and query q:
/// the cold ones, and the others whose warm start would not be used
/// ([`sublevel_query::dispatch::state_route`]: for state 0 the pair's cached warm start, for a
/// later state the pair's relative pose in the state before, more than half the bodies' summed
/// scales away, as between a sampling planner's random candidates), solved on lanes that keep
/// warm starts for the cache. Empty (every answer solved one by one) when fewer than
/// `params.newton.batch.min_lane_batch` of them are. The request's instances are `slots`,
/// query q's pair is `pairs[q]` (slot indices), `state_slots(s, buf)` fills `buf` with state s's
/// (slot, pose) and `cache` holds the warm starts the queries would start from.
#[allow(clippy::too_many_arguments)]
pub(super) fn state_lane_distances(
    request: &PlannerRequest,
    slots: &[Posed],
    pairs: &[Option<(usize, usize)>],
    state_slots: impl Fn(usize, &mut Vec<(usize, Isometry3)>),
    params: &CertifyParams,
    mode: Option<CertifyMode>,
    cache: &WarmStartCache,
) -> LaneAnswers {
    let states = request.states.len();
    let candidates = (0..states).flat_map(|_| request.queries.iter().map(|q| q.view().ask()));
    if candidates.filter(PairAsk::lane_kind).nth(params.newton.batch.min_lane_batch.max(1) - 1).is_none() {
        return LaneAnswers::default();
    }
    let n = states * request.queries.len();
    let (mut views, mut snapshot) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut buf = Vec::new();
    // Each query's relative pose pose_a⁻¹·pose_b in the state before.
    let mut before: Vec<Option<Isometry3>> = vec![None; request.queries.len()];
    let mut warm_lanes = false;
    for s in 0..states {
        state_slots(s, &mut buf);
        // Slot i at this state's pose.
        let at = |i: usize| {
            let p = &slots[i];
            let pose = buf.iter().find(|(k, _)| *k == i).map_or(p.pose, |(_, pose)| *pose);
            PosedRef { pose, ..p.borrowed() }
        };
        for ((q, query), ij) in request.queries.iter().enumerate().zip(pairs) {
            let mut pair = with_mode(query.view(), mode);
            let posed = ij.map(|(i, j)| (at(i), at(j)));
            let rel = posed.as_ref().map(|(a, b)| a.pose.inv_mul(&b.pose));
            let route = dispatch::state_route(
                &pair.ask(),
                posed.as_ref().zip(rel.as_ref()).map(|((a, b), rel)| (a, b, rel)),
                before[q].as_ref(),
                || cache.distance(pair.first, pair.second),
                &params.newton,
            );
            let lanes = route != StateRoute::One;
            if route == StateRoute::Far {
                // Routed like a cold query; the lanes keep its warm start for the cache.
                pair.options.cold = true;
                warm_lanes = true;
            }
            before[q] = rel;
            snapshot.push(if lanes { posed } else { None });
            views.push(pair);
        }
    }
    answer::lane_distances(&views, |k| snapshot[k], params, warm_lanes)
}
