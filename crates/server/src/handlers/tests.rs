//! The service answering a query whose Newton solve does not converge, and planner views
//! refusing bad state columns.

use super::queries::run_view;
use super::*;
use crate::convert as cv;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::pose_from_parts;
use sublevel_query::{AnswerSource, CertifyMode, NewtonParams};
use sublevel_scene::planner::{CandidateStates, PlannerAnswers, PlannerRequest, QueryView};
use sublevel_scene::store::MemoryStore;
use sublevel_scene::QueryOptions;

/// A catalog whose Newton solver stops after one iteration (so it never converges on two
/// ellipsoids) with a scene of two separated ellipsoids: (catalog, scene, a, b).
fn one_iteration_scene() -> (Arc<Catalog>, String, String, String) {
    let params = NewtonParams { max_iterations: 1, ..NewtonParams::default() };
    let catalog = Catalog::open(Box::new(MemoryStore::new()), params).unwrap();
    let b1 = catalog.add_body("e1", ellipsoid([0.0; 3], [0.5, 0.2, 0.3]).unwrap()).unwrap();
    let b2 = catalog.add_body("e2", ellipsoid([0.0; 3], [0.25, 0.4, 0.2]).unwrap()).unwrap();
    let s = catalog.create_scene("s").unwrap();
    let q = [0.9238795325112867, 0.0, 0.3826834323650898, 0.0];
    let a = catalog.add_instance(&s, &b1, pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0; 3]).unwrap()).unwrap();
    let b = catalog.add_instance(&s, &b2, pose_from_parts("pose", q, [1.5, 0.3, -0.2]).unwrap()).unwrap();
    (Arc::new(catalog), s, a, b)
}

/// Newton does not converge: the inline mode (`NewtonOnly`) reports "needs the SDP" without
/// solving one and keeps no warm start; the service (which answers such a request inline
/// first) returns exactly the SDP fallback's answer of a catalog asked directly.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unconverged_newton_answer_is_solved_off_the_workers_with_the_fallback() {
    let (catalog, s, a, b) = one_iteration_scene();
    let only = QueryOptions { mode: CertifyMode::NewtonOnly, ..QueryOptions::default() };
    let inline = catalog.distance_with(&s, &a, &b, &only).unwrap();
    assert!(inline.answer.needs_sdp);
    assert!(!inline.answer.converged);
    assert_eq!(inline.answer.source, AnswerSource::Newton);
    assert!(inline.answer.certificate.is_none(), "no SDP was solved");
    assert_eq!(catalog.cached_warm_starts(&s).unwrap(), 0, "an answer needing the SDP keeps no warm start");
    let g = catalog.growth_with(&s, &a, &b, &only).unwrap();
    assert!(g.answer.needs_sdp && g.answer.certificate.is_none());
    // A planner view: no answers, no warm starts kept.
    let mut view = QueryView::new(&s);
    assert!(view.run_newton_only(&catalog, &request_of(&a, &b)).unwrap().is_none());
    assert_eq!(view.warm_starts(), 0);

    // The reference: a fresh identical catalog asked in the normal mode (the fallback SDP).
    let (reference, rs, ra, rb) = one_iteration_scene();
    let want = reference.distance_with(&rs, &ra, &rb, &QueryOptions::default()).unwrap();
    assert_eq!(want.answer.source, AnswerSource::SdpFallback);
    assert!(want.answer.converged);
    let want_growth = reference.growth_with(&rs, &ra, &rb, &QueryOptions::default()).unwrap();
    assert_eq!(want_growth.answer.source, AnswerSource::SdpFallback);

    let service = SublevelService::new(catalog.clone(), crate::ServerConfig::default());
    let request =
        pb::DistanceRequest { scene_id: s.clone(), instance_a: a.clone(), instance_b: b.clone(), ..Default::default() };
    let got = service.distance(Request::new(request)).await.unwrap().into_inner().answer.unwrap();
    assert_eq!(got.source, pb::AnswerSource::SdpFallback as i32);
    assert!(got.solve.as_ref().unwrap().converged);
    assert!(want.answer.result.distance > 0.1, "{}", want.answer.result.distance);
    assert!(
        (got.distance - want.answer.result.distance).abs() <= 1e-12,
        "{} vs {}",
        got.distance,
        want.answer.result.distance
    );
    let request =
        pb::GrowthRequest { scene_id: s.clone(), instance_1: a.clone(), instance_2: b.clone(), ..Default::default() };
    let got = service.growth(Request::new(request)).await.unwrap().into_inner().answer.unwrap();
    assert_eq!(got.source, pb::AnswerSource::SdpFallback as i32);
    assert!(
        (got.value - want_growth.answer.result.value).abs() <= 1e-12 * want_growth.answer.result.value.abs().max(1.0)
    );

    // The planner path: the view answers the fallback's value too.
    let request = request_of(&a, &b);
    let answers = PlannerAnswers::for_request(&request);
    let (view, out) = run_view(catalog.clone(), &service.pools, QueryView::new(&s), request, answers).await;
    let PlannerAnswers::Single(answers) = out.unwrap() else { panic!("one list of answers") };
    let sublevel_scene::QueryAnswer::Distance(d) = &answers[0] else { panic!("a distance answer") };
    assert_eq!(d.answer.source, AnswerSource::SdpFallback);
    assert!(!d.answer.needs_sdp);
    assert!((d.answer.result.distance - want.answer.result.distance).abs() <= 1e-12);
    assert_eq!(view.warm_starts(), 1, "the blocking run keeps its warm start");

    // States and answers in columns (rows written as solved): the inline run stops at the
    // first row needing the SDP and clears what it wrote; the blocking run gives the
    // fallback's distance on the first row, and the rows after it (warm-started from it, so
    // Newton converges there) agree within 1e-9 m.
    let pose_b = pose_from_parts("pose", [0.9238795325112867, 0.0, 0.3826834323650898, 0.0], [1.5, 0.3, -0.2]);
    let states = CandidateStates::Columns { instance_ids: vec![b.clone()], poses: vec![pose_b.unwrap(); 3] };
    let request = PlannerRequest { states, ..request_of(&a, &b) };
    let mut sink = cv::ColumnsSink::new(sublevel_scene::QueryKind::Distance, 3);
    assert!(!QueryView::new(&s).run_newton_only_into(&catalog, &request, &mut sink).unwrap());
    assert!(sink.finish().value.is_empty(), "the inline run's rows are cleared");
    let sink = cv::ColumnsSink::new(sublevel_scene::QueryKind::Distance, 3);
    let (_, out) = run_view(catalog.clone(), &service.pools, QueryView::new(&s), request, sink).await;
    let rows = out.unwrap().finish();
    assert_eq!(rows.value.len(), 3);
    for (k, v) in rows.value.iter().enumerate() {
        let tol = if k == 0 { 1e-12 } else { 1e-9 };
        assert!((v - want.answer.result.distance).abs() <= tol, "row {k}: {v} vs {}", want.answer.result.distance);
        assert!(rows.converged[k] && !rows.lower_bound[k]);
    }
}

/// States in columns built in-process (not through the converter) are validated by the view:
/// a pose count that is no multiple of the instances, a repeated and an unknown instance are
/// refused naming the field, and the view is left unchanged.
#[test]
fn a_view_refuses_bad_state_columns_naming_the_field() {
    let (catalog, s, a, b) = one_iteration_scene();
    let pose = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 3.0]).unwrap();
    let columns = |ids: &[&str], poses: usize| PlannerRequest {
        states: CandidateStates::Columns {
            instance_ids: ids.iter().map(|id| (*id).to_owned()).collect(),
            poses: vec![pose; poses],
        },
        ..request_of(&a, &b)
    };
    let field_of = |request: &PlannerRequest| match QueryView::new(&s).run(&catalog, request) {
        Err(sublevel_core::Error::InvalidArgument { field, .. } | sublevel_core::Error::NotFound { field, .. }) => {
            field
        }
        other => panic!("expected INVALID_ARGUMENT or NOT_FOUND, got {other:?}"),
    };
    assert_eq!(field_of(&columns(&[&a, &b], 3)), "state_columns.poses");
    assert_eq!(field_of(&columns(&[], 0)), "state_columns.poses");
    assert_eq!(field_of(&columns(&[&b, &a, &b], 3)), "state_columns.instance_ids[2]");
    assert_eq!(field_of(&columns(&[&a, "i-nowhere"], 4)), "state_columns.instance_ids[1]");
    let mut view = QueryView::new(&s);
    assert!(view.run(&catalog, &columns(&[&a, "i-nowhere"], 4)).is_err());
    assert_eq!(view.warm_starts(), 0);
    // Two valid states: one answer list per state.
    let PlannerAnswers::PerState(states) = view.run(&catalog, &columns(&[&a, &b], 4)).unwrap() else {
        panic!("answers per state");
    };
    assert_eq!(states.iter().map(Vec::len).collect::<Vec<_>>(), [1, 1]);
}

fn request_of(a: &str, b: &str) -> PlannerRequest {
    let pair = sublevel_scene::QueryPair {
        kind: sublevel_scene::QueryKind::Distance,
        first: a.to_owned(),
        second: b.to_owned(),
        options: QueryOptions::default(),
        margin: 0.0,
    };
    PlannerRequest { queries: vec![pair], ..PlannerRequest::default() }
}

/// Large Newton-only batches run on the batch slots, not the SDP slots: with the only SDP slot
/// held by a long solve, a 1 000-pair BatchQuery (off the async workers) still answers — it used
/// to wait for that slot — with the distance the catalog computes directly, to 1e-12 m.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn large_batches_do_not_wait_for_the_sdp_slots() {
    use pb::sublevel_server::Sublevel as _;
    let catalog = Catalog::open(Box::new(MemoryStore::new()), NewtonParams::default()).unwrap();
    let b1 = catalog.add_body("e1", ellipsoid([0.0; 3], [0.5, 0.2, 0.3]).unwrap()).unwrap();
    let b2 = catalog.add_body("e2", ellipsoid([0.0; 3], [0.25, 0.4, 0.2]).unwrap()).unwrap();
    let s = catalog.create_scene("s").unwrap();
    let a = catalog.add_instance(&s, &b1, pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0; 3]).unwrap()).unwrap();
    let b =
        catalog.add_instance(&s, &b2, pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [1.5, 0.3, 0.0]).unwrap()).unwrap();
    let catalog = Arc::new(catalog);
    let want = catalog.distance(&s, &a, &b).unwrap().distance;
    let config = ServerConfig { max_concurrent_sdp: 1, batch_workers: 2, ..ServerConfig::default() };
    let service = SublevelService::new(catalog.clone(), config);

    let (release, hold) = std::sync::mpsc::channel::<()>();
    let sdp = service.pools.sdp.clone();
    let holder = tokio::spawn(async move {
        sdp.run(move || {
            let _ = hold.recv_timeout(std::time::Duration::from_secs(30));
            Ok(())
        })
        .await
    });
    while service.pools.sdp.available() > 0 {
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
    let pair = pb::QueryPair {
        kind: pb::QueryKind::Distance as i32,
        first: a.clone(),
        second: b.clone(),
        ..Default::default()
    };
    let request = pb::BatchQueryRequest { scene_id: s.clone(), pairs: vec![pair; 1000], columns: None };
    let reply = tokio::time::timeout(std::time::Duration::from_secs(20), service.batch_query(Request::new(request)))
        .await
        .expect("the batch answered while the only SDP slot was held")
        .unwrap()
        .into_inner();
    assert_eq!(reply.answers.len(), 1000);
    for answer in &reply.answers {
        let Some(pb::query_answer::Answer::Distance(d)) = &answer.answer else { panic!("a distance answer") };
        assert!((d.distance - want).abs() <= 1e-12, "{} vs {want}", d.distance);
    }
    release.send(()).unwrap();
    holder.await.unwrap().unwrap();
}
