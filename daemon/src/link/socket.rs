//! The simulator served on a Unix socket (`ecmxf-sim serve`), framing as in
//! sim/README.md.

use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::time::Duration;

use ecmxf_sim::server::SocketClient;

use super::{Link, LinkError};

/// The link. Waiting for INT0 and the transfer that follows go as one
/// message (the server waits, then clocks), one round trip per exchange.
#[derive(Debug)]
pub struct SocketLink {
    client: SocketClient,
    path: PathBuf,
    /// The INT0 wait to do before the next transfer.
    pending_wait: Option<Duration>,
    /// The answer timeout the socket has now (set only when it changes).
    answer_timeout: Option<Duration>,
    /// An answer did not come in the time given (that time): the stream is
    /// out of step until [`Link::reopen`].
    stalled: Option<Duration>,
    /// INT0's active level (command 58; high after power-up).
    int0_active_high: bool,
    int0: super::LevelChanges,
}

/// How long an answer may take beyond the server's own INT0 wait: the
/// simulator answers in microseconds, so a silence this long is a frozen or
/// hung far end (a stopped process, a link that accepts but never
/// answers), not load: the host's own stalls here are tens of ms. Without
/// it, the engine would block in a read for ever, its phase saying RUNNING
/// while nothing flows, and a stop would never be taken.
const ANSWER_LIMIT: Duration = Duration::from_millis(200);

impl SocketLink {
    /// Connects to a serving simulator.
    pub fn connect(path: &Path) -> Result<Self, LinkError> {
        let client = SocketClient::connect(path)
            .map_err(|e| LinkError::io(format!("connect to simulator at {}", path.display()), e))?;
        Ok(Self {
            client,
            path: path.into(),
            pending_wait: None,
            answer_timeout: None,
            stalled: None,
            int0_active_high: true,
            int0: super::LevelChanges::default(),
        })
    }

    fn err(&self, what: &str, e: std::io::Error) -> LinkError {
        if matches!(e.kind(), ErrorKind::UnexpectedEof | ErrorKind::BrokenPipe | ErrorKind::ConnectionReset) {
            LinkError::Closed
        } else {
            LinkError::io(format!("{what} on {}", self.path.display()), e)
        }
    }
}

impl SocketLink {
    /// Bounds the next answer's wait to `wait` (what the server may spend
    /// waiting for INT0) plus [`ANSWER_LIMIT`]; the socket option is set
    /// only when that bound changes (one system call, not one per
    /// exchange).
    fn bound_answer(&mut self, wait: Duration) -> Result<Duration, LinkError> {
        let limit = wait + ANSWER_LIMIT;
        if self.answer_timeout != Some(limit) {
            self.client.set_answer_timeout(Some(limit)).map_err(|e| self.err("set the answer timeout", e))?;
            self.answer_timeout = Some(limit);
        }
        Ok(limit)
    }
}

impl Link for SocketLink {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        // An answer that never came leaves the stream out of step: nothing
        // more goes through it until it is reopened.
        if let Some(waited) = self.stalled {
            return Err(LinkError::Stalled { what: self.describe(), waited });
        }
        let limit = self.bound_answer(self.pending_wait.unwrap_or_default())?;
        let result = match self.pending_wait.take() {
            Some(timeout) => match self.client.transfer_when_ready(timeout, tx, rx) {
                Ok(Some(lines)) => {
                    // The server waited for ready, then clocked.
                    self.int0.saw(true);
                    Ok(lines)
                }
                Ok(None) => return Err(LinkError::NotReady),
                Err(e) => Err(e),
            },
            None => self.client.transfer(tx, rx),
        };
        let lines = result.map_err(|e| {
            if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) {
                self.stalled = Some(limit);
                tracing::warn!(link = %self.describe(), waited_ms = limit.as_millis() as u64, "link stalled: no answer");
                LinkError::Stalled { what: self.describe(), waited: limit }
            } else {
                self.err("transfer", e)
            }
        })?;
        let high = lines & ecmxf_sim::server::LINE_INT0 != 0;
        self.int0.saw(high == self.int0_active_high);
        Ok(())
    }

    fn set_polarity(&mut self, int0_active_high: bool, _int1_active_high: bool) {
        self.int0_active_high = int0_active_high;
    }

    fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
        Ok(Some(self.int0.count()))
    }

    /// Defers the wait to the server, which does it just before clocking
    /// the next transfer.
    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        self.pending_wait = Some(timeout);
        Ok(true)
    }

    fn int1_active(&mut self) -> Result<bool, LinkError> {
        match self.client.wait_int1(Duration::ZERO) {
            Ok(r) => Ok(r),
            Err(e) => Err(self.err("read INT1", e)),
        }
    }

    /// Connects again: the simulator may have been restarted on the same
    /// path (its chip is then at power-up; bring-up finds the packet size).
    fn reopen(&mut self) -> Result<(), LinkError> {
        self.client = SocketClient::connect(&self.path)
            .map_err(|e| LinkError::io(format!("reconnect to simulator at {}", self.path.display()), e))?;
        self.pending_wait = None;
        self.answer_timeout = None;
        self.stalled = None;
        self.int0 = super::LevelChanges::default();
        Ok(())
    }

    fn describe(&self) -> String {
        format!("simulator socket {}", self.path.display())
    }
}
