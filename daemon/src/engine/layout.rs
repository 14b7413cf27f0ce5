//! What bring-up found and set up: the network's slaves, their place in
//! the process image, and the FIFO plan. Read by the running loop, the
//! held outputs and the master; written by bring-up alone. A module of its
//! own so that none of its readers imports bring-up (bring-up and the held
//! outputs once used each other).

use ecmxf_wire::EcatState;

/// What bring-up found and set up.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct NetworkLayout {
    /// Firmware version.
    pub firmware: u8,
    /// Slaves in ring order.
    pub slaves: Vec<SlaveSummary>,
    /// Output frame size.
    pub rx_size: usize,
    /// Input frame size.
    pub tx_size: usize,
    /// State reached.
    pub state: EcatState,
    /// RxFIFO depth in force (configured, fitted to the FIFO memory).
    pub fifo_rx_depth: u8,
    /// TxFIFO depth in force.
    pub fifo_tx_depth: u8,
    /// Low mark in force.
    pub fifo_low: u8,
    /// High mark in force.
    pub fifo_high: u8,
    /// How long one SPI packet takes on this link, as bring-up measured
    /// it for the link budget, ns: exchanges per second times this is the
    /// share of the link in use.
    pub packet_ns: u64,
}

/// One slave as found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SlaveSummary {
    /// Vendor id.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Name.
    pub name: String,
    /// Output bytes.
    pub rx_bytes: usize,
    /// Input bytes.
    pub tx_bytes: usize,
    /// Offset of its outputs in the output frame.
    pub rx_offset: usize,
    /// Offset of its inputs in the input frame.
    pub tx_offset: usize,
}
