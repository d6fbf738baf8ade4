//! The crate's single `Error → tonic::Status` mapping, and field re-labelling for errors of core
//! validation.
//!
//! The status message is the error's text (`invalid argument `poses[3].pose.rotation`: …`); an
//! [`Error::InvalidArgument`] also carries machine-readable details in the status's
//! `grpc-status-details-bin` (a `google.rpc.Status`): one `google.rpc.BadRequest` with one field
//! violation, `field` the path of the offending field in the request's vocabulary (dot-separated,
//! with indices: `poses[3].pose.rotation`, `queries[0].margin`, `data.coefficients`) and
//! `description` the reason alone. Clients read it with any gRPC library's rich-error support,
//! e.g. tonic-types' `StatusExt::get_details_bad_request()` or Python's
//! `grpc_status.rpc_status.from_call`.

use sublevel_core::Error;
use tonic::{Code, Status};
use tonic_types::{ErrorDetails, StatusExt};

/// The gRPC status of an error: its code by kind, its text as the message, and for an
/// [`Error::InvalidArgument`] the field violation in the status details.
pub fn to_status(e: Error) -> Status {
    {
        let code = match &e {
            Error::InvalidArgument { .. } | Error::Json(_) => Code::InvalidArgument,
            Error::NotFound { .. } => Code::NotFound,
            Error::ResourceExhausted(_) => Code::ResourceExhausted,
            Error::FailedPrecondition(_) => Code::FailedPrecondition,
            Error::Numerical(_) => Code::Internal,
            Error::Cancelled(_) => Code::Cancelled,
            Error::Storage(_) | Error::Io(_) => Code::Unavailable,
        };
        match &e {
            Error::InvalidArgument { field, reason } if !field.is_empty() => Status::with_error_details(
                code,
                e.to_string(),
                ErrorDetails::with_bad_request_violation(field.as_str(), reason.as_str()),
            ),
            _ => Status::new(code, e.to_string()),
        }
    }
}

/// Re-labels an [`Error::InvalidArgument`]'s field as `prefix.field` (other errors unchanged), so
/// errors of core validation name the field as the client sent it.
pub fn prefix_field(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: format!("{prefix}.{field}"), reason }
        }
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_map_to_codes_and_keep_the_field() {
        let s = to_status(Error::invalid("poses[3].pose.rotation", "bad"));
        assert_eq!(s.code(), Code::InvalidArgument);
        assert!(s.message().contains("poses[3].pose.rotation"));
        assert_eq!(to_status(Error::not_found("scene", "s-1")).code(), Code::NotFound);
        assert_eq!(to_status(Error::ResourceExhausted("x".into())).code(), Code::ResourceExhausted);
        assert_eq!(to_status(Error::Numerical("x".into())).code(), Code::Internal);
        assert_eq!(to_status(Error::Storage("x".into())).code(), Code::Unavailable);
    }

    /// An invalid argument carries one BadRequest field violation (field path, reason) beside the
    /// unchanged message; other errors carry no details.
    #[test]
    fn invalid_arguments_carry_a_bad_request_field_violation() {
        let e = Error::invalid("poses[3].pose.rotation", "must be a unit quaternion");
        let message = e.to_string();
        let s = to_status(e);
        assert_eq!(s.message(), message);
        let bad = s.get_details_bad_request().expect("BadRequest details");
        assert_eq!(bad.field_violations.len(), 1);
        assert_eq!(bad.field_violations[0].field, "poses[3].pose.rotation");
        assert_eq!(bad.field_violations[0].description, "must be a unit quaternion");
        let s = to_status(Error::not_found("scene", "s-1"));
        assert!(s.get_details_bad_request().is_none() && s.details().is_empty());
    }
}
