//! The `sublevel.v1.Sublevel` handlers: validate → call the core → convert, one module per domain.
//!
//! ```text
//! mod.rs      the service state; the trait impl, one delegating call per RPC
//! jobs.rs     StartFitJob, WatchFitJob, GetFitJob, ListFitJobs, CancelFitJob, StartGroupJob
//! bodies.rs   UploadBody, GetBody, ListBodies, DeleteBody
//! scenes.rs   CreateScene, GetScene, ListScenes, DeleteScene, AddInstance, SetPoses, RemoveInstance,
//!             ImportScene
//! robots.rs   StartRobotFitJob, UploadRobot, GetRobot, ListRobots, DeleteRobot, CheckConfigurations, CheckMotions
//! robot_checks.rs  the configuration and motion checks of those (and of query streams)
//! prepared.rs the robot checkers kept across requests until their robot or scene changes
//! scene_robots.rs  SetSceneRobot, ClearSceneRobot, SetJointPositions, AttachObject, DetachObject
//! clouds.rs   UpdatePointCloud, RemovePointCloud: point-cloud obstacles of scenes
//! queries.rs  Distance, Growth, BatchQuery, Query, QueryStream, CheckScene, and where query work
//!             runs (inline on the async workers, or on the SDP slots)
//! motions.rs  CheckInstanceMotions
//! ```
//!
//! Validation and conversions live in [`crate::convert`], blocking work goes through
//! [`crate::runtime`], the operator's limits are [`crate::limits`].

mod bodies;
mod clouds;
#[cfg(test)]
mod clouds_tests;
mod jobs;
mod motions;
mod plans;
mod prepared;
mod queries;
mod robot_checks;
mod robots;
mod scene_robots;
mod scenes;
#[cfg(test)]
mod tests;

use crate::jobs::FitJobs;
use crate::limits::QueryPools;
use crate::pb::{self, sublevel_server::Sublevel};
use crate::ServerConfig;
use std::sync::Arc;
use sublevel_scene::Catalog;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

/// The service state shared by all requests.
#[derive(Debug)]
pub struct SublevelService {
    catalog: Arc<Catalog>,
    config: ServerConfig,
    pub(crate) jobs: Arc<FitJobs>,
    /// Slots of blocking query work: batches (`ServerConfig::batch_workers`) and SDPs
    /// (`ServerConfig::max_concurrent_sdp`).
    pools: QueryPools,
    /// Mebibytes of robot files being validated at once ([`robots::ROBOT_BUILD_BUDGET_MIB`]).
    robot_builds: Arc<tokio::sync::Semaphore>,
    /// Robot checkers kept across requests ([`prepared`]).
    prepared: Arc<prepared::PreparedCheckers>,
    /// Points of sensor frames being decoded and filtered at once
    /// (`ServerConfig::max_frame_points_in_flight`; [`clouds`]).
    cloud_frames: Arc<tokio::sync::Semaphore>,
}

impl SublevelService {
    /// A service over `catalog` with `config`'s limits.
    pub fn new(catalog: Arc<Catalog>, config: ServerConfig) -> Self {
        let jobs = Arc::new(FitJobs::new(catalog.clone(), config.max_concurrent_fits, config.max_fit_queue));
        let pools = QueryPools::new(config.batch_workers, config.max_concurrent_sdp, config.max_concurrent_plans);
        let robot_builds = Arc::new(tokio::sync::Semaphore::new(robots::ROBOT_BUILD_BUDGET_MIB as usize));
        let prepared = Arc::new(prepared::PreparedCheckers::new(config.batch_workers));
        let in_flight = config.max_frame_points_in_flight.clamp(1, tokio::sync::Semaphore::MAX_PERMITS);
        let cloud_frames = Arc::new(tokio::sync::Semaphore::new(in_flight));
        Self { catalog, config, jobs, pools, robot_builds, prepared, cloud_frames }
    }
}

/// A reply of the `Sublevel` trait.
type Reply<T> = Result<Response<T>, Status>;

/// A domain handler's reply: its response, or an error of the core (mapped to its status once, in
/// the trait impl, by [`crate::convert::to_status`]) or a status of the transport (a deadline, a
/// cancelled job, a full queue).
type Handled<T> = Result<Response<T>, HandlerError>;

/// Why a domain handler failed: an error of the core or a ready status.
#[derive(Debug)]
enum HandlerError {
    /// A core error: bad input (with the field's path), not found, numerical trouble, …
    Core(sublevel_core::Error),
    /// A status made by the transport layer or the runtime.
    Status(Status),
}

impl From<sublevel_core::Error> for HandlerError {
    fn from(e: sublevel_core::Error) -> Self {
        Self::Core(e)
    }
}

impl From<Status> for HandlerError {
    fn from(s: Status) -> Self {
        Self::Status(s)
    }
}

impl From<HandlerError> for Status {
    fn from(e: HandlerError) -> Self {
        match e {
            HandlerError::Core(e) => crate::convert::to_status(e),
            HandlerError::Status(s) => s,
        }
    }
}

#[tonic::async_trait]
impl Sublevel for SublevelService {
    async fn start_fit_job(&self, request: Request<pb::StartFitJobRequest>) -> Reply<pb::StartFitJobResponse> {
        jobs::start_fit_job(self, request).await.map_err(Status::from)
    }

    type WatchFitJobStream = ReceiverStream<Result<pb::FitJobUpdate, Status>>;

    async fn watch_fit_job(&self, request: Request<pb::WatchFitJobRequest>) -> Reply<Self::WatchFitJobStream> {
        jobs::watch_fit_job(self, request).await.map_err(Status::from)
    }

    async fn get_fit_job(&self, request: Request<pb::GetFitJobRequest>) -> Reply<pb::GetFitJobResponse> {
        jobs::get_fit_job(self, request).await.map_err(Status::from)
    }

    async fn list_fit_jobs(&self, request: Request<pb::ListFitJobsRequest>) -> Reply<pb::ListFitJobsResponse> {
        jobs::list_fit_jobs(self, request).await.map_err(Status::from)
    }

    async fn cancel_fit_job(&self, request: Request<pb::CancelFitJobRequest>) -> Reply<pb::CancelFitJobResponse> {
        jobs::cancel_fit_job(self, request).await.map_err(Status::from)
    }

    async fn upload_body(&self, request: Request<pb::UploadBodyRequest>) -> Reply<pb::UploadBodyResponse> {
        bodies::upload_body(self, request).await.map_err(Status::from)
    }

    async fn get_body(&self, request: Request<pb::GetBodyRequest>) -> Reply<pb::GetBodyResponse> {
        bodies::get_body(self, request).await.map_err(Status::from)
    }

    async fn list_bodies(&self, request: Request<pb::ListBodiesRequest>) -> Reply<pb::ListBodiesResponse> {
        bodies::list_bodies(self, request).await.map_err(Status::from)
    }

    async fn delete_body(&self, request: Request<pb::DeleteBodyRequest>) -> Reply<pb::DeleteBodyResponse> {
        bodies::delete_body(self, request).await.map_err(Status::from)
    }

    async fn create_scene(&self, request: Request<pb::CreateSceneRequest>) -> Reply<pb::CreateSceneResponse> {
        scenes::create_scene(self, request).await.map_err(Status::from)
    }

    async fn get_scene(&self, request: Request<pb::GetSceneRequest>) -> Reply<pb::GetSceneResponse> {
        scenes::get_scene(self, request).await.map_err(Status::from)
    }

    async fn list_scenes(&self, request: Request<pb::ListScenesRequest>) -> Reply<pb::ListScenesResponse> {
        scenes::list_scenes(self, request).await.map_err(Status::from)
    }

    async fn delete_scene(&self, request: Request<pb::DeleteSceneRequest>) -> Reply<pb::DeleteSceneResponse> {
        scenes::delete_scene(self, request).await.map_err(Status::from)
    }

    async fn add_instance(&self, request: Request<pb::AddInstanceRequest>) -> Reply<pb::AddInstanceResponse> {
        scenes::add_instance(self, request).await.map_err(Status::from)
    }

    async fn set_poses(&self, request: Request<pb::SetPosesRequest>) -> Reply<pb::SetPosesResponse> {
        scenes::set_poses(self, request).await.map_err(Status::from)
    }

    async fn remove_instance(&self, request: Request<pb::RemoveInstanceRequest>) -> Reply<pb::RemoveInstanceResponse> {
        scenes::remove_instance(self, request).await.map_err(Status::from)
    }

    async fn import_scene(&self, request: Request<pb::ImportSceneRequest>) -> Reply<pb::ImportSceneResponse> {
        scenes::import_scene(self, request).await.map_err(Status::from)
    }

    async fn distance(&self, request: Request<pb::DistanceRequest>) -> Reply<pb::DistanceResponse> {
        queries::distance(self, request).await.map_err(Status::from)
    }

    async fn growth(&self, request: Request<pb::GrowthRequest>) -> Reply<pb::GrowthResponse> {
        queries::growth(self, request).await.map_err(Status::from)
    }

    async fn batch_query(&self, request: Request<pb::BatchQueryRequest>) -> Reply<pb::BatchQueryResponse> {
        queries::batch_query(self, request).await.map_err(Status::from)
    }

    async fn start_group_job(&self, request: Request<pb::StartGroupJobRequest>) -> Reply<pb::StartGroupJobResponse> {
        jobs::start_group_job(self, request).await.map_err(Status::from)
    }

    async fn query(&self, request: Request<pb::QueryRequest>) -> Reply<pb::QueryResponse> {
        queries::query(self, request).await.map_err(Status::from)
    }

    type QueryStreamStream = queries::QueryStream;

    async fn query_stream(
        &self,
        request: Request<tonic::Streaming<pb::QueryRequest>>,
    ) -> Reply<Self::QueryStreamStream> {
        queries::query_stream(self, request).await.map_err(Status::from)
    }

    async fn check_scene(&self, request: Request<pb::CheckSceneRequest>) -> Reply<pb::CheckSceneResponse> {
        queries::check_scene(self, request).await.map_err(Status::from)
    }

    async fn start_robot_fit_job(
        &self,
        request: Request<pb::StartRobotFitJobRequest>,
    ) -> Reply<pb::StartRobotFitJobResponse> {
        robots::start_robot_fit_job(self, request).await.map_err(Status::from)
    }

    async fn upload_robot(&self, request: Request<pb::UploadRobotRequest>) -> Reply<pb::UploadRobotResponse> {
        robots::upload_robot(self, request).await.map_err(Status::from)
    }

    async fn get_robot(&self, request: Request<pb::GetRobotRequest>) -> Reply<pb::GetRobotResponse> {
        robots::get_robot(self, request).await.map_err(Status::from)
    }

    async fn list_robots(&self, request: Request<pb::ListRobotsRequest>) -> Reply<pb::ListRobotsResponse> {
        robots::list_robots(self, request).await.map_err(Status::from)
    }

    async fn delete_robot(&self, request: Request<pb::DeleteRobotRequest>) -> Reply<pb::DeleteRobotResponse> {
        robots::delete_robot(self, request).await.map_err(Status::from)
    }

    async fn check_configurations(
        &self,
        request: Request<pb::CheckConfigurationsRequest>,
    ) -> Reply<pb::CheckConfigurationsResponse> {
        robots::check_configurations(self, request).await.map_err(Status::from)
    }

    async fn check_motions(&self, request: Request<pb::CheckMotionsRequest>) -> Reply<pb::CheckMotionsResponse> {
        robots::check_motions(self, request).await.map_err(Status::from)
    }

    async fn set_scene_robot(&self, request: Request<pb::SetSceneRobotRequest>) -> Reply<pb::SetSceneRobotResponse> {
        scene_robots::set_scene_robot(self, request).await.map_err(Status::from)
    }

    async fn clear_scene_robot(
        &self,
        request: Request<pb::ClearSceneRobotRequest>,
    ) -> Reply<pb::ClearSceneRobotResponse> {
        scene_robots::clear_scene_robot(self, request).await.map_err(Status::from)
    }

    async fn set_joint_positions(
        &self,
        request: Request<pb::SetJointPositionsRequest>,
    ) -> Reply<pb::SetJointPositionsResponse> {
        scene_robots::set_joint_positions(self, request).await.map_err(Status::from)
    }

    async fn attach_object(&self, request: Request<pb::AttachObjectRequest>) -> Reply<pb::AttachObjectResponse> {
        scene_robots::attach_object(self, request).await.map_err(Status::from)
    }

    async fn detach_object(&self, request: Request<pb::DetachObjectRequest>) -> Reply<pb::DetachObjectResponse> {
        scene_robots::detach_object(self, request).await.map_err(Status::from)
    }

    async fn update_point_cloud(
        &self,
        request: Request<pb::UpdatePointCloudRequest>,
    ) -> Reply<pb::UpdatePointCloudResponse> {
        clouds::update_point_cloud(self, request).await.map_err(Status::from)
    }

    async fn remove_point_cloud(
        &self,
        request: Request<pb::RemovePointCloudRequest>,
    ) -> Reply<pb::RemovePointCloudResponse> {
        clouds::remove_point_cloud(self, request).await.map_err(Status::from)
    }

    async fn plan(&self, request: Request<pb::PlanRequest>) -> Reply<pb::PlanResponse> {
        plans::plan(self, request).await.map_err(Status::from)
    }

    async fn time_trajectory(&self, request: Request<pb::TimeTrajectoryRequest>) -> Reply<pb::TimeTrajectoryResponse> {
        plans::time_trajectory(self, request).await.map_err(Status::from)
    }

    async fn check_instance_motions(
        &self,
        request: Request<pb::CheckInstanceMotionsRequest>,
    ) -> Reply<pb::CheckInstanceMotionsResponse> {
        motions::check_instance_motions(self, request).await.map_err(Status::from)
    }
}
