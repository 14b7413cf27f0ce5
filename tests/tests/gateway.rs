//! The ETG.8200 mailbox gateway (docs/mailbox.md), with a client written here that
//! speaks it over UDP as an engineering tool does (an EtherCAT header of
//! type 5 and one mailbox message addressed by station address): SDO
//! upload and download to a slave while the engine runs its 1 ms cycle
//! (no FIFO alarm, input frames keep coming), the master's own object
//! dictionary at address 0, a station no slave has, and a malformed
//! datagram (dropped, counted, said once in the log).

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, Simulator, run, temp_dir};
use ecmxf_wire::mbx::sdo::{SdoRequest, SdoResponse};
use ecmxf_wire::mbx::{MailboxError, MailboxHeader, MailboxType, Message};

struct Client {
    socket: UdpSocket,
    counter: u8,
}

impl Client {
    /// One request, one answer: the answer's header and body.
    fn ask(&mut self, station: u16, body: &[u8]) -> (MailboxHeader, Vec<u8>) {
        self.counter = ecmxf_wire::mbx::next_counter(self.counter);
        let header = MailboxHeader { address: station, ..MailboxHeader::new(MailboxType::Coe, 0, self.counter) };
        let mut d = vec![0u8; 2 + 6 + body.len()];
        let n = Message::write(header, body, &mut d[2..]).unwrap();
        d[..2].copy_from_slice(&(n as u16 | 5 << 12).to_le_bytes());
        self.socket.send(&d).unwrap();
        let mut buf = [0u8; 1500];
        let got = self.socket.recv(&mut buf).expect("an answer from the gateway");
        let head = u16::from_le_bytes([buf[0], buf[1]]);
        assert_eq!(head >> 12, 5, "a mailbox frame");
        assert_eq!(usize::from(head & 0x7FF), got - 2, "its length");
        let m = Message::parse(&buf[2..got]).unwrap();
        assert_eq!(m.header.counter, self.counter, "counted as the request was");
        (m.header, m.body.to_vec())
    }

    fn upload(&mut self, station: u16, index: u16, subindex: u8) -> Result<Vec<u8>, u32> {
        let mut b = [0u8; 16];
        let n = SdoRequest::Upload { index, subindex, complete_access: false }.encode(&mut b).unwrap();
        let (h, body) = self.ask(station, &b[..n]);
        assert_eq!((h.kind, h.address), (MailboxType::Coe, station), "a CoE answer from the station asked");
        match SdoResponse::decode(&body).unwrap() {
            SdoResponse::Uploaded { data, .. } => Ok(data.to_vec()),
            SdoResponse::Abort { code, .. } => Err(code),
            other => panic!("{other:?}"),
        }
    }
}

fn counters(d: &Daemon) -> (u64, u64) {
    let v = d.ctl(&["master", "--json"]).json();
    let c = &v["counters"];
    (c["fifo_alarms"].as_u64().unwrap(), c["input_frames"].as_u64().unwrap())
}

#[test]
fn an_etg8200_client_reads_and_writes_sdos_through_the_gateway_during_op() {
    let dir = temp_dir("gateway");
    let sim = Simulator::serve(&dir, &[]);
    let port = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let extra = format!("[gateway]\nlisten = \"127.0.0.1:{port}\"\n");
    let mut d = Daemon::binary_with_config(&ecmxf_e2e::config_with_cycle(&sim.link(), "sync0_us = 1000\n", &extra));
    run(async { drop(d.connect().await) });
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    socket.connect(("127.0.0.1", port)).unwrap();
    let mut c = Client { socket, counter: 0 };
    let (alarms, frames) = counters(&d);
    let started = Instant::now();

    // The master at address 0: the configured address list, slave 1's
    // configuration.
    let station = c.upload(0, 0xF020, 2).map(|b| u16::from_le_bytes([b[0], b[1]])).expect("0xF020:02");
    assert_ne!(station, 0);
    assert_eq!(c.upload(0, 0x8001, 1).unwrap(), station.to_le_bytes());
    assert_eq!(c.upload(0, 0x8001, 3).unwrap(), b"TI CiA402 3-axis");
    assert_eq!(c.upload(0, 0xA001, 1).unwrap(), 8u16.to_le_bytes(), "slave 1 in OP");
    assert_eq!(c.upload(0, 0x7000, 0), Err(0x0602_0000), "no such object");

    // Slave 1 (the TI drive): identity, then a write read back.
    assert_eq!(c.upload(station, 0x1018, 1).unwrap(), 0x059Du32.to_le_bytes());
    let mut b = [0u8; 16];
    // 0x605A quick stop option code (not in the process data, which would
    // overwrite it every cycle).
    let n = SdoRequest::Download { index: 0x605A, subindex: 0, complete_access: false, data: &[5, 0] }
        .encode(&mut b)
        .unwrap();
    let (_, body) = c.ask(station, &b[..n]);
    assert_eq!(SdoResponse::decode(&body).unwrap(), SdoResponse::Downloaded { index: 0x605A, subindex: 0 });
    assert_eq!(c.upload(station, 0x605A, 0).unwrap(), [5, 0]);
    assert_eq!(d.ctl(&["upload", "-p", "1", "0x605A", "--json"]).json()["value"], 5, "what the master's own SDO reads");
    assert_eq!(c.upload(station, 0x605A, 7), Err(0x0609_0011), "the slave's own abort");
    for _ in 0..20 {
        assert_eq!(c.upload(station, 0x1018, 2).unwrap(), 0x0402u32.to_le_bytes());
    }
    // The process data went on meanwhile.
    let (alarms_after, frames_after) = counters(&d);
    let ms = started.elapsed().as_millis() as u64;
    assert_eq!(alarms_after, alarms, "no FIFO alarm");
    assert!(frames_after - frames >= ms * 8 / 10, "{} input frames in {ms} ms", frames_after - frames);

    // A station no slave has: a mailbox error from that address.
    let (h, body) = c.ask(0x7777, &b[..n]);
    assert_eq!((h.kind, h.address), (MailboxType::Error, 0x7777));
    assert!(MailboxError::decode(&body).is_ok());

    // Not a mailbox request: dropped (no answer), counted, said once.
    c.socket.send(&[1, 2, 3]).unwrap();
    c.socket.send(&[0xFF; 40]).unwrap();
    c.socket.set_read_timeout(Some(Duration::from_millis(300))).unwrap();
    let mut buf = [0u8; 64];
    assert!(c.socket.recv(&mut buf).is_err(), "no answer to a malformed datagram");
    c.socket.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    assert_eq!(c.upload(station, 0x1018, 1).unwrap(), 0x059Du32.to_le_bytes(), "still served");
    let log = d.log();
    assert_eq!(log.matches("no mailbox request was dropped").count(), 1, "said once:\n{log}");
}
