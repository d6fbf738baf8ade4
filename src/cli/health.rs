//! `sublevel health --addr HOST:PORT [--service NAME]`: one `grpc.health.v1` Check, for container
//! healthchecks (compose, `deploy/local/container-like-test.sh`) where no grpc_health_probe is
//! installed. Prints the status; exits 0 only when it is SERVING.

use std::time::Duration;
use sublevel::{Error, Result};

/// Arguments of `sublevel health`.
#[derive(clap::Args, Debug)]
pub struct HealthArgs {
    /// `host:port` of the server (plaintext).
    #[arg(long, env = "SUBLEVEL_ADDR", default_value = "127.0.0.1:50051")]
    addr: String,
    /// Service to check; empty = the server as a whole.
    #[arg(long, default_value = "")]
    service: String,
    /// Seconds to wait for the connection and the answer.
    #[arg(long, default_value_t = 3.0)]
    timeout: f64,
}

/// Runs `sublevel health`.
///
/// # Errors
/// [`Error::Io`] when the server cannot be reached, answers an error, or is not SERVING.
pub fn run(args: HealthArgs) -> Result<()> {
    use tonic_health::pb::{health_check_response::ServingStatus, health_client::HealthClient, HealthCheckRequest};
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let timeout = Duration::from_secs_f64(args.timeout.clamp(0.01, 3600.0));
    let fail = |what: String| Error::Io(std::io::Error::other(what));
    runtime.block_on(async move {
        let endpoint = tonic::transport::Endpoint::from_shared(format!("http://{}", args.addr))
            .map_err(|e| Error::invalid("--addr", e.to_string()))?
            .connect_timeout(timeout)
            .timeout(timeout);
        let channel = endpoint.connect().await.map_err(|e| fail(format!("cannot reach {}: {e}", args.addr)))?;
        let reply = HealthClient::new(channel)
            .check(HealthCheckRequest { service: args.service.clone() })
            .await
            .map_err(|e| fail(format!("health check failed: {:?} {}", e.code(), e.message())))?;
        let status = ServingStatus::try_from(reply.into_inner().status).unwrap_or(ServingStatus::Unknown);
        println!("{}", status.as_str_name());
        if status == ServingStatus::Serving {
            Ok(())
        } else {
            Err(fail(format!("{} is {}", args.addr, status.as_str_name())))
        }
    })
}
