//! `crc [-p POS] [--reset]` (IgH `ethercat crc`): the error counters each
//! slave's ESC keeps per port, read from its registers 0x0300..0x030D
//! (ETG.1000.4 / ET1100 datasheet: per port an invalid-frame counter at
//! 0x0300 + 2n and an RX error counter at 0x0301 + 2n, forwarded RX errors
//! at 0x0308 + n, the processing unit's at 0x030C and the PDI's at 0x030D;
//! each saturates at 255). A rising RX error count on one port points at
//! the cable or connector into it. `--reset` writes 0x0300, which clears
//! them all. Registers service: admin.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Report, Table};

/// One port's counters.
#[derive(Debug, Serialize, JsonSchema)]
pub struct PortErrors {
    pub port: u32,
    /// Frames with an invalid frame (CRC) seen on this port (0x0300 + 2n).
    pub invalid_frames: u32,
    /// Physical-layer RX errors on this port (0x0301 + 2n).
    pub rx_errors: u32,
    /// Errors a slave before this one already found (0x0308 + n).
    pub forwarded_rx_errors: u32,
}

/// One slave's counters.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SlaveErrors {
    pub position: u32,
    pub name: String,
    pub ports: Vec<PortErrors>,
    /// ECAT processing unit errors (0x030C).
    pub processing_unit_errors: u32,
    /// PDI errors (0x030D).
    pub pdi_errors: u32,
    /// Working counter of the read (0: the slave did not answer; the
    /// counters are then zeros, not readings).
    pub working_counter: u32,
}

/// `ecmxfctl crc --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct CrcReport {
    /// Whether the counters were cleared first (--reset).
    pub reset: bool,
    pub slaves: Vec<SlaveErrors>,
}

impl Report for CrcReport {
    fn text(&self) -> String {
        let mut t = Table::new(&["POS", "PORT0 INV/RX/FWD", "PORT1", "PORT2", "PORT3", "ECAT", "PDI", "NAME"]);
        for s in &self.slaves {
            let mut cells = vec![s.position.to_string()];
            for p in &s.ports {
                cells.push(format!("{}/{}/{}", p.invalid_frames, p.rx_errors, p.forwarded_rx_errors));
            }
            cells.push(s.processing_unit_errors.to_string());
            cells.push(s.pdi_errors.to_string());
            let note = if s.working_counter == 0 { "  [no answer]" } else { "" };
            cells.push(format!("{}{note}", s.name));
            t.row(cells);
        }
        let mut out = t.to_string();
        if self.reset {
            out.push_str("(cleared before reading)\n");
        }
        out
    }
}

/// The counters from the 14 bytes at 0x0300.
fn errors(position: u32, name: String, b: &[u8], working_counter: u32) -> SlaveErrors {
    let at = |i: usize| u32::from(b.get(i).copied().unwrap_or(0));
    SlaveErrors {
        position,
        name,
        ports: (0..4)
            .map(|n| PortErrors {
                port: n as u32,
                invalid_frames: at(2 * n),
                rx_errors: at(2 * n + 1),
                forwarded_rx_errors: at(8 + n),
            })
            .collect(),
        processing_unit_errors: at(12),
        pdi_errors: at(13),
        working_counter,
    }
}

/// Reads (after clearing, with `reset`) the counters of one slave or all.
pub async fn run(api: &Api, position: Option<u32>, reset: bool) -> Result<CrcReport, CliError> {
    let slaves = super::slaves::fetch(api, position, false).await?.slaves;
    let mut out = Vec::with_capacity(slaves.len());
    for s in slaves {
        let slave = s.position;
        if reset {
            let req = pb::WriteRegistersRequest { slave, address: 0x0300, data: vec![0] };
            api.registers()
                .write_registers(api.req(req))
                .await
                .map_err(CliError::rpc(format!("clear the error counters of slave {slave}")))?;
        }
        let req = pb::ReadRegistersRequest { slave, address: 0x0300, length: 14 };
        let r = api.registers().read_registers(api.req(req)).await;
        let r = r.map_err(CliError::rpc(format!("read the error counters of slave {slave}")))?.into_inner();
        out.push(errors(slave, s.name, &r.data, r.working_counter));
    }
    Ok(CrcReport { reset, slaves: out })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bytes_at_0x0300_are_read_per_port() {
        let b = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14];
        let e = errors(0, "x".into(), &b, 1);
        assert_eq!((e.ports[0].invalid_frames, e.ports[0].rx_errors, e.ports[0].forwarded_rx_errors), (1, 2, 9));
        assert_eq!((e.ports[3].invalid_frames, e.ports[3].rx_errors, e.ports[3].forwarded_rx_errors), (7, 8, 12));
        assert_eq!((e.processing_unit_errors, e.pdi_errors), (13, 14));
    }
}
