//! The chip's blocking commands as bring-up runs them: to their end,
//! refused (bit7) and failed (bit3) told apart, SDOs with the slave's abort
//! code.

use std::time::{Duration, Instant};

use ecmxf_wire::Request;
use ecmxf_wire::flags::{ControlFlags, ErrorFlags};
use ecmxf_wire::payload::control::InfoUpdate;
use ecmxf_wire::payload::sdo::{SdoAbortCode, SdoAbortCodeGet, SdoAccess, SdoGet, SdoRequest};

use super::error::{BringUpError, step};
use crate::link::Link;
use crate::port::{Port, PortError};

/// Blocking commands get this long to finish.
pub(super) const SLOW: Duration = Duration::from_secs(5);

/// What [`blocking`] says of a command the chip ran and that failed (bit3).
pub(super) const FAILED_ON_CHIP: &str = "failed on the chip";

/// Runs a blocking command to its end: refused (bit7) and failed (bit3) are
/// errors; the bits are cleared for what follows.
pub(crate) fn blocking<'a, L: Link, R: Request<'a>>(
    port: &mut Port<L>,
    req: &R,
    timeout: Duration,
) -> Result<(), BringUpError> {
    let name = R::CODE.name();
    let a = port.call(req)?;
    if a.header.errors.contains(ErrorFlags::COMMAND_ERROR) {
        port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
        return Err(step(name, "refused by the chip (bad parameter or slot busy)"));
    }
    let deadline = Instant::now() + timeout;
    loop {
        let h = port.call(&InfoUpdate)?.header;
        if !h.blocking_busy() {
            if h.errors.contains(ErrorFlags::BLOCKING_FAILED) {
                port.pending_control |= ControlFlags::CLEAR_BLOCKING_ERROR;
                return Err(step(name, FAILED_ON_CHIP));
            }
            return Ok(());
        }
        if Instant::now() >= deadline {
            return Err(step(name, format!("still busy after {timeout:?}")));
        }
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// One SDO download, waited for (up to `timeout` on the slave's side):
/// `Ok(Err(code))` when the slave refuses it.
pub(super) fn sdo_download<L: Link>(
    port: &mut Port<L>,
    slave: u8,
    (index, subindex, complete_access): (u16, u8, bool),
    data: &[u8],
    timeout: Duration,
) -> Result<Result<(), SdoAbortCode>, BringUpError> {
    let req = SdoRequest {
        slave,
        index,
        subindex,
        complete_access,
        timeout_us: u32::try_from(timeout.as_micros()).unwrap_or(u32::MAX),
        access: SdoAccess::Write(data),
    };
    match blocking(port, &req, SLOW.max(timeout + Duration::from_secs(1))) {
        Ok(()) => Ok(Ok(())),
        Err(_) => Ok(Err(abort_code(port)?)),
    }
}

/// One SDO upload of at most 8 bytes (an assignment or mapping entry),
/// waited for: `None` when the slave refuses it.
pub(super) fn sdo_upload<L: Link>(
    port: &mut Port<L>,
    slave: u8,
    index: u16,
    subindex: u8,
) -> Result<Option<u32>, BringUpError> {
    let access = SdoAccess::Read { max_len: 8 };
    let req = SdoRequest { slave, index, subindex, complete_access: false, timeout_us: 1_000_000, access };
    if blocking(port, &req, SLOW).is_err() {
        abort_code(port)?;
        return Ok(None);
    }
    let reply = port.ask(&SdoGet)?;
    if reply.status != 0 {
        return Ok(None);
    }
    Ok(Some(reply.data.iter().take(4).enumerate().fold(0u32, |v, (i, b)| v | u32::from(*b) << (8 * i))))
}

/// The slave's abort code of the SDO that just failed (command 29).
pub(super) fn abort_code<L: Link>(port: &mut Port<L>) -> Result<SdoAbortCode, PortError> {
    Ok(port.call(&SdoAbortCodeGet)?.answer_to(&SdoAbortCodeGet).map_or(SdoAbortCode::GENERAL, |r| r.0))
}
