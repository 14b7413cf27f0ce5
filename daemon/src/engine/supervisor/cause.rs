//! Why the running engine goes back to bring-up, as data: carried to the
//! events (`EventKind::Recovering`), the log and the API (`Event.cause`).

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use ecmxf_wire::EcatState;

use crate::port::PortError;

/// A port error carried by a cause, shared (it holds an I/O error, which
/// cannot be copied) and kept with its type.
#[derive(Clone, Debug)]
pub struct PortFault(pub Arc<PortError>);

/// The same fault, or one that reads the same (I/O errors have no
/// equality of their own).
impl PartialEq for PortFault {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || self.0.to_string() == other.0.to_string()
    }
}

impl Eq for PortFault {}

impl fmt::Display for PortFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

/// (position, state, AL status code) of a slave at fault, as it answered.
pub(crate) type SlaveFault = (u8, EcatState, u16);

/// Why the engine left the running loop to bring the network up again.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecoverCause {
    /// The link to the chip failed (I/O error, far end gone): it is opened
    /// again before the next bring-up.
    Link(PortFault),
    /// The chip stopped answering in time or coherently (INT0 stuck, no
    /// intact answer).
    Chip(PortFault),
    /// The chip's status is back to its power-up values.
    ChipReset,
    /// The network state is ERROR; which slaves and their AL status codes
    /// (empty until they are read, or when none reports a code).
    SlaveError(Vec<SlaveFault>),
    /// The number of slaves on the ring changed.
    SlaveCount {
        /// Slaves at bring-up.
        from: usize,
        /// Slaves now.
        to: usize,
    },
    /// Working-counter errors for at least this long.
    WkcStreak(Duration),
    /// The chip stopped the process-data exchange (working-counter limit).
    ExchangeStopped,
    /// No input frame arrived for `age`, longer than `limit`, while the
    /// chip kept answering.
    InputStall {
        /// Time since the newest input frame.
        age: Duration,
        /// The limit in force.
        limit: Duration,
    },
    /// A client applied a new configuration.
    NewConfig,
    /// A client asked for a re-init.
    ReinitRequested,
    /// A client asked for a warm reset of the chip.
    WarmResetRequested,
}

impl RecoverCause {
    /// The cause of a failed exchange.
    pub fn from_port(e: PortError) -> Self {
        match e {
            e @ PortError::Link(_) => Self::Link(PortFault(Arc::new(e))),
            other => Self::Chip(PortFault(Arc::new(other))),
        }
    }

    /// The cause as one stable word (the log's and the API's `cause`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Link(_) => "link",
            Self::Chip(_) => "chip",
            Self::ChipReset => "chip_reset",
            Self::SlaveError(_) => "slave_error",
            Self::SlaveCount { .. } => "slave_count",
            Self::WkcStreak(_) => "wkc_streak",
            Self::ExchangeStopped => "exchange_stopped",
            Self::InputStall { .. } => "input_stall",
            Self::NewConfig => "new_config",
            Self::ReinitRequested => "reinit_requested",
            Self::WarmResetRequested => "warm_reset_requested",
        }
    }

    /// Whether the link itself must be opened again.
    pub fn needs_reopen(&self) -> bool {
        matches!(self, Self::Link(_))
    }
}

impl fmt::Display for RecoverCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Link(e) => write!(f, "link failed: {e}"),
            Self::Chip(e) => write!(f, "chip: {e}"),
            Self::ChipReset => f.write_str("chip reset (status back to power-up values)"),
            Self::SlaveError(s) if s.is_empty() => {
                f.write_str("a slave reports an error or is missing: no slave reports an AL status code")
            }
            Self::SlaveError(s) => {
                write!(f, "a slave reports an error or is missing: {}", crate::engine::bringup::describe_states(s))
            }
            Self::SlaveCount { from, to } => write!(f, "slave count changed from {from} to {to}"),
            Self::WkcStreak(d) => write!(f, "working-counter errors for {d:?}: a slave is not exchanging"),
            Self::ExchangeStopped => f.write_str("process-data exchange stopped (working-counter limit)"),
            Self::InputStall { age, limit } => write!(
                f,
                "process data stalled: no input frame for {} ms (limit {} ms) while the chip answers",
                age.as_millis(),
                limit.as_millis()
            ),
            Self::NewConfig => f.write_str("new configuration from a client"),
            Self::ReinitRequested => f.write_str("re-init requested by a client"),
            Self::WarmResetRequested => f.write_str("warm reset requested by a client"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn causes_read_as_sentences() {
        let c = RecoverCause::InputStall { age: 80 * MS, limit: 62 * MS };
        assert_eq!(
            c.to_string(),
            "process data stalled: no input frame for 80 ms (limit 62 ms) while the chip answers"
        );
        let closed = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        let link = RecoverCause::from_port(PortError::Link(crate::link::LinkError::io("read", closed)));
        assert!(link.needs_reopen(), "{link}");
        assert!(!RecoverCause::from_port(PortError::Aborted).needs_reopen());
        assert_eq!(
            RecoverCause::SlaveError(vec![(2, EcatState::SafeOp, 0x1b)]).to_string(),
            "a slave reports an error or is missing: slave 2 SAFEOP, AL status 0x001b (sync manager watchdog)"
        );
        assert!(!RecoverCause::ChipReset.needs_reopen());
    }
}
