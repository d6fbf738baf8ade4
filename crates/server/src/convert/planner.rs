//! Columns and planner requests: `PairColumns` → validated columns, answers → `AnswerColumns`, and
//! the requests and answers of `Query`, `QueryStream` and `CheckScene`.

use super::queries::{answer_to_proto, distance_reply_to_proto, query_options};
use super::scenes::poses_from_proto;
use super::{prefix_field, require_id, MAX_ID_BYTES};
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::{pose_from_parts, Isometry3, Real};
use sublevel_scene::planner::CandidateStates;
use sublevel_scene::{QueryAnswer, QueryKind, QueryOptions};

/// The queries of a `BatchQuery` in columns (`BatchQueryRequest.columns`), validated.
#[derive(Clone, Debug)]
pub struct PairColumns {
    /// The kind of every pair.
    pub kind: QueryKind,
    /// The instances the pairs index.
    pub instance_ids: Vec<String>,
    /// Index of each pair's first instance.
    pub first: Vec<u32>,
    /// Index of each pair's second instance.
    pub second: Vec<u32>,
    /// COLLIDE: the margin in meters.
    pub margin: Real,
    /// Cold queries (no warm start read or kept; see `PairColumns.cold`).
    pub cold: bool,
}

/// Validates `BatchQueryRequest.columns`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `columns.kind`, `columns.instance_ids[k]`, `columns.second`
/// (length), `columns.first[k]` / `columns.second[k]` (index out of range) or `columns.margin`;
/// [`Error::ResourceExhausted`] above `max_pairs` pairs or instance ids.
pub fn pair_columns_from_proto(c: &pb::PairColumns, max_pairs: usize) -> Result<PairColumns> {
    let kind = match pb::QueryKind::try_from(c.kind) {
        Ok(pb::QueryKind::Distance) => QueryKind::Distance,
        Ok(pb::QueryKind::Growth) => QueryKind::Growth,
        Ok(pb::QueryKind::Collide) => QueryKind::Collide,
        _ => return Err(Error::invalid("columns.kind", "must be DISTANCE, GROWTH or COLLIDE")),
    };
    for (field, n) in [("columns.first", c.first.len()), ("columns.instance_ids", c.instance_ids.len())] {
        if n > max_pairs {
            return Err(Error::ResourceExhausted(format!("`{field}`: {n} entries exceed the limit of {max_pairs}")));
        }
    }
    if c.first.len() != c.second.len() {
        return Err(Error::invalid(
            "columns.second",
            format!("has {} entries, `columns.first` has {}", c.second.len(), c.first.len()),
        ));
    }
    for (k, id) in c.instance_ids.iter().enumerate() {
        require_id("id", id).map_err(|_| {
            Error::invalid(format!("columns.instance_ids[{k}]"), format!("must be 1 to {MAX_ID_BYTES} bytes"))
        })?;
    }
    for (field, column) in [("columns.first", &c.first), ("columns.second", &c.second)] {
        if let Some((k, i)) = column.iter().enumerate().find(|(_, &i)| i as usize >= c.instance_ids.len()) {
            return Err(Error::invalid(
                format!("{field}[{k}]"),
                format!("index {i} is outside columns.instance_ids (length {})", c.instance_ids.len()),
            ));
        }
    }
    if kind == QueryKind::Collide && !(c.margin.is_finite() && c.margin >= 0.0) {
        return Err(Error::invalid("columns.margin", format!("must be finite and >= 0 meters, got {}", c.margin)));
    }
    Ok(PairColumns {
        kind,
        instance_ids: c.instance_ids.clone(),
        first: c.first.clone(),
        second: c.second.clone(),
        margin: c.margin,
        cold: c.cold,
    })
}

/// Answers of a columns request as `AnswerColumns`: one entry per answer in every column (three
/// for points), `decided_by_bounds` for COLLIDE only.
pub fn answers_to_columns(kind: QueryKind, answers: &[QueryAnswer]) -> pb::AnswerColumns {
    let mut c = ColumnsSink::new(kind, answers.len());
    answers.iter().for_each(|a| c.push_row(a));
    c.finish()
}

/// Answer columns (`AnswerColumns`) filled row by row as a planner run solves them
/// ([`sublevel_scene::planner::AnswerSink`]): no answer is kept once its row is written. Rows are
/// in the order pushed (state-major for candidate states); `upper` and `level` exist once a row
/// has a tree answer (earlier rows then get their value and level 0).
#[derive(Debug)]
pub struct ColumnsSink {
    columns: pb::AnswerColumns,
    /// A row had a tree answer: `upper` and `level` are filled.
    trees: bool,
}

impl ColumnsSink {
    /// Empty columns of `kind`, with room for `rows` answers.
    pub fn new(kind: QueryKind, rows: usize) -> Self {
        let columns = pb::AnswerColumns {
            kind: match kind {
                QueryKind::Distance => pb::QueryKind::Distance,
                QueryKind::Growth => pb::QueryKind::Growth,
                QueryKind::Collide => pb::QueryKind::Collide,
            } as i32,
            value: Vec::with_capacity(rows),
            point_a: Vec::with_capacity(3 * rows),
            point_b: Vec::with_capacity(3 * rows),
            converged: Vec::with_capacity(rows),
            overlapping: Vec::with_capacity(rows),
            lower_bound: Vec::with_capacity(rows),
            decided_by_bounds: Vec::with_capacity(if kind == QueryKind::Collide { rows } else { 0 }),
            upper: Vec::new(),
            level: Vec::new(),
        };
        Self { columns, trees: false }
    }

    /// The columns written so far.
    pub fn finish(self) -> pb::AnswerColumns {
        self.columns
    }

    /// Appends `a` as the next row.
    fn push_row(&mut self, a: &QueryAnswer) {
        let c = &mut self.columns;
        let nan = [Real::NAN; 3];
        let (value, pa, pb_, converged, overlapping, lower_bound) = match a {
            QueryAnswer::Distance(d) => {
                let (r, w) = (&d.answer.result, &d.answer);
                (
                    r.distance,
                    r.witness_a.coords.into(),
                    r.witness_b.coords.into(),
                    w.converged,
                    r.overlapping,
                    w.lower_bound,
                )
            }
            QueryAnswer::Growth(g) => {
                let (r, w) = (&g.answer.result, &g.answer);
                let x: [Real; 3] = r.minimizer.coords.into();
                (r.value, x, x, w.converged, r.value <= 1.0, w.lower_bound)
            }
            QueryAnswer::Collide(col) => {
                c.decided_by_bounds.push(col.decided_by_bounds);
                match &col.solve {
                    Some(d) => {
                        let r = &d.answer.result;
                        let (wa, wb) = (r.witness_a.coords.into(), r.witness_b.coords.into());
                        (col.distance, wa, wb, d.answer.converged, col.collides, d.answer.lower_bound)
                    }
                    None => {
                        let converged = col.tree.is_none_or(|t| t.within_tolerance);
                        (col.distance, nan, nan, converged, col.collides, false)
                    }
                }
            }
        };
        let tree = match a {
            QueryAnswer::Distance(d) => d.tree,
            QueryAnswer::Growth(g) => g.tree,
            QueryAnswer::Collide(c) => c.tree,
        };
        if tree.is_some() && !self.trees {
            // The first tree answer: the rows before it were single-body answers.
            self.trees = true;
            c.upper.extend_from_slice(&c.value);
            c.level.resize(c.value.len(), 0);
        }
        if self.trees {
            c.upper.push(tree.map_or(value, |t| t.upper));
            c.level.push(tree.map_or(0, |t| u32::try_from(t.level).unwrap_or(u32::MAX)));
        }
        c.value.push(value);
        c.point_a.extend_from_slice(&pa);
        c.point_b.extend_from_slice(&pb_);
        c.converged.push(converged);
        c.overlapping.push(overlapping);
        c.lower_bound.push(lower_bound);
    }
}

impl sublevel_scene::planner::AnswerSink for ColumnsSink {
    fn push(&mut self, _state: usize, _query: usize, answer: QueryAnswer) {
        self.push_row(&answer);
    }

    fn clear(&mut self) {
        let c = &mut self.columns;
        for v in [&mut c.value, &mut c.point_a, &mut c.point_b, &mut c.upper] {
            v.clear();
        }
        for v in [&mut c.converged, &mut c.overlapping, &mut c.lower_bound, &mut c.decided_by_bounds] {
            v.clear();
        }
        c.level.clear();
        self.trees = false;
    }
}

/// Validates a planner request: its poses (`poses[k]`), candidate states
/// (`states[s].poses[k]`) and queries (`queries[k].kind` / `.first` / `.second` / `.margin`).
/// `max_answers` bounds queries × max(1, states).
///
/// # Errors
/// [`Error::InvalidArgument`] naming the field; [`Error::ResourceExhausted`] above `max_answers`
/// answers or `max_poses` poses in all.
pub fn planner_request_from_proto(
    req: &pb::QueryRequest,
    max_answers: usize,
    max_poses: usize,
) -> Result<sublevel_scene::planner::PlannerRequest> {
    let (state_count, state_poses) = match &req.state_columns {
        Some(c) => {
            if !req.states.is_empty() {
                return Err(Error::invalid("state_columns", "set either `states` or `state_columns`, not both"));
            }
            let n = c.instance_ids.len().max(1);
            (c.poses.len() / (7 * n), c.poses.len() / 7)
        }
        None => (req.states.len(), req.states.iter().map(|s| s.poses.len()).sum::<usize>()),
    };
    let states_field = if req.state_columns.is_some() { "state_columns" } else { "states" };
    let answers = req.queries.len().saturating_mul(state_count.max(1));
    if answers > max_answers {
        return Err(Error::ResourceExhausted(format!(
            "`queries` × `{states_field}`: {} × {} = {answers} answers exceed the limit of {max_answers}",
            req.queries.len(),
            state_count.max(1)
        )));
    }
    let total_poses = req.poses.len() + state_poses;
    if total_poses > max_poses {
        return Err(Error::ResourceExhausted(format!("{total_poses} poses in all exceed the limit of {max_poses}")));
    }
    let poses = poses_from_proto(&req.poses, max_poses)?;
    let states = match &req.state_columns {
        Some(c) => state_columns_from_proto(c, max_poses)?,
        None => CandidateStates::Lists(
            req.states
                .iter()
                .enumerate()
                .map(|(s, st)| {
                    poses_from_proto(&st.poses, max_poses).map_err(|e| prefix_field(e, &format!("states[{s}]")))
                })
                .collect::<Result<Vec<_>>>()?,
        ),
    };
    if let Some(columns) = &req.columns {
        if !req.queries.is_empty() {
            return Err(Error::invalid("columns", "set either `queries` or `columns`, not both"));
        }
        let c = pair_columns_from_proto(columns, max_answers)?;
        if c.first.len().saturating_mul(state_count.max(1)) > max_answers {
            return Err(Error::ResourceExhausted(format!(
                "`columns` × `{states_field}`: {} × {} answers exceed the limit of {max_answers}",
                c.first.len(),
                state_count.max(1)
            )));
        }
        let queries = c
            .first
            .iter()
            .zip(&c.second)
            .map(|(&i, &j)| sublevel_scene::QueryPair {
                kind: c.kind,
                first: c.instance_ids[i as usize].clone(),
                second: c.instance_ids[j as usize].clone(),
                options: QueryOptions { cold: c.cold, ..QueryOptions::default() },
                margin: c.margin,
            })
            .collect();
        return Ok(sublevel_scene::planner::PlannerRequest { poses, queries, states });
    }
    let queries = req
        .queries
        .iter()
        .enumerate()
        .map(|(k, q)| {
            let kind = match pb::QueryKind::try_from(q.kind) {
                Ok(pb::QueryKind::Distance) => QueryKind::Distance,
                Ok(pb::QueryKind::Growth) => QueryKind::Growth,
                Ok(pb::QueryKind::Collide) => QueryKind::Collide,
                _ => return Err(Error::invalid(format!("queries[{k}].kind"), "must be DISTANCE, GROWTH or COLLIDE")),
            };
            let at = |e| prefix_field(e, &format!("queries[{k}]"));
            require_id("first", &q.first).map_err(at)?;
            require_id("second", &q.second).map_err(at)?;
            if !(q.margin.is_finite() && q.margin >= 0.0) {
                return Err(Error::invalid(
                    format!("queries[{k}].margin"),
                    format!("must be finite and >= 0 meters, got {}", q.margin),
                ));
            }
            let mut options = query_options(q.certify, q.with_gradient);
            options.cold = q.cold;
            options.signed = q.signed;
            options.tolerance = super::queries::tree_tolerance(&format!("queries[{k}].tolerance"), q.tolerance)?;
            Ok(sublevel_scene::QueryPair {
                kind,
                first: q.first.clone(),
                second: q.second.clone(),
                options,
                margin: q.margin,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(sublevel_scene::planner::PlannerRequest { poses, queries, states })
}

/// The candidate states of `QueryRequest.state_columns`, validated (the limits on states and
/// poses are checked by the caller).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `state_columns.instance_ids` (none, or `[k]`: empty, too
/// long or repeated), `state_columns.poses` (a length that is no positive multiple of 7 × the
/// instances) or `state_columns.poses[i]` (the first entry of a pose that is not finite, off the
/// supported range, or whose quaternion has no unit norm; with its state and instance);
/// [`Error::ResourceExhausted`] for more than `max_poses` instance ids.
fn state_columns_from_proto(c: &pb::StateColumns, max_poses: usize) -> Result<CandidateStates> {
    let n = c.instance_ids.len();
    if n == 0 {
        return Err(Error::invalid("state_columns.instance_ids", "must name at least one instance"));
    }
    if n > max_poses {
        return Err(Error::ResourceExhausted(format!(
            "`state_columns.instance_ids`: {n} entries exceed the limit of {max_poses}"
        )));
    }
    let mut seen = std::collections::HashSet::with_capacity(n);
    for (k, id) in c.instance_ids.iter().enumerate() {
        require_id("id", id).map_err(|_| {
            Error::invalid(format!("state_columns.instance_ids[{k}]"), format!("must be 1 to {MAX_ID_BYTES} bytes"))
        })?;
        if !seen.insert(id.as_str()) {
            return Err(Error::invalid(format!("state_columns.instance_ids[{k}]"), format!("`{id}` is repeated")));
        }
    }
    if c.poses.is_empty() || !c.poses.len().is_multiple_of(7 * n) {
        return Err(Error::invalid(
            "state_columns.poses",
            format!(
                "has {} numbers: expected a positive multiple of 7 × {n} (w, x, y, z, tx, ty, tz per instance and state)",
                c.poses.len()
            ),
        ));
    }
    let poses = c
        .poses
        .chunks_exact(7)
        .enumerate()
        .map(|(i, v)| {
            let parts = |field: &str| pose_from_parts(field, [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]);
            // The field is named only when the pose is refused (no string per pose).
            parts("").or_else(|_| {
                let (s, k) = (i / n, i % n);
                let id = &c.instance_ids[k];
                parts(&format!("state_columns.poses[{}] (state {s}, instance `{id}`)", 7 * i))
            })
        })
        .collect::<Result<Vec<Isometry3>>>()?;
    Ok(CandidateStates::Columns { instance_ids: c.instance_ids.clone(), poses })
}

/// The answers of a planner request as the proto response.
///
/// `columns`: the request asked in columns (`QueryRequest.columns`) of this kind, so the answers
/// go in `columns` rather than one message each (per state for candidate states). States in
/// `QueryRequest.state_columns` with answers in columns go in one `columns`, state-major, written
/// as they are solved by a [`ColumnsSink`] instead.
pub fn planner_answers_to_proto(
    answers: &sublevel_scene::planner::PlannerAnswers,
    request_id: u64,
    server_seconds: f64,
    columns: Option<QueryKind>,
) -> pb::QueryResponse {
    use sublevel_scene::planner::PlannerAnswers;
    let mut out = pb::QueryResponse { request_id, server_seconds, ..Default::default() };
    match (answers, columns) {
        (PlannerAnswers::Single(a), None) => out.answers = a.iter().map(answer_to_proto).collect(),
        (PlannerAnswers::Single(a), Some(kind)) => out.columns = Some(answers_to_columns(kind, a)),
        (PlannerAnswers::PerState(states), _) => {
            out.states = states
                .iter()
                .map(|a| pb::StateAnswers {
                    any_collision: a.iter().any(|x| matches!(x, QueryAnswer::Collide(c) if c.collides)),
                    answers: if columns.is_none() { a.iter().map(answer_to_proto).collect() } else { Vec::new() },
                    columns: columns.map(|kind| answers_to_columns(kind, a)),
                })
                .collect();
        }
    }
    out
}

/// The kind of a planner request asked in columns (`QueryRequest.columns`), if it is.
pub fn columns_kind(req: &pb::QueryRequest) -> Option<QueryKind> {
    let c = req.columns.as_ref()?;
    match pb::QueryKind::try_from(c.kind) {
        Ok(pb::QueryKind::Distance) => Some(QueryKind::Distance),
        Ok(pb::QueryKind::Growth) => Some(QueryKind::Growth),
        Ok(pb::QueryKind::Collide) => Some(QueryKind::Collide),
        _ => None,
    }
}

/// A scene check as the proto response (without the scene's robot, which the handler adds).
pub fn scene_check_to_proto(c: &sublevel_scene::planner::SceneCheck, server_seconds: f64) -> pb::CheckSceneResponse {
    pb::CheckSceneResponse {
        pairs: c
            .pairs
            .iter()
            .map(|p| pb::ScenePair {
                first: p.first.clone(),
                second: p.second.clone(),
                distance: Some(distance_reply_to_proto(&p.distance)),
            })
            .collect(),
        instances: u32::try_from(c.instances).unwrap_or(u32::MAX),
        candidate_pairs: c.candidate_pairs,
        narrow_phase_solves: c.narrow_phase_solves,
        all_pairs: c.all_pairs,
        server_seconds,
        robot: None,
        scene_version: c.scene_version,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_scene::planner::{AnswerSink, CollideReply};
    use sublevel_scene::TreeInfo;

    /// A collide answer decided by the bounding spheres (no witness points), with `tree` if given.
    fn bounds_answer(distance: Real, tree: Option<TreeInfo>) -> QueryAnswer {
        QueryAnswer::Collide(CollideReply {
            collides: false,
            distance,
            decided_by_bounds: true,
            solve: None,
            margin: 0.0,
            tree,
        })
    }

    /// Rows written one by one as a run solves them equal the rows of the answers collected first,
    /// and `upper` / `level` appear at the first tree answer with the earlier rows filled in
    /// (their value, level 0), as the two-pass rule of `AnswerColumns` says.
    #[test]
    fn columns_written_row_by_row_equal_the_collected_answers() {
        let tree = TreeInfo {
            lower: 0.8,
            upper: 0.9,
            level: 2,
            leaves: Some((3, 0)),
            pairs_evaluated: 5,
            pairs_pruned_by_spheres: 1,
            within_tolerance: true,
            needs_sdp: false,
        };
        let answers = [bounds_answer(0.7, None), bounds_answer(0.8, Some(tree)), bounds_answer(1.5, None)];
        let mut sink = ColumnsSink::new(QueryKind::Collide, 0);
        sink.push(0, 0, bounds_answer(9.0, None));
        sink.clear();
        for (k, a) in answers.iter().enumerate() {
            sink.push(k, 0, a.clone());
        }
        let rows = sink.finish();
        // (Compared as bytes: the witness columns hold NaN.)
        let collected = answers_to_columns(QueryKind::Collide, &answers);
        assert_eq!(prost::Message::encode_to_vec(&rows), prost::Message::encode_to_vec(&collected));
        assert_eq!(rows.value, [0.7, 0.8, 1.5]);
        assert_eq!(rows.upper, [0.7, 0.9, 1.5]);
        assert_eq!(rows.level, [0, 2, 0]);
        assert_eq!(rows.decided_by_bounds, [true, true, true]);
        assert!(rows.point_a.iter().all(|v| v.is_nan()) && rows.point_a.len() == 9);

        // A tree answer in the first row.
        let first = answers_to_columns(QueryKind::Collide, &[answers[1].clone(), answers[0].clone()]);
        assert_eq!((first.upper, first.level), (vec![0.9, 0.7], vec![2, 0]));

        // Without a tree answer there are no tree columns.
        let plain = answers_to_columns(QueryKind::Collide, &[bounds_answer(0.7, None), bounds_answer(1.5, None)]);
        assert!(plain.upper.is_empty() && plain.level.is_empty());
        assert_eq!(plain.value, [0.7, 1.5]);
    }
}
