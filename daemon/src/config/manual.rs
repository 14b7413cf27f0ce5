//! ecmxfd.toml(5): the configuration file's manual page, made from the
//! configuration's own types (their JSON schema, derived with `schemars`
//! from the same definitions the parser and `--check-config` use), so every
//! key the daemon reads is in the page with its type, its default and its
//! documentation, and a key cannot be added without appearing there.

use std::collections::HashSet;

use schemars::Schema;
use serde_json::{Map, Value};

/// What the page says before the keys.
const HEAD: &str = r#".SH SYNOPSIS
.I /etc/ecmxfd/ecmxfd.toml
.SH DESCRIPTION
The configuration of ecmxfd(8), in TOML. \fBversion = 1\fR and a
\fB[link]\fR table are required; every other table is optional and off or
at its defaults when absent. A key the daemon does not know is an error
naming it, as is a value of the wrong type or range.
.PP
\fBecmxfd \-\-check\-config FILE\fR reads a file as the daemon would and
says what it would do (the link budget, the network it expects, the
listeners) without touching the chip; its exit status is 2 for a mistake.
SIGHUP makes a running daemon read the file again: roles, tokens, the log
level and Sparkplug apply at once; the log says which other changes need a
restart.
.PP
Paths are absolute or relative to the file's folder. Durations carry
their unit in the key's name (\fB_ms\fR, \fB_us\fR, \fB_ns\fR, \fB_s\fR).
Examples are in /usr/share/doc/ecmxfd/examples (ecmxfd\-rpi.toml for a
Raspberry Pi, ecmxfd\-gateway.toml, ecmxfd\-eni.toml, ecmxfd\-sim.toml).
"#;

/// What the page says after the keys.
const TAIL: &str = r#".SH EXAMPLE
A Raspberry Pi with the chip on SPI0 and its INT lines on GPIO 24 and 25:
.PP
.nf
.RS
version = 1

[link]
backend = "spidev"
device = "/dev/spidev0.0"
spi_hz = 20000000
gpio_chip = "/dev/gpiochip0"
int0_line = 24
int1_line = 25

[cycle]
sync0_us = 1000
.RE
.fi
.SH SEE ALSO
ecmxfd(8), ecmxfctl(1), ecmxf\-sim(1)
"#;

/// The whole page, in roff, for the configuration whose JSON schema is
/// `schema` (`super::manual_page` gives it the file's).
pub(super) fn render(schema: &Schema, version: &str) -> String {
    let root = schema.as_value();
    let defs = root.get("$defs").and_then(Value::as_object).cloned().unwrap_or_default();
    let mut page = format!(
        ".TH ecmxfd.toml 5 \"\" \"ecmxfd {version}\" \"File formats\"\n.SH NAME\necmxfd.toml \\- the configuration \
         file of ecmxfd, the ECM\\-XF EtherCAT master daemon\n{HEAD}"
    );
    let top = Table { path: String::new(), array: false, schema: resolve(root, &defs).0 };
    page.push_str(".SH TOP\\-LEVEL KEYS\n");
    let mut told = HashSet::new();
    top.write_keys(&defs, &mut page, &mut told);
    top.write_tables(&defs, &mut page, &mut told);
    page.push_str(TAIL);
    page
}

/// Every key the page documents, dotted (`cycle.sync0_us`,
/// `slave.sdo.index`): what the tests hold the page and the examples to.
pub(super) fn keys(schema: &Schema) -> Vec<String> {
    let root = schema.as_value();
    let defs = root.get("$defs").and_then(Value::as_object).cloned().unwrap_or_default();
    let mut keys = Vec::new();
    collect_keys(&resolve(root, &defs).0, &defs, "", &mut keys);
    keys
}

/// The keys whose documentation is missing (neither the field nor its
/// type has a doc comment): none may be, the page would have a blank.
#[cfg(test)]
pub(super) fn undocumented(schema: &Schema) -> Vec<String> {
    fn walk(schema: &Value, defs: &Map<String, Value>, prefix: &str, missing: &mut Vec<String>) {
        for (name, field) in properties(schema) {
            let path = if prefix.is_empty() { name.clone() } else { format!("{prefix}.{name}") };
            if description(field).or_else(|| description(&resolve(field, defs).0)).is_none_or(|d| d.is_empty()) {
                missing.push(path.clone());
            }
            if let Some(t) = table_of(&path, field, defs) {
                walk(&t.schema, defs, &path, missing);
            }
        }
    }
    let root = schema.as_value();
    let defs = root.get("$defs").and_then(Value::as_object).cloned().unwrap_or_default();
    let mut missing = Vec::new();
    walk(&resolve(root, &defs).0, &defs, "", &mut missing);
    missing
}

fn collect_keys(schema: &Value, defs: &Map<String, Value>, prefix: &str, keys: &mut Vec<String>) {
    for (name, field) in properties(schema) {
        let path = if prefix.is_empty() { name.clone() } else { format!("{prefix}.{name}") };
        keys.push(path.clone());
        if let Some(t) = table_of(&path, field, defs) {
            collect_keys(&t.schema, defs, &path, keys);
        }
    }
}

/// A TOML table of the file: `[path]`, or `[[path]]` for an array of them.
struct Table {
    path: String,
    array: bool,
    schema: Value,
}

impl Table {
    /// Its plain keys (values, lists of values), one `.TP` each; what an
    /// enumeration's values mean is told where it first appears (`told`).
    fn write_keys(&self, defs: &Map<String, Value>, page: &mut String, told: &mut HashSet<String>) {
        let required = required(&self.schema);
        for (name, field) in properties(&self.schema) {
            if table_of(name, field, defs).is_some() {
                continue;
            }
            let (resolved, _) = resolve(field, defs);
            page.push_str(".TP\n");
            page.push_str(&format!(".B {}\n", roff_text(name)));
            let mut what = type_words(&resolved, defs);
            if required.contains(&name.as_str()) {
                what.push_str(", required");
            }
            if let Some(d) = default_words(name, field) {
                what.push_str(&format!(", default {d}"));
            }
            page.push_str(&format!("({})\n", roff_text(&what)));
            let text = description(field).or_else(|| description(&resolved)).unwrap_or_default();
            page.push_str(&roff_text(&text));
            page.push('\n');
            let values = enum_values(&resolved, defs);
            let key = values.iter().map(|(v, _)| v.as_str()).collect::<Vec<_>>().join(",");
            if !told.insert(key) {
                continue;
            }
            for (value, about) in values {
                if let Some(about) = about {
                    page.push_str(&format!(".RS\n.TP\n.B {}\n{}\n.RE\n", roff_text(&value), roff_text(&about)));
                }
            }
        }
    }

    /// Its tables, each a section (top level) or a subsection.
    fn write_tables(&self, defs: &Map<String, Value>, page: &mut String, told: &mut HashSet<String>) {
        for (name, field) in properties(&self.schema) {
            let path = if self.path.is_empty() { name.clone() } else { format!("{}.{name}", self.path) };
            let Some(table) = table_of(&path, field, defs) else { continue };
            let heading = if table.array { format!("[[{path}]]") } else { format!("[{path}]") };
            let macro_name = if self.path.is_empty() { ".SH" } else { ".SS" };
            page.push_str(&format!("{macro_name} {}\n", roff_text(&heading)));
            let mut about = description(field).unwrap_or_default();
            if table.array {
                about.push_str(" A list: each entry is one [[");
                about.push_str(&path);
                about.push_str("]] table.");
            } else if required(&self.schema).contains(&name.as_str()) {
                about.push_str(" Required.");
            } else {
                about.push_str(" Optional.");
            }
            page.push_str(&roff_text(about.trim()));
            page.push('\n');
            table.write_keys(defs, page, told);
            table.write_tables(defs, page, told);
        }
    }
}

/// The table a field is, if it is one (an object with keys, or a list of
/// them).
fn table_of(path: &str, field: &Value, defs: &Map<String, Value>) -> Option<Table> {
    let (resolved, _) = resolve(field, defs);
    if !properties(&resolved).is_empty() {
        return Some(Table { path: path.to_owned(), array: false, schema: resolved });
    }
    if types(&resolved).contains(&"array") {
        let (items, _) = resolve(resolved.get("items")?, defs);
        if !properties(&items).is_empty() {
            return Some(Table { path: path.to_owned(), array: true, schema: items });
        }
    }
    None
}

/// A schema with its `$ref` followed and `Option`'s null taken out:
/// (the schema, whether it was optional). The field's own description
/// stays with the field.
fn resolve(schema: &Value, defs: &Map<String, Value>) -> (Value, bool) {
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        let name = r.rsplit('/').next().unwrap_or_default();
        return match defs.get(name) {
            Some(target) => resolve(target, defs),
            None => (schema.clone(), false),
        };
    }
    for key in ["anyOf", "oneOf"] {
        if let Some(options) = schema.get(key).and_then(Value::as_array) {
            let real: Vec<&Value> = options.iter().filter(|o| types(o) != ["null"]).collect();
            if real.len() == 1 && real.len() < options.len() {
                return (resolve(real[0], defs).0, true);
            }
        }
    }
    let mut s = schema.clone();
    let nullable = types(schema).contains(&"null");
    if let Some(Value::Array(t)) = s.get_mut("type") {
        t.retain(|v| v != "null");
        if t.len() == 1 {
            let only = t[0].clone();
            s["type"] = only;
        }
    }
    (s, nullable)
}

fn types(schema: &Value) -> Vec<&str> {
    match schema.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    }
}

fn properties(schema: &Value) -> Vec<(&String, &Value)> {
    schema.get("properties").and_then(Value::as_object).map(|p| p.iter().collect()).unwrap_or_default()
}

fn required(schema: &Value) -> Vec<&str> {
    schema
        .get("required")
        .and_then(Value::as_array)
        .map(|r| r.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default()
}

fn description(schema: &Value) -> Option<String> {
    schema.get("description").and_then(Value::as_str).map(tidy)
}

/// The values an enumeration takes, with what each means when documented.
fn enum_values(schema: &Value, defs: &Map<String, Value>) -> Vec<(String, Option<String>)> {
    if let Some(values) = schema.get("enum").and_then(Value::as_array) {
        return values.iter().map(|v| (toml_value(v), None)).collect();
    }
    if let Some(c) = schema.get("const") {
        return vec![(toml_value(c), description(schema))];
    }
    let mut out = Vec::new();
    for key in ["oneOf", "anyOf"] {
        for option in schema.get(key).and_then(Value::as_array).into_iter().flatten() {
            let (o, _) = resolve(option, defs);
            let values = enum_values(&o, defs);
            let about = description(option).or_else(|| description(&o));
            match values.len() {
                1 => out.push((values[0].0.clone(), values[0].1.clone().or(about))),
                _ => out.extend(values),
            }
        }
    }
    out
}

/// The type as words: "integer", "list of strings", "one of "a", "b"".
fn type_words(schema: &Value, defs: &Map<String, Value>) -> String {
    let values = enum_values(schema, defs);
    if !values.is_empty() {
        let list: Vec<String> = values.into_iter().map(|(v, _)| v).collect();
        return format!("one of {}", list.join(", "));
    }
    let t = types(schema);
    match t.first().copied() {
        Some("array") => {
            let items = schema.get("items").map(|i| resolve(i, defs).0).unwrap_or(Value::Null);
            format!("list of {}", plural(&type_words(&items, defs)))
        }
        Some("object") => "table".to_owned(),
        Some("integer") => match (schema.get("minimum"), schema.get("maximum")) {
            (Some(lo), Some(hi)) => format!("integer {lo}..{hi}"),
            _ => "integer".to_owned(),
        },
        Some(other) => other.to_owned(),
        None => "value".to_owned(),
    }
}

fn plural(word: &str) -> String {
    if word.starts_with("one of") || word.starts_with("list") {
        word.to_owned()
    } else if let Some(range) = word.strip_prefix("integer") {
        format!("integers{range}")
    } else {
        format!("{word}s")
    }
}

/// The default as TOML writes it, if the schema names one worth saying
/// (not absent, not an empty list); a file mode in octal.
fn default_words(name: &str, field: &Value) -> Option<String> {
    match field.get("default")? {
        Value::Null => None,
        Value::Array(a) if a.is_empty() => None,
        Value::Object(_) => None,
        Value::Number(n) if name.ends_with("_mode") => n.as_u64().map(|m| format!("0o{m:o}")),
        v => Some(toml_value(v)),
    }
}

fn toml_value(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        other => other.to_string(),
    }
}

/// A doc comment as one paragraph: lines joined, references into the
/// source tree (a parenthesis naming a `.rs` file or a `src/` folder)
/// left out, since the page's reader has no source.
fn tidy(text: &str) -> String {
    let joined = text.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut out = String::with_capacity(joined.len());
    let mut rest = joined.as_str();
    while let Some(open) = rest.find(" (") {
        let Some(len) = rest[open..].find(')') else { break };
        let inner = &rest[open + 2..open + len];
        out.push_str(&rest[..open]);
        if !(inner.contains(".rs") || inner.contains("src/")) {
            out.push_str(&rest[open..=open + len]);
        }
        rest = &rest[open + len + 1..];
    }
    out.push_str(rest);
    out
}

/// Text for a roff line: backslashes and hyphens escaped, `code` in bold,
/// never a control character at a line's start.
fn roff_text(text: &str) -> String {
    let mut out = String::new();
    let mut bold = false;
    for c in text.chars() {
        match c {
            '\\' => out.push_str("\\e"),
            '-' => out.push_str("\\-"),
            '`' => {
                out.push_str(if bold { "\\fR" } else { "\\fB" });
                bold = !bold;
            }
            c => out.push(c),
        }
    }
    if bold {
        out.push_str("\\fR");
    }
    if out.starts_with('.') || out.starts_with('\'') {
        out.insert_str(0, "\\&");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_references_are_left_out_and_code_is_bold() {
        assert_eq!(tidy("the ENI's (config/eni.rs) slaves\n  (see there)"), "the ENI's slaves (see there)");
        assert_eq!(roff_text("`a-b` c"), "\\fBa\\-b\\fR c");
        assert_eq!(roff_text(".x"), "\\&.x");
    }
}
