//! A `[[slave]] esi` file listing several devices (an Elmo Gold file: boot
//! and drive firmware of two products; Beckhoff's terminal families) given
//! without the identity keys that narrow it to one: the device is the one
//! whose vendor, product code and revision the slave reports at bring-up,
//! and its CoE init commands are written (the drive's mode of operation,
//! 0x6060 = 8, is one), where they were once silently left out. A slave
//! none of the file's devices describes fails bring-up, naming the slave,
//! its identity and the file's candidates.

use ecmxf_e2e::{Daemon, config, run, temp_dir};
use ecmxf_proto::v1 as pb;

const ELMO: &str = "esi_elmo_gold_Elmo_ECAT_00010420_V11.xml";

/// Reads an object of slave 0 over the gRPC SDO service.
async fn read(ch: tonic::transport::Channel, index: u32, subindex: u32) -> Result<Vec<u8>, tonic::Status> {
    let mut sdo = pb::sdo_client::SdoClient::new(ch);
    let r = sdo.upload(pb::SdoUploadRequest { slave: 0, index, subindex, ..Default::default() }).await?;
    Ok(r.into_inner().raw)
}

/// The Elmo drive (product 0x30924, revision 0x10420) under an entry that
/// names only the file: the drive device's init commands are written (mode
/// of operation 8, cycle time 2), and the file's device with the scanned
/// identity names the objects.
#[test]
fn the_scanned_identity_chooses_the_device_whose_init_commands_are_written() {
    let Some(elmo) = ecmxf_e2e::fixture(ELMO) else { return };
    run(async {
        let dir = temp_dir("esi-identity");
        let link = ecmxf_e2e::sim_network(
            &dir,
            &format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display()),
        );
        let mut d = Daemon::with_config(&config(&link, &format!("[[slave]]\nesi = \"{}\"\n", elmo.display())));
        let ch = d.connect().await;
        assert_eq!(read(ch.clone(), 0x6060, 0).await.unwrap(), vec![8], "Op mode, the drive device's init command");
        assert_eq!(read(ch, 0x60C2, 1).await.unwrap(), vec![2], "Cycle time, the drive device's init command");
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// With a product code and no revision, the revision the slave reports
/// chooses among that product's devices: the Elmo in its boot firmware
/// (revision 1) is described by the file's boot device, which has no init
/// commands and no 0x6060, not by the highest revision (the drive
/// firmware), whose mode-of-operation write such a slave would refuse.
#[test]
fn the_scanned_revision_chooses_among_the_products_revisions() {
    let Some(elmo) = ecmxf_e2e::fixture(ELMO) else { return };
    run(async {
        let dir = temp_dir("esi-revision");
        let link = ecmxf_e2e::sim_network(
            &dir,
            &format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 1\n", elmo.display()),
        );
        let slave = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\n", elmo.display());
        let mut d = Daemon::with_config(&config(&link, &slave));
        let ch = d.connect().await;
        assert_ne!(read(ch, 0x6060, 0).await.ok(), Some(vec![8]), "the drive firmware's init command is not written");
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// The Elmo drive under an entry naming Sieb-Meyer's file (three devices of
/// another vendor, each with init commands): bring-up fails, and the
/// status's last error and the log say which slave, what it reports and
/// what the file offers.
#[test]
fn a_slave_no_device_of_the_file_describes_fails_bring_up_naming_both() {
    let Some(elmo) = ecmxf_e2e::fixture(ELMO) else { return };
    let Some(sieb) = ecmxf_e2e::fixture("esi_siebmeyer_SD2_SD3_FC2.xml") else { return };
    run(async {
        let dir = temp_dir("esi-none");
        let link = ecmxf_e2e::sim_network(
            &dir,
            &format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display()),
        );
        let slave = format!("[[slave]]\nname = \"Axis\"\nesi = \"{}\"\n", sieb.display());
        let mut d = Daemon::binary_with_config(&config(&link, &slave));
        // The engine never runs: the error it keeps failing with.
        let status = d.status_with_an_error().await;
        let log = d.log();
        for text in [&status.last_error, &log] {
            for part in [
                "slave 0 (\"Axis\")",
                "vendor 0x0000009a product 0x00030924 revision 0x00010420",
                "esi_siebmeyer_SD2_SD3_FC2.xml",
                "SD2 Drive 03622xx\" product 0x00362200 revision 0x00010001",
                "product 0x00363100 revision 0x00010001",
                "product 0x00219200 revision 0x00010001",
            ] {
                assert!(text.contains(part), "{part:?} not in: {text}");
            }
        }
        assert_ne!(status.ecat_state, pb::EcatState::Op as i32);
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}
