//! The crate's single `Error → tonic::Status` mapping, and field re-labelling for errors of core
//! validation.

use crate::Error;
use tonic::{Code, Status};

impl From<Error> for Status {
    fn from(e: Error) -> Self {
        let code = match &e {
            Error::InvalidArgument { .. } | Error::Json(_) => Code::InvalidArgument,
            Error::NotFound { .. } => Code::NotFound,
            Error::ResourceExhausted(_) => Code::ResourceExhausted,
            Error::FailedPrecondition(_) => Code::FailedPrecondition,
            Error::Numerical(_) => Code::Internal,
            Error::Storage(_) | Error::Io(_) => Code::Unavailable,
        };
        Status::new(code, e.to_string())
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
        let s = Status::from(Error::invalid("poses[3].pose.rotation", "bad"));
        assert_eq!(s.code(), Code::InvalidArgument);
        assert!(s.message().contains("poses[3].pose.rotation"));
        assert_eq!(Status::from(Error::not_found("scene", "s-1")).code(), Code::NotFound);
        assert_eq!(Status::from(Error::ResourceExhausted("x".into())).code(), Code::ResourceExhausted);
        assert_eq!(Status::from(Error::Numerical("x".into())).code(), Code::Internal);
        assert_eq!(Status::from(Error::Storage("x".into())).code(), Code::Unavailable);
    }
}
