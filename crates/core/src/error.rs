//! The crate's one error type.
//!
//! Outcomes that are not errors (a solver hitting its iteration cap, a fit the solver only
//! "almost" solved) are values with a status, not errors; an [`Error`] is bad input, a missing
//! resource, or a broken invariant. The single conversion to a gRPC `Status` lives in
//! `service::convert`, so the math core never sees tonic.

/// Everything that can go wrong in Sublevel.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A caller-supplied value is malformed; `field` names it (e.g. `pose_a.rotation`).
    #[error("invalid argument `{field}`: {reason}")]
    InvalidArgument {
        /// The offending field, in the caller's vocabulary.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An id does not name an existing resource.
    #[error("{kind} `{id}` not found{}", at_field(.field))]
    NotFound {
        /// The resource kind (`body`, `scene`, `instance`, `job`).
        kind: &'static str,
        /// The id that was looked up.
        id: String,
        /// The request field that held it (e.g. `poses[3].instance_id`); empty when the request
        /// has one id of that kind.
        field: String,
    },
    /// The request is valid but the state of a resource forbids it now (e.g. deleting a body
    /// that instances still use); the message says what to change first.
    #[error("failed precondition: {0}")]
    FailedPrecondition(String),
    /// A request exceeds a configured size limit.
    #[error("resource exhausted: {0}")]
    ResourceExhausted(String),
    /// A numerical method failed in a way that is not the caller's fault (e.g. the SDP solver
    /// returned no usable solution).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// Work was stopped on request before it finished (a cancelled fit: see
    /// [`crate::cancel`]); nothing was produced.
    #[error("cancelled: {0}")]
    Cancelled(String),
    /// The persistent store failed.
    #[error("storage: {0}")]
    Storage(String),
    /// Reading or writing a file failed.
    #[error("io: {0}")]
    Io(#[from] std::io::Error),
    /// A JSON document could not be parsed or produced.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}

impl Error {
    /// Shorthand for [`Error::InvalidArgument`].
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::InvalidArgument { field: field.into(), reason: reason.into() }
    }

    /// Shorthand for [`Error::NotFound`]; an id longer than [`CLIP_BYTES`] is clipped (a client's
    /// 16 KB id is never echoed back whole).
    pub fn not_found(kind: &'static str, id: impl Into<String>) -> Self {
        let id: String = id.into();
        Error::NotFound { kind, id: clip(&id), field: String::new() }
    }

    /// [`Error::not_found`] for an id the request field `field` held (a batch's entry), named in
    /// the message.
    pub fn not_found_at(field: impl Into<String>, kind: &'static str, id: impl Into<String>) -> Self {
        let id: String = id.into();
        Error::NotFound { kind, id: clip(&id), field: field.into() }
    }
}

/// ` (in `field`)` after a not-found message, or nothing without a field.
fn at_field(field: &str) -> String {
    if field.is_empty() {
        String::new()
    } else {
        format!(" (in `{field}`)")
    }
}

/// How many bytes of a client-supplied string an error message repeats.
pub const CLIP_BYTES: usize = 64;

/// `s` cut to at most [`CLIP_BYTES`] bytes (at a character boundary) with `…` appended when cut.
pub fn clip(s: &str) -> String {
    if s.len() <= CLIP_BYTES {
        return s.to_owned();
    }
    let mut end = CLIP_BYTES;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &s[..end])
}

/// A client-supplied number as an error message repeats it: plainly when its magnitude is between
/// 10⁻⁴ and 10⁷ (or it is 0), else in scientific notation, so that `1e300` is shown as `1e300` and
/// not as a 301-digit number; NaN and ±∞ as `NaN`, `inf`, `-inf`.
pub fn show_real(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `Result` with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(show_real(0.05), "0.05");
        assert_eq!(show_real(-525.0), "-525");
        assert_eq!(show_real(0.0), "0");
        assert_eq!(show_real(1e300), "1e300");
        assert_eq!(show_real(1e-300), "1e-300");
        assert_eq!(show_real(f64::NAN), "NaN");
        assert_eq!(show_real(f64::NEG_INFINITY), "-inf");
        assert!(show_real(f64::MAX).len() < 30);
    }
}
