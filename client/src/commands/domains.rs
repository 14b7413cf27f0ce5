//! `domains` (IgH `ethercat domains`): the process image as one domain.
//! The ECM-XF exchanges the whole image each DC cycle through its PDO
//! FIFOs (one output frame in, one input frame out), so there is exactly
//! one domain: its sizes, whether frames flow, the working-counter errors
//! the chip counted, and the FIFO levels; `-v` adds each slave's place in
//! it and the data now, as IgH's `-v` does.

use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::Report;
use crate::values::Hex;

/// `ecmxfctl domains --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DomainsReport {
    /// Always one: the chip's process image.
    pub domains: Vec<DomainReport>,
    #[serde(skip)]
    pub verbose: bool,
}

/// The one domain.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DomainReport {
    /// 0.
    pub index: u32,
    pub output_bytes: u32,
    pub input_bytes: u32,
    /// DC cycle, microseconds: one output and one input frame per cycle.
    pub cycle_us: u32,
    /// Input frames arrive (a running network that delivers nothing is not "flowing").
    pub flowing: bool,
    /// Since the latest input frame, microseconds.
    pub input_age_us: u64,
    /// Cycles with a wrong working counter, since the daemon started.
    pub wkc_errors: u64,
    /// Frames in the chip's RxFIFO (outputs waiting) and TxFIFO (inputs waiting).
    pub rx_fifo_level: u32,
    pub tx_fifo_level: u32,
    /// The RxFIFO's depth, frames.
    pub rx_fifo_depth: u32,
    /// Each slave's part of the image.
    pub slaves: Vec<DomainSlaveReport>,
    /// The images now (with -v; else null).
    pub output_image: Option<Hex>,
    pub input_image: Option<Hex>,
}

/// A slave's part of the domain.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DomainSlaveReport {
    pub position: u32,
    pub name: String,
    /// Byte offset and size in the output and input images.
    pub output_offset: u32,
    pub output_bytes: u32,
    pub input_offset: u32,
    pub input_bytes: u32,
}

impl Report for DomainsReport {
    fn text(&self) -> String {
        let mut t = String::new();
        for d in &self.domains {
            let flow = if d.flowing {
                format!("flowing (input age {:.1} ms)", d.input_age_us as f64 / 1000.0)
            } else {
                "NOT flowing".to_owned()
            };
            t.push_str(&format!(
                "Domain{}: Outputs {} B, Inputs {} B, Cycle {} us, Frames {flow}, WkcErrors {}, FIFO rx {}/{} tx {}\n",
                d.index,
                d.output_bytes,
                d.input_bytes,
                d.cycle_us,
                d.wkc_errors,
                d.rx_fifo_level,
                d.rx_fifo_depth,
                d.tx_fifo_level
            ));
            if !self.verbose {
                continue;
            }
            for s in d.slaves.iter().filter(|s| s.output_bytes > 0 || s.input_bytes > 0) {
                t.push_str(&format!(
                    "  Slave {} \"{}\": Outputs {}+{} B, Inputs {}+{} B\n",
                    s.position, s.name, s.output_offset, s.output_bytes, s.input_offset, s.input_bytes
                ));
            }
            for (what, image) in [("Outputs", &d.output_image), ("Inputs", &d.input_image)] {
                if let Some(Hex(hex)) = image {
                    t.push_str(&format!("  {what}:\n"));
                    t.push_str(&hex_lines(hex));
                }
            }
        }
        t
    }
}

/// Hex digits as IgH prints data: 16 bytes a line, spaced.
fn hex_lines(hex: &str) -> String {
    let bytes: Vec<&str> = hex.as_bytes().chunks(2).map(|c| std::str::from_utf8(c).unwrap_or("??")).collect();
    let mut out = String::new();
    for line in bytes.chunks(16) {
        out.push_str("    ");
        out.push_str(&line.join(" "));
        out.push('\n');
    }
    out
}

/// The domain now; with `verbose`, its data too.
pub async fn fetch(api: &Api, verbose: bool) -> Result<DomainsReport, CliError> {
    let m = super::master::fetch(api).await?;
    let slaves = super::slaves::fetch(api, None, false).await?.slaves;
    // Inputs only while frames flow: otherwise there is none to wait for.
    let (output_image, input_image) = match (verbose, m.process_data_flowing) {
        (true, true) => {
            let d = super::data::data(api, &[], true).await?;
            (d.output_image, d.input_image)
        }
        (true, false) => (Some(Hex::of(&super::data::outputs(api, Vec::new()).await?.image)), None),
        (false, _) => (None, None),
    };
    let domain = DomainReport {
        index: 0,
        output_bytes: m.output_image_bytes,
        input_bytes: m.input_image_bytes,
        cycle_us: m.sync0_us,
        flowing: m.process_data_flowing,
        input_age_us: m.input_age_us,
        wkc_errors: m.counters.wkc_errors,
        rx_fifo_level: m.rx_fifo_level,
        tx_fifo_level: m.tx_fifo_level,
        rx_fifo_depth: m.fifo_rx_depth,
        slaves: slaves
            .into_iter()
            .map(|s| DomainSlaveReport {
                position: s.position,
                name: s.name,
                output_offset: s.output_offset,
                output_bytes: s.output_bytes,
                input_offset: s.input_offset,
                input_bytes: s.input_bytes,
            })
            .collect(),
        output_image,
        input_image,
    };
    Ok(DomainsReport { domains: vec![domain], verbose })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_is_printed_sixteen_bytes_a_line() {
        let hex: String = (0u8..18).map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex_lines(&hex), "    00 01 02 03 04 05 06 07 08 09 0a 0b 0c 0d 0e 0f\n    10 11\n");
    }
}
