//! A mapping the daemon cannot honour is said, by name, before it runs
//! (`ecmxfd --check-config`) and when it starts (the log and the layout's
//! notes), never dropped without a word: here a device whose ESI assigns a
//! TxPDO to a sync manager it does not have, so its inputs stay empty; the
//! simulator's `ecmxf-sim check` says it too.

use std::process::Command;

use ecmxf_e2e::{Daemon, config, daemon_binary, run, temp_dir};
use ecmxf_proto::v1 as pb;

const ESI: &str = r##"<?xml version="1.0"?>
<EtherCATInfo><Vendor><Id>#x2</Id><Name>V</Name></Vendor><Descriptions><Devices>
<Device><Type ProductCode="#x10" RevisionNo="#x3">IO 1</Type><Name>IO 1</Name>
<Sm StartAddress="#x0f00" ControlByte="#x44" Enable="1">Outputs</Sm>
<Sm StartAddress="#x1000" ControlByte="#x00" Enable="1">Inputs</Sm>
<RxPdo Sm="0" Fixed="1"><Index>#x1600</Index><Name>Out</Name>
<Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>8</BitLen><Name>Output</Name><DataType>USINT</DataType></Entry>
</RxPdo>
<TxPdo Sm="3" Fixed="1"><Index>#x1a00</Index><Name>In</Name>
<Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>8</BitLen><Name>Input</Name><DataType>USINT</DataType></Entry>
</TxPdo></Device></Devices></Descriptions></EtherCATInfo>"##;

const SAID: &str = "TxPdo 0x1a00 is assigned to sync manager 3, and the device has 2: not assigned";

#[test]
fn a_pdo_on_a_sync_manager_the_device_lacks_is_named_at_check_and_at_start() {
    let dir = temp_dir("mapping-warnings");
    let esi = dir.join("io.xml");
    std::fs::write(&esi, ESI).unwrap();
    let slave = format!("[[slave]]\nesi = \"{}\"\n", esi.display());
    let link = ecmxf_e2e::sim_network(&dir, &slave);
    let text = config(&link, &slave);
    let file = dir.join("ecmxfd.toml");
    std::fs::write(&file, &text).unwrap();
    let out = Command::new(daemon_binary()).arg("--check-config").arg(&file).output().expect("run ecmxfd");
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert_eq!(out.status.code(), Some(0), "{said}");
    assert!(said.contains(&format!("slave[0].esi: IO 1 (revision 0x00000003): {SAID}")), "{said}");
    // The simulator says it of the device it makes from the file.
    let sim = Command::new(ecmxf_e2e::sim_binary()).arg("check").arg(dir.join("net.toml")).output().unwrap();
    let listed = String::from_utf8_lossy(&sim.stdout);
    assert!(sim.status.success() && listed.contains("inputs 0 B") && listed.contains(SAID), "{listed}");
    run(async {
        let mut d = Daemon::binary_with_config(&text);
        let ch = d.connect().await;
        let image = pb::process_data_client::ProcessDataClient::new(ch)
            .get_layout(pb::GetLayoutRequest {})
            .await
            .unwrap()
            .into_inner();
        assert_eq!((image.output_bytes, image.input_bytes), (1, 0), "{image:?}");
        let log = d.log();
        assert!(log.contains("WARN") && log.contains(SAID), "{log}");
        d.stop();
    });
    let _ = std::fs::remove_dir_all(&dir);
}
