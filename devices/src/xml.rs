//! Reading numbers and elements of the XML files EtherCAT tools write (ESI,
//! ENI): numbers decimal, C hex (`0x1c12`) or ESI hex (`#x1c12`), and where
//! in the file an element is.

/// Where in an XML file something is: line and column, both from 1 (0:
/// not known). Configuration tools often write a whole file on one line,
/// so a line alone would point every message at line 1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct TextPos {
    /// Line, from 1.
    pub line: u32,
    /// Column (characters), from 1.
    pub column: u32,
}

impl TextPos {
    /// Where `node` starts.
    pub(crate) fn of(node: roxmltree::Node<'_, '_>) -> Self {
        let p = node.document().text_pos_at(node.range().start);
        Self { line: p.row, column: p.col }
    }
}

impl std::fmt::Display for TextPos {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}:{}", self.line, self.column)
    }
}

/// Reads an ESI number: `#x1A`, `0x1A`, `1A` with a hex prefix only, or
/// decimal.
pub fn parse_number(text: &str) -> Option<u64> {
    let t = text.trim();
    if let Some(h) = t
        .strip_prefix("#x")
        .or_else(|| t.strip_prefix("#X"))
        .or_else(|| t.strip_prefix("0x"))
        .or_else(|| t.strip_prefix("0X"))
    {
        u64::from_str_radix(h, 16).ok()
    } else {
        t.parse::<i64>().ok().map(|v| v as u64)
    }
}
