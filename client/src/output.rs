//! Printing results: an aligned table for people, or JSON for scripts. Every
//! command builds one report value; [`Out::report`] prints it one way or
//! the other, so the two outputs cannot drift apart.

use std::io::Write;

use schemars::JsonSchema;
use serde::Serialize;

/// A command's result: serialisable (its JSON schema is published, see
/// `ecmxfctl json-schema`) and printable as text.
pub trait Report: Serialize + JsonSchema {
    /// The human-readable form.
    fn text(&self) -> String;
}

/// Where results go and in which form.
#[derive(Debug, Clone, Copy)]
pub struct Out {
    /// JSON instead of tables.
    pub json: bool,
}

impl Out {
    /// Prints a finished result: pretty JSON, or the text.
    pub fn report<R: Report>(&self, r: &R) -> std::io::Result<()> {
        let mut o = std::io::stdout().lock();
        if self.json {
            serde_json::to_writer_pretty(&mut o, r).map_err(std::io::Error::other)?;
            writeln!(o)
        } else {
            let t = r.text();
            o.write_all(t.as_bytes())?;
            if !t.is_empty() && !t.ends_with('\n') {
                writeln!(o)?;
            }
            Ok(())
        }
    }

    /// Prints one record of a stream: a JSON object on one line (NDJSON), or
    /// the text as it is; flushed at once so a pipe sees it live.
    pub fn line<R: Serialize>(&self, r: &R, text: impl FnOnce() -> String) -> std::io::Result<()> {
        let mut o = std::io::stdout().lock();
        if self.json {
            serde_json::to_writer(&mut o, r).map_err(std::io::Error::other)?;
        } else {
            o.write_all(text().as_bytes())?;
        }
        writeln!(o)?;
        o.flush()
    }
}

/// A text table: a header row and left-aligned columns two spaces apart.
#[derive(Debug, Default)]
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with these column titles.
    pub fn new(header: &[&str]) -> Self {
        Self { header: header.iter().map(|s| (*s).to_owned()).collect(), rows: Vec::new() }
    }

    /// Adds a row (missing cells print empty).
    pub fn row<I: IntoIterator<Item = S>, S: Into<String>>(&mut self, cells: I) {
        self.rows.push(cells.into_iter().map(Into::into).collect());
    }

    /// Whether no row was added.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

impl std::fmt::Display for Table {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let cols = self.header.len().max(self.rows.iter().map(Vec::len).max().unwrap_or(0));
        let mut width = vec![0usize; cols];
        for r in std::iter::once(&self.header).chain(&self.rows) {
            for (i, c) in r.iter().enumerate() {
                width[i] = width[i].max(c.chars().count());
            }
        }
        for r in std::iter::once(&self.header).chain(&self.rows) {
            let mut line = String::new();
            for (i, w) in width.iter().enumerate() {
                let c = r.get(i).map_or("", String::as_str);
                line.push_str(c);
                if i + 1 < cols {
                    line.extend(std::iter::repeat_n(' ', w - c.chars().count() + 2));
                }
            }
            writeln!(f, "{}", line.trim_end())?;
        }
        Ok(())
    }
}

/// Key/value lines ("Firmware:   0x24"), aligned.
#[derive(Debug, Default)]
pub struct Fields(Vec<(String, String)>);

impl Fields {
    /// Adds a line.
    pub fn add(&mut self, k: impl Into<String>, v: impl ToString) -> &mut Self {
        self.0.push((k.into(), v.to_string()));
        self
    }
}

impl std::fmt::Display for Fields {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let w = self.0.iter().map(|(k, _)| k.chars().count()).max().unwrap_or(0) + 1;
        for (k, v) in &self.0 {
            writeln!(f, "{:<w$} {v}", format!("{k}:"))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_align_columns_and_trim_line_ends() {
        let mut t = Table::new(&["POS", "NAME", "X"]);
        t.row(["0", "EK1100", ""]);
        t.row(["12", "a", "b"]);
        assert_eq!(t.to_string(), "POS  NAME    X\n0    EK1100\n12   a       b\n");
        let mut f = Fields::default();
        f.add("A", 1).add("Long key", "v");
        assert_eq!(f.to_string(), "A:        1\nLong key: v\n");
    }
}
