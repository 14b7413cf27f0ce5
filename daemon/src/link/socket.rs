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
    /// INT0's active level (command 58; high after power-up).
    int0_active_high: bool,
    int0: super::LevelChanges,
}

impl SocketLink {
    /// Connects to a serving simulator.
    pub fn connect(path: &Path) -> Result<Self, LinkError> {
        let client = SocketClient::connect(path)
            .map_err(|e| LinkError::io(format!("connect to simulator at {}", path.display()), e))?;
        Ok(Self {
            client,
            path: path.into(),
            pending_wait: None,
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

impl Link for SocketLink {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
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
        let lines = result.map_err(|e| self.err("transfer", e))?;
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
        self.int0 = super::LevelChanges::default();
        Ok(())
    }

    fn describe(&self) -> String {
        format!("simulator socket {}", self.path.display())
    }
}
