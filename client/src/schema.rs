//! The JSON schemas of every command's `--json` output, generated from the
//! report types themselves, so the published schema
//! (docs/ecmxfctl-json-schema.json, checked by a test) is what the code
//! prints. Streaming commands print one object per line (NDJSON); their
//! schema is that of one line.

use schemars::{JsonSchema, Schema, schema_for};

use crate::commands::{
    alias, cia402, config, crc, cstruct, data, debug, diag, domains, foe, graph, master, pdo, peripherals, reg, sdo,
    sii, slaves, states, version,
};

fn s<T: JsonSchema>() -> Schema {
    schema_for!(T)
}

/// (command, schema of its output) for every command that prints one.
pub fn all() -> Vec<(&'static str, Schema)> {
    vec![
        ("master", s::<master::MasterReport>()),
        ("slaves", s::<slaves::SlavesReport>()),
        ("rescan", s::<slaves::SlavesReport>()),
        ("graph", s::<graph::GraphReport>()),
        ("config", s::<config::ConfigReport>()),
        ("crc", s::<crc::CrcReport>()),
        ("alias", s::<alias::AliasReport>()),
        ("version", s::<version::VersionReport>()),
        ("cstruct", s::<cstruct::CStructReport>()),
        ("domains", s::<domains::DomainsReport>()),
        ("debug", s::<debug::DebugReport>()),
        ("states", s::<states::StatesReport>()),
        ("upload", s::<sdo::UploadReport>()),
        ("download", s::<sdo::DownloadReport>()),
        ("sdos", s::<sdo::SdosReport>()),
        ("sii read", s::<sii::SiiDataReport>()),
        ("sii dump", s::<sii::SiiDataReport>()),
        ("sii write", s::<sii::SiiWriteReport>()),
        ("sii decode", s::<sii::SiiDecodeReport>()),
        ("pdos", s::<pdo::PdosReport>()),
        ("data", s::<data::DataReport>()),
        ("watch", s::<data::WatchLine>()),
        ("cia402 status", s::<cia402::AxesReport>()),
        ("cia402 enable", s::<cia402::AxisReport>()),
        ("cia402 disable", s::<cia402::AxisReport>()),
        ("cia402 quickstop", s::<cia402::AxisReport>()),
        ("cia402 reset", s::<cia402::AxisReport>()),
        ("cia402 mode", s::<cia402::AxisReport>()),
        ("cia402 move", s::<cia402::MoveReport>()),
        ("gpio get", s::<peripherals::GpioReport>()),
        ("gpio set", s::<peripherals::GpioReport>()),
        ("gpio config", s::<peripherals::GpioReport>()),
        ("adc", s::<peripherals::ScalarReport>()),
        ("dac", s::<peripherals::ScalarReport>()),
        ("qei", s::<peripherals::ScalarReport>()),
        ("foe read", s::<foe::FoeReport>()),
        ("foe write", s::<foe::FoeReport>()),
        ("reg read", s::<reg::RegReport>()),
        ("reg write", s::<reg::RegReport>()),
        ("emergencies", s::<diag::EmergenciesReport>()),
        ("events", s::<diag::EventLine>()),
        ("diag", s::<diag::DiagReport>()),
        ("top", s::<crate::top::TopSnapshot>()),
        ("error", s::<crate::error::ErrorReport>()),
    ]
}

/// The whole document: `{"commands": {name: schema}}`.
pub fn document() -> serde_json::Value {
    let commands: serde_json::Map<String, serde_json::Value> =
        all().into_iter().map(|(n, s)| (n.to_owned(), s.to_value())).collect();
    serde_json::json!({
        "$comment": "ecmxfctl --json output schemas, one per command (generated: `ecmxfctl json-schema`). \
                     Streaming commands (watch, events, top) print one object per line. Errors go to \
                     standard error as the \"error\" object. Fields are only ever added within a major version.",
        "commands": commands,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_published_schema_is_what_the_code_prints() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/ecmxfctl-json-schema.json");
        let want = serde_json::to_string_pretty(&super::document()).unwrap() + "\n";
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        if have != want {
            if std::env::var_os("ECMXF_UPDATE_SCHEMA").is_some() {
                std::fs::write(&path, want).unwrap();
                return;
            }
            panic!(
                "{} is out of date with the report types: rerun with ECMXF_UPDATE_SCHEMA=1 and commit it",
                path.display()
            );
        }
    }
}
