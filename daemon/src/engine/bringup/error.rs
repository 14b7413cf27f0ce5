//! Why bring-up stopped, each failure naming its step and the slaves at
//! fault.

use std::fmt;

use ecmxf_wire::EcatState;

use crate::port::PortError;

/// Why bring-up stopped.
#[derive(Debug)]
pub enum BringUpError {
    /// The link or the exchange failed.
    Port(PortError),
    /// A step failed.
    Step {
        /// The step.
        step: &'static str,
        /// What happened.
        detail: String,
    },
    /// The network has another number of slaves than the `[[slave]]`
    /// entries.
    Count {
        /// Slaves found.
        found: usize,
        /// How many the configuration expects and where it says so ("the
        /// ENI machine.xml lists 7").
        expected: String,
    },
    /// The network differs from the configured one.
    Identity {
        /// Slave position.
        position: usize,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// A slave's `[[slave]] esi` file has several devices and none has
    /// the identity the slave reports, so which init commands it needs is
    /// unknown (engine/bringup/esi_choice.rs). Retried as an identity
    /// mismatch is: the slave may be swapped for the right one.
    EsiDevice {
        /// Slave position.
        position: usize,
        /// Its name: the entry's, else the one it reports.
        name: String,
        /// Vendor, product code and revision it reports.
        found: (u32, u32, u32),
        /// The ESI file.
        file: String,
        /// The file's candidate devices: name, product code, revision.
        candidates: Vec<(String, u32, u32)>,
    },
    /// The SPI link can never carry this network's process data at this
    /// cycle (see `link_budget`): no retry can change that, only the
    /// configuration can.
    Refused(super::super::link_budget::BudgetError),
    /// An `[[axis]]` names a slave whose process data cannot hold its
    /// controlword or statusword where the configuration says: the chip's
    /// CiA 402 helper would drive other bytes. Only the configuration can
    /// change that.
    AxisUnmapped(String),
    /// Fewer slaves answer than an `[[axis]]` needs: the slaves from
    /// `found` on are missing (a slave unplugged or powered off; the ring
    /// ends before it).
    SlavesMissing {
        /// Slaves that answered (positions `0..found`).
        found: usize,
        /// The most slaves there were before (a run, or what the axis
        /// needs).
        before: usize,
        /// The first `[[axis]]` on a missing slave.
        axis: usize,
        /// Its slave.
        slave: usize,
    },
    /// Slaves did not reach the state asked for (STATE_CHECK failed): each
    /// one not there, with its state and AL status code.
    StateRefused {
        /// The state asked for.
        asked: EcatState,
        /// (position, state, AL status code) of each slave not in `asked`
        /// or reporting a code; empty when none could be read.
        slaves: Vec<(u8, EcatState, u16)>,
    },
}

impl BringUpError {
    /// Whether trying again can never help (the configuration must change).
    pub fn is_permanent(&self) -> bool {
        matches!(self, Self::Refused(_) | Self::AxisUnmapped(_))
    }
}

impl fmt::Display for BringUpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Port(e) => write!(f, "{e}"),
            Self::Step { step, detail } => write!(f, "{step}: {detail}"),
            Self::Count { found, expected } => write!(f, "{found} slaves answer, {expected}"),
            Self::Identity { position, expected, found } => {
                write!(f, "slave {position} is {found}, the configuration expects {expected}")
            }
            Self::EsiDevice { position, name, found: (vendor, product, revision), file, candidates } => {
                let each = candidates
                    .iter()
                    .map(|(n, p, r)| format!("{n:?} product {p:#010x} revision {r:#010x}"))
                    .collect::<Vec<_>>()
                    .join("; ");
                write!(
                    f,
                    "slave {position} ({name:?}) is vendor {vendor:#010x} product {product:#010x} revision \
                     {revision:#010x}: no device of its ESI {file} has that identity, so its init commands are \
                     unknown (the file's {} candidates: {each})",
                    candidates.len()
                )
            }
            Self::SlavesMissing { found, before, axis, slave } => {
                let missing = match (*found, before.saturating_sub(1)) {
                    (a, b) if a == b => format!("slave {a} is missing"),
                    (a, b) => format!("slaves {a}-{b} are missing"),
                };
                let cable = match found {
                    0 => "the cable to the first slave".to_string(),
                    n => format!("the cable after slave {}", n - 1),
                };
                write!(
                    f,
                    "{missing}: {found} slave{} answer{}, {before} did before (unplugged, powered off, or {cable} \
                     cut?); axis[{axis}] drives slave {slave}",
                    if *found == 1 { "" } else { "s" },
                    if *found == 1 { "s" } else { "" },
                )
            }
            Self::Refused(e) => write!(f, "link budget: {e}"),
            Self::AxisUnmapped(why) => f.write_str(why),
            Self::StateRefused { asked, slaves } if slaves.is_empty() => {
                write!(f, "the slaves did not reach {asked} (STATE_CHECK failed; their states could not be read)")
            }
            Self::StateRefused { asked, slaves } => {
                write!(f, "the slaves did not reach {asked}: {}", describe_states(slaves))
            }
        }
    }
}

impl std::error::Error for BringUpError {}

impl From<PortError> for BringUpError {
    fn from(e: PortError) -> Self {
        Self::Port(e)
    }
}

/// A failure of `step`, said as `detail`.
pub(super) fn step(step: &'static str, detail: impl Into<String>) -> BringUpError {
    BringUpError::Step { step, detail: detail.into() }
}

/// "slave 2 PRE-OP, AL status 0x001d (invalid output configuration); ...".
pub(crate) fn describe_states(slaves: &[(u8, EcatState, u16)]) -> String {
    let one = |&(i, state, code): &(u8, EcatState, u16)| match code {
        0 => format!("slave {i} {state}"),
        c => format!("slave {i} {state}, AL status {c:#06x} ({})", ecmxf_wire::al_status_text(c)),
    };
    slaves.iter().map(one).collect::<Vec<_>>().join("; ")
}
