//! The chip behind a small trait: one full-duplex SPI transfer, waiting for
//! INT0 ("ready for the next transfer"), reading INT1 ("events pending").
//! Implementations: Linux hardware (spidev + GPIO character device), the
//! in-process simulator, and the simulator's socket.
//!
//! INT0 gating is the fast path (v049 ECM-XF中斷: processing usually takes
//! < 150 us; INT0 says exactly when it is done). Without INT0 wired, a link
//! waits a fixed idle time after each transfer, as the vendor driver does.

use std::fmt;
use std::time::Duration;

#[cfg(target_os = "linux")]
pub mod hardware;
#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "sim")]
pub mod socket;

/// A daemon built without the simulator (cargo feature `sim` off) has no
/// simulator to hand out: this type has no values.
#[cfg(not(feature = "sim"))]
#[derive(Debug)]
pub enum SimHandle {}
#[cfg(feature = "sim")]
pub use sim::SimHandle;

/// Why the link failed.
#[derive(Debug)]
pub enum LinkError {
    /// An OS call failed; `what` names the call and device.
    Io {
        /// What was being done, e.g. "SPI transfer on /dev/spidev0.0".
        what: String,
        /// The error.
        source: std::io::Error,
    },
    /// The far end went away (simulator socket closed).
    Closed,
    /// The link waits for INT0 as part of the transfer (the simulator
    /// socket), and INT0 did not say ready in the time it was given; nothing
    /// was clocked. The port gives it the rest of its ready timeout.
    NotReady,
    /// The far end took an exchange and gave no answer in `waited`: the
    /// chip (or the process standing for it) is not answering. The link is
    /// out of step until reopened.
    Stalled {
        /// Where, e.g. "simulator socket /run/sim.sock".
        what: String,
        /// How long the answer was waited for.
        waited: Duration,
    },
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io { what, source } => write!(f, "{what}: {source}"),
            Self::Closed => f.write_str("link closed"),
            Self::NotReady => f.write_str("chip not ready (INT0)"),
            Self::Stalled { what, waited } => {
                write!(f, "link stalled: {what} gave no answer in {} ms (chip not answering)", waited.as_millis())
            }
        }
    }
}

impl std::error::Error for LinkError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            Self::Closed | Self::NotReady | Self::Stalled { .. } => None,
        }
    }
}

impl LinkError {
    /// An I/O error with its context.
    pub fn io(what: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { what: what.into(), source }
    }
}

/// The SPI link to one chip.
pub trait Link: Send {
    /// One full-duplex transfer: `tx` out, `rx` (same length) in.
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError>;

    /// Waits until the chip is ready (INT0 active) or `timeout` passes;
    /// `Ok(false)` on timeout. Links without INT0 wait their idle time.
    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError>;

    /// Whether INT1 is active now.
    fn int1_active(&mut self) -> Result<bool, LinkError>;

    /// The line polarities the chip was told with command 58 (`true` =
    /// active-high). Links that read electrical levels need them.
    fn set_polarity(&mut self, _int0_active_high: bool, _int1_active_high: bool) {}

    /// Opens the device again after the link failed (a simulator that was
    /// restarted, a device node that came back). Links with nothing to
    /// reopen succeed.
    fn reopen(&mut self) -> Result<(), LinkError> {
        Ok(())
    }

    /// How many times INT0 changed level since the link was opened, for
    /// links that see the line; `None` when INT0 is not wired. A chip that
    /// works drops INT0 once per packet and raises it when done (v049
    /// ECM-XF中斷): `ecmxfd probe` tells such a line from one stuck at its
    /// ready level with it, which waiting alone cannot.
    fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
        Ok(None)
    }

    /// The SPI clock, Hz, when the link knows it: a packet takes at least
    /// its bits at this clock, which no host stall can make shorter (the
    /// link budget refuses a network for good only on that bound).
    fn clock_hz(&self) -> Option<u64> {
        None
    }

    /// A description for logs.
    fn describe(&self) -> String;
}

/// Counts INT0 level changes for links that observe the level at moments
/// (before and after transfers) rather than receive edge events: the
/// simulator links (the hardware link reads edge events).
#[cfg(feature = "sim")]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LevelChanges {
    ready: Option<bool>,
    changes: u64,
}

#[cfg(feature = "sim")]
impl LevelChanges {
    /// Notes whether the chip was ready when last looked at.
    pub(crate) fn saw(&mut self, ready: bool) {
        if self.ready.is_some_and(|r| r != ready) {
            self.changes += 1;
        }
        self.ready = Some(ready);
    }

    /// Changes seen so far.
    pub(crate) fn count(&self) -> u64 {
        self.changes
    }
}

impl<L: Link + ?Sized> Link for Box<L> {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        (**self).transfer(tx, rx)
    }
    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        (**self).wait_ready(timeout)
    }
    fn int1_active(&mut self) -> Result<bool, LinkError> {
        (**self).int1_active()
    }
    fn set_polarity(&mut self, int0_active_high: bool, int1_active_high: bool) {
        (**self).set_polarity(int0_active_high, int1_active_high);
    }
    fn reopen(&mut self) -> Result<(), LinkError> {
        (**self).reopen()
    }
    fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
        (**self).int0_edges()
    }
    fn clock_hz(&self) -> Option<u64> {
        (**self).clock_hz()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}
