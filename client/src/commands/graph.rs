//! `graph` (IgH `ethercat graph`): the network as Graphviz dot, for `dot
//! -Tsvg`. EtherCAT runs as a line through the slaves in ring order; the
//! chip reports each slave's place in it, not its port wiring, so the
//! graph is that line: the master, then every slave with its position,
//! name, identity and state, the DC reference clock (the first slave with
//! DC active) marked.

use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::Report;

/// `ecmxfctl graph --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct GraphReport {
    /// The graph in the dot language.
    pub dot: String,
}

impl Report for GraphReport {
    fn text(&self) -> String {
        self.dot.clone()
    }
}

/// Text safe inside a dot double-quoted string.
fn quoted(text: &str) -> String {
    text.replace('\\', "\\\\").replace('"', "\\\"")
}

/// Draws the slaves the daemon lists.
pub async fn fetch(api: &Api) -> Result<GraphReport, CliError> {
    let slaves = super::slaves::fetch(api, None, false).await?.slaves;
    let reference = slaves.iter().find(|s| s.dc.active).map(|s| s.position);
    let mut dot = String::from("digraph ethercat {\n    rankdir=LR;\n    node [shape=box, fontname=\"monospace\"];\n");
    dot.push_str("    master [label=\"ecmxfd\\nECM-XF\", shape=ellipse];\n");
    let mut previous = "master".to_string();
    for s in &slaves {
        let node = format!("slave{}", s.position);
        let dc = if reference == Some(s.position) { "\\nDC reference clock" } else { "" };
        let style = if s.mismatch.is_empty() { "" } else { ", color=red" };
        dot.push_str(&format!(
            "    {node} [label=\"{}: {}\\n{:#010x}:{:#010x}\\n{}{dc}\"{style}];\n",
            s.position,
            quoted(&s.name),
            s.vendor_id,
            s.product_code,
            s.state
        ));
        dot.push_str(&format!("    {previous} -> {node};\n"));
        previous = node;
    }
    dot.push_str("}\n");
    Ok(GraphReport { dot })
}
