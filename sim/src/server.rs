//! The simulator over a Unix stream socket, in real time: one SPI transfer
//! per message, plus the INT0/INT1 line states and run-time control. The
//! framing is documented in sim/README.md so a host driver in C or Python
//! can be written against it; [`SocketClient`] is the Rust side.
//!
//! Every message, both ways, is an 8-byte header and a payload:
//! `kind: u8, flags: u8, reserved: u16 = 0, length: u32 LE`.

use std::collections::HashMap;
use std::io::{self, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread;
use std::time::{Duration, Instant};

use crate::chip::Chip;
use crate::control;

/// One full-duplex transfer: payload = MOSI; reply payload = MISO, flags =
/// lines after the transfer.
pub const KIND_TRANSFER: u8 = 0x01;
/// Line states: reply flags = lines, payload = sim time (u64 LE, ns) and
/// time until the chip is ready (u64 LE, ns; 0 = ready).
pub const KIND_LINES: u8 = 0x02;
/// Wait until INT0 is active: payload = timeout (u32 LE, us); reply payload
/// = one byte, 1 when ready.
pub const KIND_WAIT_READY: u8 = 0x03;
/// Wait until INT1 is active: payload = timeout (u32 LE, us); reply payload
/// = one byte, 1 when active.
pub const KIND_WAIT_INT1: u8 = 0x04;
/// Wait until INT0 is active, then transfer: payload = timeout (u32 LE,
/// us) followed by MOSI; reply payload = MISO, flags = lines after the
/// transfer, or flags bit7 and no payload when INT0 stayed inactive (nothing
/// was clocked). One round trip per exchange instead of two.
pub const KIND_TRANSFER_WHEN_READY: u8 = 0x05;
/// One transfer with a forecast of INT0, for hosts that see the line as a
/// kernel does (edge events; the preload emulation of spidev and the GPIO
/// character device, sim/hw-emu): payload = MOSI; reply payload = MISO
/// followed by a [`Forecast`] (13 bytes), flags = lines after the transfer.
pub const KIND_TRANSFER_FORECAST: u8 = 0x06;
/// Wait until the lines change: payload = timeout (u32 LE, us), mask (u8),
/// the lines as the host knows them (u8); the server waits until `lines &
/// mask` differs from them or the time-out. Reply flags = lines, payload =
/// 1 byte (1 = changed) followed by a [`Forecast`]. Catches what no
/// transfer causes: `int0 stuck`, INT1 events.
pub const KIND_WAIT_LINES: u8 = 0x07;
/// Claim GPIO lines for this connection, as a line request does in the
/// kernel: payload = UTF-8 `CHIP CONSUMER OFFSET...`; reply flags 0 =
/// claimed, 1 = a line is held by another connection (payload: its
/// consumer). Claims end when the connection closes.
pub const KIND_GPIO_CLAIM: u8 = 0x08;
/// Who holds a GPIO line: payload = UTF-8 `CHIP OFFSET`; reply flags 0 =
/// free, 1 = held (payload: the consumer).
pub const KIND_GPIO_OWNER: u8 = 0x09;
/// Reply flag of [`KIND_TRANSFER_WHEN_READY`]: timed out, nothing clocked.
pub const FLAG_TIMED_OUT: u8 = 0x80;
/// A control command (UTF-8 text); reply flags 0 = ok, 1 = error, payload =
/// the answer text.
pub const KIND_CONTROL: u8 = 0x10;
/// The reply to a message the server could not understand; payload = text.
pub const KIND_ERROR: u8 = 0x7F;
/// Lines byte: INT0 electrical level.
pub const LINE_INT0: u8 = 1 << 0;
/// Lines byte: INT1 electrical level.
pub const LINE_INT1: u8 = 1 << 1;
/// [`Forecast::ready_lines`]: INT0 is held at its level by a fault (`int0
/// stuck`): packets make no edges.
pub const LINE_INT0_HELD: u8 = 1 << 7;
/// Largest payload accepted.
pub const MAX_PAYLOAD: usize = 64 * 1024;

/// What INT0 will do without further transfers: the chip's level is a
/// function of when it is ready again (v049 ECM-XF中斷: INT0 drops when a
/// packet is complete and rises when it is processed), so a host that is
/// told this once per transfer can time the rising edge itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Forecast {
    /// Packets the chip took during the transfer (each one a busy period:
    /// two edges of INT0, unless the line is held).
    pub packets: u32,
    /// Nanoseconds until the chip is ready again (0 = ready now).
    pub until_ready_ns: u64,
    /// The lines byte once the chip is ready (bit0 INT0's level then), and
    /// [`LINE_INT0_HELD`] when a fault holds INT0 (its level never moves).
    pub ready_lines: u8,
}

impl Forecast {
    /// Encoded size.
    pub const LEN: usize = 13;

    fn of(chip: &Chip, now: u64, packets: u32) -> Self {
        let ready_at = chip.ready_at().max(now);
        let held = if chip.faults.int0_stuck.is_some() { LINE_INT0_HELD } else { 0 };
        Self { packets, until_ready_ns: ready_at - now, ready_lines: Server::lines(chip, ready_at) | held }
    }

    /// The 13 bytes: packets (u32 LE), ns until ready (u64 LE), lines.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[..4].copy_from_slice(&self.packets.to_le_bytes());
        b[4..12].copy_from_slice(&self.until_ready_ns.to_le_bytes());
        b[12] = self.ready_lines;
        b
    }

    /// Reads the 13 bytes; `None` when short.
    pub fn decode(b: &[u8]) -> Option<Self> {
        let b: &[u8; Self::LEN] = b.get(..Self::LEN)?.try_into().ok()?;
        Some(Self {
            packets: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            until_ready_ns: u64::from_le_bytes([b[4], b[5], b[6], b[7], b[8], b[9], b[10], b[11]]),
            ready_lines: b[12],
        })
    }
}

fn write_msg(w: &mut impl Write, kind: u8, flags: u8, payload: &[u8]) -> io::Result<()> {
    let mut h = [0u8; 8];
    h[0] = kind;
    h[1] = flags;
    h[4..8].copy_from_slice(&(payload.len() as u32).to_le_bytes());
    w.write_all(&h)?;
    w.write_all(payload)
}

/// How long the server polls for the next message before it blocks: a
/// blocked thread's wake-up can take milliseconds on a busy or virtual
/// machine, and the chip it stands for answers in microseconds. The
/// simulator spends its own CPU on that, never the host's: the client side
/// ([`SocketClient`]) blocks in `read`, as a host blocks in the spidev
/// ioctl while the kernel clocks the bytes, so the daemon's CPU time
/// measured against the socket simulator is its own work (when the client
/// spun instead, that was most of the daemon's idle CPU).
pub const SERVER_SPIN: Duration = Duration::from_millis(2);

/// Fills `buf` from the stream, polling (non-blocking, yielding) for up to
/// `spin` before blocking.
fn read_spinning(stream: &mut UnixStream, buf: &mut [u8], spin: Duration) -> io::Result<()> {
    if spin.is_zero() {
        return stream.read_exact(buf);
    }
    let mut got = 0;
    let start = Instant::now();
    stream.set_nonblocking(true)?;
    while got < buf.len() && start.elapsed() < spin {
        match stream.read(&mut buf[got..]) {
            Ok(0) => {
                stream.set_nonblocking(false)?;
                return Err(io::ErrorKind::UnexpectedEof.into());
            }
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => thread::yield_now(),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => {
                stream.set_nonblocking(false)?;
                return Err(e);
            }
        }
    }
    stream.set_nonblocking(false)?;
    stream.read_exact(&mut buf[got..])
}

fn read_msg(r: &mut UnixStream, spin: Duration) -> io::Result<(u8, u8, Vec<u8>)> {
    let mut h = [0u8; 8];
    read_spinning(r, &mut h, spin)?;
    let len = u32::from_le_bytes([h[4], h[5], h[6], h[7]]) as usize;
    if len > MAX_PAYLOAD {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("payload of {len} bytes exceeds {MAX_PAYLOAD}"),
        ));
    }
    let mut payload = vec![0u8; len];
    read_spinning(r, &mut payload, spin)?;
    Ok((h[0], h[1], payload))
}

/// The longest a wait goes without looking at the chip, ns: control
/// commands (faults) change it from other connections.
const LOOK_EVERY_NS: u64 = 1_000_000;

/// GPIO lines claimed by connections: (chip, offset) -> (connection,
/// consumer).
type Claims = HashMap<(String, u32), (u64, String)>;

/// A chip running against the wall clock, shared by connections.
#[derive(Debug)]
pub struct Server {
    chip: Mutex<Chip>,
    epoch: Instant,
    claims: Mutex<Claims>,
    connections: AtomicU64,
    /// How long it polls for a message, and yields instead of sleeping
    /// before a modelled moment ([`SERVER_SPIN`] unless told otherwise).
    spin: Duration,
}

impl Server {
    /// Starts the clock at 0 now.
    pub fn new(chip: Chip) -> Self {
        Self {
            chip: Mutex::new(chip),
            epoch: Instant::now(),
            claims: Mutex::default(),
            connections: AtomicU64::new(0),
            spin: SERVER_SPIN,
        }
    }

    /// Spins for `spin` instead of [`SERVER_SPIN`]: less CPU for later
    /// answers (zero: blocks for every message and sleeps through every
    /// modelled wait, its CPU then the simulation's work alone).
    pub fn with_spin(mut self, spin: Duration) -> Self {
        self.spin = spin;
        self
    }

    /// Waits from `now` towards `until` (ns of simulated time), briefly:
    /// callers loop. Sleeps while `until` is further than the spin
    /// window away, to within it (a sleep can overshoot by milliseconds
    /// on a busy machine); yields inside it; with no spin window, sleeps
    /// all the way.
    fn pause(&self, now: u64, until: u64) {
        let left = Duration::from_nanos(until.saturating_sub(now));
        let window = self.spin.min(Duration::from_millis(1));
        if left > self.spin {
            thread::sleep(left - window);
        } else if self.spin.is_zero() {
            thread::sleep(left);
        } else {
            thread::yield_now();
        }
    }

    fn claims(&self) -> MutexGuard<'_, Claims> {
        self.claims.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `CHIP CONSUMER OFFSET...`: all or none, as the kernel grants a line
    /// request.
    fn claim(&self, connection: u64, text: &str) -> Result<String, String> {
        let mut words = text.split_whitespace();
        let (Some(chip), Some(consumer)) = (words.next(), words.next()) else {
            return Err("claim needs CHIP CONSUMER OFFSET...".into());
        };
        let offsets: Vec<u32> = words.map(str::parse).collect::<Result<_, _>>().map_err(|e| format!("offset: {e}"))?;
        let mut claims = self.claims();
        for o in &offsets {
            if let Some((_, holder)) = claims.get(&(chip.to_string(), *o)) {
                return Err(holder.clone());
            }
        }
        for o in offsets {
            claims.insert((chip.to_string(), o), (connection, consumer.to_string()));
        }
        Ok(String::new())
    }

    fn owner(&self, text: &str) -> Result<Option<String>, String> {
        let mut words = text.split_whitespace();
        let (Some(chip), Some(offset)) = (words.next(), words.next()) else {
            return Err("owner needs CHIP OFFSET".into());
        };
        let offset: u32 = offset.parse().map_err(|e| format!("offset: {e}"))?;
        Ok(self.claims().get(&(chip.to_string(), offset)).map(|(_, c)| c.clone()))
    }

    /// Simulated time: nanoseconds since start.
    pub fn now_ns(&self) -> u64 {
        self.epoch.elapsed().as_nanos() as u64
    }

    /// The chip, brought up to now. A poisoned lock (a panicked handler) is
    /// taken over: the chip's state is still consistent per call.
    pub fn chip(&self) -> MutexGuard<'_, Chip> {
        let mut c = self.chip.lock().unwrap_or_else(|e| e.into_inner());
        let now = self.now_ns();
        c.advance_to(now);
        c
    }

    fn lines(chip: &Chip, now: u64) -> u8 {
        (if chip.int0_level(now) { LINE_INT0 } else { 0 }) | if chip.int1_level() { LINE_INT1 } else { 0 }
    }

    /// Accepts connections until `stop` is set, one thread per connection.
    pub fn serve(self: Arc<Self>, listener: UnixListener, stop: Arc<AtomicBool>) -> io::Result<()> {
        listener.set_nonblocking(true)?;
        while !stop.load(Ordering::Relaxed) {
            match listener.accept() {
                Ok((stream, _)) => {
                    stream.set_nonblocking(false)?;
                    let me = Arc::clone(&self);
                    thread::spawn(move || {
                        // A client that disconnects mid-message ends here.
                        let _ = me.handle(stream);
                    });
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => thread::sleep(Duration::from_millis(5)),
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Waits until the wall clock reaches simulated time `at`.
    fn wait_until(&self, at: u64) {
        loop {
            let now = self.now_ns();
            if now >= at {
                return;
            }
            self.pause(now, at);
        }
    }

    fn wait(&self, timeout_us: u32, mut done: impl FnMut(&Chip, u64) -> bool) -> bool {
        let deadline = self.now_ns() + u64::from(timeout_us) * 1000;
        loop {
            let (ok, ready_at, next_event) = {
                let c = self.chip();
                let now = self.now_ns();
                (done(&c, now), c.ready_at(), c.next_event_at())
            };
            let now = self.now_ns();
            if ok {
                return true;
            }
            if now >= deadline {
                return false;
            }
            // The next moment the answer may change: the chip ready
            // again, its next cycle or blocking command's end (INT1
            // sources), the deadline; and a look at least every
            // millisecond for what a control command changed (a fault).
            let until = [Some(ready_at).filter(|&t| t > now), next_event.filter(|&t| t > now)]
                .into_iter()
                .flatten()
                .fold(deadline.min(now + LOOK_EVERY_NS), u64::min);
            self.pause(now, until);
        }
    }

    /// Serves one connection; the GPIO lines it claimed are free again
    /// when it ends, as a line request's are when its file is closed.
    pub fn handle(&self, stream: UnixStream) -> io::Result<()> {
        let connection = self.connections.fetch_add(1, Ordering::Relaxed);
        let result = self.serve_connection(connection, stream);
        self.claims().retain(|_, (c, _)| *c != connection);
        result
    }

    fn serve_connection(&self, connection: u64, mut stream: UnixStream) -> io::Result<()> {
        loop {
            let (kind, _flags, payload) = match read_msg(&mut stream, self.spin) {
                Ok(m) => m,
                Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(()),
                Err(e) => {
                    let _ = write_msg(&mut stream, KIND_ERROR, 0, e.to_string().as_bytes());
                    return Err(e);
                }
            };
            match kind {
                KIND_TRANSFER => {
                    let mut miso = vec![0u8; payload.len()];
                    let lines = {
                        let mut c = self.chip();
                        let now = self.now_ns();
                        c.transfer(now, &payload, &mut miso);
                        let after = self.now_ns().max(c.now_ns);
                        Self::lines(&c, after)
                    };
                    write_msg(&mut stream, KIND_TRANSFER, lines, &miso)?;
                }
                KIND_TRANSFER_FORECAST => {
                    let mut reply = vec![0u8; payload.len() + Forecast::LEN];
                    let (miso, tail) = reply.split_at_mut(payload.len());
                    let (taken, wire_end) = {
                        let mut c = self.chip();
                        let now = self.now_ns();
                        let packets = c.stats.packets;
                        c.transfer(now, &payload, miso);
                        (u32::try_from(c.stats.packets - packets).unwrap_or(u32::MAX), c.now_ns)
                    };
                    // The answer leaves when the clock would have shifted the
                    // last byte, as a spidev ioctl returns: the forecast is
                    // then measured from a moment the host also sees, so its
                    // INT0 edge is never early.
                    self.wait_until(wire_end);
                    let lines = {
                        let c = self.chip();
                        let now = self.now_ns().max(c.now_ns);
                        tail.copy_from_slice(&Forecast::of(&c, now, taken).encode());
                        Self::lines(&c, now)
                    };
                    write_msg(&mut stream, KIND_TRANSFER_FORECAST, lines, &reply)?;
                }
                KIND_WAIT_LINES => {
                    let Ok([t0, t1, t2, t3, mask, known]) = <[u8; 6]>::try_from(payload.as_slice()) else {
                        write_msg(&mut stream, KIND_ERROR, 0, b"wait-lines needs timeout (u32 us), mask, lines")?;
                        continue;
                    };
                    let timeout = u32::from_le_bytes([t0, t1, t2, t3]);
                    let changed = self.wait(timeout, |c, now| Self::lines(c, now) & mask != known & mask);
                    let (lines, forecast) = {
                        let c = self.chip();
                        let now = self.now_ns().max(c.now_ns);
                        (Self::lines(&c, now), Forecast::of(&c, now, 0))
                    };
                    let mut reply = vec![u8::from(changed)];
                    reply.extend_from_slice(&forecast.encode());
                    write_msg(&mut stream, KIND_WAIT_LINES, lines, &reply)?;
                }
                KIND_GPIO_CLAIM => {
                    let (flags, answer) = match self.claim(connection, &String::from_utf8_lossy(&payload)) {
                        Ok(a) => (0, a),
                        Err(holder) => (1, holder),
                    };
                    write_msg(&mut stream, KIND_GPIO_CLAIM, flags, answer.as_bytes())?;
                }
                KIND_GPIO_OWNER => match self.owner(&String::from_utf8_lossy(&payload)) {
                    Ok(None) => write_msg(&mut stream, KIND_GPIO_OWNER, 0, &[])?,
                    Ok(Some(consumer)) => write_msg(&mut stream, KIND_GPIO_OWNER, 1, consumer.as_bytes())?,
                    Err(e) => write_msg(&mut stream, KIND_ERROR, 0, e.as_bytes())?,
                },
                KIND_TRANSFER_WHEN_READY => {
                    let Some((t, mosi)) = payload.split_first_chunk::<4>() else {
                        write_msg(&mut stream, KIND_ERROR, 0, b"transfer-when-ready needs a 4-byte timeout")?;
                        continue;
                    };
                    let ready =
                        self.wait(u32::from_le_bytes(*t), |c, now| c.ready(now) && c.faults.int0_stuck.is_none());
                    if !ready {
                        write_msg(&mut stream, KIND_TRANSFER_WHEN_READY, FLAG_TIMED_OUT, &[])?;
                        continue;
                    }
                    let mut miso = vec![0u8; mosi.len()];
                    let lines = {
                        let mut c = self.chip();
                        let now = self.now_ns();
                        c.transfer(now, mosi, &mut miso);
                        let after = self.now_ns().max(c.now_ns);
                        Self::lines(&c, after)
                    };
                    write_msg(&mut stream, KIND_TRANSFER_WHEN_READY, lines, &miso)?;
                }
                KIND_LINES => {
                    let (lines, now, wait) = {
                        let c = self.chip();
                        let now = self.now_ns();
                        (Self::lines(&c, now), now, c.ready_at().saturating_sub(now))
                    };
                    let mut p = now.to_le_bytes().to_vec();
                    p.extend_from_slice(&wait.to_le_bytes());
                    write_msg(&mut stream, KIND_LINES, lines, &p)?;
                }
                KIND_WAIT_READY | KIND_WAIT_INT1 => {
                    let Ok(t) = <[u8; 4]>::try_from(payload.as_slice()) else {
                        write_msg(&mut stream, KIND_ERROR, 0, b"wait needs a 4-byte timeout in microseconds")?;
                        continue;
                    };
                    let timeout = u32::from_le_bytes(t);
                    let ok = if kind == KIND_WAIT_READY {
                        self.wait(timeout, |c, now| c.ready(now) && c.faults.int0_stuck.is_none())
                    } else {
                        self.wait(timeout, |c, _| c.int1_active())
                    };
                    let lines = {
                        let c = self.chip();
                        Self::lines(&c, self.now_ns())
                    };
                    write_msg(&mut stream, kind, lines, &[u8::from(ok)])?;
                }
                KIND_CONTROL => {
                    let text = String::from_utf8_lossy(&payload).into_owned();
                    let result = control::execute(&mut self.chip(), &text);
                    let (flags, answer) = match result {
                        Ok(a) => (0, a),
                        Err(e) => (1, e),
                    };
                    write_msg(&mut stream, KIND_CONTROL, flags, answer.as_bytes())?;
                }
                other => {
                    write_msg(&mut stream, KIND_ERROR, 0, format!("unknown message kind {other:#04x}").as_bytes())?
                }
            }
        }
    }
}

/// Binds the socket, removing a stale file left by a previous run.
pub fn bind(path: &Path) -> io::Result<UnixListener> {
    if path.exists() && UnixStream::connect(path).is_err() {
        std::fs::remove_file(path)?;
    }
    UnixListener::bind(path)
}

/// The host side of the socket.
#[derive(Debug)]
pub struct SocketClient {
    stream: UnixStream,
}

/// An answer that is not what was asked for.
fn unexpected(kind: u8, payload: &[u8]) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("simulator answered kind {kind:#04x}: {}", String::from_utf8_lossy(payload)),
    )
}

impl std::os::fd::AsRawFd for SocketClient {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        self.stream.as_raw_fd()
    }
}

impl SocketClient {
    /// Connects to a serving simulator.
    pub fn connect(path: &Path) -> io::Result<Self> {
        Ok(Self { stream: UnixStream::connect(path)? })
    }

    /// How long a read of an answer may block (`None`: for ever); a read
    /// past it fails with `WouldBlock` or `TimedOut`, and the connection is
    /// then out of step (the late answer is still to come).
    pub fn set_answer_timeout(&self, timeout: Option<Duration>) -> io::Result<()> {
        self.stream.set_read_timeout(timeout)
    }

    fn request(&mut self, kind: u8, payload: &[u8]) -> io::Result<(u8, Vec<u8>)> {
        write_msg(&mut self.stream, kind, 0, payload)?;
        let (k, flags, p) = read_msg(&mut self.stream, Duration::ZERO)?;
        if k != kind {
            return Err(unexpected(k, &p));
        }
        Ok((flags, p))
    }

    /// One transfer; returns MISO and the lines byte.
    pub fn transfer(&mut self, mosi: &[u8], miso: &mut [u8]) -> io::Result<u8> {
        let (lines, p) = self.request(KIND_TRANSFER, mosi)?;
        let n = p.len().min(miso.len());
        miso[..n].copy_from_slice(&p[..n]);
        Ok(lines)
    }

    /// Waits up to `timeout` for INT0, then transfers; `Ok(None)` when INT0
    /// stayed inactive (nothing clocked).
    pub fn transfer_when_ready(&mut self, timeout: Duration, mosi: &[u8], miso: &mut [u8]) -> io::Result<Option<u8>> {
        let us = timeout.as_micros().min(u128::from(u32::MAX)) as u32;
        let mut p = us.to_le_bytes().to_vec();
        p.extend_from_slice(mosi);
        let (flags, back) = self.request(KIND_TRANSFER_WHEN_READY, &p)?;
        if flags & FLAG_TIMED_OUT != 0 {
            return Ok(None);
        }
        let n = back.len().min(miso.len());
        miso[..n].copy_from_slice(&back[..n]);
        Ok(Some(flags))
    }

    /// One transfer; returns the lines byte after it and what INT0 will do.
    pub fn transfer_forecast(&mut self, mosi: &[u8], miso: &mut [u8]) -> io::Result<(u8, Forecast)> {
        let (lines, p) = self.request(KIND_TRANSFER_FORECAST, mosi)?;
        let split = p.len().saturating_sub(Forecast::LEN);
        let forecast =
            Forecast::decode(&p[split..]).ok_or_else(|| unexpected(KIND_TRANSFER_FORECAST, b"short reply"))?;
        let n = split.min(miso.len());
        miso[..n].copy_from_slice(&p[..n]);
        Ok((lines, forecast))
    }

    /// Waits up to `timeout` until `lines & mask` differs from `known &
    /// mask`; returns whether it did, the lines and the forecast.
    pub fn wait_lines(&mut self, timeout: Duration, mask: u8, known: u8) -> io::Result<(bool, u8, Forecast)> {
        let us = timeout.as_micros().min(u128::from(u32::MAX)) as u32;
        let mut p = us.to_le_bytes().to_vec();
        p.extend_from_slice(&[mask, known]);
        let (lines, back) = self.request(KIND_WAIT_LINES, &p)?;
        let forecast = back.get(1..).and_then(Forecast::decode).ok_or_else(|| unexpected(KIND_WAIT_LINES, &back))?;
        Ok((back.first() == Some(&1), lines, forecast))
    }

    /// Claims GPIO lines for this connection; `Err` names the consumer
    /// that holds one of them.
    pub fn gpio_claim(&mut self, chip: &str, consumer: &str, offsets: &[u32]) -> io::Result<Result<(), String>> {
        let mut text = format!("{chip} {consumer}");
        for o in offsets {
            text.push_str(&format!(" {o}"));
        }
        let (flags, p) = self.request(KIND_GPIO_CLAIM, text.as_bytes())?;
        Ok(if flags == 0 { Ok(()) } else { Err(String::from_utf8_lossy(&p).into_owned()) })
    }

    /// The consumer holding a GPIO line, if any.
    pub fn gpio_owner(&mut self, chip: &str, offset: u32) -> io::Result<Option<String>> {
        let (flags, p) = self.request(KIND_GPIO_OWNER, format!("{chip} {offset}").as_bytes())?;
        Ok((flags != 0).then(|| String::from_utf8_lossy(&p).into_owned()))
    }

    /// Lines byte, simulated time and ns until ready.
    pub fn lines(&mut self) -> io::Result<(u8, u64, u64)> {
        let (lines, p) = self.request(KIND_LINES, &[])?;
        let word = |i: usize| p.get(i..i + 8).map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])));
        Ok((lines, word(0), word(8)))
    }

    /// Waits for INT0 ready; false on timeout.
    pub fn wait_ready(&mut self, timeout: Duration) -> io::Result<bool> {
        let us = timeout.as_micros().min(u128::from(u32::MAX)) as u32;
        let (_, p) = self.request(KIND_WAIT_READY, &us.to_le_bytes())?;
        Ok(p.first() == Some(&1))
    }

    /// Waits for INT1 active; false on timeout.
    pub fn wait_int1(&mut self, timeout: Duration) -> io::Result<bool> {
        let us = timeout.as_micros().min(u128::from(u32::MAX)) as u32;
        let (_, p) = self.request(KIND_WAIT_INT1, &us.to_le_bytes())?;
        Ok(p.first() == Some(&1))
    }

    /// Runs a control command; `Err` text for refused commands.
    pub fn control(&mut self, command: &str) -> io::Result<Result<String, String>> {
        let (flags, p) = self.request(KIND_CONTROL, command.as_bytes())?;
        let text = String::from_utf8_lossy(&p).into_owned();
        Ok(if flags == 0 { Ok(text) } else { Err(text) })
    }
}
