//! `ecmxf-proto`: the `ecmxf.v1` gRPC API.
//!
//! Not built yet (issue #5). Nothing here pretends to work: the crate exists
//! so the workspace layout is in place.
