//! The simulator served on a Unix socket (`ecmxf-sim serve`), framing as in
//! sim/README.md.

use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::time::Duration;

use ecmxf_sim::server::SocketClient;

use super::{Link, LinkError};

/// The link.
#[derive(Debug)]
pub struct SocketLink {
    client: SocketClient,
    path: PathBuf,
}

impl SocketLink {
    /// Connects to a serving simulator.
    pub fn connect(path: &Path) -> Result<Self, LinkError> {
        let client = SocketClient::connect(path)
            .map_err(|e| LinkError::io(format!("connect to simulator at {}", path.display()), e))?;
        Ok(Self { client, path: path.into() })
    }

    fn err(&self, what: &str, e: std::io::Error) -> LinkError {
        if e.kind() == ErrorKind::UnexpectedEof || e.kind() == ErrorKind::BrokenPipe {
            LinkError::Closed
        } else {
            LinkError::io(format!("{what} on {}", self.path.display()), e)
        }
    }
}

impl Link for SocketLink {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        match self.client.transfer(tx, rx) {
            Ok(_) => Ok(()),
            Err(e) => Err(self.err("transfer", e)),
        }
    }

    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        match self.client.wait_ready(timeout) {
            Ok(r) => Ok(r),
            Err(e) => Err(self.err("wait for INT0", e)),
        }
    }

    fn int1_active(&mut self) -> Result<bool, LinkError> {
        match self.client.wait_int1(Duration::ZERO) {
            Ok(r) => Ok(r),
            Err(e) => Err(self.err("read INT1", e)),
        }
    }

    fn describe(&self) -> String {
        format!("simulator socket {}", self.path.display())
    }
}
