//! `Sdo` and `Sii` against `ecmxfd --sim`: typed values, aborts with their
//! code, deadlines, the object listing, EEPROM read/write/decode.

use std::time::Duration;

use ecmxf_e2e::{Daemon, full_status, run};
use ecmxf_proto::v1 as pb;
use pb::sdo_client::SdoClient;
use pb::sii_client::SiiClient;
use pb::value::Kind;
use tonic::Code;

fn upload(slave: u32, index: u32, subindex: u32, data_type: pb::DataType) -> pb::SdoUploadRequest {
    pb::SdoUploadRequest { slave, index, subindex, complete_access: false, data_type: data_type as i32 }
}

fn download(slave: u32, index: u32, subindex: u32, data_type: pb::DataType, kind: Kind) -> pb::SdoDownloadRequest {
    pb::SdoDownloadRequest {
        slave,
        index,
        subindex,
        complete_access: false,
        data_type: data_type as i32,
        value: Some(pb::Value { kind: Some(kind) }),
    }
}

#[test]
fn sdo_typed_values_aborts_deadlines_and_listing() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut sdo = SdoClient::new(ch);

        // Known objects are typed without being told.
        let r = sdo.upload(upload(1, 0x1018, 1, pb::DataType::Unspecified)).await.unwrap().into_inner();
        assert_eq!(r.value.unwrap().kind, Some(Kind::Unsigned(0x59D)));
        assert_eq!(r.data_type, pb::DataType::Unsigned32 as i32);
        assert_eq!(r.raw, 0x59Du32.to_le_bytes());
        // A string.
        let r = sdo.upload(upload(1, 0x1008, 0, pb::DataType::Unspecified)).await.unwrap().into_inner();
        assert!(matches!(r.value.unwrap().kind, Some(Kind::Text(ref t)) if !t.is_empty()));

        // Write then read back a signed 16-bit object (quick stop option
        // code; 0x6060 would be overwritten by the process data in OP).
        sdo.download(download(1, 0x605A, 0, pb::DataType::Unspecified, Kind::Integer(6))).await.unwrap();
        let r = sdo.upload(upload(1, 0x605A, 0, pb::DataType::Unspecified)).await.unwrap().into_inner();
        assert_eq!(r.value.unwrap().kind, Some(Kind::Integer(6)));
        // An unknown object with an explicit type, and as raw bytes.
        let w = sdo
            .download(download(1, 0x6083, 0, pb::DataType::Unsigned32, Kind::Unsigned(1234)))
            .await
            .unwrap()
            .into_inner();
        assert_eq!(w.bytes_written, 4);
        let r = sdo.upload(upload(1, 0x6083, 0, pb::DataType::Unsigned32)).await.unwrap().into_inner();
        assert_eq!(r.value.unwrap().kind, Some(Kind::Unsigned(1234)));
        sdo.download(download(1, 0x6083, 0, pb::DataType::Unspecified, Kind::Raw(vec![0x10, 0x27, 0, 0])))
            .await
            .unwrap();
        let r = sdo.upload(upload(1, 0x6083, 0, pb::DataType::Unspecified)).await.unwrap().into_inner();
        assert_eq!(r.raw, vec![0x10, 0x27, 0, 0]);
        // Without a type from the client, CiA 402 types 0x6083 (profile
        // acceleration, UNSIGNED32).
        assert_eq!(r.value.unwrap().kind, Some(Kind::Unsigned(10_000)));
        assert_eq!(r.data_type, pb::DataType::Unsigned32 as i32);

        // A missing object: ABORTED, with the abort code in the details.
        let e = sdo.upload(upload(1, 0x2FFF, 0, pb::DataType::Unspecified)).await.unwrap_err();
        assert_eq!(e.code(), Code::Aborted, "{e:?}");
        assert!(e.message().contains("0x2fff:00"), "{}", e.message());
        assert_eq!(full_status(&e), "SDO_ABORT");
        let info = tonic_types::StatusExt::get_details_error_info(&e).unwrap();
        assert_eq!(info.metadata["abort_code"], "0x06020000");
        assert!(info.metadata["meaning"].contains("does not exist"), "{info:?}");
        // Read-only object.
        let e = sdo.download(download(1, 0x1018, 1, pb::DataType::Unspecified, Kind::Unsigned(1))).await.unwrap_err();
        assert_eq!(e.code(), Code::Aborted, "{e:?}");

        // Bad arguments name the field and reach nothing.
        for (req, field) in [
            (download(1, 0x6060, 0, pb::DataType::Unspecified, Kind::Integer(300)), "value"),
            (download(1, 0x2FFF, 0, pb::DataType::Unspecified, Kind::Integer(1)), "data_type"),
            (download(1, 0x10000, 0, pb::DataType::Unsigned8, Kind::Unsigned(1)), "index"),
            (download(1, 0x6060, 256, pb::DataType::Unsigned8, Kind::Unsigned(1)), "subindex"),
            (download(300, 0x6060, 0, pb::DataType::Unsigned8, Kind::Unsigned(1)), "slave"),
            (
                pb::SdoDownloadRequest {
                    value: None,
                    ..download(1, 0x6060, 0, pb::DataType::Integer8, Kind::Integer(1))
                },
                "value",
            ),
        ] {
            let e = sdo.download(req).await.unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{field}: {e:?}");
            assert!(e.message().contains(field), "{field}: {}", e.message());
            assert_eq!(full_status(&e), "BAD_ARGUMENT");
            let bad = tonic_types::StatusExt::get_details_bad_request(&e).expect("BadRequest");
            assert_eq!(bad.field_violations[0].field, field, "{e:?}");
        }
        let e = sdo.upload(upload(1, 0x6060, 0, pb::DataType::Unsigned64)).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "1 byte is not a u64: {e:?}");

        // The client's deadline bounds the call: DEADLINE_EXCEEDED, and the
        // next call gets its own answer (no stale result).
        let mut req = tonic::Request::new(upload(1, 0x1018, 1, pb::DataType::Unspecified));
        req.set_timeout(Duration::from_millis(1));
        let e = sdo.upload(req).await.unwrap_err();
        assert!(matches!(e.code(), Code::DeadlineExceeded | Code::Cancelled), "{e:?}");
        let r = sdo.upload(upload(1, 0x1018, 2, pb::DataType::Unspecified)).await.unwrap().into_inner();
        assert_eq!(r.value.unwrap().kind, Some(Kind::Unsigned(0x402)));

        // The object listing: identity, PDO assignment, the axes' objects.
        let probe = pb::ListObjectsRequest { slave: 1, source: pb::DictionarySource::Probe as i32 };
        let list = sdo.list_objects(probe).await.unwrap().into_inner();
        assert_eq!(list.source, pb::DictionarySource::Probe as i32);
        let names: Vec<&str> = list.entries.iter().map(|e| e.name.as_str()).collect();
        for want in [
            "identity.vendor_id",
            "statusword",
            "controlword",
            "position_actual",
            "axis1.statusword",
            "rx_pdo_assign.count",
        ] {
            assert!(names.contains(&want), "{want} missing from {names:?}");
        }
        let e = sdo.list_objects(pb::ListObjectsRequest { slave: 7, source: 0 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
    });
}

/// What a client nobody here wrote sees: a malformed request body is the
/// caller's fault (INVALID_ARGUMENT naming the message, not INTERNAL), an
/// unknown method UNIMPLEMENTED, each with full details; and a Go client
/// (`buf curl`, connect-go: it takes the status from the details, as
/// grpc-go and grpcurl do) shows ABORTED with the abort code for a missing
/// object and INVALID_ARGUMENT for slave 99.
#[test]
fn errors_read_the_same_from_any_client() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;

        /// `SdoUploadRequest.slave` (field 1, a uint32) sent as a string.
        #[derive(Clone, PartialEq, prost::Message)]
        struct Malformed {
            #[prost(string, tag = "1")]
            slave: String,
        }
        let raw = |path: &'static str| {
            let mut grpc = tonic::client::Grpc::new(ch.clone());
            async move {
                grpc.ready().await.unwrap();
                let codec = tonic_prost::ProstCodec::<Malformed, pb::SdoUploadResponse>::default();
                let path = tonic::codegen::http::uri::PathAndQuery::from_static(path);
                grpc.unary(tonic::Request::new(Malformed { slave: "one".into() }), path, codec).await.unwrap_err()
            }
        };
        let e = raw("/ecmxf.v1.Sdo/Upload").await;
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains("not a valid ecmxf.v1.SdoUploadRequest"), "{}", e.message());
        assert_eq!(full_status(&e), "INVALID_ARGUMENT");
        let e = raw("/ecmxf.v1.Sdo/NoSuchMethod").await;
        assert_eq!(e.code(), Code::Unimplemented, "{e:?}");
        assert_eq!(full_status(&e), "UNIMPLEMENTED");

        let Some(buf) = ecmxf_e2e::buf_binary() else { return };
        let curl = |body: &str| {
            let out = std::process::Command::new(&buf)
                .args(["curl", "--protocol", "grpc", "--http2-prior-knowledge", "--unix-socket"])
                .arg(&d.socket)
                .args(["-d", body, "http://localhost/ecmxf.v1.Sdo/Upload"])
                .output()
                .expect("run buf curl");
            let text = String::from_utf8_lossy(&out.stdout).into_owned();
            let err = String::from_utf8_lossy(&out.stderr).into_owned();
            assert!(!out.status.success(), "an error: {text}{err}");
            serde_json::from_str::<serde_json::Value>(&err)
                .unwrap_or_else(|e| panic!("buf curl's error is JSON ({e}):\n{text}{err}"))
        };
        let missing = curl(r#"{"slave": 1, "index": 12287, "subindex": 0}"#);
        assert_eq!(missing["code"], "aborted", "{missing}");
        let message = missing["message"].as_str().unwrap();
        assert!(message.contains("0x06020000") && message.contains("0x2fff:00"), "{missing}");
        assert_eq!(missing["details"][0]["type"], "google.rpc.ErrorInfo", "{missing}");
        let bad = curl(r#"{"slave": 99, "index": 4120, "subindex": 1}"#);
        assert_eq!(bad["code"], "invalid_argument", "{bad}");
        assert!(bad["message"].as_str().unwrap().contains("slave 99"), "{bad}");
    });
}

#[test]
fn sii_read_write_with_backup_and_decode() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut sii = SiiClient::new(ch);
        let r = sii.read(pb::SiiReadRequest { slave: 1, word: 8, count: 4 }).await.unwrap().into_inner();
        assert_eq!(r.data.len(), 8);
        assert_eq!(u32::from_le_bytes(r.data[0..4].try_into().unwrap()), 0x59D, "vendor id at word 8");

        // Write two words (serial number, word 0x0E) and get the old ones back.
        let w = sii
            .write(pb::SiiWriteRequest { slave: 1, word: 0x0E, data: vec![0x78, 0x56, 0x34, 0x12] })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(w.words_written, 2);
        assert_eq!(w.backup.len(), 4);
        let r = sii.read(pb::SiiReadRequest { slave: 1, word: 0x0E, count: 2 }).await.unwrap().into_inner();
        assert_eq!(r.data, vec![0x78, 0x56, 0x34, 0x12]);
        let dec = sii.decode(pb::SiiDecodeRequest { slave: 1 }).await.unwrap().into_inner();
        assert_eq!((dec.vendor_id, dec.product_code, dec.serial), (0x59D, 0x402, 0x1234_5678));
        assert!(dec.mailbox_protocols & 4 != 0, "CoE");
        assert!(!dec.name.is_empty() && !dec.sync_managers.is_empty(), "{dec:?}");
        // Restore.
        sii.write(pb::SiiWriteRequest { slave: 1, word: 0x0E, data: w.backup.clone() }).await.unwrap();

        // A category whose length runs past the EEPROM's size: an error
        // naming the offset, not a decode with empty fields.
        let w =
            sii.write(pb::SiiWriteRequest { slave: 1, word: 0x41, data: vec![0xFF, 0x7F] }).await.unwrap().into_inner();
        let e = sii.decode(pb::SiiDecodeRequest { slave: 1 }).await.unwrap_err();
        assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
        assert!(e.message().contains("corrupt") && e.message().contains("offset 0x0080"), "{e:?}");
        sii.write(pb::SiiWriteRequest { slave: 1, word: 0x41, data: w.backup }).await.unwrap();
        sii.decode(pb::SiiDecodeRequest { slave: 1 }).await.expect("restored");

        for (req, field) in [
            (pb::SiiWriteRequest { slave: 1, word: 0, data: vec![1] }, "data"),
            (pb::SiiWriteRequest { slave: 1, word: 0x1_0000, data: vec![1, 2] }, "word"),
        ] {
            let e = sii.write(req).await.unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument);
            assert!(e.message().contains(field), "{}", e.message());
        }
        let e = sii.read(pb::SiiReadRequest { slave: 1, word: 0, count: 0 }).await.unwrap_err();
        assert!(e.message().contains("count"), "{e:?}");
        let e = sii.read(pb::SiiReadRequest { slave: 1, word: 0xFFFF, count: 4 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");

        // A long read (2048 transactions) with a 100 ms deadline: the whole
        // call is bounded, the engine drops the rest, and the next call
        // is served at once.
        let mut req = tonic::Request::new(pb::SiiReadRequest { slave: 1, word: 0, count: 4096 });
        req.set_timeout(Duration::from_millis(100));
        let t = std::time::Instant::now();
        let e = sii.read(req).await.unwrap_err();
        // Ours answers 10 ms early; only a host stall longer than that lets
        // tonic's own deadline layer answer first (CANCELLED "Timeout expired").
        let tonic_layer = e.code() == Code::Cancelled && e.message().contains("Timeout expired");
        assert!(e.code() == Code::DeadlineExceeded || tonic_layer, "{e:?}");
        assert!(t.elapsed() < Duration::from_millis(600), "{:?}", t.elapsed());
        let r = sii.read(pb::SiiReadRequest { slave: 1, word: 8, count: 2 }).await.unwrap().into_inner();
        assert_eq!(u32::from_le_bytes(r.data[0..4].try_into().unwrap()), 0x59D);
    });
}

/// With `[[slave]] esi = ...` the object listing comes from the slave's ESI
/// (here the real SOES sample from ../shared/fixtures, simulated from the
/// same file). Skipped without the fixtures unless ECMXF_REQUIRE_FIXTURES.
#[test]
fn object_listing_from_an_esi_file() {
    let Some(esi) = ecmxf_e2e::fixture("esi_soes_lan9252_evb9252_dig.xml") else { return };
    run(async {
        let dir = ecmxf_e2e::temp_dir("esi");
        let network = dir.join("net.toml");
        std::fs::write(&network, format!("version = 1\n[[slave]]\nesi = \"{}\"\nproduct_code = 1234\n", esi.display()))
            .unwrap();
        let link = format!("backend = \"sim\"\nnetwork = \"{}\"", network.display());
        let extra = format!("[[slave]]\nesi = \"{}\"\n", esi.display());
        let mut d = Daemon::with_config(&ecmxf_e2e::config(&link, &extra));
        let ch = d.connect().await;
        let mut sdo = SdoClient::new(ch);
        let esi = pb::ListObjectsRequest { slave: 0, source: pb::DictionarySource::Esi as i32 };
        let list = sdo.list_objects(esi).await.unwrap().into_inner();
        assert_eq!(list.source, pb::DictionarySource::Esi as i32);
        let identity = list.entries.iter().find(|e| e.index == 0x1018 && e.subindex == 1).expect("0x1018:01 listed");
        assert_eq!(identity.data_type, pb::DataType::Unsigned32 as i32);
        assert_eq!(identity.access, "ro");
        let param = list.entries.iter().find(|e| e.index == 0x8000 && e.subindex == 1).expect("0x8000:01 listed");
        assert_eq!((param.name.as_str(), param.access.as_str()), ("Parameters.Multiplier", "rw"));
        let name = list.entries.iter().find(|e| e.index == 0x1009).expect("0x1009 listed");
        assert_eq!(name.bit_length, 8 * name.value.len() as u32, "a string's size is its value's");
        // What the ESI lists, the slave answers.
        let r = sdo
            .upload(pb::SdoUploadRequest { slave: 0, index: 0x1018, subindex: 2, complete_access: false, data_type: 0 })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.value.unwrap().kind, Some(Kind::Unsigned(1234)));
        drop(d);
        let _ = std::fs::remove_dir_all(&dir);
    });
}
