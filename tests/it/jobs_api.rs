//! Integration tests of the stored fit jobs: GetFitJob, ListFitJobs (paged), CancelFitJob of a
//! running 2d = 8 fit and of a queued job, jobs kept across a restart, and the shutdown grace.

use crate::util::{config, sphere_points, ChildServer, Server};
use std::path::Path;
use std::time::{Duration, Instant};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// A 2d = 8 fit of the chair mesh (tens of Clarabel iterations, seconds to solve).
pub(crate) fn chair8(name: &str) -> pb::StartFitJobRequest {
    let off = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/psb/chair_101.off")).unwrap();
    pb::StartFitJobRequest {
        name: name.into(),
        degree: 8,
        source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh {
            mesh_format: pb::MeshFormat::Off as i32,
            data: off,
            ..Default::default()
        })),
        ..Default::default()
    }
}

/// A 2d = 2 fit of a sphere cloud (milliseconds).
fn ball(name: &str) -> pb::StartFitJobRequest {
    pb::StartFitJobRequest {
        name: name.into(),
        degree: 2,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud {
            xyz: sphere_points([0.0, 0.0, 0.0], 0.5, 200),
        })),
        ..Default::default()
    }
}

/// Waits until the job's stream reports the SDP stage.
pub(crate) async fn wait_for_solve(c: &mut SublevelClient<Channel>, job_id: &str) {
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: job_id.into() }).await.unwrap().into_inner();
    loop {
        let u = stream.message().await.unwrap().expect("stream ended before the solve");
        assert_eq!(u.state, pb::JobState::Running as i32, "{u:?}");
        if u.stage == pb::FitStage::Solve as i32 {
            return;
        }
    }
}

/// The terminal update of a job.
async fn finish(c: &mut SublevelClient<Channel>, job_id: &str) -> pb::FitJobUpdate {
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: job_id.into() }).await.unwrap().into_inner();
    let mut last = None;
    while let Some(u) = stream.message().await.unwrap() {
        last = Some(u);
    }
    last.expect("no update")
}

async fn get(c: &mut SublevelClient<Channel>, job_id: &str) -> pb::FitJob {
    c.get_fit_job(pb::GetFitJobRequest { job_id: job_id.into() }).await.unwrap().into_inner().job.unwrap()
}

/// Cancelling a running 2d = 8 fit stops it at the next Clarabel iteration: CancelFitJob returns
/// CANCELLED within a second or two, no body is stored, and a queued job cancelled before it
/// starts ends CANCELLED at once. Get and List report both; unknown ids are NOT_FOUND.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_a_running_and_a_queued_fit() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let running = c.start_fit_job(chair8("chair8")).await.unwrap().into_inner().job_id;
    // One fitting slot (the default): this one waits.
    let queued = c.start_fit_job(ball("queued")).await.unwrap().into_inner().job_id;
    let job = get(&mut c, &queued).await;
    assert_eq!((job.state, job.stage), (pb::JobState::Running as i32, pb::FitStage::Queued as i32), "{job:?}");
    assert_eq!((job.kind.as_str(), job.name.as_str()), ("fit", "queued"));
    assert!(job.created_unix_ms > 1_700_000_000_000 && job.finished_unix_ms == 0, "{job:?}");

    let t = Instant::now();
    let r = c.cancel_fit_job(pb::CancelFitJobRequest { job_id: queued.clone() }).await.unwrap();
    let job = r.into_inner().job.unwrap();
    assert_eq!(job.state, pb::JobState::Cancelled as i32, "{job:?}");
    assert!(job.error.contains("before it started"), "{job:?}");
    assert!(t.elapsed() < Duration::from_secs(1), "a queued job cancels at once: {:?}", t.elapsed());

    wait_for_solve(&mut c, &running).await;
    let t = Instant::now();
    let r = c.cancel_fit_job(pb::CancelFitJobRequest { job_id: running.clone() }).await.unwrap();
    let took = t.elapsed();
    let job = r.into_inner().job.unwrap();
    assert_eq!(job.state, pb::JobState::Cancelled as i32, "{job:?}");
    assert!(job.error.contains("CancelFitJob"), "{job:?}");
    assert!(job.body_id.is_empty() && job.finished_unix_ms >= job.created_unix_ms, "{job:?}");
    assert!(took < Duration::from_secs(3), "cancel took {took:?}");
    eprintln!("CancelFitJob of a running 2d = 8 fit returned CANCELLED after {took:?}");
    let last = finish(&mut c, &running).await;
    assert_eq!(last.state, pb::JobState::Cancelled as i32, "{last:?}");
    // Cancelling again changes nothing.
    let again = c.cancel_fit_job(pb::CancelFitJobRequest { job_id: running.clone() }).await.unwrap();
    assert_eq!(again.into_inner().job.unwrap(), job);

    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert!(bodies.is_empty(), "a cancelled job stores no body: {bodies:?}");
    for e in [
        c.get_fit_job(pb::GetFitJobRequest { job_id: "j-never".into() }).await.unwrap_err(),
        c.cancel_fit_job(pb::CancelFitJobRequest { job_id: "j-never".into() }).await.unwrap_err(),
    ] {
        assert_eq!(e.code(), Code::NotFound, "{e:?}");
    }
    let e = c.get_fit_job(pb::GetFitJobRequest::default()).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    server.stop().await;
}

/// Finished jobs survive a restart: ListFitJobs pages through them ordered by id and GetFitJob
/// answers each with the same fields as before the restart.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn finished_jobs_are_listed_after_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let mut before = Vec::new();
    for name in ["a", "b", "c"] {
        let id = c.start_fit_job(ball(name)).await.unwrap().into_inner().job_id;
        let last = finish(&mut c, &id).await;
        assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
        let job = get(&mut c, &id).await;
        assert_eq!((job.state, job.body_id.as_str()), (pb::JobState::Succeeded as i32, last.body_id.as_str()));
        assert!(job.finished_unix_ms >= job.created_unix_ms && job.created_unix_ms > 0, "{job:?}");
        before.push(job);
    }
    before.sort_by(|x, y| x.job_id.cmp(&y.job_id));
    server.stop().await;

    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let mut listed = Vec::new();
    let mut token = String::new();
    loop {
        let page = c
            .list_fit_jobs(pb::ListFitJobsRequest { page_size: 2, page_token: token.clone() })
            .await
            .unwrap()
            .into_inner();
        assert!(page.jobs.len() <= 2);
        listed.extend(page.jobs);
        if page.next_page_token.is_empty() {
            break;
        }
        token = page.next_page_token;
    }
    assert_eq!(listed, before);
    for job in &before {
        assert_eq!(&get(&mut c, &job.job_id).await, job);
        let body = c.get_body(pb::GetBodyRequest { body_id: job.body_id.clone() }).await.unwrap().into_inner();
        assert_eq!(body.name, job.name);
    }
    server.stop().await;
}

/// SIGTERM during a 2d = 8 fit with `--shutdown-grace 3s`: health and the job's stream say so at
/// once, the fit is cancelled at its next Clarabel iteration, the process exits 0 well within
/// the grace, no body is stored, and after a restart the job reads CANCELLED (jobs are not
/// resumed).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_during_a_fit_exits_within_the_grace_and_the_job_reads_cancelled() {
    let grace = Duration::from_secs(3);
    let dir = tempfile::tempdir().unwrap();
    let mut server = ChildServer::spawn_with(dir.path(), &["--shutdown-grace", "3s"]);
    let mut c = server.client().await;
    let job_id = c.start_fit_job(chair8("chair8")).await.unwrap().into_inner().job_id;
    wait_for_solve(&mut c, &job_id).await;
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: job_id.clone() }).await.unwrap().into_inner();
    assert_eq!(stream.message().await.unwrap().unwrap().stage, pb::FitStage::Solve as i32);
    let t = Instant::now();
    server.signal("-TERM");
    let end = stream.message().await;
    assert!(matches!(&end, Err(s) if s.code() == Code::Unavailable), "{end:?}");
    let status = loop {
        if let Some(s) = server.child.try_wait().unwrap() {
            break s;
        }
        assert!(t.elapsed() < 2 * grace, "no exit {:?} after SIGTERM", 2 * grace);
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    let exit = t.elapsed();
    assert!(status.success(), "{status:?}");
    assert!(exit < grace, "exit took {exit:?}, grace {grace:?}");
    eprintln!("SIGTERM during a 2d = 8 fit: exit after {exit:?} (grace {grace:?})");
    drop(c);
    drop(server);

    let server = ChildServer::spawn(dir.path());
    let mut c = server.client().await;
    let job = get(&mut c, &job_id).await;
    assert_eq!(job.state, pb::JobState::Cancelled as i32, "{job:?}");
    assert!(job.error.contains("shutting down"), "{job:?}");
    let last = finish(&mut c, &job_id).await;
    assert_eq!(last.state, pb::JobState::Cancelled as i32, "{last:?}");
    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert!(bodies.is_empty(), "{bodies:?}");
}

/// A request that never ends (an open QueryStream) does not hold the process past the grace:
/// with `--shutdown-grace 1s` it exits about one second after SIGTERM.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_with_an_open_stream_exits_after_the_grace() {
    let grace = Duration::from_secs(1);
    let dir = tempfile::tempdir().unwrap();
    let mut server = ChildServer::spawn_with(dir.path(), &["--shutdown-grace", "1s"]);
    let mut c = server.client().await;
    let (tx, rx) = tokio::sync::mpsc::channel::<pb::QueryRequest>(1);
    let mut replies = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    tx.send(pb::QueryRequest { scene_id: scene, request_id: 7, ..Default::default() }).await.unwrap();
    assert_eq!(replies.message().await.unwrap().unwrap().request_id, 7);
    let t = Instant::now();
    server.signal("-TERM");
    let status = loop {
        if let Some(s) = server.child.try_wait().unwrap() {
            break s;
        }
        assert!(t.elapsed() < 5 * grace, "no exit 5 s after SIGTERM");
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    let exit = t.elapsed();
    assert!(status.success(), "{status:?}");
    assert!(exit >= grace && exit < grace + Duration::from_millis(500), "exit after {exit:?}");
    drop(tx);
}
