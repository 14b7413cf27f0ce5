//! The master's own object dictionary, as a mailbox gateway client reads
//! it at station address 0 (after ETG.5001.3 annex A, the master object
//! dictionary of ETG.1510): CoE SDO uploads, expedited or normal, of
//!
//! - 0x1008 device name, 0x1009 hardware version (the chip's firmware),
//!   0x100A software version, 0x1018 identity (vendor, product, revision,
//!   serial: 0, no vendor id is assigned to ecmxfd);
//! - 0x8000 + n, slave n's configuration: 1 fixed station address, 3
//!   name, 5 vendor id, 6 product code, 7 revision;
//! - 0xA000 + n, slave n's diagnosis: 1 AL status (its state), 2 AL
//!   status code;
//! - 0xF000 modular device profile: 1 index distance (1), 2 number of
//!   modules (the slaves);
//! - 0xF020 the configured address list: one station address per slave.
//!
//! Everything else aborts as missing; a download aborts as read-only.

use crate::master::mailbox_channel::framing::{SdoAbortCode, SdoRequest, SdoResponse};
use crate::master::{Call, SlaveInfoCode};

use crate::master::Master;

fn u16_(v: u16) -> Vec<u8> {
    v.to_le_bytes().to_vec()
}

fn u32_(v: u32) -> Vec<u8> {
    v.to_le_bytes().to_vec()
}

/// The value of `index:subindex`, or the abort code.
async fn value(master: &Master, index: u16, subindex: u8, call: Call) -> Result<Vec<u8>, SdoAbortCode> {
    let layout = master.layout();
    let slaves = layout.slaves.len();
    let missing = || if subindex == 0 { SdoAbortCode::OBJECT_MISSING } else { SdoAbortCode::SUBINDEX_MISSING };
    let slave_of = |base: u16| {
        let n = usize::from(index - base);
        (n < slaves).then_some(n as u8).ok_or(SdoAbortCode::OBJECT_MISSING)
    };
    match (index, subindex) {
        (0x1008, 0) => Ok(b"ecmxfd".to_vec()),
        (0x1009, 0) => Ok(format!("ECM-XF firmware {}", layout.firmware).into_bytes()),
        (0x100A, 0) => Ok(env!("CARGO_PKG_VERSION").as_bytes().to_vec()),
        (0x1018, 0) => Ok(vec![4]),
        (0x1018, 1..=4) => Ok(u32_(0)),
        (0xF000, 0) => Ok(vec![2]),
        (0xF000, 1) => Ok(u16_(1)),
        (0xF000, 2) => Ok(u16_(slaves as u16)),
        (0xF020, 0) => Ok(vec![slaves.min(255) as u8]),
        (0xF020, s) if usize::from(s) <= slaves => {
            master.station_address(s - 1, call).await.map(u16_).ok_or(SdoAbortCode::GENERAL)
        }
        (0x8000..=0x8FFF, _) => {
            let n = slave_of(0x8000)?;
            let s = &layout.slaves[usize::from(n)];
            match subindex {
                0 => Ok(vec![7]),
                1 => master.station_address(n, call).await.map(u16_).ok_or(SdoAbortCode::GENERAL),
                3 => Ok(s.name.as_bytes().to_vec()),
                5 => Ok(u32_(s.vendor_id)),
                6 => Ok(u32_(s.product_code)),
                7 => Ok(u32_(s.revision)),
                _ => Err(missing()),
            }
        }
        (0xA000..=0xAFFF, _) => {
            let n = slave_of(0xA000)?;
            let item = match subindex {
                0 => return Ok(vec![2]),
                1 => SlaveInfoCode::State,
                2 => SlaveInfoCode::AlStatus,
                _ => return Err(missing()),
            };
            let v = master.slave_number(n, item, call).await.map_err(|_| SdoAbortCode::GENERAL)?;
            Ok(u16_(v as u16))
        }
        _ => Err(missing()),
    }
}

/// The CoE body answering a CoE body sent to the master; `None` when it is
/// not an SDO request.
pub(crate) async fn answer(master: &Master, body: &[u8], call: Call) -> Option<Vec<u8>> {
    let request = SdoRequest::decode(body).ok()?;
    let response = match request {
        SdoRequest::Upload { index, subindex, complete_access: false } => {
            match value(master, index, subindex, call).await {
                Ok(data) => Ok((index, subindex, data)),
                Err(code) => Err((index, subindex, code)),
            }
        }
        SdoRequest::Upload { index, subindex, complete_access: true } => {
            Err((index, subindex, SdoAbortCode::NO_COMPLETE_ACCESS))
        }
        SdoRequest::Download { index, subindex, .. } => Err((index, subindex, SdoAbortCode::READ_ONLY)),
    };
    let mut out = vec![0u8; 512];
    let n = match &response {
        Ok((index, subindex, data)) => {
            SdoResponse::Uploaded { index: *index, subindex: *subindex, complete_access: false, data }.encode(&mut out)
        }
        Err((index, subindex, code)) => {
            SdoResponse::Abort { index: *index, subindex: *subindex, code: code.0 }.encode(&mut out)
        }
    }
    .ok()?;
    out.truncate(n);
    Some(out)
}
