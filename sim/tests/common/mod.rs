//! A minimal host that talks to the simulated chip with `ecmxf-wire` packets
//! only, the way a driver on the SPI bus would: wait for INT0, clock a whole
//! packet, read the answer to the previous command from what came back.
#![allow(dead_code)]

use ecmxf_sim::{Chip, ChipConfig, Network};
use ecmxf_wire::flags::ControlFlags;
use ecmxf_wire::payload::control::InfoUpdate;
use ecmxf_wire::{
    CheckType, CommandCode, CommandHeader, DecodeError, Reply, Request, ResponseHeader, decode_response, encode_request,
};

/// The host side of the link.
pub struct Host {
    pub chip: Chip,
    pub now: u64,
    pub index: u8,
    pub check: CheckType,
    pub data_size: usize,
    pub control: ControlFlags,
    /// INT0 polarity the host expects (active-high after power-up).
    pub int0_active_high: bool,
    /// RxFIFO count from the last header read.
    pub last_rx_count: u8,
}

/// What came back from one exchange.
#[derive(Clone, Debug)]
pub struct Answer {
    pub header: ResponseHeader,
    pub data: Vec<u8>,
}

impl Host {
    pub fn new(net: Network) -> Self {
        Self::with_config(net, ChipConfig::default())
    }

    pub fn with_config(net: Network, config: ChipConfig) -> Self {
        Self {
            chip: Chip::new(net, config),
            now: 0,
            index: 0,
            check: CheckType::Fixed,
            data_size: 112,
            control: ControlFlags::empty(),
            int0_active_high: true,
            last_rx_count: 0,
        }
    }

    pub fn packet_len(&self) -> usize {
        self.data_size + 32
    }

    /// Clocks raw bytes now, without waiting for INT0.
    pub fn clock(&mut self, mosi: &[u8]) -> Vec<u8> {
        let mut miso = vec![0u8; mosi.len()];
        self.chip.transfer(self.now, mosi, &mut miso);
        self.now += mosi.len() as u64 * self.chip.byte_ns();
        miso
    }

    /// Waits for INT0 (ready), then clocks a packet.
    pub fn exchange_raw(&mut self, mosi: &[u8]) -> Vec<u8> {
        self.now = self.now.max(self.chip.ready_at());
        assert_eq!(self.chip.int0_level(self.now), self.int0_active_high, "INT0 must be active when the chip is ready");
        self.clock(mosi)
    }

    fn next_index(&mut self) -> u8 {
        self.index = self.index.wrapping_add(1);
        self.index
    }

    /// Sends one request; returns the raw answer bytes (to the previous
    /// command) and the header sent.
    pub fn send<'a, R: Request<'a>>(&mut self, req: &R) -> (Vec<u8>, CommandHeader) {
        let mut header = CommandHeader::new(R::CODE, self.next_index());
        header.control = std::mem::take(&mut self.control);
        let mut buf = vec![0u8; self.packet_len()];
        let sent = encode_request(req, header, self.check, &mut buf).expect("encode");
        (self.exchange_raw(&buf), sent)
    }

    /// Decodes an answer with the check type in force.
    pub fn decode(&self, bytes: &[u8]) -> Result<Answer, DecodeError> {
        decode_response(bytes, self.check).map(|p| Answer { header: p.header, data: p.data.to_vec() })
    }

    /// Sends `req` and a following INFO_UPDATE, returning the answer to `req`.
    pub fn call<'a, R: Request<'a>>(&mut self, req: &R) -> Answer {
        let (_, sent) = self.send(req);
        let (bytes, _) = self.send(&InfoUpdate);
        let a = self.decode(&bytes).expect("answer decodes");
        assert_eq!((a.header.index, a.header.code), (sent.index, sent.code), "answer echoes index and code");
        a
    }

    /// `call`, then the reply parsed as `P`.
    pub fn get<'a, R: Request<'a>, P: for<'b> Reply<'b>>(&mut self, req: &R) -> P {
        let a = self.call(req);
        assert_eq!(a.header.code, P::CODE);
        P::decode(&ecmxf_wire::ReplyFields { value: a.header.return_value, data_len: a.header.data_len }, &a.data)
            .expect("reply parses")
    }

    /// Polls with INFO_UPDATE until the blocking slot is free; returns the
    /// last header.
    pub fn wait_idle(&mut self) -> ResponseHeader {
        for _ in 0..1_000_000 {
            let (bytes, _) = self.send(&InfoUpdate);
            let h = self.decode(&bytes).expect("status decodes").header;
            if !h.blocking_busy() {
                return h;
            }
            self.now += 200_000;
        }
        panic!("blocking command never finished");
    }

    /// Runs a blocking command to completion; returns the status after it.
    pub fn blocking<'a, R: Request<'a>>(&mut self, req: &R) -> ResponseHeader {
        assert!(R::CODE.is_blocking(), "{} is not blocking", R::CODE);
        let a = self.call(req);
        assert!(
            !a.header.errors.contains(ecmxf_wire::ErrorFlags::COMMAND_ERROR),
            "{} refused: {:?}",
            R::CODE,
            a.header
        );
        self.wait_idle()
    }

    /// Advances simulated time without traffic.
    pub fn idle(&mut self, ns: u64) {
        self.now += ns;
        self.chip.advance_to(self.now);
    }
}

/// The code of a header, for assertions.
pub fn code(h: &ResponseHeader) -> CommandCode {
    h.code
}

/// Frame sizes after [`bring_up_to_op`].
#[derive(Clone, Copy, Debug)]
pub struct Frames {
    pub rx: usize,
    pub tx: usize,
}

/// ECAT_INIT (125 us DC), PRE-OP, SAFE-OP, OP with the default mappings,
/// FIFO on with `prefill` zero frames. No assertions beyond success.
pub fn bring_up_to_op(h: &mut Host, prefill: usize) -> Frames {
    use ecmxf_wire::EcatState;
    use ecmxf_wire::payload::ecat_init::{DcTiming, EcatInit};
    use ecmxf_wire::payload::fifo::{FifoEnable, FifoPackSize, FifoPackSizeGet};
    use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoDirection, PdoFifoOp};
    use ecmxf_wire::payload::state::{SlaveSelector, StateSet};
    h.call(&InfoUpdate);
    let dc = DcTiming { assign_activate: 0x0300, sync0_ns: 125_000, sync1_ns: 0, shift_ns: 0 };
    h.blocking(&EcatInit { special_slaves: false, master_shift: false, disable_lrw: false, dc });
    h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::SafeOp });
    let rx: FifoPackSize = h.get(&FifoPackSizeGet(PdoDirection::Outputs));
    let tx: FifoPackSize = h.get(&FifoPackSizeGet(PdoDirection::Inputs));
    let frames = Frames { rx: rx.0.into(), tx: tx.0.into() };
    let per_packet = h.data_size / frames.rx.max(1);
    let mut left = prefill;
    while left > 0 {
        let n = left.min(per_packet);
        let zeros = vec![0u8; frames.rx * n];
        h.call(&PdoFifoOp { op: FifoOpFlags::WRITE, frames: n as u8, outputs: &zeros });
        left -= n;
    }
    let st = h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::Op });
    assert_eq!(st.ecat_state, EcatState::Op);
    h.call(&FifoEnable(true));
    frames
}
