//! The operational flags of `sublevel serve` (shutdown grace, TLS, authentication), flattened
//! into [`super::serve::ServeArgs`] and applied to a [`ServerConfig`] by [`SecurityArgs::apply`].

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use sublevel::service::auth::AuthTokens;
use sublevel::service::tls::TlsConfig;
use sublevel::service::ServerConfig;
use sublevel::{Error, Result};

/// Operational flags of `sublevel serve`.
#[derive(clap::Args, Debug)]
pub struct SecurityArgs {
    /// After SIGTERM / Ctrl-C: how long to wait for in-flight requests and for cancelled fit jobs
    /// to record their end before exiting anyway (e.g. `10s`, `500ms`, `2m`; a bare number is
    /// seconds).
    #[arg(long, env = "SUBLEVEL_SHUTDOWN_GRACE", default_value = "10s", value_parser = parse_duration)]
    pub shutdown_grace: Duration,
    /// Serve TLS with this certificate chain (PEM; needs --tls-key). Default: plaintext.
    #[arg(long, env = "SUBLEVEL_TLS_CERT", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The private key of --tls-cert (PEM: PKCS#8, PKCS#1 or SEC1).
    #[arg(long, env = "SUBLEVEL_TLS_KEY", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// mTLS: require every client to present a certificate signed by this CA (PEM; needs
    /// --tls-cert).
    #[arg(long, env = "SUBLEVEL_TLS_CLIENT_CA", requires = "tls_cert")]
    pub tls_client_ca: Option<PathBuf>,
    /// Require bearer tokens from this file: lines `admin TOKEN` or `read TOKEN` (`#` comments;
    /// tokens of at least 16 characters). Admin tokens may write and delete; read tokens may
    /// read and query. Health and reflection stay open. Default: no authentication.
    #[arg(long, env = "SUBLEVEL_AUTH_TOKENS")]
    pub auth_tokens: Option<PathBuf>,
}

impl SecurityArgs {
    /// Copies the flags into `config`, reading the TLS files and the token file.
    ///
    /// # Errors
    /// Those of [`TlsConfig::load`] and [`AuthTokens::load`].
    pub fn apply(&self, config: &mut ServerConfig) -> Result<()> {
        config.shutdown_grace = self.shutdown_grace;
        if let (Some(cert), Some(key)) = (&self.tls_cert, &self.tls_key) {
            config.tls = Some(TlsConfig::load(cert, key, self.tls_client_ca.as_deref())?);
        }
        if let Some(path) = &self.auth_tokens {
            let tokens = AuthTokens::load(path)?;
            tracing::info!(?tokens, file = %path.display(), "bearer-token authentication on");
            config.auth = Some(Arc::new(tokens));
        }
        Ok(())
    }
}

/// Parses `10s`, `500ms`, `2m` or a bare number of seconds (fractions allowed) into a duration
/// of at most one hour.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `--shutdown-grace` for anything else.
pub fn parse_duration(text: &str) -> Result<Duration> {
    let t = text.trim();
    let (number, unit) = match t.find(|c: char| c.is_ascii_alphabetic()) {
        Some(i) => t.split_at(i),
        None => (t, "s"),
    };
    let scale = match unit {
        "ms" => 1e-3,
        "s" => 1.0,
        "m" => 60.0,
        other => return Err(Error::invalid("--shutdown-grace", format!("unknown unit {other:?} (use ms, s or m)"))),
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| Error::invalid("--shutdown-grace", format!("{text:?} is not a duration such as 10s or 500ms")))?;
    let seconds = value * scale;
    if !(seconds.is_finite() && (0.0..=3600.0).contains(&seconds)) {
        return Err(Error::invalid("--shutdown-grace", format!("must be between 0 and 1 hour, got {text:?}")));
    }
    Ok(Duration::from_secs_f64(seconds))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel::service::DEFAULT_SHUTDOWN_GRACE;

    #[test]
    fn durations_parse_with_units() {
        assert_eq!(parse_duration("10s").unwrap(), Duration::from_secs(10));
        assert_eq!(parse_duration("500ms").unwrap(), Duration::from_millis(500));
        assert_eq!(parse_duration("2m").unwrap(), Duration::from_secs(120));
        assert_eq!(parse_duration("1.5").unwrap(), Duration::from_millis(1500));
        assert_eq!(parse_duration("10s").unwrap(), DEFAULT_SHUTDOWN_GRACE);
        for bad in ["", "ten", "5h", "-1s", "2h30m", "inf"] {
            assert!(parse_duration(bad).is_err(), "{bad}");
        }
    }
}
