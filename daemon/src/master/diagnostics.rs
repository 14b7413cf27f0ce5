//! What the chip tells of the slaves' health, read live: its CoE
//! emergency history (COE_EMERGENCY, v049 83). Each slave as a listing
//! shows it: `slave_listing.rs`.

use ecmxf_wire::PayloadError;
pub(crate) use ecmxf_wire::flags::{ErrorFlags, StatusFlags};
pub(crate) use ecmxf_wire::payload::emergency::EmergencyRecord;
use ecmxf_wire::payload::emergency::{CoeEmergencyReply, EMERGENCY_MAX};

use super::{Call, Master};
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
