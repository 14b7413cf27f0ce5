//! Errors of the TOML files that describe a network (the simulator's
//! network file) or a daemon (its configuration): both name the file, the
//! line and the dotted key, so a user fixes either the same way.

use std::fmt;
use std::path::{Path, PathBuf};

/// Why a network file was refused.
#[derive(Debug)]
pub enum ConfigError {
    /// Could not read the file.
    Io(PathBuf, std::io::Error),
    /// Syntax or schema error; toml's message names key, line and column.
    Toml(PathBuf, String),
    /// A value is wrong.
    Invalid {
        /// The file.
        file: PathBuf,
        /// The key, e.g. `slave[2].profile`.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The value of `key` is wrong, at this line (see [`ConfigError::at_line`]).
    InvalidAt {
        /// The file.
        file: PathBuf,
        /// 1-based line of the key (or of the nearest table on its path,
        /// when the key itself is not written).
        line: usize,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The file is not UTF-8 text.
    NotText {
        /// The file.
        file: PathBuf,
        /// 1-based line of the first byte that is not UTF-8.
        line: usize,
        /// Byte offset of it.
        offset: usize,
    },
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Toml(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Invalid { file, key, message } => write!(f, "{}: {key}: {message}", file.display()),
            Self::InvalidAt { file, line, key, message } => {
                write!(f, "{}: line {line}: {key}: {message}", file.display())
            }
            Self::NotText { file, line, offset } => {
                write!(
                    f,
                    "{}: line {line}: not UTF-8 text (byte offset {offset}); is this a TOML file?",
                    file.display()
                )
            }
        }
    }
}

impl ConfigError {
    /// The same error, with the line of its key in `text` where it can be
    /// found.
    pub fn at_line(self, text: &str) -> Self {
        match self {
            Self::Invalid { file, key, message } => match key_line(text, &key) {
                Some(line) => Self::InvalidAt { file, line, key, message },
                None => Self::Invalid { file, key, message },
            },
            other => other,
        }
    }

    /// Reads a configuration file as text: I/O errors and bytes that are not
    /// UTF-8 (a binary file given by mistake) are errors naming the file
    /// and, for the latter, the line.
    pub fn read(path: &Path) -> Result<String, Self> {
        let bytes = std::fs::read(path).map_err(|e| Self::Io(path.into(), e))?;
        String::from_utf8(bytes).map_err(|e| {
            let offset = e.utf8_error().valid_up_to();
            let line = e.as_bytes()[..offset].iter().filter(|b| **b == b'\n').count() + 1;
            Self::NotText { file: path.into(), line, offset }
        })
    }
}

/// A path as a TOML string value, quoted and escaped (for files that
/// point at other files: network files, generated configurations).
pub fn toml_path(path: &Path) -> String {
    toml_string(&path.display().to_string())
}

/// `text` as a TOML string, quoted and escaped.
pub fn toml_string(text: &str) -> String {
    toml::Value::String(text.to_string()).to_string()
}

/// The 1-based line where a dotted key (`cycle.sync0_us`, `slave[2].alias`)
/// is written in `text`; the nearest table on its path when the key itself
/// is not written (a default that conflicts with a written value).
pub fn key_line(text: &str, key: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(text).ok()?;
    let mut table = root.get_ref();
    let mut at = None;
    for part in key.split('.') {
        let (name, index) = match part.split_once('[') {
            Some((n, rest)) => (n, rest.trim_end_matches(']').parse::<usize>().ok()),
            None => (part, None),
        };
        let Some((k, v)) = table.iter().find(|(k, _)| k.get_ref() == name) else { break };
        at = Some(k.span().start);
        let mut value = v;
        if let Some(i) = index {
            let DeValue::Array(items) = v.get_ref() else { break };
            let Some(item) = items.get(i) else { break };
            at = Some(item.span().start);
            value = item;
        }
        let DeValue::Table(t) = value.get_ref() else { break };
        table = t;
    }
    at.map(|offset| text[..offset.min(text.len())].matches('\n').count() + 1)
}

impl std::error::Error for ConfigError {}
