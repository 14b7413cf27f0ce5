//! Bring-up driven by a configuration: expected identities, a PDO remap,
//! start-up SDOs, the chip's CiA402 helper; and a network that differs from
//! the configuration, reported naming the slave.

use std::time::{Duration, Instant};

use ecmxf_sim::Chip;
use ecmxf_wire::payload::cia402::Cia402State;
use ecmxf_wire::payload::slave_info::{SlaveInfo, SlaveInfoCode};
use ecmxfd::config::Config;
use ecmxfd::link::sim::SimLink;
use ecmxfd::master::Call;
use ecmxfd::master::Immediate;
use ecmxfd::master::Master;
use ecmxfd::master::Phase;

/// Asks the chip's CiA402 helper to enable axis 0, as Cia402.Command ENABLE does.
async fn enable(m: &Master) {
    let set = ecmxf_wire::payload::cia402::Cia402StateSet { axis: 0, state: Cia402State::OperationEnabled };
    m.immediate(Immediate::Cia402StateSet(set), Call::anonymous(None)).await.expect("402_STATE_SET");
}

const CONFIG: &str = r#"
version = 1
[link]
backend = "sim"
[realtime]
priority = 0
lock_memory = false
[cycle]
sync0_us = 250
fifo_rx_depth = 200
fifo_tx_depth = 40
fifo_low = 64
fifo_high = 160

[[slave]]
name = "core"
vendor_id = 0x89A
product_code = 0x30000000
dc_assign_activate = 0   # free-running: DCSYNC + ECAT_INIT_DC for this slave only
  [[slave.sdo]]
  index = 0x6083
  value = 5555
  size = 4

[[slave]]
name = "ti"
vendor_id = 0x59D
product_code = 0x402
  # Axis 1 only: controlword, mode, target position (7 bytes).
  [[slave.rx_pdos]]
  index = 0x1600
  entries = [[0x6040, 0, 16], [0x6060, 0, 8], [0x607A, 0, 32]]
  [[slave.sdo]]
  index = 0x6085
  bytes = [0x10, 0x27, 0, 0]

[[slave]]
name = "io"
vendor_id = 0x1337

[[axis]]
slave = 1
controlword_offset = 0
statusword_offset = 0
"#;

fn rt_block<F: std::future::Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap().block_on(f)
}

fn start(text: &str) -> Master {
    let config = Config::parse(text, std::path::Path::new("test.toml")).unwrap();
    let (link, _sim) = SimLink::new(Chip::new(ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()));
    Master::start(link, config)
}

#[test]
fn configured_mapping_sdos_and_helper_are_applied() {
    let m = start(CONFIG);
    let t = Instant::now();
    while m.status().phase != Phase::Running {
        assert!(t.elapsed() < Duration::from_secs(20), "not running: {:?} {:?}", m.status(), m.last_error());
        std::thread::sleep(Duration::from_millis(20));
    }
    let l = m.layout();
    assert_eq!(l.slaves[1].rx_bytes, 7, "the remap took");
    // Per-slave DC: the first drive free-runs, the second follows the cycle
    // (the IO slave has no DC unit).
    let dc = |slave| {
        let d = rt_block(m.slave_info(slave, SlaveInfoCode::DcCycle, Call::anonymous(None))).unwrap();
        match SlaveInfo::decode(SlaveInfoCode::DcCycle, &d).unwrap() {
            SlaveInfo::DcCycle(ns) => ns,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!((dc(0), dc(1), dc(2)), (0, 250_000, 0));
    assert_eq!(l.rx_size, 13 + 7 + 1);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        assert_eq!(m.sdo_read(0, 0x6083, 0, false, Call::anonymous(None)).await.unwrap(), 5555u32.to_le_bytes());
        assert_eq!(m.sdo_read(1, 0x6085, 0, false, Call::anonymous(None)).await.unwrap(), 10_000u32.to_le_bytes());
        // Restart interlock: the axis comes up disabled; enabled on request,
        // the helper walks TI axis 1 to operation enabled.
        let mut inputs = m.subscribe();
        let at = l.slaves[1].tx_offset;
        let f = inputs.recv().await.unwrap();
        let sw = u16::from_le_bytes([f.data[at], f.data[at + 1]]);
        assert_ne!(Cia402State::from_statusword(sw), Cia402State::OperationEnabled, "enabled without a request");
        enable(&m).await;
        let t = Instant::now();
        loop {
            let f = inputs.recv().await.unwrap();
            let sw = u16::from_le_bytes([f.data[at], f.data[at + 1]]);
            if Cia402State::from_statusword(sw) == Cia402State::OperationEnabled {
                break;
            }
            assert!(t.elapsed() < Duration::from_secs(3), "axis not enabled: statusword {sw:#06x}");
        }
    });
    m.stop();
}

#[test]
fn a_different_network_is_named() {
    let wrong = CONFIG.replace("product_code = 0x402", "product_code = 0x403");
    let m = start(&wrong);
    let t = Instant::now();
    let e = loop {
        if let Some(e) = m.last_error() {
            assert!(e.bring_up().is_some() && !e.is_permanent(), "a bring-up failure, retried: {e}");
            break e.to_string();
        }
        assert!(t.elapsed() < Duration::from_secs(20), "no error reported");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(
        e.contains("slave 1") && e.contains("0x00000403") && e.contains("0x00000402") && e.contains("\"ti\""),
        "{e}"
    );
    assert_ne!(m.status().phase, Phase::Running);
    m.stop();
}

/// A process image the SPI link cannot carry is refused at bring-up with
/// the sizes and what to change, instead of reaching OP and running dry.
#[test]
fn a_frame_bigger_than_the_spi_packet_is_refused_naming_the_sizes() {
    // No remap (PDO_CONFIG_SET alone needs 112 bytes): 40-byte packets.
    let remap =
        "  [[slave.rx_pdos]]\n  index = 0x1600\n  entries = [[0x6040, 0, 16], [0x6060, 0, 8], [0x607A, 0, 32]]\n";
    assert!(CONFIG.contains(remap));
    let small = CONFIG.replace(remap, "").replace("[realtime]", "[chip]\ndata_size = 40\n[realtime]");
    let m = start(&small);
    let t = Instant::now();
    let e = loop {
        if let Some(e) = m.last_error() {
            assert!(e.is_permanent(), "only the configuration can change it: {e}");
            break e.to_string();
        }
        assert!(t.elapsed() < Duration::from_secs(20), "no error reported: {:?}", m.status());
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(e.contains("link budget") && e.contains("carries 40") && e.contains("chip.data_size"), "{e}");
    assert_ne!(m.status().phase, Phase::Running);
    m.stop();
}

fn running(text: &str) -> Master {
    let m = start(text);
    let t = Instant::now();
    while m.status().phase != Phase::Running {
        assert!(t.elapsed() < Duration::from_secs(20), "not running: {:?} {:?}", m.status(), m.last_error());
        std::thread::sleep(Duration::from_millis(20));
    }
    m
}

/// Waits until an input frame satisfies `pred`.
async fn until(m: &Master, what: &str, mut pred: impl FnMut(&[u8]) -> bool) {
    let mut inputs = m.subscribe();
    let t = Instant::now();
    loop {
        let f = inputs.recv().await.unwrap();
        if pred(&f.data) {
            return;
        }
        assert!(t.elapsed() < Duration::from_secs(3), "never saw {what}");
    }
}

#[test]
fn outputs_are_zeroed_when_the_last_writer_goes() {
    let m = running(&format!("{CONFIG}\n[outputs]\non_last_writer_gone = \"zero\"\n"));
    let io = m.layout().slaves[2].clone();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let a = m.output_writer();
        let b = m.output_writer();
        a.write(io.rx_offset, &[0x5A]).unwrap();
        until(&m, "the outputs looped back", |d| d[io.tx_offset] == 0x5A).await;
        drop(a);
        tokio::time::sleep(Duration::from_millis(100)).await;
        until(&m, "outputs held while a writer remains", |d| d[io.tx_offset] == 0x5A).await;
        assert_eq!(m.output_writers(), 1);
        drop(b);
        until(&m, "zeroed outputs", |d| d[io.tx_offset] == 0).await;
        // A new writer starts over.
        let c = m.output_writer();
        c.write(io.rx_offset, &[0x11]).unwrap();
        until(&m, "the new writer's outputs", |d| d[io.tx_offset] == 0x11).await;
    });
    m.stop();
}

#[test]
fn axes_quick_stop_when_the_last_writer_goes() {
    let config =
        Config::parse(&format!("{CONFIG}\n[outputs]\non_last_writer_gone = \"quick-stop\"\n"), "t.toml".as_ref());
    let (link, sim) = SimLink::new(Chip::new(ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()));
    let m = Master::start(link, config.unwrap());
    let t = Instant::now();
    while m.status().phase != Phase::Running {
        assert!(t.elapsed() < Duration::from_secs(20), "not running: {:?}", m.last_error());
        std::thread::sleep(Duration::from_millis(20));
    }
    let l = m.layout();
    let (at, cw_at) = (l.slaves[1].tx_offset, l.slaves[1].rx_offset);
    let state = move |d: &[u8]| Cia402State::from_statusword(u16::from_le_bytes([d[at], d[at + 1]]));
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        enable(&m).await;
        until(&m, "operation enabled", |d| state(d) == Cia402State::OperationEnabled).await;
        drop(m.output_writer());
        until(&m, "the axis stopped and disabled", |d| state(d) == Cia402State::SwitchOnDisabled).await;
        // It got there by the quick stop command, and stays there.
        let cw = sim.with_chip(|c| u16::from_le_bytes([c.master.outputs[cw_at], c.master.outputs[cw_at + 1]]));
        assert_eq!(cw & 0x0087, 0x0002, "controlword {cw:#06x} is quick stop");
        let mut inputs = m.subscribe();
        for _ in 0..200 {
            assert_eq!(state(&inputs.recv().await.unwrap().data), Cia402State::SwitchOnDisabled);
        }
    });
    m.stop();
}

#[test]
fn holding_the_last_outputs_is_the_default() {
    let m = running(CONFIG);
    let io = m.layout().slaves[2].clone();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let w = m.output_writer();
        w.write(io.rx_offset, &[0x3C]).unwrap();
        until(&m, "the outputs looped back", |d| d[io.tx_offset] == 0x3C).await;
        drop(w);
        tokio::time::sleep(Duration::from_millis(100)).await;
        let mut inputs = m.subscribe();
        for _ in 0..100 {
            assert_eq!(inputs.recv().await.unwrap().data[io.tx_offset], 0x3C, "outputs held");
        }
    });
    m.stop();
}

#[test]
fn quick_stop_needs_an_axis() {
    let text = CONFIG.replace("[[axis]]\nslave = 1\ncontrolword_offset = 0\nstatusword_offset = 0\n", "")
        + "\n[outputs]\non_last_writer_gone = \"quick-stop\"\n";
    let e = Config::parse(&text, std::path::Path::new("test.toml")).unwrap_err().to_string();
    assert!(e.contains("outputs.on_last_writer_gone") && e.contains("axis"), "{e}");
    let e = Config::parse(&format!("{CONFIG}\n[outputs]\non_last_writer_gone = \"drop\"\n"), "t.toml".as_ref())
        .unwrap_err()
        .to_string();
    assert!(e.contains("drop") && e.contains("hold-last"), "{e}");
}

#[test]
fn a_new_configuration_is_applied_while_running() {
    let m = running(CONFIG);
    assert_eq!(m.layout().slaves[1].rx_bytes, 7);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        // The TI drive remapped (no mode byte), another start-up value.
        let text = CONFIG
            .replace("[[0x6040, 0, 16], [0x6060, 0, 8], [0x607A, 0, 32]]", "[[0x6040, 0, 16], [0x607A, 0, 32]]")
            .replace("value = 5555", "value = 6666");
        let new = Config::parse(&text, "t.toml".as_ref()).unwrap();
        m.apply_config(new.clone(), Call::anonymous(Some(Duration::from_secs(20)))).await.unwrap();
        assert_eq!(m.layout().slaves[1].rx_bytes, 6, "the new mapping took");
        assert_eq!(m.sdo_read(0, 0x6083, 0, false, Call::anonymous(None)).await.unwrap(), 6666u32.to_le_bytes());
        assert_eq!(m.config(), new);

        // What cannot change names itself, and nothing happens.
        let mut other = new.clone();
        other.link = ecmxfd::config::LinkConfig::SimSocket { socket: "/tmp/x.sock".into() };
        let e = m.apply_config(other, Call::anonymous(None)).await.unwrap_err();
        assert!(matches!(e, ecmxfd::master::EngineError::BadArgument { field: "link", .. }), "{e}");
        let mut other = new.clone();
        other.cycle.sync0_us = 100;
        let e = m.apply_config(other, Call::anonymous(None)).await.unwrap_err();
        assert!(e.to_string().contains("sync0_us"), "{e}");
        assert_eq!(m.status().recoveries, 1);

        // A configuration the network does not match: the error names the
        // slave; a good one brings it back.
        let wrong = Config::parse(&text.replace("product_code = 0x402", "product_code = 0x403"), "t.toml".as_ref());
        let e = m.apply_config(wrong.unwrap(), Call::anonymous(Some(Duration::from_secs(2)))).await.unwrap_err();
        assert!(e.to_string().contains("slave 1"), "{e}");
        m.apply_config(new, Call::anonymous(Some(Duration::from_secs(30)))).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.status().phase, Phase::Running);
    });
    m.stop();
}
