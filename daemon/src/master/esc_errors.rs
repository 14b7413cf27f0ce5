//! The error counters a slave's ESC keeps (registers 0x0300..0x030D,
//! ETG.1000.4 and the ESC datasheets): per port an invalid-frame counter
//! at 0x0300 + 2n and a physical-layer RX error counter at 0x0301 + 2n,
//! forwarded RX errors at 0x0308 + n (found by a slave before this one),
//! the processing unit's at 0x030C and the PDI's at 0x030D; each saturates
//! at 255. A count rising on one port points at the cable into it. Read
//! with one datagram; the dashboard's slaves table shows them, `ecmxfctl
//! crc` reads the same registers.

use super::{Call, EngineError, Master};

/// The counters' first register and their length.
const AT: u16 = 0x0300;
const LENGTH: u16 = 14;

/// One port's counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PortErrors {
    /// Frames with a bad CRC or framing seen on the port.
    pub invalid_frames: u8,
    /// Physical-layer RX errors on the port.
    pub rx_errors: u8,
    /// Errors a slave before this one had already found.
    pub forwarded: u8,
}

/// A slave's counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EscErrors {
    /// Ports 0..=3.
    pub ports: [PortErrors; 4],
    /// ECAT processing unit errors.
    pub processing_unit: u8,
    /// PDI errors.
    pub pdi: u8,
}

impl EscErrors {
    /// The counters from the 14 bytes at 0x0300.
    fn decode(b: &[u8]) -> Self {
        let at = |i: usize| b.get(i).copied().unwrap_or(0);
        Self {
            ports: std::array::from_fn(|n| PortErrors {
                invalid_frames: at(2 * n),
                rx_errors: at(2 * n + 1),
                forwarded: at(8 + n),
            }),
            processing_unit: at(12),
            pdi: at(13),
        }
    }

    /// Every count added up: 0 for a clean slave.
    pub fn total(&self) -> u32 {
        let ports: u32 = self
            .ports
            .iter()
            .map(|p| u32::from(p.invalid_frames) + u32::from(p.rx_errors) + u32::from(p.forwarded))
            .sum();
        ports + u32::from(self.processing_unit) + u32::from(self.pdi)
    }
}

impl Master {
    /// Slave `slave`'s ESC error counters; `None` when it did not answer
    /// the read (working counter 0).
    pub async fn esc_errors(&self, slave: u8, call: Call) -> Result<Option<EscErrors>, EngineError> {
        let a = self.read_registers(slave, AT, LENGTH, call).await?;
        Ok((a.working_counter != 0).then(|| EscErrors::decode(&a.data)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bytes_at_0x0300_are_read_per_port() {
        let mut b = [0u8; 14];
        (b[2], b[3], b[9], b[12], b[13]) = (2, 5, 1, 3, 4);
        let e = EscErrors::decode(&b);
        assert_eq!(e.ports[1], PortErrors { invalid_frames: 2, rx_errors: 5, forwarded: 1 });
        assert_eq!(e.ports[0], PortErrors::default());
        assert_eq!((e.processing_unit, e.pdi), (3, 4));
        assert_eq!(e.total(), 15);
    }
}
