//! `sublevel scene import SCENE.yaml [--addr HOST:PORT] [--name N]`: imports a MoveIt planning
//! scene (YAML, or JSON for a `.json` file) into a running server with `ImportScene`, and prints
//! the new scene's id, then a summary (objects, instances by kind, primitive bodies, skipped
//! shapes) and one line per instance.

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
    /// its primitives and planes become instances of exact primitive bodies; meshes are skipped.
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
    /// Seconds to wait for the connection and the answer.
    #[arg(long, default_value_t = 60.0)]
    timeout: f64,
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
    let mut request = tonic::Request::new(pb::ImportSceneRequest { name: args.name.clone(), scene: Some(scene) });
    if let Some(token) = &args.token {
        let value = format!("Bearer {token}")
            .parse()
            .map_err(|_| Error::invalid("--token", "must be printable ASCII without spaces"))?;
        request.metadata_mut().insert("authorization", value);
    }
    let timeout = std::time::Duration::from_secs_f64(args.timeout.clamp(0.01, 3600.0));
    let fail = |what: String| Error::Io(std::io::Error::other(what));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let reply = runtime.block_on(async {
        let endpoint = tonic::transport::Endpoint::from_shared(format!("http://{}", args.addr))
            .map_err(|e| Error::invalid("--addr", e.to_string()))?
            .connect_timeout(timeout)
            .timeout(timeout);
        let channel = endpoint.connect().await.map_err(|e| fail(format!("cannot reach {}: {e}", args.addr)))?;
        SublevelClient::new(channel)
            .import_scene(request)
            .await
            .map(tonic::Response::into_inner)
            .map_err(|e| fail(format!("ImportScene failed: {:?}: {}", e.code(), e.message())))
    })?;
    print!("{}", summary(&reply));
    Ok(())
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
        "scene `{}`: {} objects, {} instances ({}) of {} primitive bodies, {} shapes skipped",
        r.name,
        r.objects,
        r.instances.len(),
        if kinds.is_empty() { "none".to_owned() } else { kinds.join(", ") },
        r.bodies,
        r.skipped.len()
    );
    for i in &r.instances {
        let note = if i.note.is_empty() { String::new() } else { format!("  ({})", i.note) };
        let _ = writeln!(out, "  {}  {}  {}  {}{note}", i.name, i.instance_id, i.kind, i.body_id);
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
            objects: 3,
            bodies: 2,
            ..Default::default()
        };
        let text = summary(&r);
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("s-1"));
        assert_eq!(
            lines.next(),
            Some("scene `kitchen`: 3 objects, 3 instances (2 box, 1 cylinder) of 2 primitive bodies, 1 shapes skipped")
        );
        assert!(text.contains("skipped mug shape 0 (mesh)"));
    }
}
