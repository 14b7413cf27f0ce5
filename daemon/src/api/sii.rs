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
use crate::master::sii::Categories;

/// Most words one Read or Write moves.
pub(crate) const MAX_WORDS: u32 = 4096;

/// The `Sii` service.
#[derive(Debug, Clone)]
pub(crate) struct SiiService(pub Arc<Context>);

fn word(v: u32) -> Result<u16, Status> {
    u16::try_from(v).map_err(|_| bad_argument("word", format!("{v:#x} is outside 0..=0xFFFF")))
}

fn bytes_of(words: &[u16]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
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
        let words = bounded(&caller, self.0.master.eeprom_read_words(s, w, r.count as u16, caller.call)).await?;
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
        let backup = bounded(&caller, async {
            let backup = m.eeprom_read_words(s, w, values.len() as u16, caller.call).await?;
            m.eeprom_write_words(s, w, &values, caller.call).await.map_err(to_status)?;
            Ok::<_, Status>(backup)
        })
        .await?;
        Ok(Response::new(pb::SiiWriteResponse { backup: bytes_of(&backup), words_written: values.len() as u32 }))
    }

    async fn decode(&self, request: Request<pb::SiiDecodeRequest>) -> Result<Response<pb::SiiDecodeResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let s = self.0.slave(request.get_ref().slave)?;
        let words = bounded(&caller, async {
            self.0.master.sii_words(s, Categories::All, caller.call).await.map_err(to_status)
        })
        .await?;
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
