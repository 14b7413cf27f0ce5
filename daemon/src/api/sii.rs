//! `Sii` service: the slave's EEPROM, word-addressed (ETG.1000.6 / ETG.2010
//! SII layout).

use std::sync::Arc;

use ecmxf_devices::sii::{MailboxArea, PdoRecord, Sii, decode_text};
use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::sii_server::Sii as SiiApi;
use tonic::{Request, Response, Status};

use super::Context;
use super::auth::Role;
use super::bounded;
use super::status::{bad_argument, to_status};
use crate::master::Master;

/// Most words one Read or Write moves.
pub const MAX_WORDS: u32 = 4096;
/// Where the category area starts (word 0x40).
const CATEGORIES: u16 = 0x40;

/// The `Sii` service.
#[derive(Debug, Clone)]
pub struct SiiService(pub Arc<Context>);

fn word(v: u32) -> Result<u16, Status> {
    u16::try_from(v).map_err(|_| bad_argument("word", format!("{v:#x} is outside 0..=0xFFFF")))
}

fn bytes_of(words: &[u16]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// Reads the image: the fixed area, then category headers up to the end
/// marker (0xFFFF) or the end of the 64 Kword address space.
async fn read_image(m: &Master, s: u8) -> Result<Vec<u16>, Status> {
    let mut words = m.eeprom_read_words(s, 0, CATEGORIES, None).await.map_err(to_status)?;
    // The EEPROM's own size (word 0x3E: (n + 1) x 128 bytes, ETG.1000.6
    // table 2): a category that runs past it is a corrupt image, said with
    // its offset, not read on into whatever the EEPROM answers there.
    let size = words.get(0x3E).map_or(0x1_0000, |&n| (u32::from(n) + 1) * 64).min(0x1_0000);
    let mut at = u32::from(CATEGORIES);
    while at + 2 <= size {
        let head = m.eeprom_read_words(s, at as u16, 2, None).await.map_err(to_status)?;
        words.extend_from_slice(&head);
        if head[0] == 0xFFFF || head[0] == 0 {
            break;
        }
        if at + 2 + u32::from(head[1]) > size {
            return Err(Status::failed_precondition(format!(
                "slave {s}'s SII is corrupt: category {:#06x} at byte offset {:#06x} is {} bytes long and runs past the EEPROM's size of {} bytes (word 0x3E)",
                head[0],
                at * 2,
                u32::from(head[1]) * 2,
                size * 2
            )));
        }
        let len = u32::from(head[1]);
        let body = m.eeprom_read_words(s, (at + 2) as u16, len as u16, None).await.map_err(to_status)?;
        words.extend_from_slice(&body);
        at += 2 + len;
    }
    Ok(words)
}

fn mailbox(m: &MailboxArea) -> pb::SiiMailbox {
    pb::SiiMailbox {
        rx_offset: m.rx_offset.into(),
        rx_size: m.rx_size.into(),
        tx_offset: m.tx_offset.into(),
        tx_size: m.tx_size.into(),
    }
}

fn pdos(sii: &Sii, list: &[PdoRecord]) -> Vec<pb::SiiPdo> {
    let text = |i: u8| sii.string(i).map(decode_text).unwrap_or_default();
    list.iter()
        .map(|p| pb::SiiPdo {
            index: p.index.into(),
            sync_manager: p.sm.into(),
            name: text(p.name),
            entries: p
                .entries
                .iter()
                .map(|e| pb::SiiPdoEntry {
                    index: e.index.into(),
                    subindex: e.subindex.into(),
                    name: text(e.name),
                    data_type: e.data_type.into(),
                    bit_length: e.bits.into(),
                })
                .collect(),
        })
        .collect()
}

#[tonic::async_trait]
impl SiiApi for SiiService {
    async fn read(&self, request: Request<pb::SiiReadRequest>) -> Result<Response<pb::SiiReadResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let r = request.get_ref();
        let (s, w) = (self.0.slave(r.slave)?, word(r.word)?);
        if r.count == 0 || r.count > MAX_WORDS {
            return Err(bad_argument("count", format!("{} words; read 1..={MAX_WORDS} at a time", r.count)));
        }
        let words = bounded(&caller, self.0.master.eeprom_read_words(s, w, r.count as u16, caller.deadline)).await?;
        Ok(Response::new(pb::SiiReadResponse { data: bytes_of(&words) }))
    }

    async fn write(&self, request: Request<pb::SiiWriteRequest>) -> Result<Response<pb::SiiWriteResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let r = request.get_ref();
        let (s, w) = (self.0.slave(r.slave)?, word(r.word)?);
        if r.data.is_empty() || r.data.len() % 2 != 0 || r.data.len() > 2 * MAX_WORDS as usize {
            return Err(bad_argument(
                "data",
                format!("{} bytes; give an even number, 2..={} (whole words)", r.data.len(), 2 * MAX_WORDS),
            ));
        }
        let values: Vec<u16> = r.data.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
        tracing::warn!(who = %caller.who, slave = s, word = w, words = values.len(), "SII write");
        let m = &self.0.master;
        let t = caller.deadline;
        let backup = bounded(&caller, async {
            let backup = m.eeprom_read_words(s, w, values.len() as u16, t).await?;
            m.eeprom_write_words(s, w, &values, t).await.map_err(to_status)?;
            Ok::<_, Status>(backup)
        })
        .await?;
        Ok(Response::new(pb::SiiWriteResponse { backup: bytes_of(&backup), words_written: values.len() as u32 }))
    }

    async fn decode(&self, request: Request<pb::SiiDecodeRequest>) -> Result<Response<pb::SiiDecodeResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let s = self.0.slave(request.get_ref().slave)?;
        let words = bounded(&caller, read_image(&self.0.master, s)).await?;
        let image = bytes_of(&words);
        let sii = Sii::parse(&image).map_err(|e| Status::internal(format!("slave {s}'s SII does not parse: {e}")))?;
        let text = |i: u8| sii.string(i).map(decode_text).unwrap_or_default();
        let general = sii.general.clone().unwrap_or_default();
        Ok(Response::new(pb::SiiDecodeResponse {
            vendor_id: sii.vendor_id,
            product_code: sii.product_code,
            revision: sii.revision,
            serial: sii.serial,
            checksum_ok: sii.checksum_ok(),
            bootstrap_mailbox: Some(mailbox(&sii.bootstrap_mailbox)),
            mailbox: Some(mailbox(&sii.mailbox)),
            mailbox_protocols: sii.protocols.into(),
            size_bytes: (u32::from(sii.size_word) + 1) * 128,
            version: sii.version.into(),
            strings: sii.strings.iter().map(|b| decode_text(b)).collect(),
            name: text(general.name),
            group: text(general.group),
            order: text(general.order),
            ebus_current_ma: general.ebus_current_ma.into(),
            fmmu: sii.fmmu.iter().map(|&b| b.into()).collect(),
            sync_managers: sii
                .sync_managers
                .iter()
                .map(|m| pb::SiiSyncManager {
                    start: m.start.into(),
                    length: m.length.into(),
                    control: m.control.into(),
                    enable: m.enable.into(),
                    kind: m.kind.into(),
                })
                .collect(),
            rx_pdos: pdos(&sii, &sii.rx_pdos),
            tx_pdos: pdos(&sii, &sii.tx_pdos),
            image,
        }))
    }
}
