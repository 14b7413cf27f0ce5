//! CoE init commands as ETG.2100 (ENI) and ETG.2000 (ESI) files write them
//! (`Mailbox/CoE/InitCmds/InitCmd`), and the XML reading both file kinds
//! share for them: the ENI and the ESI readers each use this, neither the
//! other (daemon/tests/layers.rs checks the folder has no import circle).

use roxmltree::Node;

use crate::xml::{TextPos, parse_number};

/// A state transition an init command belongs to (ETG.2100 `Transition`:
/// two letters, from and to: I INIT, P PRE-OP, S SAFE-OP, O OP, B BOOT).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Transition {
    /// INIT to PRE-OP.
    InitPreOp,
    /// PRE-OP to SAFE-OP.
    PreOpSafeOp,
    /// SAFE-OP to OP.
    SafeOpOp,
    /// Any other (to INIT, to or from BOOT, back down).
    Other([u8; 2]),
}

impl Transition {
    fn parse(text: &str) -> Option<Self> {
        match text.trim() {
            "IP" => Some(Self::InitPreOp),
            "PS" => Some(Self::PreOpSafeOp),
            "SO" => Some(Self::SafeOpOp),
            t if t.len() == 2 && t.bytes().all(|b| b"IPSOB".contains(&b)) => {
                let b = t.as_bytes();
                Some(Self::Other([b[0], b[1]]))
            }
            _ => None,
        }
    }

    /// The two letters.
    pub fn letters(&self) -> String {
        match self {
            Self::InitPreOp => "IP".into(),
            Self::PreOpSafeOp => "PS".into(),
            Self::SafeOpOp => "SO".into(),
            Self::Other(b) => String::from_utf8_lossy(b).into_owned(),
        }
    }
}

/// How an init command's `Ccs` was read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CcsConvention {
    /// `Ccs` 1: a download (ETG.2100, TwinCAT).
    Etg,
    /// `Ccs` 2 with data: a download as SOEM writes it.
    Soem,
}

/// What an init command does.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CoeAccess {
    /// An SDO download of these bytes.
    Download(Vec<u8>),
    /// An SDO upload (`Ccs` 2 without data).
    Upload,
}

/// One CoE init command (`Mailbox/CoE/InitCmds/InitCmd`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CoeInitCmd {
    /// The transitions it runs at, as the file lists them.
    pub transitions: Vec<Transition>,
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// `CompleteAccess="1"` (or `true`).
    pub complete_access: bool,
    /// Download or upload.
    pub access: CoeAccess,
    /// How `Ccs` was read.
    pub ccs: CcsConvention,
    /// `Timeout`, ms (0 or absent: the reader's default).
    pub timeout_ms: u32,
    /// `Comment`.
    pub comment: String,
    /// `Disabled` is true, or (ESI) the data is `AdaptAutomatically`: a
    /// value the configuration tool computes, which a master cannot.
    pub disabled: bool,
    /// Where it is in the file.
    pub at: TextPos,
}

/// Why an ENI file was refused: what, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EniError {
    /// Where in the file (line 0 when unknown).
    pub at: TextPos,
    /// What is wrong, naming the element.
    pub message: String,
}

impl std::fmt::Display for EniError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.at.line > 0 { write!(f, "{}: {}", self.at, self.message) } else { f.write_str(&self.message) }
    }
}

impl std::error::Error for EniError {}

pub(crate) fn pos_of(node: Node<'_, '_>) -> TextPos {
    TextPos::of(node)
}

pub(crate) fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

pub(crate) fn children<'a, 'i: 'a>(n: Node<'a, 'i>, name: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.has_tag_name(name))
}

pub(crate) fn fail(node: Node<'_, '_>, message: String) -> EniError {
    EniError { at: pos_of(node), message }
}

/// A number in element `name` of `parent`, at most `max`.
pub(crate) fn number(parent: Node<'_, '_>, name: &str, path: &str, max: u64) -> Result<Option<u64>, EniError> {
    let Some(node) = child(parent, name) else { return Ok(None) };
    let text = node.text().unwrap_or("").trim();
    match parse_number(text) {
        Some(v) if v <= max => Ok(Some(v)),
        Some(_) => Err(fail(node, format!("{path}/{name} {text:?} is above {max}"))),
        None => Err(fail(node, format!("{path}/{name} {text:?} is not a number"))),
    }
}

pub(crate) fn required(parent: Node<'_, '_>, name: &str, path: &str, max: u64) -> Result<u64, EniError> {
    number(parent, name, path, max)?.ok_or_else(|| fail(parent, format!("{path} has no {name}")))
}

pub(crate) fn hex_bytes(node: Node<'_, '_>, path: &str) -> Result<Vec<u8>, EniError> {
    let text: String = node.text().unwrap_or("").chars().filter(|c| !c.is_whitespace()).collect();
    if text.len() % 2 != 0 {
        return Err(fail(node, format!("{path}/Data {text:?} has an odd number of hex digits")));
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16))
        .collect::<Result<_, _>>()
        .map_err(|_| fail(node, format!("{path}/Data {text:?} is not hex bytes")))
}

pub(crate) fn flag(text: Option<&str>) -> bool {
    matches!(text.map(str::trim), Some("1" | "true"))
}

/// The `Transition` elements of an init command.
pub(crate) fn transitions(cmd: Node<'_, '_>, path: &str) -> Result<Vec<Transition>, EniError> {
    children(cmd, "Transition")
        .map(|t| {
            let text = t.text().unwrap_or("").trim();
            Transition::parse(text).ok_or_else(|| fail(t, format!("{path}/Transition {text:?} is not a transition")))
        })
        .collect()
}

/// One CoE init command element. `ccs_default`: the `Ccs` when the element
/// has none (ESI files have none: their init commands are downloads).
pub(crate) fn coe_init_cmd(cmd: Node<'_, '_>, path: &str, ccs_default: Option<u64>) -> Result<CoeInitCmd, EniError> {
    let transitions = transitions(cmd, path)?;
    if transitions.is_empty() {
        return Err(fail(cmd, format!("{path} has no Transition")));
    }
    let ccs = match (number(cmd, "Ccs", path, 255)?, ccs_default) {
        (Some(c), _) | (None, Some(c)) => c,
        (None, None) => return Err(fail(cmd, format!("{path} has no Ccs"))),
    };
    let data = child(cmd, "Data").map(|d| hex_bytes(d, path)).transpose()?.unwrap_or_default();
    let (access, convention) = match ccs {
        1 => (CoeAccess::Download(data), CcsConvention::Etg),
        2 if !data.is_empty() => (CoeAccess::Download(data), CcsConvention::Soem),
        2 => (CoeAccess::Upload, CcsConvention::Etg),
        other => {
            let node = child(cmd, "Ccs").unwrap_or(cmd);
            return Err(fail(node, format!("{path}/Ccs {other} is neither 1 (download) nor 2 (upload)")));
        }
    };
    Ok(CoeInitCmd {
        transitions,
        index: required(cmd, "Index", path, 0xFFFF)? as u16,
        subindex: number(cmd, "SubIndex", path, 0xFF)?.unwrap_or(0) as u8,
        complete_access: flag(cmd.attribute("CompleteAccess")),
        access,
        ccs: convention,
        timeout_ms: number(cmd, "Timeout", path, u64::from(u32::MAX))?.unwrap_or(0) as u32,
        comment: child(cmd, "Comment").and_then(|c| c.text()).unwrap_or("").trim().to_string(),
        disabled: flag(child(cmd, "Disabled").and_then(|d| d.text()))
            || flag(child(cmd, "Data").and_then(|d| d.attribute("AdaptAutomatically"))),
        at: pos_of(cmd),
    })
}
