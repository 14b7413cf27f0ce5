//! Simulated slaves built from a slave entry of an ENI file
//! ([`ecmxf_devices::eni`]): the devices a configuration tool knew when it
//! wrote the file, for networks no ESI describes (the TwinCAT fixture's IMU,
//! SOEM's sample devices).
//!
//! An entry with `ProcessData` is the device its PDOs and sync managers
//! say. An entry without (SOEM's sample gives only Info and Mailbox) is a
//! CoE device whose PDOs are the ones its own init commands assign: each
//! such PDO maps one 32-bit object (0x7nn0:01 for an RxPDO 0x16nn,
//! 0x6nn0:01 for a TxPDO 0x1Ann), assignable and mappable in PRE-OP, none
//! assigned until the master writes it, as a configurable device ships.

use ecmxf_devices::eni::{CoeAccess, EniSlave};
use ecmxf_devices::esi::{EsiDevice, EsiPdo, EsiSm};
use ecmxf_devices::od::DataType;
use ecmxf_wire::payload::pdo::PdoEntry;

use super::esi::SimulatedDevice;
use super::pdo_map::{RX_ASSIGN, TX_ASSIGN};
use super::sii::{protocol, sm_type};
use super::slave::Slave;

/// The slave an ENI entry describes.
pub fn slave_from_eni(entry: &EniSlave, alias: u16) -> Slave {
    let mut device = entry.device();
    if entry.process_data.is_none() && device.protocols & protocol::COE != 0 {
        implied_pdos(entry, &mut device);
    }
    let mut slave = device.to_slave(entry.vendor_id, alias);
    slave.name = entry.name.clone();
    slave
}

/// The PDO indices an entry's init commands write into 0x1C12 / 0x1C13:
/// one subindex at a time (2 bytes each) or the whole list with complete
/// access (count, pad, then 2 bytes each).
fn assigned_by_init_cmds(entry: &EniSlave, assign: u16) -> Vec<u16> {
    let mut out = Vec::new();
    for c in entry.coe_init_cmds.iter().filter(|c| c.index == assign && !c.disabled) {
        let CoeAccess::Download(data) = &c.access else { continue };
        let list: &[u8] = match (c.complete_access, c.subindex) {
            (true, 0) => data.get(2..).unwrap_or_default(),
            (_, 0) => &[],
            _ => data,
        };
        for pair in list.chunks_exact(2) {
            let pdo = u16::from_le_bytes([pair[0], pair[1]]);
            if pdo != 0 && !out.contains(&pdo) {
                out.push(pdo);
            }
        }
    }
    out
}

fn implied_pdos(entry: &EniSlave, device: &mut EsiDevice) {
    for (assign, rx) in [(RX_ASSIGN, true), (TX_ASSIGN, false)] {
        let pdos: Vec<EsiPdo> = assigned_by_init_cmds(entry, assign)
            .into_iter()
            .map(|index| {
                let object = if rx { 0x7000 } else { 0x6000 } + (index & 0xFF) * 0x10;
                let entry = PdoEntry { index: object, subindex: 1, bits: 32 };
                EsiPdo {
                    index,
                    name: format!("{} {index:#06x}", if rx { "RxPDO" } else { "TxPDO" }),
                    sm: None,
                    fixed: false,
                    mandatory: false,
                    excludes: Vec::new(),
                    entries: vec![(entry, format!("Value {object:#06x}"), DataType::UInt32)],
                }
            })
            .collect();
        if rx { device.rx_pdos = pdos } else { device.tx_pdos = pdos }
    }
    // Process-data sync managers after the mailbox's, above its areas.
    let top = device.sms.iter().map(|s| u32::from(s.start) + u32::from(s.size)).max().unwrap_or(0x1000);
    let base = (top.div_ceil(0x100) * 0x100) as u16;
    device.sms.push(EsiSm { kind: sm_type::OUTPUTS, start: base, size: 0, control: 0x64, enable: 1 });
    device.sms.push(EsiSm { kind: sm_type::INPUTS, start: base + 0x100, size: 0, control: 0x20, enable: 1 });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::esm::AlState;
    use crate::net::od::SdoServer;
    use crate::net::pdo_map::layout;
    use ecmxf_devices::eni::Eni;

    const SOEM_LIKE: &str = r#"<EtherCATConfig><Config>
  <Slave><Info><Name>B</Name><VendorId>1</VendorId><ProductCode>0x10055aa</ProductCode></Info>
    <Mailbox><Send><Start>0x1000</Start><Length>256</Length></Send><Receive><Start>0x1200</Start><Length>256</Length></Receive>
      <Protocol>CoE</Protocol><CoE><InitCmds>
        <InitCmd CompleteAccess="1"><Transition>PS</Transition><Ccs>2</Ccs><Index>0x1c12</Index><SubIndex>0</SubIndex><Data>0300011607161c16</Data></InitCmd>
        <InitCmd><Transition>PS</Transition><Ccs>2</Ccs><Index>0x1c13</Index><SubIndex>1</SubIndex><Data>021a</Data></InitCmd>
      </InitCmds></CoE></Mailbox></Slave>
</Config></EtherCATConfig>"#;

    #[test]
    fn a_slave_without_process_data_has_the_pdos_its_init_commands_assign() {
        let eni = Eni::parse(SOEM_LIKE).unwrap();
        let mut slave = slave_from_eni(&eni.slaves[0], 0);
        assert_eq!(slave.name, "B");
        assert_eq!(layout(&slave.od, true).unwrap().bits, 0, "nothing assigned before the master writes it");
        let ok = crate::net::pdo_map::validate_write;
        // Complete access is judged as a whole: a PDO the device lacks
        // refuses the write and changes nothing.
        let bad = [2, 0, 0x01, 0x16, 0x05, 0x16];
        assert!(slave.od.download(RX_ASSIGN, 0, true, &bad, AlState::PreOp, ok).is_err());
        assert_eq!(slave.od.int(RX_ASSIGN, 1), 0, "a refused write changed nothing");
        let data = [3, 0, 0x01, 0x16, 0x07, 0x16, 0x1C, 0x16];
        assert_eq!(slave.od.download(RX_ASSIGN, 0, true, &data, AlState::PreOp, ok), Ok(()));
        let rx = layout(&slave.od, true).unwrap();
        assert_eq!(rx.entries.iter().map(|e| e.index).collect::<Vec<_>>(), [0x7010, 0x7070, 0x71C0]);
        assert_eq!(rx.bits, 96);
        slave.od.download(TX_ASSIGN, 1, false, &[0x02, 0x1A], AlState::PreOp, ok).unwrap();
        slave.od.download(TX_ASSIGN, 0, false, &[1], AlState::PreOp, ok).unwrap();
        assert_eq!(layout(&slave.od, false).unwrap().entries[0].index, 0x6020);
    }
}
