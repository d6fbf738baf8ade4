//! A planner-side client of `sublevel serve --demo`: finds the demo scene, queries distance and
//! growth between the chair and the human, then slides the chair in small steps with `SetPoses`
//! and shows the warm-started answers.
//!
//! ```text
//! cargo run --release -- serve --demo          # terminal 1
//! cargo run --release --example client         # terminal 2 (SUBLEVEL_ADDR to point elsewhere)
//! ```
//!
//! Every call about a scene carries the `x-scene-id` metadata ([`scene_request`]), which a
//! scene-sharding proxy routes on (`deploy/SCALING.md`).

use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::scene_request;

fn pose(tx: f64, ty: f64, tz: f64) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }),
        translation: Some(pb::Vec3 { x: tx, y: ty, z: tz }),
    }
}

#[tokio::main]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let addr = std::env::var("SUBLEVEL_ADDR").unwrap_or_else(|_| "127.0.0.1:50051".into());
    let mut client = SublevelClient::connect(format!("http://{addr}")).await?;

    let bodies = client.list_bodies(pb::ListBodiesRequest::default()).await?.into_inner().bodies;
    for b in &bodies {
        println!("body {:<10} {} degree {} volume {:.3}", b.name, b.body_id, b.degree, b.volume);
    }
    let scenes = client.list_scenes(pb::ListScenesRequest::default()).await?.into_inner().scenes;
    let Some(demo) = scenes.iter().find(|s| s.name == "demo") else {
        return Err("no scene named `demo`: start the server with `sublevel serve --demo`".into());
    };
    let scene = client
        .get_scene(scene_request(&demo.scene_id, pb::GetSceneRequest { scene_id: demo.scene_id.clone() }))
        .await?
        .into_inner();
    let name_of =
        |body_id: &str| bodies.iter().find(|b| b.body_id == body_id).map(|b| b.name.clone()).unwrap_or_default();
    let chair = scene.instances.iter().find(|i| name_of(&i.body_id) == "chair_101").ok_or("no chair instance")?;
    let human = scene.instances.iter().find(|i| name_of(&i.body_id) == "human_10").ok_or("no human instance")?;
    let human_x = human.pose.as_ref().and_then(|p| p.translation.as_ref()).map(|t| t.x).unwrap_or(0.0);

    println!("\nchair slides through the human (human at x = {human_x:.2} m):");
    println!(
        "{:>8} {:>10} {:>11} {:>6} {:>6} {:>12} {:>6} {:>6}",
        "x [m]", "distance", "d(chair|h)", "conv", "iters", "kkt", "warm", ""
    );
    for k in 0..=12 {
        let x = human_x - 2.4 + 0.4 * k as f64;
        client
            .set_poses(scene_request(
                &scene.scene_id,
                pb::SetPosesRequest {
                    scene_id: scene.scene_id.clone(),
                    poses: vec![pb::InstancePose {
                        instance_id: chair.instance_id.clone(),
                        pose: Some(pose(x, 0.0, 0.0)),
                    }],
                },
            ))
            .await?;
        let d = client
            .distance(scene_request(
                &scene.scene_id,
                pb::DistanceRequest {
                    scene_id: scene.scene_id.clone(),
                    instance_a: chair.instance_id.clone(),
                    instance_b: human.instance_id.clone(),
                    ..Default::default()
                },
            ))
            .await?
            .into_inner();
        let g = client
            .growth(scene_request(
                &scene.scene_id,
                pb::GrowthRequest {
                    scene_id: scene.scene_id.clone(),
                    instance_1: chair.instance_id.clone(),
                    instance_2: human.instance_id.clone(),
                    ..Default::default()
                },
            ))
            .await?
            .into_inner();
        let (Some(da), Some(ga)) = (d.answer, g.answer) else { return Err("empty answer".into()) };
        let ds = da.solve.unwrap_or_default();
        println!(
            "{:>8.2} {:>10.4} {:>11.4} {:>6} {:>6} {:>12.1e} {:>6}",
            x, da.distance, ga.value, ds.converged, ds.iterations, ds.kkt_residual, ds.warm_started
        );
    }
    Ok(())
}
