//! `sublevel scene import SCENE.yaml [--addr HOST:PORT] [--name N] [--skip-meshes]
//! [--mesh-tolerance M]`: imports a MoveIt planning scene (YAML, or JSON for a `.json` file) into a
//! running server with `ImportScene`, and prints the new scene's id, then a summary (objects,
//! instances by kind, primitive bodies, mesh fit jobs, skipped shapes) and one line per instance
//! and per mesh job. Then it follows the mesh jobs (`WatchFitJob`) until each ends, printing
//! their progress on stderr and each job's outcome on stdout; it fails when a job does not
//! succeed.

use std::path::PathBuf;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Error, Result};

/// Arguments of `sublevel scene`.
#[derive(clap::Args, Debug)]
pub struct SceneArgs {
    #[command(subcommand)]
    command: SceneCommand,
}

/// What `sublevel scene` does.
#[derive(clap::Subcommand, Debug)]
enum SceneCommand {
    /// Import a MoveIt planning scene (moveit_msgs/PlanningScene as YAML or JSON) as a new scene:
    /// its primitives and planes become instances of exact primitive bodies; each mesh is fitted
    /// as a compound body (a job followed here until it ends) and added at its pose.
    Import(ImportArgs),
}

/// Arguments of `sublevel scene import`.
#[derive(clap::Args, Debug)]
struct ImportArgs {
    /// The planning scene file: YAML, or JSON when its name ends in `.json`.
    scene: PathBuf,
    /// `host:port` of the server (plaintext).
    #[arg(long, env = "SUBLEVEL_ADDR", default_value = "127.0.0.1:50051")]
    addr: String,
    /// The new scene's name (default: the planning scene's own `name`, else "imported").
    #[arg(long, default_value = "")]
    name: String,
    /// A bearer token (`serve --auth-tokens`; ImportScene needs an admin token).
    #[arg(long, env = "SUBLEVEL_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Seconds to wait for the connection and the answer (the mesh jobs are followed without
    /// a limit).
    #[arg(long, default_value_t = 60.0)]
    timeout: f64,
    /// Skip the meshes (listed as skipped, with their poses) instead of fitting them.
    #[arg(long)]
    skip_meshes: bool,
    /// Leaf-excess tolerance of the meshes' compound fits, meters; 0: 1 % of each mesh's
    /// bounding-box diagonal.
    #[arg(long, default_value_t = 0.0)]
    mesh_tolerance: f64,
}

/// Runs `sublevel scene`.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read, the server cannot be reached or answers an error
/// (its code and message, e.g. the scene's field that does not validate).
pub fn run(args: SceneArgs) -> Result<()> {
    match args.command {
        SceneCommand::Import(a) => import(a),
    }
}

fn import(args: ImportArgs) -> Result<()> {
    let bytes = std::fs::read(&args.scene)?;
    let json = args.scene.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let scene =
        if json { pb::import_scene_request::Scene::Json(bytes) } else { pb::import_scene_request::Scene::Yaml(bytes) };
    let token = match &args.token {
        Some(token) => Some(
            format!("Bearer {token}")
                .parse::<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>()
                .map_err(|_| Error::invalid("--token", "must be printable ASCII without spaces"))?,
        ),
        None => None,
    };
    let request = authorized(
        &token,
        pb::ImportSceneRequest {
            name: args.name.clone(),
            scene: Some(scene),
            skip_meshes: args.skip_meshes,
            mesh_tolerance: args.mesh_tolerance,
        },
    );
    let timeout = std::time::Duration::from_secs_f64(args.timeout.clamp(0.01, 3600.0));
    let fail = |what: String| Error::Io(std::io::Error::other(what));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async {
        let endpoint = tonic::transport::Endpoint::from_shared(format!("http://{}", args.addr))
            .map_err(|e| Error::invalid("--addr", e.to_string()))?
            .connect_timeout(timeout);
        let channel = endpoint.connect().await.map_err(|e| fail(format!("cannot reach {}: {e}", args.addr)))?;
        let mut client = SublevelClient::new(channel);
        let mut request = request;
        request.set_timeout(timeout);
        let reply = client
            .import_scene(request)
            .await
            .map(tonic::Response::into_inner)
            .map_err(|e| fail(format!("ImportScene failed: {:?}: {}", e.code(), e.message())))?;
        print!("{}", summary(&reply));
        let mut failed = Vec::new();
        for m in &reply.meshes {
            let watch = authorized(&token, pb::WatchFitJobRequest { job_id: m.job_id.clone() });
            let last = follow_job(&mut client, watch, &m.name)
                .await
                .map_err(|e| fail(format!("WatchFitJob {} failed: {:?}: {}", m.job_id, e.code(), e.message())))?;
            println!("{}", job_outcome(&m.name, &last));
            if last.state != pb::JobState::Succeeded as i32 {
                failed.push(m.name.clone());
            }
        }
        if !failed.is_empty() {
            return Err(fail(format!("the fit jobs of {} did not succeed", failed.join(", "))));
        }
        Ok(())
    })
}

/// A request carrying the bearer token, when there is one.
fn authorized<T>(
    token: &Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>,
    message: T,
) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    if let Some(value) = token {
        request.metadata_mut().insert("authorization", value.clone());
    }
    request
}

/// Streams a fit job's updates until its terminal one, printing each progress step on stderr
/// (`name`: the mesh's planning name); returns the terminal update.
async fn follow_job(
    client: &mut SublevelClient<tonic::transport::Channel>,
    request: tonic::Request<pb::WatchFitJobRequest>,
    name: &str,
) -> std::result::Result<pb::FitJobUpdate, tonic::Status> {
    let mut stream = client.watch_fit_job(request).await?.into_inner();
    let mut last = None;
    let mut shown = String::new();
    while let Some(update) = stream.message().await? {
        // The message names the part being fitted (`part j/n`).
        let line = format!("  {name}: {:3.0} % {}", 100.0 * update.fraction, update.message);
        if line != shown {
            eprintln!("{line}");
            shown = line;
        }
        last = Some(update);
    }
    last.ok_or_else(|| tonic::Status::unavailable("the job's stream ended without an update"))
}

/// One line for a mesh job's terminal update: its state, body and message (or error).
fn job_outcome(name: &str, last: &pb::FitJobUpdate) -> String {
    let state = pb::JobState::try_from(last.state).map_or("unknown", |s| s.as_str_name());
    if last.state == pb::JobState::Succeeded as i32 {
        format!("  mesh {name}  {}  {state}  body {}: {}", last.job_id, last.body_id, last.message)
    } else {
        format!("  mesh {name}  {}  {state}: {}", last.job_id, last.error)
    }
}

/// The printed summary: the scene id on the first line, then the counts, the instances and the
/// skipped shapes.
fn summary(r: &pb::ImportSceneResponse) -> String {
    use std::fmt::Write;
    let mut kinds: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    for i in &r.instances {
        *kinds.entry(i.kind.as_str()).or_default() += 1;
    }
    let kinds: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    let mut out = format!("{}\n", r.scene_id);
    let _ = writeln!(
        out,
        "scene `{}`: {} objects, {} instances ({}) of {} primitive bodies, {} meshes fitting, {} shapes skipped",
        r.name,
        r.objects,
        r.instances.len(),
        if kinds.is_empty() { "none".to_owned() } else { kinds.join(", ") },
        r.bodies,
        r.meshes.len(),
        r.skipped.len()
    );
    for i in &r.instances {
        let note = if i.note.is_empty() { String::new() } else { format!("  ({})", i.note) };
        let _ = writeln!(out, "  {}  {}  {}  {}{note}", i.name, i.instance_id, i.kind, i.body_id);
    }
    for m in &r.meshes {
        let _ =
            writeln!(out, "  {}  job {}  mesh of {} vertices, {} triangles", m.name, m.job_id, m.vertices, m.triangles);
    }
    for s in &r.skipped {
        let _ = writeln!(out, "  skipped {} shape {} ({}): {}", s.object_id, s.shape_index, s.kind, s.reason);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first line is the scene id alone (scripts read it); the counts follow.
    #[test]
    fn the_summary_starts_with_the_scene_id() {
        let instance = |name: &str, kind: &str| pb::ImportedInstance {
            name: name.into(),
            instance_id: format!("i-{name}"),
            kind: kind.into(),
            body_id: "b-1".into(),
            ..Default::default()
        };
        let r = pb::ImportSceneResponse {
            scene_id: "s-1".into(),
            name: "kitchen".into(),
            instances: vec![instance("table#0", "box"), instance("table#1", "box"), instance("can", "cylinder")],
            skipped: vec![pb::SkippedShape { object_id: "mug".into(), kind: "mesh".into(), ..Default::default() }],
            meshes: vec![pb::ImportedMesh {
                name: "crate".into(),
                job_id: "j-1".into(),
                vertices: 8,
                triangles: 12,
                ..Default::default()
            }],
            objects: 3,
            bodies: 2,
            ..Default::default()
        };
        let text = summary(&r);
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("s-1"));
        assert_eq!(
            lines.next(),
            Some(
                "scene `kitchen`: 3 objects, 3 instances (2 box, 1 cylinder) of 2 primitive bodies, 1 meshes fitting, \
                 1 shapes skipped"
            )
        );
        assert!(text.contains("skipped mug shape 0 (mesh)"));
        assert!(text.contains("crate  job j-1  mesh of 8 vertices, 12 triangles"), "{text}");
    }
}
