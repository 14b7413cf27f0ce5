//! What the chip and the slaves tell of their health, read live: the
//! chip's CoE emergency history (COE_EMERGENCY, v049 83), and what a
//! slave reads as (SLV_INFO_GET, v049 15; read for listings in
//! `slave_listing.rs`).

pub(crate) use ecmxf_wire::flags::{ErrorFlags, StatusFlags};
pub(crate) use ecmxf_wire::payload::emergency::EmergencyRecord;
use ecmxf_wire::payload::emergency::{CoeEmergencyReply, EMERGENCY_MAX};
use ecmxf_wire::{EcatState, PayloadError};

use super::{Call, Identity, Master};
use crate::engine::error::EngineError;
use crate::engine::slot::Immediate;

/// Why the chip's emergency history could not be read.
#[derive(Clone, Debug)]
pub enum HistoryError {
    /// The chip command failed.
    Engine(EngineError),
    /// The chip's answer does not decode as emergency records.
    Unreadable(PayloadError),
}

impl From<EngineError> for HistoryError {
    fn from(e: EngineError) -> Self {
        Self::Engine(e)
    }
}

impl std::fmt::Display for HistoryError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Engine(e) => e.fmt(f),
            Self::Unreadable(e) => write!(f, "emergency history: {e}"),
        }
    }
}

impl std::error::Error for HistoryError {}

/// A slave as read live from the chip.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct SlaveReading {
    /// Its EtherCAT state.
    pub state: EcatState,
    /// Its AL status code.
    pub al_status: u16,
    /// Its identity and name, when asked for fresh ones.
    pub identity: Option<(Identity, String)>,
    /// Its station alias.
    pub alias: u32,
    /// Its configured station address.
    pub configured_address: u32,
    /// Whether it has distributed clocks.
    pub dc_supported: bool,
    /// Whether its distributed clock is active.
    pub dc_active: bool,
    /// Its SYNC0 cycle, ns.
    pub dc_cycle_ns: u32,
    /// Its SYNC0 shift, ns.
    pub dc_shift_ns: i32,
}

impl Master {
    /// The chip's last `count` emergency records (`None`: as many as it
    /// keeps, 8), empty slots left out, newest first.
    pub(crate) async fn emergency_history(
        &self,
        count: Option<u8>,
        call: Call,
    ) -> Result<Vec<EmergencyRecord>, HistoryError> {
        let n = count.unwrap_or(EMERGENCY_MAX);
        if !(1..=EMERGENCY_MAX).contains(&n) {
            let reason = format!("{n} records; the chip keeps 1..={EMERGENCY_MAX}");
            return Err(EngineError::BadArgument { field: "count", reason }.into());
        }
        let (_, data) = self.immediate(Immediate::Emergencies(n), call).await?;
        let reply = CoeEmergencyReply::new(&data).map_err(HistoryError::Unreadable)?;
        let mut out: Vec<EmergencyRecord> = reply.records().filter(|r| !r.is_empty()).collect();
        out.sort_by_key(|r| std::cmp::Reverse(r.number));
        Ok(out)
    }
}
