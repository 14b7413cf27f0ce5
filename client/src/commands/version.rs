//! `version` (IgH `ethercat version`): this tool, the daemon, the chip's
//! firmware and the API they speak (Master.GetInfo).

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Report};

/// `ecmxfctl version --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct VersionReport {
    /// ecmxfctl's version.
    pub ecmxfctl: String,
    /// ecmxfd's version.
    pub daemon: String,
    /// The chip's firmware version (FW_VERSION_GET).
    pub firmware: u32,
    /// The gRPC API package both speak.
    pub api: String,
}

impl Report for VersionReport {
    fn text(&self) -> String {
        let mut f = Fields::default();
        f.add("ecmxfctl", &self.ecmxfctl)
            .add("ecmxfd", &self.daemon)
            .add("Chip firmware", format!("{:#04x} ({})", self.firmware, self.firmware))
            .add("API", &self.api);
        f.to_string()
    }
}

/// Asks the daemon.
pub async fn fetch(api: &Api) -> Result<VersionReport, CliError> {
    let i = api.master().get_info(api.req(pb::GetInfoRequest {})).await.map_err(CliError::rpc("master info"))?;
    let i = i.into_inner();
    Ok(VersionReport {
        ecmxfctl: env!("CARGO_PKG_VERSION").into(),
        daemon: i.daemon_version,
        firmware: i.firmware_version,
        api: "ecmxf.v1".into(),
    })
}
