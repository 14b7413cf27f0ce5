//! `debug` (IgH `ethercat debug`): the daemon's log filter, shown or set at
//! run time (Master.GetLogFilter/SetLogFilter). IgH's levels are numbers
//! for the master's own messages; here 0 is `info`, 1 and 2 the daemon's
//! own `debug` and `trace` with its libraries kept at `info` (their debug
//! output is every HTTP/2 frame), and anything else is a filter in
//! tracing's syntax (`warn,ecmxfd::engine=debug`). A filter set so lasts
//! until the daemon reads its configuration again (SIGHUP) or restarts.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Report};

/// `ecmxfctl debug --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DebugReport {
    /// The filter in force.
    pub filter: String,
    /// RUST_LOG set it (it cannot be changed at run time).
    pub from_env: bool,
    /// This command set it.
    pub set: bool,
}

impl Report for DebugReport {
    fn text(&self) -> String {
        let mut f = Fields::default();
        let source = match (self.from_env, self.set) {
            (true, _) => "from RUST_LOG",
            (false, true) => "set now, until the next reload or restart",
            (false, false) => "",
        };
        f.add("Log filter", &self.filter);
        if !source.is_empty() {
            f.add("Source", source);
        }
        f.to_string()
    }
}

/// What IgH's numbers mean here; other text is passed as given.
fn filter_of(level: &str) -> &str {
    match level {
        "0" => "info",
        "1" => "info,ecmxfd=debug",
        "2" => "info,ecmxfd=trace",
        other => other,
    }
}

/// Shows the filter, or sets it first.
pub async fn run(api: &Api, level: Option<&str>) -> Result<DebugReport, CliError> {
    let mut m = api.master();
    let (r, set) = match level {
        None => {
            (m.get_log_filter(api.req(pb::GetLogFilterRequest {})).await.map_err(CliError::rpc("log filter"))?, false)
        }
        Some(level) => {
            let req = pb::SetLogFilterRequest { filter: filter_of(level).to_owned() };
            (m.set_log_filter(api.req(req)).await.map_err(CliError::rpc("set the log filter"))?, true)
        }
    };
    let r = r.into_inner();
    Ok(DebugReport { filter: r.filter, from_env: r.from_env, set })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn igh_levels_are_tracing_levels() {
        assert_eq!(filter_of("0"), "info");
        assert_eq!(filter_of("2"), "info,ecmxfd=trace");
        assert_eq!(filter_of("warn,ecmxfd::engine=debug"), "warn,ecmxfd::engine=debug");
    }
}
