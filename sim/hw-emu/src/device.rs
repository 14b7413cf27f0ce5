//! The emulated device files: what an open `/dev/spidevB.C`, an open
//! `/dev/gpiochipN` and a line request's file do with the calls made on
//! them. Each one is a connection to the simulator (its file descriptor is
//! the connection's, so `close` ends it, and the simulator frees a closed
//! request's lines as the kernel does).
//!
//! Everything here takes the caller's pointers as the kernel would: the
//! interposed functions (interpose.rs) pass them on unchanged.

use std::collections::HashMap;
use std::io;
use std::mem::ManuallyDrop;
use std::ops::{Deref, DerefMut};
use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::Duration;

use ecmxf_sim::server::{LINE_INT0, LINE_INT1, SocketClient};
use libc::c_int;

use crate::config::{Config, Node};
use crate::lines::{self, Int0, Line, Request, Wire};
use crate::spi::{self, Effect, Noise, Settings};
use crate::uapi::{self, LineEvent, flag};

/// An errno.
pub type Errno = c_int;

/// Descriptors below 4096 that are emulated files, one bit each.
static OWNED: [AtomicU64; 64] = [const { AtomicU64::new(0) }; 64];

/// The emulation: its settings, the open devices, INT0.
#[derive(Debug)]
pub struct Emu {
    /// Settings.
    pub config: Config,
    devices: Mutex<HashMap<RawFd, Arc<Mutex<Device>>>>,
    int0: Mutex<Int0>,
    /// Call counters.
    pub stats: Stats,
}

/// The process's emulation, or `None` when `ECMXF_SIM_SOCKET` is unset.
pub fn emu() -> Option<&'static Emu> {
    static EMU: OnceLock<Option<Emu>> = OnceLock::new();
    EMU.get_or_init(|| {
        Config::from_env().map(|config| Emu {
            config,
            devices: Mutex::default(),
            int0: Mutex::default(),
            stats: Stats::default(),
        })
    })
    .as_ref()
}

/// Calls made on the emulated files, for the per-exchange cost figures.
#[derive(Debug, Default)]
pub struct Stats {
    /// `SPI_IOC_MESSAGE` calls.
    pub spi_messages: AtomicU64,
    /// Bytes clocked.
    pub spi_bytes: AtomicU64,
    /// Other spidev ioctls (settings).
    pub spi_settings: AtomicU64,
    /// `GPIO_V2_LINE_GET_VALUES` calls.
    pub get_values: AtomicU64,
    /// `ppoll`/`poll` calls on line requests.
    pub polls: AtomicU64,
    /// `read` calls on line requests.
    pub reads: AtomicU64,
    /// Events read.
    pub events: AtomicU64,
    /// Other GPIO ioctls (chip and line info, requests, configuration).
    pub gpio_other: AtomicU64,
    /// Round trips to the simulator.
    pub round_trips: AtomicU64,
}

impl Stats {
    /// `name value` lines.
    pub fn render(&self) -> String {
        let v = |a: &AtomicU64| a.load(Ordering::Relaxed);
        format!(
            "spi_messages {}\nspi_bytes {}\nspi_settings {}\ngpio_get_values {}\ngpio_polls {}\ngpio_reads {}\n\
             gpio_events {}\ngpio_other {}\nsimulator_round_trips {}\n",
            v(&self.spi_messages),
            v(&self.spi_bytes),
            v(&self.spi_settings),
            v(&self.get_values),
            v(&self.polls),
            v(&self.reads),
            v(&self.events),
            v(&self.gpio_other),
            v(&self.round_trips),
        )
    }
}

fn bump(a: &AtomicU64) {
    a.fetch_add(1, Ordering::Relaxed);
}

/// An open emulated file.
#[derive(Debug)]
enum Device {
    Spi { client: Client, settings: Settings, noise: Noise },
    Chip { client: Client, name: String },
    Lines { client: Client, request: Request },
}

/// A device's connection. Its descriptor is the one the program holds:
/// the program's `close` closes it, never a drop here (the number may
/// already be another file's by then).
#[derive(Debug)]
struct Client(ManuallyDrop<SocketClient>);

impl Deref for Client {
    type Target = SocketClient;
    fn deref(&self) -> &SocketClient {
        &self.0
    }
}

impl DerefMut for Client {
    fn deref_mut(&mut self) -> &mut SocketClient {
        &mut self.0
    }
}

/// CLOCK_MONOTONIC (or another clock) in ns.
pub fn clock(id: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write to.
    unsafe { libc::clock_gettime(id, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

fn now() -> u64 {
    clock(libc::CLOCK_MONOTONIC)
}

fn realtime_offset() -> i64 {
    clock(libc::CLOCK_REALTIME) as i64 - now() as i64
}

/// Sleeps until CLOCK_MONOTONIC reads `at`.
fn sleep_until(at: u64) {
    let ts = libc::timespec { tv_sec: (at / 1_000_000_000) as libc::time_t, tv_nsec: (at % 1_000_000_000) as _ };
    // SAFETY: a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
    while unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) }
        == libc::EINTR
    {}
}

fn io_errno(e: &io::Error) -> Errno {
    e.raw_os_error().unwrap_or(libc::EIO)
}

impl Emu {
    fn lock_int0(&self) -> MutexGuard<'_, Int0> {
        self.int0.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn device(&self, fd: RawFd) -> Option<Arc<Mutex<Device>>> {
        self.devices.lock().unwrap_or_else(|e| e.into_inner()).get(&fd).cloned()
    }

    /// Whether `fd` is an emulated file. Every `read`, `ioctl` and `close`
    /// of the process asks, so descriptors below 4096 are looked up in a
    /// bitmap without a lock.
    pub fn owns(&self, fd: RawFd) -> bool {
        match usize::try_from(fd) {
            Ok(i) if i < OWNED.len() * 64 => OWNED[i / 64].load(Ordering::Acquire) & (1 << (i % 64)) != 0,
            Ok(_) => self.devices.lock().unwrap_or_else(|e| e.into_inner()).contains_key(&fd),
            Err(_) => false,
        }
    }

    fn mark(fd: RawFd, owned: bool) {
        if let Ok(i) = usize::try_from(fd) {
            if let Some(word) = OWNED.get(i / 64) {
                if owned {
                    word.fetch_or(1 << (i % 64), Ordering::Release);
                } else {
                    word.fetch_and(!(1 << (i % 64)), Ordering::Release);
                }
            }
        }
    }

    fn connect(&self) -> Result<Client, Errno> {
        bump(&self.stats.round_trips);
        SocketClient::connect(&self.config.socket).map(|c| Client(ManuallyDrop::new(c))).map_err(|e| {
            eprintln!("ecmxf-hw-emu: no simulator at {}: {e}", self.config.socket.display());
            libc::ENODEV
        })
    }

    fn insert(&self, device: Device) -> RawFd {
        let fd = match &device {
            Device::Spi { client, .. } | Device::Chip { client, .. } | Device::Lines { client, .. } => {
                client.as_raw_fd()
            }
        };
        self.devices.lock().unwrap_or_else(|e| e.into_inner()).insert(fd, Arc::new(Mutex::new(device)));
        Self::mark(fd, true);
        fd
    }

    /// `open(path, flags)` of an emulated node.
    pub fn open(&self, path: &str, node: Node, flags: c_int) -> Result<RawFd, Errno> {
        if self.config.deny.iter().any(|p| p == path) {
            return Err(libc::EACCES);
        }
        if flags & libc::O_DIRECTORY != 0 {
            return Err(libc::ENOTDIR);
        }
        let client = self.connect()?;
        let device = match node {
            Node::Spi => Device::Spi { client, settings: Settings::default(), noise: Noise::default() },
            Node::GpioChip => {
                let name = path.rsplit('/').next().unwrap_or(path).to_string();
                Device::Chip { client, name }
            }
        };
        Ok(self.insert(device))
    }

    /// `close(fd)`: forgets the file (the caller closes the descriptor,
    /// which ends the connection); `false` when it is not emulated.
    pub fn close(&self, fd: RawFd) -> bool {
        if !self.owns(fd) {
            return false;
        }
        let gone = self.devices.lock().unwrap_or_else(|e| e.into_inner()).remove(&fd);
        Self::mark(fd, false);
        let Some(device) = gone else { return false };
        if matches!(&*device.lock().unwrap_or_else(|e| e.into_inner()), Device::Spi { .. }) {
            self.write_stats();
        }
        true
    }

    /// Writes the counters to `ECMXF_EMU_STATS`, if set.
    pub fn write_stats(&self) {
        if let Some(path) = &self.config.stats {
            let _ = std::fs::write(path, self.stats.render());
        }
    }

    /// `ioctl(fd, request, arg)`.
    ///
    /// # Safety
    /// `arg` points to what `request` says, as for the kernel.
    pub unsafe fn ioctl(&self, fd: RawFd, request: u64, arg: *mut libc::c_void) -> Result<c_int, Errno> {
        let device = self.device(fd).ok_or(libc::EBADF)?;
        // Every request here takes an argument; the kernel's copy from a
        // null one fails so.
        if arg.is_null() {
            return Err(libc::EFAULT);
        }
        let mut device = device.lock().unwrap_or_else(|e| e.into_inner());
        match &mut *device {
            // SAFETY: passed on from the caller.
            Device::Spi { client, settings, noise } => unsafe { self.spi_ioctl(client, settings, noise, request, arg) },
            Device::Chip { client, name } => {
                bump(&self.stats.gpio_other);
                // SAFETY: passed on from the caller.
                unsafe { self.chip_ioctl(client, name, request, arg) }
            }
            // SAFETY: passed on from the caller.
            Device::Lines { client, request: lr } => unsafe { self.lines_ioctl(client, lr, request, arg) },
        }
    }

    /// # Safety
    /// As [`Emu::ioctl`].
    unsafe fn spi_ioctl(
        &self,
        client: &mut Client,
        settings: &mut Settings,
        noise: &mut Noise,
        request: u64,
        arg: *mut libc::c_void,
    ) -> Result<c_int, Errno> {
        if let Some(n) = uapi::spi_message_count(request) {
            bump(&self.stats.spi_messages);
            // SAFETY: the caller passes `n` transfers, as the number says.
            let transfers = unsafe { std::slice::from_raw_parts(arg as *const uapi::SpiIocTransfer, n) };
            // SAFETY: each transfer's buffers are the caller's, `len` long.
            return unsafe { self.spi_message(client, settings, noise, transfers) };
        }
        bump(&self.stats.spi_settings);
        // SAFETY: each arm reads or writes the argument type its request
        // number encodes.
        unsafe {
            match request {
                uapi::SPI_RD_MODE => *(arg as *mut u8) = settings.mode as u8,
                uapi::SPI_RD_MODE32 => *(arg as *mut u32) = settings.mode,
                uapi::SPI_WR_MODE => settings.mode = (settings.mode & !0xFF) | u32::from(*(arg as *const u8)),
                uapi::SPI_WR_MODE32 => settings.mode = *(arg as *const u32),
                uapi::SPI_RD_LSB_FIRST => *(arg as *mut u8) = u8::from(settings.mode & uapi::SPI_LSB_FIRST != 0),
                uapi::SPI_WR_LSB_FIRST => {
                    if *(arg as *const u8) != 0 {
                        settings.mode |= uapi::SPI_LSB_FIRST;
                    } else {
                        settings.mode &= !uapi::SPI_LSB_FIRST;
                    }
                }
                uapi::SPI_RD_BITS_PER_WORD => *(arg as *mut u8) = settings.bits_per_word,
                uapi::SPI_WR_BITS_PER_WORD => {
                    // 0 means 8 (spi_setup); the Pi's controller takes 8 only,
                    // this one 8, 16 and 32 (spi.rs).
                    let bits = match *(arg as *const u8) {
                        0 => 8,
                        b @ (8 | 16 | 32) => b,
                        _ => return Err(libc::EINVAL),
                    };
                    settings.bits_per_word = bits;
                }
                uapi::SPI_RD_MAX_SPEED_HZ => *(arg as *mut u32) = settings.max_speed_hz,
                uapi::SPI_WR_MAX_SPEED_HZ => {
                    let hz = *(arg as *const u32);
                    if hz == 0 {
                        return Err(libc::EINVAL);
                    }
                    settings.max_speed_hz = hz;
                }
                _ => return Err(libc::ENOTTY),
            }
        }
        Ok(0)
    }

    /// `SPI_IOC_MESSAGE`: each transfer goes to the simulator as one
    /// chip-select period, through the wires' [`Effect`]; the call returns
    /// when the clock would have shifted the bytes out (spidev's ioctl
    /// blocks that long), and INT0 learns what the chip did.
    ///
    /// # Safety
    /// Each transfer's non-zero buffers are valid for `len` bytes.
    unsafe fn spi_message(
        &self,
        client: &mut Client,
        settings: &Settings,
        noise: &mut Noise,
        transfers: &[uapi::SpiIocTransfer],
    ) -> Result<c_int, Errno> {
        /// spidev's `bufsiz` module parameter, default 4096.
        const BUFSIZ: usize = 4096;
        let total: usize = transfers.iter().map(|t| t.len as usize).sum();
        if total > BUFSIZ {
            return Err(libc::EMSGSIZE);
        }
        for t in transfers {
            let effect = Effect::of(settings, &self.config.wiring, t.speed_hz, t.bits_per_word)?;
            let len = t.len as usize;
            let mut mosi = vec![0u8; len];
            if t.tx_buf != 0 {
                // SAFETY: the caller's tx buffer, `len` bytes.
                mosi.copy_from_slice(unsafe { std::slice::from_raw_parts(t.tx_buf as *const u8, len) });
            }
            let speed = if t.speed_hz == 0 { settings.max_speed_hz } else { t.speed_hz };
            let start = now();
            let mut miso = vec![0xFFu8; len];
            if !effect.deselected {
                effect.to_chip(&mut mosi, noise);
                bump(&self.stats.round_trips);
                // The simulator answers when its clock has shifted the bytes.
                let (lines, forecast) = client.transfer_forecast(&mosi, &mut miso).map_err(|e| io_errno(&e))?;
                self.lock_int0().transferred(start, now(), lines, &forecast);
            }
            effect.to_host(&mut miso, noise);
            sleep_until(start + spi::wire_ns(len, speed) + u64::from(t.delay_usecs) * 1000);
            if t.rx_buf != 0 {
                // SAFETY: the caller's rx buffer, `len` bytes.
                unsafe { std::slice::from_raw_parts_mut(t.rx_buf as *mut u8, len) }.copy_from_slice(&miso);
            }
        }
        self.stats.spi_bytes.fetch_add(total as u64, Ordering::Relaxed);
        Ok(total as c_int)
    }

    /// # Safety
    /// As [`Emu::ioctl`].
    unsafe fn chip_ioctl(
        &self,
        client: &mut Client,
        name: &str,
        request: u64,
        arg: *mut libc::c_void,
    ) -> Result<c_int, Errno> {
        let lines = self.config.gpio_lines;
        match request {
            uapi::GPIO_GET_CHIPINFO => {
                let mut info = uapi::ChipInfo { name: [0; 32], label: [0; 32], lines };
                put_name(&mut info.name, name);
                put_name(&mut info.label, &self.config.gpio_label);
                // SAFETY: the request number says `arg` is a gpiochip_info.
                unsafe { *(arg as *mut uapi::ChipInfo) = info };
                Ok(0)
            }
            uapi::GPIO_V2_GET_LINEINFO => {
                // SAFETY: the request number says `arg` is a gpio_v2_line_info.
                let info = unsafe { &mut *(arg as *mut uapi::LineInfo) };
                if info.offset >= lines || info.padding != [0; 4] {
                    return Err(libc::EINVAL);
                }
                let offset = info.offset;
                bump(&self.stats.round_trips);
                let owner = client.gpio_owner(name, offset).map_err(|e| io_errno(&e))?;
                *info = uapi::LineInfo {
                    name: [0; 32],
                    consumer: [0; 32],
                    offset,
                    num_attrs: 0,
                    flags: flag::INPUT | if owner.is_some() { flag::USED } else { 0 },
                    attrs: [uapi::LineAttribute::default(); uapi::NUM_ATTRS_MAX],
                    padding: [0; 4],
                };
                put_name(&mut info.name, &format!("GPIO{offset}"));
                if let Some(consumer) = owner {
                    put_name(&mut info.consumer, &consumer);
                }
                Ok(0)
            }
            uapi::GPIO_V2_GET_LINE => {
                // SAFETY: the request number says `arg` is a gpio_v2_line_request.
                let lr = unsafe { &mut *(arg as *mut uapi::LineRequest) };
                lr.fd = self.request_lines(name, lr)?;
                Ok(0)
            }
            _ => Err(libc::ENOTTY),
        }
    }

    /// `GPIO_V2_GET_LINE_IOCTL`: checks the request as the kernel does
    /// (linereq_create), claims the lines at the simulator (EBUSY when
    /// another request holds one) and opens the request's file.
    fn request_lines(&self, chip: &str, lr: &uapi::LineRequest) -> Result<RawFd, Errno> {
        let n = lr.num_lines as usize;
        if n == 0 || n > uapi::LINES_MAX || lr.padding != [0; 5] || lr.config.padding != [0; 5] {
            return Err(libc::EINVAL);
        }
        if lr.event_buffer_size as usize > uapi::LINES_MAX * 16 {
            return Err(libc::EINVAL);
        }
        let offsets = &lr.offsets[..n];
        if offsets.iter().any(|&o| o >= self.config.gpio_lines) {
            return Err(libc::EINVAL);
        }
        let mut new_lines = Vec::with_capacity(n);
        for (i, &offset) in offsets.iter().enumerate() {
            if offsets[..i].contains(&offset) {
                return Err(libc::EBUSY);
            }
            let (flags, debounce_ns, output) = line_config(&lr.config, i)?;
            if flags & flag::EVENT_CLOCK_HTE != 0 {
                return Err(libc::EOPNOTSUPP);
            }
            let wire = if offset == self.config.int0_line {
                Wire::Int0
            } else if offset == self.config.int1_line {
                Wire::Int1
            } else {
                Wire::Other
            };
            new_lines.push(Line { offset, wire, flags, debounce_ns, output, seqno: 0, int1: None, cursor: 0 });
        }
        let consumer: String = String::from_utf8_lossy(&lr.consumer)
            .trim_end_matches('\0')
            .chars()
            .map(|c| if c.is_whitespace() { '_' } else { c })
            .collect();
        let consumer = if consumer.is_empty() { "?".to_string() } else { consumer };
        let mut client = self.connect()?;
        bump(&self.stats.round_trips);
        match client.gpio_claim(chip, &consumer, offsets).map_err(|e| io_errno(&e))? {
            Ok(()) => {}
            Err(_holder) => return Err(libc::EBUSY),
        }
        // The lines' levels now: INT0's starts the process's model if it
        // has none; INT1's is the request's first look.
        bump(&self.stats.round_trips);
        let (_, lines, forecast) = client.wait_lines(Duration::ZERO, 0, 0).map_err(|e| io_errno(&e))?;
        let mut request = Request::new(new_lines, lr.event_buffer_size);
        {
            let mut int0 = self.lock_int0();
            if !int0.known() {
                int0.observed(now(), lines, &forecast);
            }
            let cursor = int0.cursor();
            for l in &mut request.lines {
                l.cursor = cursor;
            }
        }
        request.int1_seen(now(), lines::int1(lines), 0);
        Ok(self.insert(Device::Lines { client, request }))
    }

    /// # Safety
    /// As [`Emu::ioctl`].
    unsafe fn lines_ioctl(
        &self,
        client: &mut Client,
        request: &mut Request,
        number: u64,
        arg: *mut libc::c_void,
    ) -> Result<c_int, Errno> {
        match number {
            uapi::GPIO_V2_LINE_GET_VALUES => {
                bump(&self.stats.get_values);
                // SAFETY: the request number says `arg` is gpio_v2_line_values.
                let values = unsafe { &mut *(arg as *mut uapi::LineValues) };
                let n = request.lines.len();
                let mask = values.mask & if n == 64 { u64::MAX } else { (1 << n) - 1 };
                if mask == 0 {
                    return Err(libc::EINVAL);
                }
                let asks =
                    |request: &Request, wire| (0..n).any(|i| mask & (1 << i) != 0 && request.lines[i].wire == wire);
                let int1 = if asks(request, Wire::Int1) {
                    // INT1 moves on its own (chip events): ask.
                    bump(&self.stats.round_trips);
                    let (_, lines, _) = client.wait_lines(Duration::ZERO, 0, 0).map_err(|e| io_errno(&e))?;
                    request.int1_seen(now(), lines::int1(lines), realtime_offset());
                    lines::int1(lines)
                } else {
                    false
                };
                let int0 = asks(request, Wire::Int0) && self.lock_int0().level(now());
                let mut bits = 0;
                for i in 0..n {
                    if mask & (1 << i) != 0 && request.value(i, int0, int1) {
                        bits |= 1 << i;
                    }
                }
                values.bits = bits;
                Ok(0)
            }
            uapi::GPIO_V2_LINE_SET_VALUES => {
                bump(&self.stats.gpio_other);
                // SAFETY: as above.
                let values = unsafe { &*(arg as *const uapi::LineValues) };
                for (i, line) in request.lines.iter_mut().enumerate() {
                    if values.mask & (1 << i) != 0 {
                        if line.flags & flag::OUTPUT == 0 {
                            return Err(libc::EPERM);
                        }
                        line.output = values.bits & (1 << i) != 0;
                    }
                }
                Ok(0)
            }
            uapi::GPIO_V2_LINE_SET_CONFIG => {
                bump(&self.stats.gpio_other);
                // SAFETY: the request number says `arg` is gpio_v2_line_config.
                let config = unsafe { &*(arg as *const uapi::LineConfig) };
                if config.padding != [0; 5] {
                    return Err(libc::EINVAL);
                }
                let mut new = Vec::with_capacity(request.lines.len());
                for i in 0..request.lines.len() {
                    new.push(line_config(config, i)?);
                }
                for (line, (flags, debounce_ns, output)) in request.lines.iter_mut().zip(new) {
                    (line.flags, line.debounce_ns, line.output) = (flags, debounce_ns, output);
                }
                Ok(0)
            }
            _ => Err(libc::ENOTTY),
        }
    }

    /// Waits up to `timeout` (`None`: for ever) for an edge event on a line
    /// request: the forecast edge is slept for; anything else is asked of
    /// the simulator, which watches the lines. `Ok(true)` when events are
    /// queued.
    pub fn wait_events(&self, fd: RawFd, timeout: Option<Duration>) -> Result<bool, Errno> {
        let device = self.device(fd).ok_or(libc::EBADF)?;
        let mut device = device.lock().unwrap_or_else(|e| e.into_inner());
        let Device::Lines { client, request } = &mut *device else {
            // spidev and gpiochip files have nothing to read here.
            if let Some(t) = timeout {
                std::thread::sleep(t);
            }
            return Ok(false);
        };
        let deadline = timeout.map(|t| now() + t.as_nanos() as u64);
        loop {
            let offset = realtime_offset();
            let t = now();
            let next_edge = {
                let mut int0 = self.lock_int0();
                int0.advance(t);
                request.collect(&int0, t, offset);
                int0.next_edge_at()
            };
            if request.readable() {
                return Ok(true);
            }
            if deadline.is_some_and(|d| t >= d) {
                return Ok(false);
            }
            let left = deadline.map_or(u64::MAX, |d| d - t);
            if !request.detects_edges() {
                std::thread::sleep(Duration::from_nanos(left.min(1_000_000_000)));
                continue;
            }
            let debounce = request.lines.iter().map(|l| l.debounce_ns).max().unwrap_or(0);
            if let Some(at) = next_edge.filter(|at| request.has(Wire::Int0) && *at <= t + left) {
                sleep_until(at.max(t) + debounce);
                continue;
            }
            // Nothing this process will cause: the simulator watches.
            let mut mask = 0;
            let mut known = 0;
            if request.has(Wire::Int0) {
                mask |= LINE_INT0;
                known |= if self.lock_int0().level(t) { LINE_INT0 } else { 0 };
            }
            if let Some(level) = request.lines.iter().find(|l| l.wire == Wire::Int1).and_then(|l| l.int1) {
                mask |= LINE_INT1;
                known |= if level { LINE_INT1 } else { 0 };
            }
            if mask == 0 {
                std::thread::sleep(Duration::from_nanos(left.min(1_000_000_000)));
                continue;
            }
            bump(&self.stats.round_trips);
            let slice = Duration::from_nanos(left.min(100_000_000));
            let (changed, lines, forecast) = client.wait_lines(slice, mask, known).map_err(|e| io_errno(&e))?;
            if changed {
                let t = now();
                if mask & LINE_INT0 != 0 {
                    self.lock_int0().observed(t, lines, &forecast);
                }
                request.int1_seen(t, lines::int1(lines), realtime_offset());
            }
        }
    }

    /// `read(fd, buf, len)` on a line request: whole events, blocking
    /// until one is queued (line request files are blocking).
    ///
    /// # Safety
    /// `buf` is valid for `len` bytes.
    pub unsafe fn read(&self, fd: RawFd, buf: *mut libc::c_void, len: usize) -> Result<isize, Errno> {
        let size = std::mem::size_of::<LineEvent>();
        {
            let device = self.device(fd).ok_or(libc::EBADF)?;
            let is_lines = matches!(&*device.lock().unwrap_or_else(|e| e.into_inner()), Device::Lines { .. });
            if !is_lines {
                return Err(libc::EINVAL);
            }
        }
        bump(&self.stats.reads);
        if len < size {
            return Err(libc::EINVAL);
        }
        self.wait_events(fd, None)?;
        let device = self.device(fd).ok_or(libc::EBADF)?;
        let mut device = device.lock().unwrap_or_else(|e| e.into_inner());
        let Device::Lines { request, .. } = &mut *device else { return Err(libc::EINVAL) };
        let events = request.take(len / size);
        self.stats.events.fetch_add(events.len() as u64, Ordering::Relaxed);
        // SAFETY: `buf` holds `len` >= events * size bytes; LineEvent is
        // plain data, copied byte-wise (no alignment needed).
        unsafe { std::ptr::copy_nonoverlapping(events.as_ptr() as *const u8, buf as *mut u8, events.len() * size) };
        Ok((events.len() * size) as isize)
    }

    /// Counts a poll.
    pub fn polled(&self) {
        bump(&self.stats.polls);
    }
}

/// One line's flags, debounce (ns) and output value from a line config:
/// the last attribute whose mask has the line wins, as in the kernel.
fn line_config(config: &uapi::LineConfig, index: usize) -> Result<(u64, u64, bool), Errno> {
    if config.num_attrs as usize > uapi::NUM_ATTRS_MAX {
        return Err(libc::EINVAL);
    }
    let mut flags = config.flags;
    let mut debounce_ns = 0;
    let mut output = false;
    for a in &config.attrs[..config.num_attrs as usize] {
        if a.attr.padding != 0 {
            return Err(libc::EINVAL);
        }
        if a.mask & (1 << index) == 0 {
            continue;
        }
        match a.attr.id {
            uapi::ATTR_FLAGS => flags = a.attr.value,
            uapi::ATTR_OUTPUT_VALUES => output = a.attr.value & (1 << index) != 0,
            uapi::ATTR_DEBOUNCE => debounce_ns = (a.attr.value & 0xFFFF_FFFF) * 1000,
            _ => return Err(libc::EINVAL),
        }
    }
    lines::validate(flags)?;
    if debounce_ns > 0 && flags & flag::INPUT == 0 {
        return Err(libc::EINVAL);
    }
    Ok((flags, debounce_ns, output))
}

fn put_name(field: &mut [u8; uapi::NAME_SIZE], text: &str) {
    let n = text.len().min(uapi::NAME_SIZE - 1);
    field[..n].copy_from_slice(&text.as_bytes()[..n]);
}
