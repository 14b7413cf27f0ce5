//! The ENI files of ../shared/fixtures (origins in its MANIFEST): every
//! `eni_*.xml` there parses, every slave has an identity, every CoE init
//! command an index and a transition; and what the two known files hold is
//! read as they mean it (TwinCAT: decimal numbers, Ccs 1 = download; SOEM:
//! C hex, Ccs 2 used for writes, complete access).
//!
//! When the fixtures folder is absent the tests say so and pass, unless
//! ECMXF_REQUIRE_FIXTURES is set (CI sets it), where they fail.

use ecmxf_devices::eni::{BitRange, CcsConvention, CoeAccess, Eni, Transition};

mod common;
use common::fixtures;

fn load(name: &str) -> Option<Eni> {
    let path = fixtures()?.join(name);
    Some(Eni::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
}

#[test]
fn every_eni_fixture_parses() {
    let Some(dir) = fixtures() else { return };
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !(name.starts_with("eni_") && name.ends_with(".xml")) {
            continue;
        }
        let eni = Eni::load(&entry.path()).unwrap_or_else(|e| panic!("{name}: {e}"));
        for s in &eni.slaves {
            assert!(s.vendor_id != 0 || s.product_code != 0, "{name}: slave {:?} has no identity", s.name);
            for c in &s.coe_init_cmds {
                assert!(!c.transitions.is_empty(), "{name}: {:?} {}", s.name, c.at);
            }
        }
        seen += 1;
    }
    assert!(seen >= 2, "the two ENI fixtures of the MANIFEST");
}

#[test]
fn the_twincat_export_reads_as_twincat_means_it() {
    let Some(eni) = load("eni_twincat_elmo4_imu.xml") else { return };
    let names: Vec<&str> = eni.slaves.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names[0], "Imu");
    assert_eq!(eni.slaves.len(), 5, "{names:?}");
    assert_eq!((eni.slaves[0].vendor_id, eni.slaves[0].product_code, eni.slaves[0].revision), (33, 1, Some(65537)));
    for elmo in &eni.slaves[1..] {
        assert_eq!((elmo.vendor_id, elmo.product_code, elmo.revision), (0x9A, 0x30924, Some(0x10420)), "{}", elmo.name);
        let cmds = &elmo.coe_init_cmds;
        assert_eq!(cmds.len(), 12, "{}", elmo.name);
        assert!(cmds.iter().all(|c| c.ccs == CcsConvention::Etg && c.transitions == [Transition::PreOpSafeOp]));
        // In the file's order: clear 0x1C12, clear 0x1C13, ... assign 0x1601.
        assert_eq!((cmds[0].index, cmds[0].subindex, &cmds[0].access), (0x1C12, 0, &CoeAccess::Download(vec![0])));
        let assign = cmds.iter().find(|c| c.comment == "download pdo 0x1C12:01 index").expect("the 0x1C12:01 command");
        assert_eq!(
            (assign.index, assign.subindex, &assign.access),
            (0x1C12, 1, &CoeAccess::Download(vec![0x01, 0x16]))
        );
        let mode = cmds.iter().find(|c| c.index == 0x6060).expect("modes of operation");
        assert_eq!(mode.access, CoeAccess::Download(vec![8]));
        assert!(cmds.windows(2).all(|w| w[0].at < w[1].at), "file order");
        let registers = elmo.elements.iter().find(|(e, _)| e.starts_with("InitCmds")).map(|(_, n)| *n);
        assert_eq!(registers, Some(49), "{:?}", elmo.elements);
        assert_eq!(elmo.register_init_cmds.len(), 49);
        let watchdog = elmo.register_init_cmds.iter().find(|c| c.ado == 0x0420).expect("the SM watchdog");
        assert_eq!((watchdog.cmd, watchdog.data.as_slice(), watchdog.writes()), (5, &[0x10, 0x27][..], true));
        assert_eq!(watchdog.transitions, [Transition::InitPreOp]);
        let check = elmo.register_init_cmds.iter().find(|c| c.comment == "check vendor id" && c.ado == 0x0508);
        let check = check.expect("the vendor id check reads the SII data register");
        assert!(!check.writes() && check.validates, "{check:?}");
    }
    assert!(eni.elements.iter().any(|(e, _)| *e == "ProcessImage"), "{:?}", eni.elements);
    assert!(eni.elements.iter().any(|(e, _)| *e == "Cyclic"), "{:?}", eni.elements);
}

#[test]
fn the_twincat_export_gives_process_data_dc_and_its_image() {
    let Some(eni) = load("eni_twincat_elmo4_imu.xml") else { return };
    assert_eq!(eni.cycle_us, Some(10_000));
    // The IMU, known only from the ENI: one fixed TxPDO of seven 16-bit
    // values on SM3 at 0x2800, a CoE mailbox.
    let imu = eni.slaves[0].device();
    assert_eq!((imu.product_code, imu.revision), (1, 65537));
    assert_eq!(imu.tx_pdos.len(), 1);
    assert_eq!((imu.tx_pdos[0].index, imu.tx_pdos[0].sm, imu.tx_pdos[0].entries.len()), (0x1A00, Some(3), 7));
    assert_eq!(
        imu.sms.iter().map(|s| (s.kind, s.start)).collect::<Vec<_>>(),
        [(1, 16384), (2, 18432), (3, 4096), (4, 10240)]
    );
    assert_ne!(imu.protocols & ecmxf_devices::sii::protocol::COE, 0);
    let elmo = &eni.slaves[1];
    let pd = elmo.process_data.as_ref().unwrap();
    assert_eq!(pd.outputs, Some(BitRange { start: 776, len: 48 }));
    assert_eq!(pd.inputs, Some(BitRange { start: 776, len: 112 }));
    let assigned: Vec<u16> = pd.rx_pdos.iter().chain(&pd.tx_pdos).filter(|p| p.sm.is_some()).map(|p| p.index).collect();
    assert_eq!(assigned, [0x1601, 0x1A03]);
    let dc = elmo.dc.unwrap();
    assert!(dc.reference_clock && dc.cycle_time0_ns == 10_000_000, "{dc:?}");
    assert!(!eni.slaves[2].dc.unwrap().reference_clock);
    // Each variable of a slave, from the start of that slave's data; the
    // tool's own variables (frame and device states) belong to none.
    let rel: Vec<(usize, &str, bool, u32, u32)> = eni
        .relative_variables()
        .iter()
        .map(|v| (v.slave, v.variable.name.as_str(), v.variable.output, v.relative_bit, v.variable.bit_size))
        .collect();
    assert_eq!(rel.len(), 7 + 4 * 4 + 4 * 2, "{rel:#?}");
    assert!(rel.contains(&(0, "Imu.Transmit PDO Mapping.Error code", false, 96, 16)));
    assert!(rel.contains(&(1, "WheelRearLeft.Inputs.Status word", false, 96, 16)));
    assert!(rel.contains(&(4, "WheelFrontRight.Outputs.Control word", true, 32, 16)));
}

#[test]
fn soems_sample_reads_its_ccs_2_as_writes() {
    let Some(eni) = load("eni_soem_sample.xml") else { return };
    assert_eq!(eni.slaves.len(), 2);
    let (a, b) = (&eni.slaves[0], &eni.slaves[1]);
    assert_eq!((a.vendor_id, a.product_code), (1, 0x1234));
    assert_eq!((b.vendor_id, b.product_code), (1, 0x0100_55AA));
    let writes: Vec<(u16, u8, Vec<u8>)> = a
        .coe_init_cmds
        .iter()
        .map(|c| match &c.access {
            CoeAccess::Download(d) => (c.index, c.subindex, d.clone()),
            CoeAccess::Upload => panic!("Ccs 2 with data is a write here"),
        })
        .collect();
    assert_eq!(
        writes,
        vec![(0x1C13, 0, vec![0]), (0x1C13, 1, vec![0x02, 0x1A]), (0x1C13, 2, vec![0x05, 0x1A]), (0x1C13, 0, vec![2])]
    );
    assert!(a.coe_init_cmds.iter().all(|c| c.ccs == CcsConvention::Soem));
    let ca = &b.coe_init_cmds[0];
    assert!(ca.complete_access);
    assert_eq!(ca.access, CoeAccess::Download(vec![3, 0, 0x01, 0x16, 0x07, 0x16, 0x1C, 0x16]));
}
