//! A device takes what its own ESI's init commands write: the vendor ships
//! those commands, so the real device accepts them even where its file's
//! dictionary lacks the object (Sieb & Meyer's SD2 writes 0x6060 at PS and
//! lists no 0x6060). The simulated device does too, and says so at
//! `ecmxf-sim check`; the network reaches OP with the value written.

use std::process::Command;

use ecmxf_e2e::{Daemon, config, run, temp_dir};

/// What `ecmxf-sim check` says of the network file in `dir`.
fn sim_check(dir: &std::path::Path) -> String {
    let check = Command::new(ecmxf_e2e::sim_binary()).arg("check").arg(dir.join("net.toml")).output().unwrap();
    assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    String::from_utf8_lossy(&check.stdout).into_owned()
}

/// The network `link` with `slave` is in OP, and the drive's mode of
/// operation is `mode` (as its init command wrote it).
fn in_op_with_mode(link: &str, slave: &str, mode: &str) {
    run(async {
        let mut d = Daemon::with_config(&config(link, slave));
        d.connect().await;
        let master = d.ctl(&["--json", "master"]).json();
        assert_eq!(master["state"], "OP", "{master}");
        let read = d.ctl(&["upload", "-p", "0", "0x6060", "0"]);
        assert_eq!(read.stdout.trim(), mode, "the init command's value: {}", read.stderr);
        d.stop();
    });
}

#[test]
fn a_drive_whose_init_commands_write_an_object_its_file_lacks_reaches_op() {
    let Some(esi) = ecmxf_e2e::fixture("esi_siebmeyer_SD2_SD3_FC2.xml") else { return };
    let dir = temp_dir("device-init-cmds");
    let slave = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x00362200\nrevision = 0x00010001\n", esi.display());
    let link = ecmxf_e2e::sim_network(&dir, &slave);
    let said = sim_check(&dir);
    assert!(said.contains("0x6060:00, written by its own init commands, not in its dictionary: added"), "{said}");
    assert!(said.contains("0x6061:00, required by its device profile, not in its dictionary: added"), "{said}");
    in_op_with_mode(&link, &slave, "2");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `text` with every `<Object>` whose index is `index` taken out.
fn without_object(text: &str, index: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    let key = format!("<Index>{index}</Index>");
    while let Some(at) = rest.find("<Object>") {
        let end = rest[at..].find("</Object>").map_or(rest.len(), |e| at + e + "</Object>".len());
        out.push_str(&rest[..at]);
        if !rest[at..end].contains(&key) {
            out.push_str(&rest[at..end]);
        }
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// A drive file of the kind that stopped bring-up for good: its dictionary
/// declares 0x6060 read-only and has no 0x60C2, yet its own PS init
/// commands write both (built here from the Elmo ESI, whose init commands
/// write them). The device takes both, the network reaches OP, and the
/// mode the init command wrote is the drive's.
#[test]
fn a_drive_whose_init_commands_write_a_read_only_object_reaches_op() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    let dir = temp_dir("device-init-cmds-ro");
    let text = ecmxf_devices::esi::read_xml(&elmo).unwrap();
    let mut strict = String::new();
    let mut rest = text.as_str();
    let mode = "<Index>#x6060</Index>";
    while let Some(at) = rest.find(mode) {
        let (head, tail) = rest.split_at(at);
        strict.push_str(head);
        let object_end = tail.find("</Object>").unwrap_or(tail.len());
        strict.push_str(&tail[..object_end].replacen("<Access>rw</Access>", "<Access>ro</Access>", 1));
        rest = &tail[object_end..];
    }
    strict.push_str(rest);
    let strict = without_object(&strict, "#x60C2");
    assert!(!strict.contains("<Index>#x60C2</Index>\n\t      <Name>"), "0x60C2 is out of the dictionary");
    let esi = dir.join("strict-drive.xml");
    std::fs::write(&esi, &strict).unwrap();
    let slave = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", esi.display());
    let link = ecmxf_e2e::sim_network(&dir, &slave);
    let said = sim_check(&dir);
    assert!(
        said.contains("0x6060:00, written by its own init commands, read-only in its dictionary: made writable"),
        "{said}"
    );
    assert!(said.contains("0x60c2:01, written by its own init commands, not in its dictionary: added"), "{said}");
    in_op_with_mode(&link, &slave, "8");
    let _ = std::fs::remove_dir_all(&dir);
}
