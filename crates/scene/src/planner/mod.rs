//! What a motion planner asks of a scene: queries on a private view of it, many candidate states
//! per call, collide-with-margin tests decided as cheaply as possible, and scene-wide checks with
//! a broad phase.
//!
//! ```text
//! QueryView      the stored scene + this client's pose overrides + this client's warm starts
//!   run(request) = apply its pose updates (all or nothing), then answer its queries — once, or
//!                  once per candidate state (the state's poses on top, dropped afterwards)
//! collide(a, b, m) = the cheap tests (bounding spheres, separating axis, a common point;
//!                    collide_cheap) decide when they can, with no solve (nanoseconds)
//!                    otherwise the distance solve (warm-started): distance < m or overlapping
//! check_scene    posed bounding boxes grown by m/2 → BVH (parry) → candidate pairs
//!                → bounding spheres, separating axis → distance solves → pairs closer than m,
//!                by distance
//! MotionScene    one instance moving pose to pose (slerp) among the others, certified by
//!                conservative advancement: free, or its first contact parameter
//! ```
//!
//! Nothing here takes a scene's lock while solving: the instances a request names are read (a
//! body `Arc` and a pose each) under the lock, then every solve runs on that snapshot.
//!
//! ```text
//! mod.rs     requests (candidate states as lists or columns), answers, answer sinks
//! view.rs    QueryView: a client's private view, and the routing of a request's candidate
//!            states to the batch solver's lanes
//! check.rs   check_scene: the broad phase and the narrow phase
//! cloud_check.rs  check_scene's instances against the scene's point clouds
//! motion/    MotionScene: rigid-body motions of instances, and the proven pair bounds they step on
//! ```
//!
//! How each pair is answered (compound trees, cheap collide bounds, the batch solver's lanes, one
//! warm-started solve) is decided by [`sublevel_query::dispatch`]; its cheap bounds and the
//! per-pair answer path are re-exported here.

mod check;
mod cloud_check;
mod motion;
#[cfg(test)]
mod tests;
mod view;

pub use crate::answer::{answer_pair, answer_pair_with, CollideReply, Posed};
pub use check::{check_scene, SceneCheck, ScenePair};
pub use motion::{InstanceMotionAnswer, MotionOptions, MotionScene, Moving, Slerp, EXACT_FRACTION};
pub use sublevel_query::dispatch::{collide_cheap, collide_lower_bound, sphere_lower_bound, Ahead, CheapCollide};
pub use view::QueryView;

use crate::answer::{QueryAnswer, QueryPair};
use crate::{Error, Result};
use sublevel_core::math::Isometry3;

/// A planner request on a [`QueryView`] (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct PlannerRequest {
    /// Pose updates of the view, applied before the queries (validated: unknown or repeated
    /// instances reject the whole request).
    pub poses: Vec<(String, Isometry3)>,
    /// The queries, answered in order.
    pub queries: Vec<QueryPair>,
    /// Candidate states: when there are any, the queries are answered once per state, with the
    /// state's poses on top of the view.
    pub states: CandidateStates,
}

/// The candidate states of a [`PlannerRequest`], as a client sends them.
#[derive(Clone, Debug)]
pub enum CandidateStates {
    /// Each state its own list of (instance id, pose) (`QueryRequest.states`); an unknown or
    /// repeated instance is named `states[s].poses[k].instance_id`.
    Lists(Vec<Vec<(String, Isometry3)>>),
    /// Every state poses the same instances, in order (`QueryRequest.state_columns`): instance
    /// `instance_ids[k]` of state s is at `poses[s · instance_ids.len() + k]`, so that no state
    /// carries a name or a list of its own; an unknown or repeated instance is named
    /// `state_columns.instance_ids[k]`, and a length that is no multiple of the instances
    /// `state_columns.poses`.
    Columns {
        /// The instances every state poses.
        instance_ids: Vec<String>,
        /// Their poses, state-major.
        poses: Vec<Isometry3>,
    },
}

impl Default for CandidateStates {
    /// No candidate state.
    fn default() -> Self {
        Self::Lists(Vec::new())
    }
}

impl CandidateStates {
    /// The number of states (0 for columns without instances).
    pub fn len(&self) -> usize {
        match self {
            Self::Lists(states) => states.len(),
            Self::Columns { instance_ids, poses } => poses.len().checked_div(instance_ids.len()).unwrap_or(0),
        }
    }

    /// True when there is no state (the queries are answered once).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The answers of a [`PlannerRequest`]: one list of answers, or one per candidate state.
#[derive(Clone, Debug)]
pub enum PlannerAnswers {
    /// Answers of a request without states.
    Single(Vec<QueryAnswer>),
    /// Answers per candidate state.
    PerState(Vec<Vec<QueryAnswer>>),
}

impl PlannerAnswers {
    /// No answer yet, shaped for `request`: [`PlannerAnswers::Single`] without candidate states,
    /// else one empty list per state.
    pub fn for_request(request: &PlannerRequest) -> Self {
        match request.states.len() {
            0 => Self::Single(Vec::new()),
            n => Self::PerState(vec![Vec::new(); n]),
        }
    }
}

/// Where a planner run puts its answers ([`QueryView::run_into`]), as they are solved: a caller
/// that writes them out at once (e.g. the service's answer columns) never holds them all.
pub trait AnswerSink {
    /// Takes the answer of query `query` (its index in [`PlannerRequest::queries`]) in candidate
    /// state `state` (0 without states). Answers come state by state, queries in order.
    fn push(&mut self, state: usize, query: usize, answer: QueryAnswer);

    /// Forgets every answer pushed so far (a Newton-only run stopped at an answer that needs the
    /// SDP, [`QueryView::run_newton_only_into`], is then run again from its start).
    fn clear(&mut self);
}

impl AnswerSink for PlannerAnswers {
    /// Appends to the answers of `state` (a state outside [`PlannerAnswers::for_request`]'s shape
    /// is ignored).
    fn push(&mut self, state: usize, _query: usize, answer: QueryAnswer) {
        match self {
            Self::Single(a) => a.push(answer),
            Self::PerState(s) => {
                if let Some(a) = s.get_mut(state) {
                    a.push(answer);
                }
            }
        }
    }

    fn clear(&mut self) {
        match self {
            Self::Single(a) => a.clear(),
            Self::PerState(s) => s.iter_mut().for_each(Vec::clear),
        }
    }
}

/// An error naming the first instance id of `ids` that appears twice, as `field(k)`.
fn check_unique<'a>(
    field: impl Fn(usize) -> String,
    ids: impl ExactSizeIterator<Item = &'a str> + Clone,
) -> Result<()> {
    let repeated = |k: usize, id: &str| Err(Error::invalid(field(k), format!("instance `{id}` appears twice")));
    // A state poses a few instances: pairwise comparison, no set (nor field name) per state.
    if ids.len() <= 16 {
        for (k, id) in ids.clone().enumerate() {
            if ids.clone().take(k).any(|p| p == id) {
                return repeated(k, id);
            }
        }
        return Ok(());
    }
    let mut seen = std::collections::HashSet::new();
    for (k, id) in ids.enumerate() {
        if !seen.insert(id) {
            return repeated(k, id);
        }
    }
    Ok(())
}

/// The ids of a list of poses.
fn ids_of(poses: &[(String, Isometry3)]) -> impl ExactSizeIterator<Item = &str> + Clone {
    poses.iter().map(|(id, _)| id.as_str())
}
