//! A value is written only as its object's type: against the daemon on a
//! simulator of its own process, mistyped SDO downloads (a boolean, a
//! real, text, integers the object cannot hold, another data_type, raw
//! bytes of another size, complete access from a subindex past 1) are
//! INVALID_ARGUMENT naming the object, its type and the value, and none
//! reaches the slave: its mailbox counts no request (the simulator's own
//! counter, `ecmxf-sim ctl mailbox`) and every object reads back as it
//! was. A malformed `grpc-timeout` is refused naming it.

use ecmxf_e2e::{Daemon, Simulator, config, full_status, run, temp_dir};
use ecmxf_proto::v1 as pb;
use pb::DataType as T;
use pb::sdo_client::SdoClient;
use pb::value::Kind;
use tonic::Code;
use tonic::transport::Channel;

/// The TI-like drive of the demo network.
const SLAVE: u32 = 1;

fn download(index: u32, data_type: T, kind: Kind) -> pb::SdoDownloadRequest {
    pb::SdoDownloadRequest {
        slave: SLAVE,
        index,
        subindex: 0,
        complete_access: false,
        data_type: data_type as i32,
        value: Some(pb::Value { kind: Some(kind) }),
    }
}

/// The CoE requests that reached the simulated slave: through its
/// receive mailbox, and run by the chip itself (SDO_REQ, how the daemon's
/// SDOs go).
fn requests(sim: &Simulator) -> u64 {
    let answer = sim.ctl(&format!("mailbox {SLAVE}"));
    let count = |key: &str| -> u64 {
        let n = answer.split_whitespace().find_map(|w| w.strip_prefix(key));
        n.and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("no {key} in {answer:?}"))
    };
    count("requests=") + count("chip_sdos=")
}

async fn read(sdo: &mut SdoClient<Channel>, index: u32) -> Vec<u8> {
    let r = pb::SdoUploadRequest { slave: SLAVE, index, subindex: 0, complete_access: false, data_type: 0 };
    sdo.upload(r).await.unwrap_or_else(|e| panic!("{index:#06x}: {e:?}")).into_inner().raw
}

#[test]
fn mistyped_writes_are_refused_and_none_reaches_the_slave() {
    run(async {
        let dir = temp_dir("typed");
        let sim = Simulator::serve(&dir, &[]);
        let mut d = Daemon::binary_with_config(&config(&sim.link(), ""));
        let mut sdo = SdoClient::new(d.connect().await);
        // The devices name the image's entries over their mailboxes after
        // the first image: done before requests are counted.
        let named = "process image entries named by their devices";
        assert!(d.logged(named, std::time::Duration::from_secs(10)).await, "{}", d.log());

        // Objects of known type (CiA 402) that no PDO maps, so only an SDO
        // changes them: INTEGER16, UNSIGNED16, UNSIGNED32 x2.
        let objects = [0x605A, 0x6072, 0x6083, 0x6085];
        let mut before = Vec::new();
        for index in objects {
            before.push(read(&mut sdo, index).await);
        }

        let mistyped = [
            (download(0x6083, T::Unspecified, Kind::Boolean(true)), "UNSIGNED32", "true"),
            (download(0x6072, T::Unspecified, Kind::Boolean(false)), "UNSIGNED16", "false"),
            (download(0x605A, T::Unspecified, Kind::Boolean(true)), "INTEGER16", "true"),
            (download(0x6083, T::Unspecified, Kind::Real(1.5)), "UNSIGNED32", "1.5"),
            (download(0x605A, T::Unspecified, Kind::Real(2.0)), "INTEGER16", "2"),
            (download(0x6072, T::Unspecified, Kind::Text("100".into())), "UNSIGNED16", "\"100\""),
            (download(0x6083, T::Unspecified, Kind::Text("abc".into())), "UNSIGNED32", "\"abc\""),
            (download(0x6072, T::Unspecified, Kind::Unsigned(70_000)), "UNSIGNED16", "70000"),
            (download(0x6072, T::Unspecified, Kind::Integer(70_000)), "UNSIGNED16", "70000"),
            (download(0x605A, T::Unspecified, Kind::Integer(40_000)), "INTEGER16", "40000"),
            (download(0x605A, T::Unspecified, Kind::Unsigned(32_768)), "INTEGER16", "32768"),
            (download(0x6083, T::Unspecified, Kind::Integer(-1)), "UNSIGNED32", "-1"),
            (download(0x6072, T::Unspecified, Kind::Integer(-1)), "UNSIGNED16", "-1"),
            (download(0x6085, T::Unspecified, Kind::Unsigned(1 << 32)), "UNSIGNED32", "4294967296"),
            (download(0x6072, T::Unsigned64, Kind::Unsigned(5)), "UNSIGNED16", "UNSIGNED64"),
            (download(0x6083, T::Unsigned16, Kind::Unsigned(5)), "UNSIGNED32", "UNSIGNED16"),
            (download(0x605A, T::Unsigned16, Kind::Unsigned(5)), "INTEGER16", "UNSIGNED16"),
            (download(0x6083, T::Real32, Kind::Real(1.0)), "UNSIGNED32", "REAL32"),
            (download(0x6083, T::Unspecified, Kind::Raw(vec![1, 2])), "UNSIGNED32", "2 bytes"),
            (download(0x6072, T::Unspecified, Kind::Raw(vec![1, 2, 3, 4])), "UNSIGNED16", "4 bytes"),
            (download(0x6085, T::Unspecified, Kind::Raw(vec![0; 8])), "UNSIGNED32", "8 bytes"),
        ];
        assert!(mistyped.len() >= 20);
        let sent = requests(&sim);
        for (req, t, given) in mistyped {
            let object = format!("{:#06x}:00 of slave {SLAVE}", req.index);
            let e = sdo.download(req.clone()).await.expect_err(&format!("{req:?} was written"));
            assert_eq!(e.code(), Code::InvalidArgument, "{req:?}: {e:?}");
            assert_eq!(full_status(&e), "BAD_ARGUMENT", "{e:?}");
            for part in [object.as_str(), t, given] {
                assert!(e.message().contains(part), "{req:?}: {part:?} missing from {:?}", e.message());
            }
        }
        // Complete access starts at subindex 0 or 1: from any other,
        // neither direction sends anything.
        for sub in 2..=255 {
            let up = pb::SdoUploadRequest {
                slave: SLAVE,
                index: 0x1018,
                subindex: sub,
                complete_access: true,
                data_type: 0,
            };
            let down = pb::SdoDownloadRequest {
                subindex: sub,
                complete_access: true,
                ..download(0x1018, T::Unspecified, Kind::Raw(vec![0; 4]))
            };
            for e in [sdo.upload(up).await.unwrap_err(), sdo.download(down).await.unwrap_err()] {
                assert_eq!(e.code(), Code::InvalidArgument, "subindex {sub}: {e:?}");
                assert!(e.message().contains("subindex"), "{}", e.message());
            }
        }
        assert_eq!(requests(&sim), sent, "a refused write reached the slave's mailbox");
        for (index, was) in objects.iter().zip(&before) {
            assert_eq!(&read(&mut sdo, *index).await, was, "{index:#06x} changed");
        }

        // Written as its type, a value goes: an unsigned and a
        // non-negative integer to UNSIGNED16, a type named as the
        // object's own, a signed one to INTEGER16, raw bytes of the size.
        let sent = requests(&sim);
        let good = [
            (download(0x6072, T::Unspecified, Kind::Unsigned(1234)), 0x6072, 1234u32.to_le_bytes()[..2].to_vec()),
            (download(0x6072, T::Unspecified, Kind::Integer(900)), 0x6072, 900u32.to_le_bytes()[..2].to_vec()),
            (download(0x6083, T::Unsigned32, Kind::Unsigned(80_969_800)), 0x6083, 80_969_800u32.to_le_bytes().to_vec()),
            (download(0x605A, T::Unspecified, Kind::Integer(-1)), 0x605A, vec![0xFF, 0xFF]),
            (download(0x6085, T::Unspecified, Kind::Raw(vec![1, 2, 3, 4])), 0x6085, vec![1, 2, 3, 4]),
        ];
        for (req, index, want) in good {
            let w = sdo.download(req.clone()).await.unwrap_or_else(|e| panic!("{req:?}: {e:?}")).into_inner();
            assert_eq!(w.bytes_written as usize, want.len(), "{req:?}");
            assert_eq!(read(&mut sdo, index).await, want, "{req:?}");
        }
        assert_eq!(requests(&sim), sent + 10, "each write and read back reached the slave once");

        // Process data by entry name: the same encoder, the same refusal.
        let mut pd = pb::process_data_client::ProcessDataClient::new(d.connect().await);
        let lease = pb::AcquireLeaseRequest { slaves: vec![SLAVE], ttl_ms: 0 };
        let lease = pd.acquire_lease(lease).await.unwrap().into_inner();
        for (kind, t, given) in [
            (Kind::Boolean(true), "INTEGER32", "boolean true"),
            (Kind::Real(1.5), "INTEGER32", "1.5"),
            (Kind::Integer(1 << 40), "INTEGER32", "1099511627776"),
        ] {
            let writes = vec![ecmxf_e2e::by_entry("1.target_position", kind)];
            let req = pb::WriteOutputsRequest { lease_id: lease.id.clone(), writes };
            let e = pd.write_outputs(req).await.unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
            for part in ["1.target_position", t, given] {
                assert!(e.message().contains(part), "{part:?} missing from {:?}", e.message());
            }
        }
        d.stop();
    });
}

#[test]
fn a_malformed_grpc_timeout_is_refused_naming_it() {
    run(async {
        let mut d = Daemon::sim();
        let mut sdo = SdoClient::new(d.connect().await);
        let upload =
            pb::SdoUploadRequest { slave: SLAVE, index: 0x1018, subindex: 1, complete_access: false, data_type: 0 };
        for timeout in ["-5S", "abcS", "5", "123456789m", "1.5S", "5s"] {
            let mut r = tonic::Request::new(upload);
            r.metadata_mut().insert("grpc-timeout", timeout.parse().unwrap());
            let e = sdo.upload(r).await.expect_err(timeout);
            assert_eq!(e.code(), Code::InvalidArgument, "{timeout}: {e:?}");
            assert!(e.message().contains("grpc-timeout"), "{timeout}: {}", e.message());
            let bad = tonic_types::StatusExt::get_details_bad_request(&e).expect("BadRequest");
            assert_eq!(bad.field_violations[0].field, "grpc-timeout", "{e:?}");
        }
        // A well-formed one bounds the call as before.
        let mut r = tonic::Request::new(upload);
        r.metadata_mut().insert("grpc-timeout", "5S".parse().unwrap());
        sdo.upload(r).await.unwrap();
    });
}

/// An object only the slave's ESI describes (0x8000:01, UDINT, of the
/// SOES sample): typed from there.
#[test]
fn an_object_only_the_esi_describes_is_typed_from_it() {
    let Some(esi) = ecmxf_e2e::fixture("esi_soes_lan9252_evb9252_dig.xml") else { return };
    run(async {
        let dir = temp_dir("typed-esi");
        let network =
            ecmxf_e2e::sim_network(&dir, &format!("[[slave]]\nesi = \"{}\"\nproduct_code = 1234\n", esi.display()));
        let mut d = Daemon::with_config(&config(&network, &format!("[[slave]]\nesi = \"{}\"\n", esi.display())));
        let mut sdo = SdoClient::new(d.connect().await);
        let at = |data_type: T, kind: Kind| pb::SdoDownloadRequest {
            slave: 0,
            subindex: 1,
            ..download(0x8000, data_type, kind)
        };
        let read = pb::SdoUploadRequest { slave: 0, index: 0x8000, subindex: 1, complete_access: false, data_type: 0 };
        let was = sdo.upload(read).await.unwrap().into_inner().raw;
        for req in [
            at(T::Unspecified, Kind::Boolean(true)),
            at(T::Unspecified, Kind::Integer(-1)),
            at(T::Unsigned16, Kind::Unsigned(7)),
            at(T::Unspecified, Kind::Raw(vec![7, 0])),
        ] {
            let e = sdo.download(req.clone()).await.expect_err(&format!("{req:?} was written"));
            assert_eq!(e.code(), Code::InvalidArgument, "{req:?}: {e:?}");
            for part in ["0x8000:01 of slave 0", "UNSIGNED32"] {
                assert!(e.message().contains(part), "{req:?}: {part:?} missing from {:?}", e.message());
            }
        }
        assert_eq!(sdo.upload(read).await.unwrap().into_inner().raw, was, "a refused write changed 0x8000:01");
        let w = sdo.download(at(T::Unspecified, Kind::Unsigned(7))).await.unwrap().into_inner();
        assert_eq!(w.bytes_written, 4);
        assert_eq!(sdo.upload(read).await.unwrap().into_inner().raw, vec![7, 0, 0, 0]);
        drop(d);
        let _ = std::fs::remove_dir_all(&dir);
    });
}
