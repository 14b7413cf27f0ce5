//! Packet exchange with the chip's rules (v049 SPI 命令傳送與回應接收說明;
//! docs/protocol.md §6 and §7).
//!
//! The answer to a packet arrives with the next one, and a packet with the
//! same index and code as the one before it does not execute again but
//! repeats its answer. Two ways of sending follow:
//!
//! - **Guarded** ([`Port::call`]): send `C` with a fresh index, then resend
//!   the identical packet until `C`'s answer arrives intact. The resend never
//!   executes `C` twice; a corrupt answer is recovered by resending again; an
//!   intact answer that does not echo `C` means `C` failed its check word
//!   and never ran, so resending it is safe too. Every command whose answer
//!   matters goes this way.
//! - **Once** ([`Port::send_once`]): send, and look at the answer when the
//!   next exchange brings it ([`Port::answer_to`]); a lost one is asked
//!   again later. Only for what costs nothing to repeat: questions, polls,
//!   and the start of a read (`engine::slot::transaction`). The answers to
//!   the last [`ONCE_KEPT`] packets sent once are kept as they arrive,
//!   whatever exchange brings them: a FIFO call (two exchanges) or two
//!   between a read and its next look must not take its answer away, or
//!   the read runs again, and again while the FIFO keeps pressing.
//! - **Pipelined** ([`Port::send_pipelined`]): for the cyclic FIFO call,
//!   whose reads are destructive (v049 PDO_DATA_FIFO_OP takes the input
//!   frames out of the TxFIFO). Its answer rides on the next exchange,
//!   whoever makes it; the port keeps it and says what became of the call
//!   ([`Fate`]). While the call is still the last packet sent, a resend
//!   fetches its answer as a guarded call would ([`Port::fetch_pipelined`]);
//!   once another packet went out, a corrupt answer is lost for good.
//!   Sent and fetched at once, a pipelined call is a guarded one.
//!
//! A packet the chip was not ready for comes back with the "not ready" check
//! word and was not taken: it is resent as is.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ecmxf_wire::flags::ControlFlags;
use ecmxf_wire::framing::{DATA_DEFAULT, DATA_MAX, OVERHEAD, PacketLayout, find_packet_start};
use ecmxf_wire::payload::control::InfoUpdate;
use ecmxf_wire::payload::spi::{CrcTypeSet, SpiReconfig};
use ecmxf_wire::{
    CheckType, CommandCode, CommandHeader, DecodeError, EncodeError, HEADER_LEN, PayloadError, Request, ResponseHeader,
    decode_response, encode_request, read_answer,
};

use crate::link::{Link, LinkError};

/// Why an exchange failed for good.
#[derive(Debug)]
pub enum PortError {
    /// The link failed.
    Link(LinkError),
    /// INT0 never said ready within the timeout.
    NotReady(Duration),
    /// A command could not be encoded (a bug or a bad argument upstream).
    Encode(EncodeError),
    /// No intact answer after this many attempts.
    NoAnswer {
        /// The command.
        code: CommandCode,
        /// Attempts made.
        attempts: u32,
        /// The last decode failure.
        last: Option<DecodeError>,
    },
    /// The packet size could not be found in the byte stream.
    Unsynchronized,
    /// The daemon is stopping: the wait was abandoned (see
    /// [`Port::set_abort`]).
    Aborted,
    /// A pipelined packet's answer was asked for again after another packet
    /// went out: resending it would run it twice.
    NotLastSent {
        /// The command.
        code: CommandCode,
    },
    /// An intact answer whose data does not read as its command's reply.
    BadAnswer {
        /// The command.
        code: CommandCode,
        /// What did not read.
        error: PayloadError,
    },
}

impl std::fmt::Display for PortError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Link(e) => write!(f, "{e}"),
            Self::NotReady(t) => write!(f, "chip not ready (INT0) within {t:?}"),
            Self::Encode(e) => write!(f, "cannot encode command: {e}"),
            Self::NoAnswer { code, attempts, last: Some(d) } => {
                write!(f, "no intact answer to {code} after {attempts} attempts (last: {d})")
            }
            Self::NoAnswer { code, attempts, last: None } => {
                write!(f, "no intact answer to {code} after {attempts} attempts")
            }
            Self::Unsynchronized => f.write_str("no packet boundary found in the chip's byte stream"),
            Self::Aborted => f.write_str("stopped while waiting for the chip"),
            Self::NotLastSent { code } => {
                write!(f, "the answer to {code} can no longer be fetched: another packet went out")
            }
            Self::BadAnswer { code, error } => write!(f, "the chip's answer to {code} does not read: {error}"),
        }
    }
}

impl std::error::Error for PortError {}

impl From<LinkError> for PortError {
    fn from(e: LinkError) -> Self {
        Self::Link(e)
    }
}

/// Guarded attempts of a first contact ([`Port::find_chip`]) before the
/// search: a chip at the port's settings answers the first.
const FIRST_CONTACT_ATTEMPTS: u32 = 2;

/// The longest single wait for INT0: how soon an abort is seen.
pub const WAIT_SLICE: Duration = Duration::from_millis(100);

/// Exchange counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PortStats {
    /// Packets clocked.
    pub exchanges: u64,
    /// Answers with the "not ready" check word (packet resent).
    pub not_ready: u64,
    /// Answers that failed validation.
    pub corrupt: u64,
    /// Guarded commands resent after a corrupt answer or a refused packet.
    pub retries: u64,
}

/// What an exchange brought back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Received {
    NotReady,
    Corrupt(DecodeError),
    Answer(ResponseHeader),
}

/// An answer: header and valid data, borrowed until the next exchange.
/// The data is read through the request that asked for it
/// ([`Answer::answer_to`]), as the type that request names: no caller
/// picks answer bytes apart by hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Answer<'a> {
    /// The header: status, error flags, FIFO counts, return value.
    pub header: ResponseHeader,
    data: &'a [u8],
}

impl<'a> Answer<'a> {
    /// The data read as the answer to `request` ([`Request::Answer`]); an
    /// answer to another command, or a NOP, is refused.
    pub fn answer_to<'q, R: Request<'q>>(&self, request: &R) -> Result<R::Answer<'a>, PayloadError> {
        read_answer(request, &self.header, self.data)
    }

    /// The valid data untouched, for answers relayed to a client as the chip
    /// gave them (the peripheral commands' pass-through).
    pub fn relayed(&self) -> &'a [u8] {
        self.data
    }
}

/// How many packets sent once have their answers kept (a transaction's
/// read or poll, and the emergency question beside it).
pub const ONCE_KEPT: usize = 3;

/// A packet sent once and, when it came, its answer (data copied into a
/// buffer of the largest data section: nothing is allocated once running).
#[derive(Debug)]
struct OnceAnswer {
    sent: Option<(u8, CommandCode)>,
    header: Option<ResponseHeader>,
    data: Vec<u8>,
}

/// What became of a packet sent pipelined ([`Port::send_pipelined`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fate {
    /// No exchange has brought its answer yet.
    Waiting,
    /// Its answer arrived intact ([`Port::pipelined`] gives it).
    Answered,
    /// The next exchange brought an intact answer to something else: the
    /// chip refused the packet for its check word and never ran it
    /// (docs/protocol.md §7).
    Refused,
    /// The next exchange brought a corrupt answer: the call ran (a packet
    /// refused on the way in is answered intact), and what its answer
    /// carried is gone unless the packet can still be resent.
    Lost,
}

/// A packet sent pipelined, as the port follows it.
#[derive(Clone, Copy, Debug)]
pub struct Pipelined<'a> {
    /// What became of it.
    pub fate: Fate,
    /// Its answer, once it arrived intact.
    pub answer: Option<Answer<'a>>,
    /// How many times the packet had been resent when that answer was
    /// made: 0, made as the packet ran; 1, by its first resend; and so on.
    /// The chip answers a repeat with fresh counts, taken as the packet
    /// before the repeat arrived (docs/protocol.md §12): from 2 on, after
    /// the packet itself ran.
    pub resends: u32,
}

/// How many pipelined packets the port follows at once: the one whose
/// answer the next exchange brings, and the one before it, until the
/// engine has taken its answer.
const PIPELINED_KEPT: usize = 2;

/// A packet sent pipelined and what became of it; the answer's data is
/// copied into a buffer of the largest data section (nothing is allocated
/// once running).
#[derive(Debug)]
struct PipelinedAnswer {
    sent: Option<(u8, CommandCode)>,
    fate: Fate,
    /// How many times the packet had been resent when the answer that
    /// arrived was made (see [`Pipelined::resends`]).
    resends: u32,
    header: Option<ResponseHeader>,
    data: Vec<u8>,
}

/// The chip's packet port over a link.
#[derive(Debug)]
pub struct Port<L> {
    link: L,
    check: CheckType,
    layout: PacketLayout,
    tx: Vec<u8>,
    rx: Vec<u8>,
    prev_rx: Vec<u8>,
    prev_header: Option<ResponseHeader>,
    /// The answers to the last packets sent once (see [`Port::answer_to`]),
    /// the newest at `once_next - 1`.
    once: [OnceAnswer; ONCE_KEPT],
    once_next: usize,
    /// Packets sent pipelined (see [`Port::send_pipelined`]).
    pipelined: [PipelinedAnswer; PIPELINED_KEPT],
    next_index: u8,
    last_sent: Option<(u8, CommandCode)>,
    /// How many times `last_sent` has been resent since it was first
    /// taken (repeats, which the chip does not execute but answers again
    /// with fresh counts).
    repeats: u32,
    /// Control bits to send with the next packet (error clears).
    pub pending_control: ControlFlags,
    ready_timeout: Duration,
    abort: Option<Arc<AtomicBool>>,
    max_attempts: u32,
    status: ResponseHeader,
    /// The exchange that brought `status`.
    status_exchange: u64,
    stats: PortStats,
    /// How long an exchange takes, ns, averaged (1/8 weight for the newest).
    exchange_ns: u64,
    /// When the last exchange began (None: none yet).
    last_began: Option<Instant>,
}

impl<L: Link> Port<L> {
    /// A port in the chip's power-up state (112-byte data, fixed check word).
    pub fn new(link: L) -> Self {
        Self {
            link,
            check: CheckType::Fixed,
            layout: PacketLayout::default(),
            tx: Vec::with_capacity(DATA_MAX + 32),
            rx: Vec::with_capacity(DATA_MAX + 32),
            prev_rx: Vec::with_capacity(DATA_MAX + 32),
            prev_header: None,
            once: std::array::from_fn(|_| OnceAnswer { sent: None, header: None, data: Vec::with_capacity(DATA_MAX) }),
            once_next: 0,
            pipelined: std::array::from_fn(|_| PipelinedAnswer {
                sent: None,
                fate: Fate::Waiting,
                resends: 0,
                header: None,
                data: Vec::with_capacity(DATA_MAX),
            }),
            next_index: 0,
            last_sent: None,
            repeats: 0,
            pending_control: ControlFlags::empty(),
            ready_timeout: Duration::from_millis(100),
            abort: None,
            max_attempts: 16,
            status: ResponseHeader::default(),
            status_exchange: 0,
            stats: PortStats::default(),
            exchange_ns: 0,
            last_began: None,
        }
    }

    /// The link.
    pub fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    /// Gives the link back.
    pub fn into_link(self) -> L {
        self.link
    }

    /// How long to wait for INT0 before giving up.
    pub fn set_ready_timeout(&mut self, t: Duration) {
        self.ready_timeout = t;
    }

    /// While `flag` is set, every exchange fails with
    /// [`PortError::Aborted`] instead of waiting for INT0, and a wait in
    /// progress ends within [`WAIT_SLICE`]: a daemon told to stop during
    /// bring-up or recovery (a chip that never gets ready, a link that
    /// hangs) stops within a second. `None` disarms it (the safe stop
    /// itself must reach the chip).
    pub fn set_abort(&mut self, flag: Option<Arc<AtomicBool>>) {
        self.abort = flag;
    }

    fn aborted(&self) -> bool {
        self.abort.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// Waits for INT0 up to the ready timeout, in slices so an abort is
    /// seen; `Ok(false)` on time-out.
    fn wait_ready(&mut self) -> Result<bool, PortError> {
        let start = Instant::now();
        loop {
            if self.aborted() {
                return Err(PortError::Aborted);
            }
            let left = self.ready_timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                return Ok(false);
            }
            if self.link.wait_ready(left.min(WAIT_SLICE))? {
                return Ok(true);
            }
        }
    }

    /// One transfer after INT0 said ready. A link that waits for INT0 as
    /// part of the transfer ([`LinkError::NotReady`]) is given the rest of
    /// the ready timeout, slice by slice.
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError> {
        let start = Instant::now();
        loop {
            match self.link.transfer(tx, rx) {
                Err(LinkError::NotReady) => {
                    if self.aborted() {
                        return Err(PortError::Aborted);
                    }
                    let left = self.ready_timeout.saturating_sub(start.elapsed());
                    if left.is_zero() {
                        return Err(PortError::NotReady(self.ready_timeout));
                    }
                    self.link.wait_ready(left.min(WAIT_SLICE))?;
                }
                r => return r.map_err(PortError::Link),
            }
        }
    }

    /// How long one exchange takes on this link (the wait for INT0 and
    /// the transfer), averaged over the recent ones: what the engine
    /// plans around when it fits cyclic exchanges into a blocking
    /// command's run.
    pub fn exchange_time(&self) -> Duration {
        Duration::from_nanos(self.exchange_ns)
    }

    /// When the last exchange began, if one did: the chip noted its FIFO
    /// counts as that packet arrived, and the next answer reports them
    /// (docs/protocol.md §12).
    pub fn last_began(&self) -> Option<Instant> {
        self.last_began
    }

    /// Counters.
    pub fn stats(&self) -> PortStats {
        self.stats
    }

    /// The newest intact header.
    pub fn status(&self) -> &ResponseHeader {
        &self.status
    }

    /// The exchange (as counted by [`PortStats::exchanges`]) that brought
    /// [`Port::status`]: a header brought after the exchange of packet `n`
    /// was built by the chip after it processed `n`.
    pub fn status_exchange(&self) -> u64 {
        self.status_exchange
    }

    /// Check type in force.
    pub fn check(&self) -> CheckType {
        self.check
    }

    /// Data-section size in force.
    pub fn data_size(&self) -> usize {
        self.layout.data_size()
    }

    /// Records `sent` as the last packet sent (its index and code, which a
    /// repeat must match to be a poll), not resent yet; `None`: no packet
    /// the chip may have taken is known (a resize).
    fn took(&mut self, sent: Option<(u8, CommandCode)>) {
        self.last_sent = sent;
        self.repeats = 0;
    }

    fn fresh_index(&mut self) -> u8 {
        self.next_index = self.next_index.wrapping_add(1);
        if self.last_sent.is_some_and(|(i, _)| i == self.next_index) {
            self.next_index = self.next_index.wrapping_add(1);
        }
        self.next_index
    }

    fn encode<'a, R: Request<'a>>(&mut self, req: &R, index: u8, check: CheckType) -> Result<CommandHeader, PortError> {
        let mut header = CommandHeader::new(R::CODE, index);
        header.control = std::mem::take(&mut self.pending_control);
        self.tx.clear();
        self.tx.resize(self.layout.packet_len(), 0);
        encode_request(req, header, check, &mut self.tx).map_err(PortError::Encode)
    }

    /// Waits for INT0, clocks `self.tx`, decodes into `self.rx`.
    fn clock(&mut self, decode_as: CheckType) -> Result<Received, PortError> {
        let began = Instant::now();
        // The answer this exchange brings was made for the packet taken
        // before it: `last_sent`, resent `repeats` times by then.
        let made_for = (self.last_sent, self.repeats);
        if !self.wait_ready()? {
            return Err(PortError::NotReady(self.ready_timeout));
        }
        self.rx.clear();
        self.rx.resize(self.tx.len(), 0);
        let (tx, mut rx) = (std::mem::take(&mut self.tx), std::mem::take(&mut self.rx));
        let r = self.transfer(&tx, &mut rx);
        (self.tx, self.rx) = (tx, rx);
        r?;
        self.stats.exchanges += 1;
        self.last_began = Some(began);
        let took = began.elapsed().as_nanos().min(u128::from(u32::MAX)) as u64;
        self.exchange_ns = match self.exchange_ns {
            0 => took,
            avg => avg - avg / 8 + took / 8,
        };
        Ok(match decode_response(&self.rx, decode_as) {
            Ok(p) => {
                let header = p.header;
                self.status = header;
                self.status_exchange = self.stats.exchanges;
                self.keep_once_answer(header);
                self.note_pipelined(Some(header), made_for);
                Received::Answer(header)
            }
            Err(DecodeError::ChipNotReady) => {
                self.stats.not_ready += 1;
                Received::NotReady
            }
            Err(e) => {
                self.stats.corrupt += 1;
                self.note_pipelined(None, made_for);
                Received::Corrupt(e)
            }
        })
    }

    /// Settles the packets sent pipelined with an exchange's answer
    /// (`None`: corrupt). Its own answer settles a packet whatever came
    /// before; anything else settles only one still waiting, as refused
    /// (intact) or lost (corrupt): the first exchange after a packet brings
    /// its answer or none. A "not ready" exchange carries no answer and
    /// never comes here.
    fn note_pipelined(&mut self, header: Option<ResponseHeader>, made_for: (Option<(u8, CommandCode)>, u32)) {
        for slot in &mut self.pipelined {
            let Some(sent) = slot.sent else { continue };
            if slot.fate == Fate::Answered {
                continue;
            }
            match header {
                Some(h) if (h.index, h.code) == sent && !h.is_nop() => {
                    let n = usize::from(h.data_len);
                    slot.data.clear();
                    slot.data.extend_from_slice(self.rx.get(HEADER_LEN..HEADER_LEN + n).unwrap_or(&[]));
                    slot.header = Some(h);
                    slot.fate = Fate::Answered;
                    slot.resends = if made_for.0 == Some(sent) { made_for.1 } else { 0 };
                }
                Some(_) if slot.fate == Fate::Waiting => slot.fate = Fate::Refused,
                None if slot.fate == Fate::Waiting => slot.fate = Fate::Lost,
                _ => {}
            }
        }
    }

    /// Keeps `header`'s answer (in `self.rx`) if it answers a packet sent
    /// once that has no answer yet: the first intact one (a packet is
    /// answered once; a NOP carries no answer).
    fn keep_once_answer(&mut self, header: ResponseHeader) {
        if header.is_nop() {
            return;
        }
        let sent = Some((header.index, header.code));
        if let Some(slot) = self.once.iter_mut().find(|o| o.sent == sent && o.header.is_none()) {
            let n = usize::from(header.data_len);
            slot.data.clear();
            slot.data.extend_from_slice(self.rx.get(HEADER_LEN..HEADER_LEN + n).unwrap_or(&[]));
            slot.header = Some(header);
        }
    }

    /// The answer to the packet sent once with `index` and `code`, if it
    /// arrived intact (whichever exchange brought it) and that packet is
    /// among the last [`ONCE_KEPT`] sent once.
    pub fn answer_to(&self, index: u8, code: CommandCode) -> Option<Answer<'_>> {
        let o = self.once.iter().find(|o| o.sent == Some((index, code)))?;
        Some(Answer { header: o.header?, data: &o.data })
    }

    fn keep_prev(&mut self, header: Option<ResponseHeader>) {
        std::mem::swap(&mut self.prev_rx, &mut self.rx);
        self.prev_header = header;
    }

    /// The answer to the packet sent before the last call, if it arrived
    /// intact during that call.
    pub fn previous(&self) -> Option<Answer<'_>> {
        let h = self.prev_header?;
        let n = usize::from(h.data_len);
        Some(Answer { header: h, data: self.prev_rx.get(HEADER_LEN..HEADER_LEN + n).unwrap_or(&[]) })
    }

    fn current(&self, header: ResponseHeader) -> Answer<'_> {
        let n = usize::from(header.data_len);
        Answer { header, data: self.rx.get(HEADER_LEN..HEADER_LEN + n).unwrap_or(&[]) }
    }

    /// Sends `req` guarded (see the module doc) and returns its answer. The
    /// answer to the packet before it is kept in [`Port::previous`].
    pub fn call<'a, R: Request<'a>>(&mut self, req: &R) -> Result<Answer<'_>, PortError> {
        let index = self.fresh_index();
        self.encode(req, index, self.check)?;
        self.send_guarded(index, R::CODE, self.check)
    }

    /// Sends `req` guarded and reads its answer as the type the request
    /// names; for callers that need nothing of the header but what the
    /// reply carries.
    pub fn ask<'a, R: Request<'a>>(&mut self, req: &R) -> Result<R::Answer<'_>, PortError> {
        let answer = self.call(req)?;
        answer.answer_to(req).map_err(|error| PortError::BadAnswer { code: R::CODE, error })
    }

    fn send_guarded(&mut self, index: u8, code: CommandCode, decode_as: CheckType) -> Result<Answer<'_>, PortError> {
        let mut sent_once = false;
        let mut last = None;
        for _ in 0..self.max_attempts * 2 {
            let got = self.clock(decode_as)?;
            if !sent_once {
                match got {
                    Received::NotReady => continue,
                    Received::Answer(h) => self.keep_prev(Some(h)),
                    Received::Corrupt(e) => {
                        last = Some(e);
                        self.keep_prev(None);
                    }
                }
                sent_once = true;
                self.took(Some((index, code)));
                continue;
            }
            if got != Received::NotReady {
                self.repeats += 1;
            }
            match got {
                Received::NotReady => {}
                Received::Answer(h) if h.index == index && h.code == code && !h.is_nop() => {
                    return Ok(self.current(h));
                }
                // An intact answer that is not ours: our packet failed its
                // check word and did not run. Resending is safe.
                Received::Answer(_) => self.stats.retries += 1,
                Received::Corrupt(e) => {
                    last = Some(e);
                    self.stats.retries += 1;
                }
            }
        }
        Err(PortError::NoAnswer { code, attempts: self.max_attempts * 2, last })
    }

    /// Sends `req` once, without waiting for its answer: that arrives with
    /// the next exchange and is then [`Port::previous`] (a corrupt one is
    /// simply absent). For questions worth asking again rather than
    /// waiting for (the emergency watch, polls, a read's start); whatever
    /// answered the packet before is dropped. Returns the packet's index,
    /// which its answer echoes.
    pub fn send_once<'a, R: Request<'a>>(&mut self, req: &R) -> Result<u8, PortError> {
        let index = self.send_unwaited(req)?;
        let slot = &mut self.once[self.once_next];
        (slot.sent, slot.header) = (Some((index, R::CODE)), None);
        self.once_next = (self.once_next + 1) % ONCE_KEPT;
        Ok(index)
    }

    /// Sends `req` pipelined (see the module doc): one exchange, which
    /// brings the answer to the packet before; this packet's answer comes
    /// with the next exchange, whoever makes it, and is followed by
    /// [`Port::pipelined`] until [`Port::forget_pipelined`]. Of the
    /// packets followed, one already settled gives way when more are sent
    /// than the port keeps. Returns the packet's index.
    pub fn send_pipelined<'a, R: Request<'a>>(&mut self, req: &R) -> Result<u8, PortError> {
        let index = self.send_unwaited(req)?;
        let sent = Some((index, R::CODE));
        // The index wrapped round to a packet still followed: that one is
        // long settled, and must not be read as this one.
        for p in self.pipelined.iter_mut().filter(|p| p.sent == sent) {
            p.sent = None;
        }
        // A free slot, else one already settled: the engine forgets each
        // packet once it has taken what became of it.
        let at = (self.pipelined.iter().position(|p| p.sent.is_none()))
            .or_else(|| self.pipelined.iter().position(|p| p.fate != Fate::Waiting))
            .unwrap_or(0);
        let slot = &mut self.pipelined[at];
        (slot.sent, slot.fate, slot.header) = (sent, Fate::Waiting, None);
        Ok(index)
    }

    /// Sends `req` with a fresh index until the chip takes it, without
    /// waiting for its answer; the answer that exchange brought is kept as
    /// [`Port::previous`].
    fn send_unwaited<'a, R: Request<'a>>(&mut self, req: &R) -> Result<u8, PortError> {
        let index = self.fresh_index();
        self.encode(req, index, self.check)?;
        loop {
            match self.clock(self.check)? {
                Received::NotReady => continue,
                Received::Answer(h) => self.keep_prev(Some(h)),
                Received::Corrupt(_) => self.keep_prev(None),
            }
            self.took(Some((index, R::CODE)));
            return Ok(index);
        }
    }

    /// What became of the packet sent pipelined with `index` and `code`,
    /// and its answer when it arrived intact; `None` for a packet not
    /// followed.
    pub fn pipelined(&self, index: u8, code: CommandCode) -> Option<Pipelined<'_>> {
        let slot = self.pipelined.iter().find(|p| p.sent == Some((index, code)))?;
        let answer = slot.header.map(|header| Answer { header, data: &slot.data });
        Some(Pipelined { fate: slot.fate, answer, resends: slot.resends })
    }

    /// Stops following the packet sent pipelined with `index` and `code`.
    pub fn forget_pipelined(&mut self, index: u8, code: CommandCode) {
        if let Some(slot) = self.pipelined.iter_mut().find(|p| p.sent == Some((index, code))) {
            slot.sent = None;
        }
    }

    /// Whether the packet with `index` and `code` is the last one sent, so
    /// that resending it only fetches its answer again.
    pub fn is_last_sent(&self, index: u8, code: CommandCode) -> bool {
        self.last_sent == Some((index, code))
    }

    /// Whether the last packet clocked was the first sending of the one
    /// with `index` and `code` (not a resend): the chip executed it then,
    /// after noting its FIFO levels, so the next answer's counts come from
    /// before its effects (docs/protocol.md §12).
    pub fn ran_last(&self, index: u8, code: CommandCode) -> bool {
        self.last_sent == Some((index, code)) && self.repeats == 0
    }

    /// Fetches the answer to the packet sent pipelined with `index` and
    /// `code` by resending it as a guarded call does, while it is still the
    /// last packet sent ([`Port::is_last_sent`]; otherwise
    /// [`PortError::NotLastSent`]): the resend never runs it twice, and a
    /// packet the chip refused runs now. Its fate is then
    /// [`Fate::Answered`].
    pub fn fetch_pipelined(&mut self, index: u8, code: CommandCode) -> Result<(), PortError> {
        if self.pipelined(index, code).is_some_and(|p| p.fate == Fate::Answered) {
            return Ok(());
        }
        if !self.is_last_sent(index, code) {
            return Err(PortError::NotLastSent { code });
        }
        let mut last = None;
        for _ in 0..self.max_attempts * 2 {
            let got = self.clock(self.check)?;
            if got != Received::NotReady {
                self.repeats += 1;
            }
            match got {
                Received::NotReady => continue,
                Received::Corrupt(e) => last = Some(e),
                Received::Answer(_) => {}
            }
            if self.pipelined(index, code).is_some_and(|p| p.fate == Fate::Answered) {
                return Ok(());
            }
            self.stats.retries += 1;
        }
        Err(PortError::NoAnswer { code, attempts: self.max_attempts * 2, last })
    }

    /// Switches the check type (command 25): the command goes out with the
    /// old type, everything after it with the new one. A guarded status call
    /// in the new type only succeeds if the chip switched; otherwise the old
    /// type is kept and the switch sent again.
    pub fn set_check(&mut self, new: CheckType) -> Result<(), PortError> {
        let old = self.check;
        for _ in 0..self.max_attempts {
            let index = self.fresh_index();
            self.encode(&CrcTypeSet(new), index, old)?;
            while let Received::NotReady = self.clock(old)? {}
            self.took(Some((index, CommandCode::CrcTypeSet)));
            self.check = new;
            if self.call(&InfoUpdate).is_ok() {
                return Ok(());
            }
            self.check = old;
            self.stats.retries += 1;
        }
        Err(PortError::NoAnswer { code: CommandCode::CrcTypeSet, attempts: self.max_attempts, last: None })
    }

    /// Changes the data-section size (command 23, always with the fixed check
    /// word; the chip counts one CRC error for it, v049 note under 23). If
    /// the answer does not come back in the new size, the port finds the
    /// size in the byte stream and tries again while it is still the old one.
    pub fn resize(&mut self, data_size: usize) -> Result<(), PortError> {
        let new = PacketLayout::new(data_size).map_err(PortError::Encode)?;
        for _ in 0..self.max_attempts {
            if self.layout == new {
                return Ok(());
            }
            let index = self.fresh_index();
            self.encode(&SpiReconfig { data_size: data_size as u16 }, index, CheckType::Fixed)?;
            while let Received::NotReady = self.clock(self.check)? {}
            self.took(Some((index, CommandCode::SpiReconfig)));
            self.layout = new;
            if self.call(&InfoUpdate).is_err() {
                self.synchronize()?;
            }
        }
        if self.layout == new {
            Ok(())
        } else {
            Err(PortError::NoAnswer { code: CommandCode::SpiReconfig, attempts: self.max_attempts, last: None })
        }
    }

    /// The first contact with a chip in a state the host does not know (as
    /// `ecmxfd probe`, another driver or a daemon stopped mid-way left it:
    /// another packet size, CRC-32): one InfoUpdate with few attempts, and
    /// at the first failure the search ([`Port::synchronize`]). The garbled
    /// answers of a first contact at the wrong packet size and check are
    /// the host's ignorance of the chip's settings, not link errors: they
    /// are not counted (a start after a probe counted 33 corrupt answers
    /// and as many retries).
    pub fn find_chip(&mut self) -> Result<(), PortError> {
        let before = self.stats;
        let attempts = std::mem::replace(&mut self.max_attempts, FIRST_CONTACT_ATTEMPTS);
        let first = self.call(&InfoUpdate).map(|_| ());
        self.max_attempts = attempts;
        if first.is_err() {
            self.synchronize()?;
            self.stats.corrupt = before.corrupt;
            self.stats.retries = before.retries;
        }
        Ok(())
    }

    /// Finds the packet size and check type of a chip in an unknown state:
    /// clocks single bytes until it has seen an end word followed by a start
    /// word twice, takes their distance as the packet length (docs/protocol.md
    /// §3; the vendor driver does the same), completes the packet in
    /// progress with zeros (the chip refuses it as a bad packet), then reads
    /// the check type from the status byte of the next answer.
    pub fn synchronize(&mut self) -> Result<(), PortError> {
        let mut stream: Vec<u8> = Vec::with_capacity(3 * (DATA_MAX + OVERHEAD));
        let mut starts: Vec<usize> = Vec::new();
        while starts.len() < 2 {
            if stream.len() > 3 * (DATA_MAX + OVERHEAD) {
                return Err(PortError::Unsynchronized);
            }
            stream.push(self.clock_byte()?);
            // The wire crate's boundary rule, on the newest 8 bytes.
            let tail = stream.len().saturating_sub(8);
            if let Some(start) = find_packet_start(&stream[tail..]) {
                starts.push(tail + start);
            }
        }
        let layout = PacketLayout::from_packet_len(starts[1] - starts[0]).ok_or(PortError::Unsynchronized)?;
        let in_packet = stream.len() - starts[1];
        let fill = vec![0u8; layout.packet_len() - in_packet];
        let mut sink = vec![0u8; fill.len()];
        if !self.wait_ready()? {
            return Err(PortError::NotReady(self.ready_timeout));
        }
        self.transfer(&fill, &mut sink)?;
        self.layout = layout;
        self.took(None);
        for _ in 0..self.max_attempts {
            let index = self.fresh_index();
            self.encode(&InfoUpdate, index, self.check)?;
            if let Received::Answer(h) = self.clock(self.check)? {
                self.check = h.status.check_type;
            } else if let Some(check) = CheckType::ALL.into_iter().find(|c| decode_response(&self.rx, *c).is_ok()) {
                self.check = check;
            }
            self.took(Some((index, CommandCode::InfoUpdate)));
            if self.call(&InfoUpdate).is_ok() {
                return Ok(());
            }
        }
        Err(PortError::Unsynchronized)
    }

    /// Clocks one zero byte after INT0 said ready and returns the byte the
    /// chip sent: the unit [`Port::synchronize`] reads an unknown stream
    /// in, and what `ecmxfd probe` looks at when no boundary turns up. A
    /// byte that completes a packet makes the chip process it (a packet of
    /// zeros is refused as bad), so INT0 goes busy once per packet length.
    pub fn clock_byte(&mut self) -> Result<u8, PortError> {
        if !self.wait_ready()? {
            return Err(PortError::NotReady(self.ready_timeout));
        }
        let mut byte = [0u8; 1];
        self.transfer(&[0], &mut byte)?;
        Ok(byte[0])
    }

    /// Size of the data section a fresh chip uses.
    pub const POWER_UP_DATA: usize = DATA_DEFAULT;
}
