//! Compiles the .proto files with protox (pure Rust: no system `protoc`),
//! generates the tonic services and prost messages, and writes the encoded
//! file descriptor sets that the daemon's reflection service serves (the
//! API's, and the google.rpc error model's).
#![forbid(unsafe_code)]

use std::path::PathBuf;

use prost::Message;

const FILES: [&str; 7] = [
    "ecmxf/v1/common.proto",
    "ecmxf/v1/master.proto",
    "ecmxf/v1/sdo.proto",
    "ecmxf/v1/pdo.proto",
    "ecmxf/v1/cia402.proto",
    "ecmxf/v1/admin.proto",
    "ecmxf/v1/peripherals.proto",
];

/// The Sparkplug B payload schema (Eclipse Sparkplug 3.0, 6.4).
const SPARKPLUG: &str = "sparkplug/sparkplug_b.proto";

/// The error model's messages (the status and the details the daemon
/// sends): served by reflection so that clients decode error details
/// with nothing but the daemon; no Rust code is generated from them
/// (the daemon builds them with tonic-types).
const ERROR_MODEL: [&str; 2] = ["google/rpc/status.proto", "google/rpc/error_details.proto"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for f in FILES {
        println!("cargo:rerun-if-changed={f}");
    }
    let fds = protox::compile(FILES, ["."])?;
    let out = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out.join("ecmxf_descriptor.bin"), fds.encode_to_vec())?;
    // Messages and clients with tonic's prost codec.
    tonic_prost_build::configure().build_server(false).compile_fds(fds.clone())?;
    // Servers on their own pass: same messages (extern), but a codec that
    // answers a request body that does not decode INVALID_ARGUMENT (the
    // caller's fault) instead of tonic's INTERNAL (src/codec.rs).
    let server = out.join("server");
    std::fs::create_dir_all(&server)?;
    tonic_prost_build::configure()
        .build_client(false)
        .extern_path(".ecmxf.v1", "crate::v1")
        .codec_path("crate::codec::RequestCodec")
        .out_dir(&server)
        .compile_fds(fds)?;
    // The Sparkplug B payload (MQTT edge node, daemon/src/sparkplug):
    // messages only, its own package, not part of the gRPC API.
    println!("cargo:rerun-if-changed={SPARKPLUG}");
    let sparkplug = protox::compile([SPARKPLUG], ["."])?;
    tonic_prost_build::configure().build_client(false).build_server(false).compile_fds(sparkplug)?;
    for f in ERROR_MODEL {
        println!("cargo:rerun-if-changed={f}");
    }
    let errors = protox::compile(ERROR_MODEL, ["."])?;
    std::fs::write(out.join("error_model_descriptor.bin"), errors.encode_to_vec())?;
    Ok(())
}
