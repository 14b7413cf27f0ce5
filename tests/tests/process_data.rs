//! `ProcessData` against `ecmxfd --sim`: mapping, the named layout, streamed
//! inputs (whole, selected, decimated, on change), leases and output writes
//! (unary and client-streamed), the digital-IO slave's loopback proving the
//! outputs reach the bus.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, by_entry, run};
use ecmxf_proto::v1 as pb;
use ecmxf_sim::chip::fifo::PlayedFrame;
use ecmxfd::realtime::monotonic_ns;
use pb::master_client::MasterClient;
use pb::process_data_client::ProcessDataClient;
use pb::value::Kind;
use tokio_stream::StreamExt;
use tonic::Code;

fn raw(b: Vec<u8>) -> Option<pb::Value> {
    Some(pb::Value { kind: Some(Kind::Raw(b)) })
}

#[test]
fn layout_streams_leases_and_outputs() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());

        let mapping = pd.get_mapping(pb::GetMappingRequest { slave: None }).await.unwrap().into_inner();
        assert_eq!(mapping.slaves.len(), 3);
        assert!(!mapping.slaves[1].rx_pdos.is_empty() && !mapping.slaves[1].tx_pdos.is_empty());
        let one = pd.get_mapping(pb::GetMappingRequest { slave: Some(1) }).await.unwrap().into_inner();
        assert_eq!(one.slaves[0], mapping.slaves[1]);
        let e = pd.get_mapping(pb::GetMappingRequest { slave: Some(5) }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);

        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let names: Vec<&str> = image.entries.iter().map(|e| e.name.as_str()).collect();
        for want in ["1.statusword", "1.controlword", "1.position_actual"] {
            assert!(names.contains(&want), "{want} missing from {names:?}");
        }
        // Entries tile each slave's part of the image exactly.
        let out_bits: u32 =
            image.entries.iter().filter(|e| e.direction == pb::Direction::Output as i32).map(|e| e.bit_length).sum();
        assert!(out_bits <= image.output_bytes * 8, "{out_bits} bits in {} bytes", image.output_bytes);
        let io_out: Vec<&pb::ImageEntry> =
            image.entries.iter().filter(|e| e.slave == 2 && e.direction == pb::Direction::Output as i32).collect();
        let io_in: Vec<&pb::ImageEntry> =
            image.entries.iter().filter(|e| e.slave == 2 && e.direction == pb::Direction::Input as i32).collect();
        assert!(!io_out.is_empty() && !io_in.is_empty(), "{image:?}");

        // A lease on the IO slave; a second one is refused; writes outside it too.
        let lease =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 1000 }).await.unwrap().into_inner();
        let e = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }).await.unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
        assert!(e.message().contains("slave 2"), "{}", e.message());
        let e = pd
            .write_outputs(pb::WriteOutputsRequest {
                lease_id: lease.id.clone(),
                writes: vec![by_entry("1.controlword", Kind::Unsigned(6))],
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "slave 1 is not leased: {e:?}");
        let e = pd
            .write_outputs(pb::WriteOutputsRequest {
                lease_id: "nope".into(),
                writes: vec![by_entry(&io_out[0].name, Kind::Unsigned(1))],
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "no lease: {e:?}");
        for (w, field) in [
            (by_entry("no.such", Kind::Unsigned(1)), "writes.entry"),
            (by_entry(&io_in[0].name, Kind::Unsigned(1)), "writes.entry"),
            (
                pb::OutputWrite { target: Some(pb::output_write::Target::Offset(100_000)), value: raw(vec![1]) },
                "writes.offset",
            ),
            (pb::OutputWrite { target: None, value: raw(vec![1]) }, "writes.target"),
        ] {
            let e = pd
                .write_outputs(pb::WriteOutputsRequest { lease_id: lease.id.clone(), writes: vec![w] })
                .await
                .unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{field}: {e:?}");
            assert!(e.message().contains(field), "{field}: {}", e.message());
        }

        // Write the IO slave's outputs: the loopback shows them in its inputs.
        let out0 = io_out[0].clone();
        let in0 = io_in[0].clone();
        let value = if out0.bit_length == 1 { Kind::Boolean(true) } else { Kind::Unsigned(0xA5) };
        pd.write_outputs(pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![by_entry(&out0.name, value)],
        })
        .await
        .unwrap();
        let mut stream = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![in0.name.clone()], decimation: 1, on_change: false })
            .await
            .unwrap()
            .into_inner();
        let start = Instant::now();
        let want = if out0.bit_length == 1 { Kind::Boolean(true) } else { Kind::Unsigned(0xA5) };
        loop {
            let s = stream.next().await.unwrap().unwrap();
            if s.values[0].value.as_ref().and_then(|v| v.kind.clone()) == Some(want.clone()) {
                break;
            }
            assert!(start.elapsed() < Duration::from_secs(3), "loopback never showed {want:?}: {s:?}");
        }
        drop(stream);

        // ReadOutputs: the written entry reads back; inputs and unknown names are refused.
        let outs =
            pd.read_outputs(pb::ReadOutputsRequest { entries: vec![out0.name.clone()] }).await.unwrap().into_inner();
        assert_eq!(outs.image.len() as u32, image.output_bytes);
        assert_eq!(outs.values[0].name, out0.name);
        assert_eq!(outs.values[0].value.as_ref().and_then(|v| v.kind.clone()), Some(want.clone()));
        for bad in [in0.name.clone(), "no.such".to_string()] {
            let e = pd.read_outputs(pb::ReadOutputsRequest { entries: vec![bad.clone()] }).await.unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{bad}: {e:?}");
            assert!(e.message().contains(&bad), "{}", e.message());
        }

        // Whole-image stream, decimated: every 10th frame.
        let mut stream = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 10, on_change: false })
            .await
            .unwrap()
            .into_inner();
        let a = stream.next().await.unwrap().unwrap();
        let b = stream.next().await.unwrap().unwrap();
        assert_eq!(a.image.len() as u32, image.input_bytes);
        assert!(b.seq - a.seq >= 10, "{} -> {}", a.seq, b.seq);
        drop(stream);

        // On change: a quiet input sends once, then again when written.
        let mut stream = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![in0.name.clone()], decimation: 0, on_change: true })
            .await
            .unwrap()
            .into_inner();
        let first = stream.next().await.unwrap().unwrap();
        let quiet = tokio::time::timeout(Duration::from_millis(300), stream.next()).await;
        assert!(quiet.is_err(), "nothing changed, yet a sample came: {quiet:?}");
        let off = if out0.bit_length == 1 { Kind::Boolean(false) } else { Kind::Unsigned(0x5A) };
        pd.write_outputs(pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![by_entry(&out0.name, off)],
        })
        .await
        .unwrap();
        let changed = tokio::time::timeout(Duration::from_secs(2), stream.next()).await.unwrap().unwrap().unwrap();
        assert!(changed.seq > first.seq && changed.values != first.values);
        drop(stream);
        let e = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec!["x".into()], decimation: 0, on_change: false })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);

        // Client streaming of outputs, by byte offset.
        let offset = out0.bit_offset / 8;
        let msgs: Vec<pb::WriteOutputsRequest> = (0..10u8)
            .map(|i| pb::WriteOutputsRequest {
                lease_id: lease.id.clone(),
                writes: vec![pb::OutputWrite {
                    target: Some(pb::output_write::Target::Offset(offset)),
                    value: raw(vec![i]),
                }],
            })
            .collect();
        let r = pd.stream_outputs(tokio_stream::iter(msgs)).await.unwrap().into_inner();
        assert_eq!(r.applied, 10);

        // Keep-alive, release, and expiry without keep-alive.
        let kept = pd.keep_alive(pb::KeepAliveRequest { lease_id: lease.id.clone() }).await.unwrap().into_inner();
        assert_eq!(kept.slaves, vec![2]);
        pd.release_lease(pb::ReleaseLeaseRequest { lease_id: lease.id.clone() }).await.unwrap();
        let e = pd.keep_alive(pb::KeepAliveRequest { lease_id: lease.id.clone() }).await.unwrap_err();
        assert_eq!(e.code(), Code::NotFound);
        let short =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![], ttl_ms: 150 }).await.unwrap().into_inner();
        assert_eq!(short.slaves, vec![0, 1, 2]);
        let mut master = MasterClient::new(ch.clone());
        assert_eq!(master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner().output_writers, 1);
        tokio::time::sleep(Duration::from_millis(400)).await;
        assert_eq!(
            master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner().output_writers,
            0,
            "expired lease still counted"
        );
        let e = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![], ttl_ms: 50 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);

        // Remapping: setting a slave's mapping to what it has re-runs the
        // bring-up with it and comes back with the same image.
        let m1 = mapping.slaves[1].clone();
        let r = pd.set_mapping(pb::SetMappingRequest { mapping: Some(m1.clone()) }).await.unwrap().into_inner();
        assert_eq!(r.image.unwrap().entries, image.entries);
        let mut too_many = m1.clone();
        too_many.rx_pdos = vec![m1.rx_pdos[0].clone(); 4];
        let e = pd.set_mapping(pb::SetMappingRequest { mapping: Some(too_many) }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        assert!(e.message().contains("mapping.rx_pdos") && e.message().contains("assigned twice"), "{}", e.message());

        // The fixed-mapping drive refuses a remap: the error says so and the
        // previous mapping runs again.
        let mut fixed = mapping.slaves[0].clone();
        fixed.rx_pdos[0].entries.truncate(1);
        let e = pd.set_mapping(pb::SetMappingRequest { mapping: Some(fixed) }).await.unwrap_err();
        assert!(e.message().contains("previous mapping is back"), "{e:?}");
        let status = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!(status.phase, pb::EnginePhase::Running as i32, "{status:?}");
        let again = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        assert_eq!(again.entries, image.entries);
    });
}

/// Losing the lease (no keep-alive) applies `outputs.on_last_writer_gone`:
/// here "zero", seen through the IO slave's loopback.
#[test]
fn a_lost_lease_applies_the_safe_action() {
    run(async {
        let config = ecmxf_e2e::config("backend = \"sim\"", "[outputs]\non_last_writer_gone = \"zero\"\n");
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());
        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let out =
            image.entries.iter().find(|e| e.slave == 2 && e.direction == pb::Direction::Output as i32).unwrap().clone();
        let inp =
            image.entries.iter().find(|e| e.slave == 2 && e.direction == pb::Direction::Input as i32).unwrap().clone();
        let on = if out.bit_length == 1 { Kind::Boolean(true) } else { Kind::Unsigned(0xFF) };
        let off = if out.bit_length == 1 { Kind::Boolean(false) } else { Kind::Unsigned(0) };
        let lease =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 200 }).await.unwrap().into_inner();
        pd.write_outputs(pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![by_entry(&out.name, on.clone())],
        })
        .await
        .unwrap();
        let mut stream = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![inp.name.clone()], decimation: 0, on_change: true })
            .await
            .unwrap()
            .into_inner();
        let value = |s: &pb::InputSample| s.values[0].value.as_ref().and_then(|v| v.kind.clone());
        let start = Instant::now();
        loop {
            let s = stream.next().await.unwrap().unwrap();
            if value(&s) == Some(on.clone()) {
                break;
            }
            assert!(start.elapsed() < Duration::from_secs(3), "output never seen");
        }
        // No keep-alive: after 200 ms the lease lapses and the outputs go to zero.
        let start = Instant::now();
        loop {
            let s = tokio::time::timeout(Duration::from_secs(3), stream.next())
                .await
                .expect("no zeroing")
                .unwrap()
                .unwrap();
            if value(&s) == Some(off.clone()) {
                break;
            }
        }
        assert!(start.elapsed() >= Duration::from_millis(150), "zeroed before the lease lapsed: {:?}", start.elapsed());
        let mut diag = pb::diagnostics_client::DiagnosticsClient::new(ch);
        let c = diag.get_counters(pb::GetCountersRequest {}).await.unwrap().into_inner();
        assert_eq!(c.slaves[2].state, pb::EcatState::Op as i32);
        let e = pd
            .write_outputs(pb::WriteOutputsRequest { lease_id: lease.id, writes: vec![by_entry(&out.name, on)] })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied);
    });
}

/// A channel to the daemon whose HTTP/2 receive window is small (16 KiB),
/// so what a slow reader has not read yet stays in the daemon, where the
/// stream's age bound applies, not in a large client buffer.
async fn small_window(socket: &std::path::Path) -> tonic::transport::Channel {
    let path = socket.to_path_buf();
    tonic::transport::Endpoint::from_static("http://localhost")
        .initial_stream_window_size(Some(16 * 1024))
        .initial_connection_window_size(Some(16 * 1024))
        .connect_with_connector(tower::service_fn(move |_: tonic::transport::Uri| {
            let path = path.clone();
            async move {
                Ok::<_, std::io::Error>(hyper_util::rt::TokioIo::new(tokio::net::UnixStream::connect(path).await?))
            }
        }))
        .await
        .expect("connect")
}

/// A subscriber that stops reading for 2 s at a 125 us cycle (16000
/// frames) does not get a queue of old samples when it reads again: past
/// what its own 16 KiB window held, samples are at most the stream's age
/// bound (100 ms) old, and the skipped frames are counted in `lost`.
#[test]
fn a_slow_subscriber_gets_recent_samples_and_a_loss_count() {
    run(async {
        let mut d = Daemon::sim();
        d.connect().await;
        let mut stream = ProcessDataClient::new(small_window(&d.socket).await)
            .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 1, on_change: false })
            .await
            .unwrap()
            .into_inner();
        let first = stream.next().await.unwrap().unwrap();
        let sample_bytes = prost::Message::encoded_len(&first) + 5;
        tokio::time::sleep(Duration::from_secs(2)).await;
        // What the client's window held when it stopped reading is old by
        // nature; everything after it must be recent.
        let buffered = 16 * 1024 / sample_bytes + 2 * 32;
        let (mut lost, mut ages) = (0u64, Vec::new());
        for _ in 0..buffered + 400 {
            let s = stream.next().await.unwrap().unwrap();
            lost += s.lost;
            ages.push(Duration::from_nanos(monotonic_ns().saturating_sub(s.monotonic_ns)));
        }
        let fresh_from = ages.iter().position(|a| *a < Duration::from_millis(150));
        let fresh_from = fresh_from.unwrap_or_else(|| panic!("no recent sample after the pause: {ages:?}"));
        assert!(
            fresh_from <= buffered,
            "{fresh_from} stale samples after the pause, more than the {buffered} the client window holds"
        );
        let late: Vec<&Duration> = ages[fresh_from..].iter().filter(|a| **a > Duration::from_millis(250)).collect();
        assert!(late.len() <= 5, "old samples after fresh ones: {late:?}");
        assert!(lost > 10_000, "the frames skipped during the pause are counted: lost = {lost}");
    });
}

/// `cycle.output_latency_us`: the daemon keeps the RxFIFO only as deep as
/// the budget needs, and says how long writes took to reach the wire.
/// Checked through the IO slave's loopback (what flows), not only the
/// daemon's own figure: at a 5 ms budget (125 us cycle) the median write
/// comes back within the budget, where the harness's deep FIFO without a
/// budget (128..240 frames) takes about 23 ms.
#[test]
fn a_latency_budget_bounds_how_long_writes_take_to_come_back() {
    run(async {
        let config =
            ecmxf_e2e::config_with_cycle("backend = \"sim\"", "sync0_us = 125\noutput_latency_us = 5000\n", "");
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());
        let mut master = MasterClient::new(ch);
        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let (out_at, in_at) = ecmxf_e2e::io_slave_bytes(&image);
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 5000 }).await.unwrap();
        let lease = lease.into_inner().id;
        let mut inputs = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 1, on_change: false })
            .await
            .unwrap()
            .into_inner();
        let mut took = Vec::new();
        for k in 0..60u8 {
            let value = k + 1;
            let t0 = monotonic_ns();
            pd.write_outputs(pb::WriteOutputsRequest {
                lease_id: lease.clone(),
                writes: vec![pb::OutputWrite {
                    target: Some(pb::output_write::Target::Offset(out_at)),
                    value: raw(vec![value]),
                }],
            })
            .await
            .unwrap();
            let start = Instant::now();
            loop {
                let s = inputs.next().await.unwrap().unwrap();
                if s.monotonic_ns >= t0 && s.image.get(in_at as usize) == Some(&value) {
                    took.push((s.monotonic_ns - t0) / 1000);
                    break;
                }
                assert!(start.elapsed() < Duration::from_secs(2), "write {value} never came back");
            }
        }
        took.sort_unstable();
        let median = took[took.len() / 2];
        let s = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        println!(
            "write -> loopback median {median} us; daemon: wire p50 {} us, p99 {} us, budget {} us, late {}",
            s.output_latency_p50_us,
            s.output_latency_p99_us,
            s.output_latency_budget_us,
            s.counters.as_ref().map_or(0, |c| c.output_latency_misses)
        );
        assert_eq!(s.output_latency_budget_us, 5000);
        assert!(s.output_latency_p50_us > 0 && s.output_latency_p50_us <= 5000, "{s:?}");
        // The loopback adds a cycle or two and the input read (every few
        // cycles with this budget; about 4.8 ms in all, release build): far
        // under the deep FIFO's 23 ms, with room for a loaded debug build.
        assert!(median <= 10_000, "median write -> loopback {median} us: {took:?}");
    });
}

/// What reaches the slaves, frame by frame: the simulator records the
/// output frames it plays (`record 2`), and a sequence of writes to the IO
/// slave shows there in order, each value one unbroken run of cycles,
/// never an older value after a newer one.
#[test]
fn writes_reach_the_slave_in_order_as_the_simulator_records_them() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("record");
        let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
        let config = ecmxf_e2e::config_with_cycle(&sim.link(), "sync0_us = 125\noutput_latency_us = 2000\n", "");
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch);
        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let (out_at, _) = ecmxf_e2e::io_slave_bytes(&image);
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 5000 }).await.unwrap();
        let lease = lease.into_inner().id;
        assert!(sim.ctl("record 2").starts_with("ok recording slave 2"), "{}", sim.ctl("status"));
        let values: Vec<u8> = (1..=40).collect();
        for v in &values {
            pd.write_outputs(pb::WriteOutputsRequest {
                lease_id: lease.clone(),
                writes: vec![pb::OutputWrite {
                    target: Some(pb::output_write::Target::Offset(out_at)),
                    value: raw(vec![*v]),
                }],
            })
            .await
            .unwrap();
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        let text = sim.ctl("recorded");
        let mut lines = text.lines();
        assert!(lines.next().is_some_and(|l| l.starts_with("ok frames=")), "{text}");
        // (cycle, value) per played frame; cycles count up by one.
        let played: Vec<(u64, u8)> =
            lines.map(|l| PlayedFrame::parse(l).map(|f| (f.cycle, f.bytes[0])).unwrap()).collect();
        assert!(played.len() > 1000, "{} frames recorded", played.len());
        assert!(played.windows(2).all(|w| w[1].0 == w[0].0 + 1), "a frame per cycle, none missing");
        // The values in the order they were played, each run once.
        let mut runs: Vec<u8> = played.iter().map(|(_, v)| *v).collect();
        runs.dedup();
        let runs: Vec<u8> = runs.into_iter().filter(|v| *v != 0).collect();
        assert_eq!(runs, values, "every write reached the slave, in order, once");
        drop(sim);
    });
}

/// `StreamFrames`: a client streams a counter to the IO slave, one frame
/// per DC cycle at 125 us (8 kHz) for 10 s (`ECMXF_FRAMES_SOAK_SECS`),
/// sending only what the credits allow. Checked twice: the daemon reports
/// every frame once, in order, with its DC cycle and that cycle's input
/// frame, which loops the frame's own value back; and the simulator's
/// record of what the slave consumed shows every frame once, in order, one
/// per cycle (a repeat only in a cycle the chip marked as an underrun), in
/// the cycles the daemon reported. Sending without credit, a wrong frame
/// size, a second stream on the same slave and a latest-value write to a
/// streamed slave are refused by name.
#[test]
fn streamed_frames_reach_the_slave_once_each_in_order() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("frames");
        let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
        let config = ecmxf_e2e::config_with_cycle(&sim.link(), "sync0_us = 125\n", "");
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch);
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 30_000 }).await.unwrap();
        let lease = lease.into_inner().id;
        let batch = |frames: Vec<pb::OutputFrame>| pb::FrameBatch {
            lease_id: lease.clone(),
            slaves: vec![2],
            queue_frames: 512,
            frames,
            pair_inputs: false,
        };
        let frame = |seq: u64| pb::OutputFrame { seq, data: ecmxf_e2e::frames::counter_frame(seq) };
        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let (_, in_at) = ecmxf_e2e::io_slave_bytes(&image);
        // 10 s by default; ECMXF_FRAMES_SOAK_SECS=60 for a one-minute soak.
        let secs: u64 = std::env::var("ECMXF_FRAMES_SOAK_SECS").ok().and_then(|s| s.parse().ok()).unwrap_or(10);
        let total = secs * 8000;
        assert!(sim.ctl(&format!("record 2 {}", total + 100_000)).starts_with("ok recording"));

        // A second stream on the same slave while one is open.
        let (tx, rx) = tokio::sync::mpsc::channel(1);
        tx.send(pb::FrameBatch { slaves: vec![2], ..batch(Vec::new()) }).await.unwrap();
        let open = pd.stream_frames(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap();
        let (tx2, rx2) = tokio::sync::mpsc::channel(1);
        tx2.send(batch(Vec::new())).await.unwrap();
        let e = pd.stream_frames(tokio_stream::wrappers::ReceiverStream::new(rx2)).await.unwrap_err();
        assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
        // ... and a latest-value write to its bytes.
        let (out_at, _) = ecmxf_e2e::io_slave_bytes(&image);
        let write = pb::WriteOutputsRequest {
            lease_id: lease.clone(),
            writes: vec![pb::OutputWrite {
                target: Some(pb::output_write::Target::Offset(out_at)),
                value: Some(pb::Value { kind: Some(pb::value::Kind::Raw(vec![9])) }),
            }],
        };
        let e = pd.write_outputs(write).await.unwrap_err();
        assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
        assert!(e.message().contains("StreamFrames"), "{e:?}");
        drop((tx, open));
        tokio::time::sleep(Duration::from_millis(50)).await;

        let run = ecmxf_e2e::frames::stream_counter(&mut pd, &lease, total).await;
        assert_eq!((run.last.pushed, run.last.last_seq), (total, total - 1), "{:?}", run.last);
        // What the daemon told: each frame with its cycle and the input
        // frame of that cycle, which loops back the frame's own value.
        let pairing = run.pairing(in_at as usize).unwrap();
        assert_eq!(pairing.told, total, "{pairing:?}");

        // What the slave consumed, as the simulator recorded it: the chip
        // plays what is still queued in its RxFIFO; look until the last
        // frame shows (or 3 s).
        let started = Instant::now();
        let recorded = loop {
            let record = ecmxf_e2e::frames::recorded(&sim);
            let r = ecmxf_e2e::frames::check_record(&record, &run).unwrap();
            if r.played == total || started.elapsed() > Duration::from_secs(3) {
                break r;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        assert_eq!(recorded.played, total, "every frame played: {recorded:?}");

        // The pairing is exact while neither FIFO overflowed nor ran dry.
        // A host stall longer than the TxFIFO's depth (40 cycles = 5 ms
        // here) makes the chip drop input frames, one longer than the
        // RxFIFO's margin (about 23 ms here) repeats outputs (underruns):
        // both counted, and frames queued across such a stall can pair
        // with another cycle's inputs (documented in proto/README.md), so
        // only the frames at the slave are checked then.
        let mut master = pb::master_client::MasterClient::new(d.connect().await);
        let status = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        let dropped = status.counters.unwrap_or_default().inputs_dropped_by_chip;
        if dropped == 0 && recorded.underruns == 0 {
            assert_eq!(pairing.mismatched, 0, "each frame paired with the input frame of its own cycle: {pairing:?}");
            assert!(pairing.with_inputs * 100 >= total * 99, "inputs for (almost) every frame: {pairing:?}");
            assert!(recorded.cycles_agree, "the reported cycles are the chip's: {recorded:?}");
            assert_eq!(pairing.late_cycles, 0, "no cycle without its frame: {pairing:?}");
        }
        println!(
            "{total} frames ({secs} s) through StreamFrames at 8 kHz: once each, in order; {} underrun cycles; \
             {} of {total} paired with their cycle's input frame, {} mismatched; {dropped} inputs dropped by the chip",
            recorded.underruns, pairing.with_inputs, pairing.mismatched
        );

        // A client that stops sending with its stream open: the queue runs
        // dry, which is counted and said once (FRAMES_DRY, the policy as
        // its detail); the outputs hold (hold-last).
        let mut diag = pb::diagnostics_client::DiagnosticsClient::new(d.connect().await);
        let mut events = diag.stream_events(pb::StreamEventsRequest {}).await.unwrap().into_inner();
        let (tx, rx) = tokio::sync::mpsc::channel(4);
        tx.send(batch((0..100).map(frame).collect())).await.unwrap();
        let mut reports = pd.stream_frames(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
        let dry = loop {
            let r = reports.next().await.unwrap().unwrap();
            if r.dry > 0 {
                break r;
            }
        };
        assert_eq!(dry.pushed, 100, "{dry:?}");
        let event = loop {
            let e = tokio::time::timeout(Duration::from_secs(2), events.next()).await.expect("a FRAMES_DRY event");
            let e = e.unwrap().unwrap();
            if e.kind == pb::EventKind::FramesDry as i32 {
                break e;
            }
        };
        assert_eq!((event.counter, event.detail.as_str()), (100, "hold-last"), "{event:?}");
        assert!(event.text.contains("ran dry after 100 frames"), "{}", event.text);
        drop(tx);
        drop(reports);
        tokio::time::sleep(Duration::from_millis(50)).await;

        // Frames without credit, and of the wrong size, end a stream by name.
        // The error that ends a stream opened with `first`, whether it
        // comes as the answer or inside the stream.
        let ended = |first: pb::FrameBatch| {
            let mut pd = pd.clone();
            async move {
                let (tx, rx) = tokio::sync::mpsc::channel(4);
                tx.send(first).await.unwrap();
                match pd.stream_frames(tokio_stream::wrappers::ReceiverStream::new(rx)).await {
                    Err(e) => e,
                    Ok(s) => s.into_inner().filter_map(|r| r.err()).next().await.expect("an error"),
                }
            }
        };
        let mut b = batch((0..600).map(frame).collect());
        b.queue_frames = 16;
        let e = ended(b).await;
        assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
        assert!(e.message().contains("credit"), "{}", e.message());
        let e = ended(batch(vec![pb::OutputFrame { seq: 7, data: vec![1, 2] }])).await;
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains("frames.data"), "{}", e.message());
        // Ended inside the stream: the status travels in the trailers.
        assert_eq!(ecmxf_e2e::full_status(&e), "BAD_ARGUMENT");
        drop(sim);
    });
}

/// Two streams at once on different slaves: a CSP sine trajectory to the
/// first axis of the 3-axis drive (slave 1) and the counter to the IO slave
/// (slave 2), both at 125 us. The simulator's record of the drive's
/// outputs shows every trajectory frame once, in order, one per cycle; the
/// drive's actual position in each frame's paired input frame is the
/// target that frame carried (the simulated axis follows a reachable CSP
/// target within the cycle); and the counter pairs as before.
#[test]
fn a_csp_sine_and_a_counter_stream_to_two_slaves_at_once() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("csp");
        let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
        let config = ecmxf_e2e::config_with_cycle(&sim.link(), "sync0_us = 125\n", ecmxf_e2e::TI_AXIS);
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut cia = pb::cia402_client::Cia402Client::new(ch.clone());
        let enable =
            pb::AxisCommandRequest { axis: 0, command: pb::AxisCommand::Enable as i32, wait: true, timeout_ms: 3000 };
        let s = cia.command(enable).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::OperationEnabled as i32, "{s:?}");
        let mut pd = ProcessDataClient::new(ch.clone());
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![1, 2], ttl_ms: 30_000 }).await.unwrap();
        let lease = lease.into_inner().id;
        let image = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let byte = |index: u32, dir: pb::Direction| {
            let e = image.entries.iter().find(|e| e.slave == 1 && e.index == index && e.direction == dir as i32);
            (e.unwrap_or_else(|| panic!("slave 1 has no {index:#06x}")).bit_offset / 8) as usize
        };
        // Slave 1's output bytes: the frame.
        let (start, end) = image
            .entries
            .iter()
            .filter(|e| e.slave == 1 && e.direction == pb::Direction::Output as i32)
            .fold((usize::MAX, 0), |(lo, hi), e| {
                (lo.min(e.bit_offset as usize / 8), hi.max((e.bit_offset + e.bit_length).div_ceil(8) as usize))
            });
        let len = end - start;
        let (cw, mode, target) = (
            byte(0x6040, pb::Direction::Output) - start,
            byte(0x6060, pb::Direction::Output) - start,
            byte(0x607A, pb::Direction::Output) - start,
        );
        let actual = byte(0x6064, pb::Direction::Input);
        // 2 s of a 1 Hz sine of 20000 counts (at most 16 counts a cycle).
        let total = 16_000u64;
        let sine = |seq: u64| (20_000.0 * (std::f64::consts::TAU * seq as f64 / 8000.0).sin()).round() as i32;
        let frame = move |seq: u64| {
            let mut f = vec![0u8; len];
            f[cw..cw + 2].copy_from_slice(&0x000Fu16.to_le_bytes());
            f[mode] = 8;
            f[target..target + 4].copy_from_slice(&sine(seq).to_le_bytes());
            f
        };
        assert!(sim.ctl("record 1 100000").starts_with("ok recording"));
        let mut pd2 = ProcessDataClient::new(ch.clone());
        let (csp, counter) = tokio::join!(
            ecmxf_e2e::frames::stream(&mut pd, &lease, 1, total, frame),
            ecmxf_e2e::frames::stream_counter(&mut pd2, &lease, total)
        );
        assert_eq!(csp.last.frame_bytes as usize, len);
        assert_eq!(csp.played.iter().map(|p| p.seq).collect::<Vec<_>>(), (0..total).collect::<Vec<_>>());
        let (_, in_at) = ecmxf_e2e::io_slave_bytes(&image);
        let pairing = counter.pairing(in_at as usize).unwrap();
        assert_eq!(pairing.told, total, "{pairing:?}");
        // The drive followed: actual position = the frame's target.
        let mut followed = 0;
        let mut off = Vec::new();
        for p in &csp.played {
            if let Some(b) = p.inputs.get(actual..actual + 4) {
                let pos = i32::from_le_bytes(b.try_into().unwrap());
                if pos == sine(p.seq) {
                    followed += 1;
                } else if off.len() < 5 {
                    off.push((p.seq, pos, sine(p.seq)));
                }
            }
        }
        // Paired exactly unless a host stall overflowed the TxFIFO or
        // emptied the RxFIFO (see the test above).
        let mut master = pb::master_client::MasterClient::new(ch.clone());
        let counters =
            master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner().counters.unwrap_or_default();
        if counters.inputs_dropped_by_chip == 0 && counters.fifo_alarms == 0 {
            assert!(
                followed * 100 >= total * 99,
                "{followed} of {total} frames: actual = target; first misses {off:?}"
            );
        }
        // What the drive consumed, as recorded: exact unless this client
        // fell behind its 1024-frame queue (a host stall of 128 ms here),
        // which the daemon counts as dry frames and fills by repeating.
        if csp.last.dry > 0 {
            println!("CSP sine: the queue ran dry for {} frame(s): this host stalled the client", csp.last.dry);
            return;
        }
        let started = Instant::now();
        let sequence: Vec<Vec<u8>> = (0..total).map(frame).collect();
        let played = loop {
            let record = ecmxf_e2e::frames::recorded(&sim);
            let f = ecmxf_sim::chip::fifo::PlayRecord::follows(&record, &sequence).unwrap();
            if f.played as u64 == total || started.elapsed() > Duration::from_secs(3) {
                break f;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        assert_eq!(played.played as u64, total, "{played:?}");
        println!(
            "CSP sine: {total} frames to axis 1 at 8 kHz, once each in order ({} underrun cycles); actual = target in {followed}; \
             counter alongside: {pairing:?}",
            played.underruns
        );
    });
}

/// `request` with a deadline (`grpc-timeout`).
fn within<T>(request: T, deadline: Duration) -> tonic::Request<T> {
    let mut r = tonic::Request::new(request);
    r.set_timeout(deadline);
    r
}

/// The daemon lays out the process image itself once the network runs, as
/// its own client taking every other turn of the blocking slot, and keeps
/// it across a re-init that finds the same network (when it was built inside
/// the first caller's deadline, it was thrown away call after call while
/// SDO clients kept the slot busy, and writes by name failed for seconds).
#[test]
fn writes_by_name_succeed_from_the_start_while_16_sdo_readers_keep_the_slot_busy() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let readers: Vec<_> = (0..16)
            .map(|_| {
                let (ch, stop) = (ch.clone(), stop.clone());
                tokio::spawn(async move {
                    let mut sdo = pb::sdo_client::SdoClient::new(ch);
                    let mut reads = 0u32;
                    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                        let r = pb::SdoUploadRequest { slave: 1, index: 0x1018, subindex: 1, ..Default::default() };
                        match sdo.upload(r).await {
                            Ok(_) => reads += 1,
                            // The re-init below: the engine is recovering.
                            Err(e) if e.code() == Code::Unavailable => {
                                tokio::time::sleep(Duration::from_millis(10)).await
                            }
                            Err(e) => panic!("{e:?}"),
                        }
                    }
                    reads
                })
            })
            .collect();
        let mut pd = ProcessDataClient::new(ch.clone());
        let second = Duration::from_secs(1);
        let lease =
            pd.acquire_lease(within(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }, second)).await.unwrap();
        let lease = lease.into_inner().id;
        for i in 0..10u64 {
            let write = by_entry("2.0x7000:01", Kind::Unsigned(i));
            let r = pd.write_outputs(within(
                pb::WriteOutputsRequest { lease_id: lease.clone(), writes: vec![write] },
                second,
            ));
            r.await.unwrap_or_else(|e| panic!("write {i} with a 1 s deadline: {e:?}"));
        }
        // A re-init that finds the same network keeps the layout: answered
        // at once, however busy the slot.
        MasterClient::new(ch.clone()).reinit(pb::ReinitRequest {}).await.unwrap();
        let layout = pd.get_layout(within(pb::GetLayoutRequest {}, Duration::from_millis(100))).await;
        assert_eq!(layout.unwrap().into_inner().entries.iter().filter(|e| e.slave == 2).count(), 2);
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        for r in readers {
            assert!(r.await.unwrap() > 0, "every reader got its turns");
        }
    });
}
