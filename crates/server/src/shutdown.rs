//! The shutdown grace: once the shutdown signal fires, the server has `grace` to drain in-flight
//! requests and let cancelled fit jobs record their end; then [`super::serve_catalog`] returns
//! anyway (a request still in flight, e.g. an open `QueryStream` or a long certify batch, is
//! abandoned with its connection).
//!
//! ```text
//! signal ──► health NOT_SERVING, jobs cancelled, WatchFitJob streams end, listener closes
//!        ──► in-flight requests drain ──► every job recorded ──► return      (normal case)
//!        ──► `grace` elapsed ─────────────────────────────────► return      (grace expired)
//! ```

use std::future::Future;
use std::time::Duration;

/// Default of `serve --shutdown-grace` (Kubernetes waits 30 s before SIGKILL; 10 s leaves room).
pub const DEFAULT_SHUTDOWN_GRACE: Duration = Duration::from_secs(10);

/// Splits `shutdown` into the future the transport waits on (it completes with `shutdown`) and a
/// deadline that completes `grace` after it (never, when `shutdown` never completes).
pub(crate) fn graced(
    shutdown: impl Future<Output = ()> + Send,
    grace: Duration,
) -> (impl Future<Output = ()> + Send, impl Future<Output = ()> + Send) {
    let (fired, fired_rx) = tokio::sync::oneshot::channel::<()>();
    let signal = async move {
        shutdown.await;
        let _ = fired.send(());
    };
    let deadline = async move {
        if fired_rx.await.is_err() {
            // The server ended on its own (a transport error) before any shutdown.
            std::future::pending::<()>().await;
        }
        tokio::time::sleep(grace).await;
    };
    (signal, deadline)
}

/// Runs `serving` until it completes or `deadline` does, whichever comes first; a deadline that
/// wins is logged and answers `Ok(())` (the grace expired with work in flight).
pub(crate) async fn within<T: Default>(
    serving: impl Future<Output = sublevel_core::Result<T>>,
    deadline: impl Future<Output = ()>,
    grace: Duration,
) -> sublevel_core::Result<T> {
    tokio::select! {
        out = serving => out,
        () = deadline => {
            tracing::warn!(?grace, "shutdown grace expired with requests or jobs in flight; stopping anyway");
            Ok(T::default())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_deadline_follows_the_signal_by_the_grace() {
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let (signal, deadline) = graced(
            async move {
                let _ = rx.await;
            },
            Duration::from_millis(300),
        );
        let start = tokio::time::Instant::now();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(200)).await;
            let _ = tx.send(());
        });
        // The transport never finishes on its own: the deadline ends it 0.2 s + 0.3 s after start.
        let serving = async move {
            signal.await;
            std::future::pending::<sublevel_core::Result<u32>>().await
        };
        let out = within(serving, deadline, Duration::from_millis(300)).await.expect("deadline answers Ok");
        assert_eq!(out, 0);
        let took = start.elapsed();
        assert!(took >= Duration::from_millis(500) && took < Duration::from_millis(900), "{took:?}");
    }
}
