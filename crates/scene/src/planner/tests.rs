//! Routing of candidate states to the batch solver's lanes.

use super::view::state_lane_distances;
use super::*;
use crate::answer::{QueryKind, QueryOptions};
use crate::cache::WarmStartCache;
use std::sync::Arc;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{Real, Vector3};
use sublevel_query::CertifyParams;

/// Spheres r = 0.5 at the origin ("a") and r = 0.25 ("b", moved by the states), a non-cold
/// distance query a → b over states putting b at `xs`: the routed answers (state s at index s)
/// with the cache `cache`.
fn routed(xs: &[[Real; 3]], cache: &WarmStartCache) -> Vec<Ahead> {
    let big = Arc::new(ellipsoid([0.0; 3], [0.5; 3]).unwrap());
    let small = Arc::new(ellipsoid([0.0; 3], [0.25; 3]).unwrap());
    let slots = vec![
        Posed { body: big, tree: None, primitive: None, pose: Isometry3::identity() },
        Posed { body: small, tree: None, primitive: None, pose: Isometry3::identity() },
    ];
    let at = |x: &[Real; 3]| Isometry3::translation(x[0], x[1], x[2]);
    let request = PlannerRequest {
        queries: vec![QueryPair {
            kind: QueryKind::Distance,
            first: "a".into(),
            second: "b".into(),
            options: QueryOptions::default(),
            margin: 0.0,
        }],
        states: CandidateStates::Lists(xs.iter().map(|x| vec![("b".to_string(), at(x))]).collect()),
        ..Default::default()
    };
    let state_slots = |s: usize, buf: &mut Vec<(usize, Isometry3)>| {
        buf.clear();
        buf.push((1, at(&xs[s])));
    };
    let params = CertifyParams::default();
    let mut lanes = state_lane_distances(&request, &slots, &[Some((0, 1))], state_slots, &params, None, cache);
    (0..xs.len()).map(|s| lanes.take(s)).collect()
}

/// Candidate states far apart (steps of 0.94 m between spheres of summed scale 0.75 m: past the
/// warm start's reach) take the lanes although the query is not cold, and their answers match
/// the closed form ‖c_b‖ − 0.75 (10⁻⁹ m) and keep valid warm starts for the cache; a trajectory
/// of 5 cm steps stays off the lanes (each state warm-started from the one before: only the
/// first, without a cached warm start, would take them, and one pair is no batch); a cached
/// warm start near the first state keeps that state off them.
#[test]
fn far_candidate_states_take_the_lanes_and_a_trajectory_does_not() {
    let far: Vec<[Real; 3]> = (0..8).map(|k| [1.5 + 0.5 * k as Real, 0.8 * (k % 2) as Real, 0.0]).collect();
    let answers = routed(&far, &WarmStartCache::default());
    for (x, a) in far.iter().zip(&answers) {
        let Ahead::Newton(d) = a else { panic!("state at {x:?} did not take the lanes: {a:?}") };
        let gap = Vector3::from(*x).norm() - 0.75;
        assert!((d.distance - gap).abs() < 1e-9, "{x:?}: {} vs {gap}", d.distance);
        assert!(d.status.converged() && d.warm_start.valid, "{x:?}: {d:?}");
    }
    let near: Vec<[Real; 3]> = (0..8).map(|k| [1.5 + 0.05 * k as Real, 0.0, 0.0]).collect();
    assert!(routed(&near, &WarmStartCache::default()).iter().all(|a| matches!(a, Ahead::Nothing)));
    // With a cached warm start near the first state: still none.
    let (big, small) = (ellipsoid([0.0; 3], [0.5; 3]).unwrap(), ellipsoid([0.0; 3], [0.25; 3]).unwrap());
    let id = Isometry3::identity();
    let d =
        sublevel_query::distance(&big, &id, &small, &Isometry3::translation(1.45, 0.0, 0.0), None, &Default::default());
    let mut cache = WarmStartCache::default();
    cache.put_distance("a", "b", d.warm_start);
    assert!(routed(&near, &cache).iter().all(|a| matches!(a, Ahead::Nothing)));
    // The far states with that cache: the first starts from the cached warm start 5 cm away,
    // the rest take the lanes.
    let answers = routed(&far, &cache);
    assert!(matches!(answers[0], Ahead::Nothing));
    assert!(answers[1..].iter().all(|a| matches!(a, Ahead::Newton(_))));
}
