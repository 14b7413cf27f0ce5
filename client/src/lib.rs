//! `ecmxfctl`: command-line diagnostics over the ecmxf gRPC API.
//!
//! Not built yet (issue #6). Nothing here pretends to work: the crate exists
//! so the workspace layout is in place.
