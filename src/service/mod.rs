//! The gRPC service layer (tonic). STUB.
