//! `ecmxfd probe`: first contact with a new board. Runs the link steps of
//! bring-up one at a time against the configured chip (spidev and GPIO, or
//! the simulator) and says for each whether it worked, and when not, the
//! likely cause and the fix. The daemon itself only logs the first error of
//! a bring-up that fails, which on a board never seen working does not say
//! whether the wiring, the kernel set-up or the network is at fault.
//!
//! The steps, in the order a link comes up (v049 "ECM-XF 初始化EtherCAT網路
//! 及從站配置說明", figure 7, and docs/protocol.md §3):
//! 1. the SPI device and the GPIO lines open;
//! 2. INT0 says ready, goes busy when a packet is complete and comes back;
//! 3. the packet boundary is found in the chip's byte stream;
//! 4. the check word switches to CRC-32 (and the packet to its configured
//!    size), and answers stay intact over a few hundred exchanges;
//! 5. the firmware version is read;
//! 6. the network is initialised (ECAT_INIT) and its slaves counted and
//!    compared with the configuration;
//! 7. every slave's state and AL status code are read.
//!
//! After a failed step the rest are skipped: each needs the one before.
//! The probe leaves the network in PRE-OP; the daemon's bring-up starts from
//! any state, so `ecmxfd` can be started right after it.

use std::io::{self, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use ecmxf_wire::framing::OVERHEAD;
use ecmxf_wire::payload::control::{FwVersionGet, InfoUpdate};
use ecmxf_wire::payload::slave_info::SlaveInfoCode;
use ecmxf_wire::{CheckType, DATA_MAX, EcatState, al_status_text};

use crate::config::{Config, LinkConfig};
use crate::link::{Link, LinkError};
use crate::master::bring_up_steps::{self as bringup, BringUpError};
use crate::master::{StartError, open_link};
use crate::port::{Port, PortError};

/// The steps' names, in order (step `n` is `STEPS[n - 1]`).
pub const STEPS: [&str; 7] =
    ["device opens", "INT0 toggles", "packet boundary", "check word switch", "firmware", "slave count", "state read"];

/// The fix when only the error itself can tell.
const NAMED: &str = "the message on the step's line names the call that failed and the system's reason";

/// Status exchanges made in step 4 to see whether answers arrive intact.
pub const EXCHANGES: u32 = 200;

/// Above this share of corrupt answers in step 4 (percent of packets) the
/// link fails: every corrupt answer is a resend, and in the cyclic exchange
/// a late or lost FIFO answer.
pub const CORRUPT_FAIL_PERCENT: u64 = 10;

/// How long the probe waits for INT0 at least: a board on the bench is not
/// judged by the real-time loop's ready timeout.
const READY_TIMEOUT: Duration = Duration::from_secs(1);

/// What a step found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It worked; what was found.
    Ok(String),
    /// It worked, with a problem worth fixing (the daemon will run).
    Warn(Finding),
    /// It did not work (the daemon will not run).
    Fail(Finding),
    /// Not run: a step before it failed.
    Skipped,
}

impl Verdict {
    fn failed(&self) -> bool {
        matches!(self, Self::Fail(_))
    }
}

/// What went wrong, why it likely did, and what to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Finding {
    /// What was seen.
    pub what: String,
    /// The likely cause.
    pub cause: String,
    /// What to do.
    pub fix: String,
}

fn fail(what: impl Into<String>, cause: impl Into<String>, fix: impl Into<String>) -> Verdict {
    Verdict::Fail(Finding { what: what.into(), cause: cause.into(), fix: fix.into() })
}

fn warn(what: impl Into<String>, cause: impl Into<String>, fix: impl Into<String>) -> Verdict {
    Verdict::Warn(Finding { what: what.into(), cause: cause.into(), fix: fix.into() })
}

/// The board as the hints speak of it.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Board {
    /// A chip on SPI.
    Hardware {
        /// `link.spi_hz`.
        spi_hz: u32,
        /// `(gpio_chip, int0_line)` when INT0 is wired.
        int0: Option<(PathBuf, u32)>,
        /// `link.idle_us`.
        idle_us: u32,
    },
    /// The simulator, in process or on a socket.
    Simulator {
        /// Its socket, when served.
        socket: Option<PathBuf>,
    },
}

impl Board {
    fn of(config: &Config) -> Self {
        match &config.link {
            LinkConfig::Sim { .. } => Self::Simulator { socket: None },
            LinkConfig::SimSocket { socket } => Self::Simulator { socket: Some(socket.clone()) },
            LinkConfig::Spidev { spi_hz, gpio_chip, int0_line, idle_us, .. } => {
                Self::Hardware { spi_hz: *spi_hz, int0: gpio_chip.clone().zip(*int0_line), idle_us: *idle_us }
            }
        }
    }

    /// Why the chip's answers are garbled, and the fix.
    fn bit_errors(&self) -> (String, String) {
        match self {
            Self::Hardware { spi_hz, .. } => (
                format!(
                    "bit errors on the SPI wires: a clock of {} MHz too fast for the wiring (long or unshielded \
                     wires, no ground next to SCLK), or a loose MISO/MOSI contact",
                    *spi_hz as f64 / 1e6
                ),
                format!(
                    "lower link.spi_hz (try {} Hz), keep the wires under 10 cm with a ground wire next to SCLK \
                     (docs/raspberry-pi.md, 1. Wiring)",
                    (spi_hz / 2).max(1_000_000)
                ),
            ),
            Self::Simulator { socket } => (
                "bit flips injected into the simulator (`ecmxf-sim ctl flip miso|mosi RATE`)".into(),
                format!("`ecmxf-sim ctl --socket {} flip miso 0` (and mosi)", socket_shown(socket)),
            ),
        }
    }
}

fn socket_shown(socket: &Option<PathBuf>) -> String {
    socket.as_ref().map_or("SOCKET".into(), |s| s.display().to_string())
}

/// Step 1: opens the link as the daemon would, or says why it cannot.
pub fn open(config: &Config) -> Result<Box<dyn Link>, Verdict> {
    open_link(config).map(|(link, _handle)| link).map_err(|e| device_failure(config, &e))
}

/// The cause and fix of a link that does not open, from the error's cause
/// (the errno the link kept, not its words) and the configuration.
fn device_failure(config: &Config, e: &StartError) -> Verdict {
    let what = e.to_string();
    let (cause, fix) = match (e, &config.link) {
        (StartError::Network(_), _) => (
            "the simulator's network file has a mistake".to_string(),
            "correct the key the message names (sim/README.md lists the keys)".to_string(),
        ),
        (StartError::NoSimulator, _) => (
            "this ecmxfd was built without the simulator".into(),
            "set link.backend = \"spidev\" for the chip, or build with the `sim` feature".into(),
        ),
        (StartError::Link(e), LinkConfig::SimSocket { socket }) => (
            if matches!(e, LinkError::Io { source, .. } if source.kind() == std::io::ErrorKind::ConnectionRefused) {
                "the socket file is left from a simulator that is no longer running".into()
            } else {
                "no simulator serves this socket".into()
            },
            format!("start one: `ecmxf-sim serve --socket {}`", socket.display()),
        ),
        (StartError::Link(LinkError::Io { what: op, source }), LinkConfig::Spidev { device, gpio_chip, .. }) => {
            let device = device.display();
            let chip = gpio_chip.as_ref().map_or("the GPIO chip".into(), |c| c.display().to_string());
            let gpio = op.starts_with("request ");
            // From the cause the link kept (the errno, or a path that is no
            // GPIO chip), not from the message's words.
            let errno = source.raw_os_error();
            let not_chip = source.get_ref().is_some_and(|e| e.is::<crate::link::hardware::NotGpioChip>());
            if errno == Some(nix::libc::EACCES) || errno == Some(nix::libc::EPERM) {
                (
                    format!("this user may not open {}", if gpio { chip.as_str() } else { "the SPI device" }),
                    "run as root, or as a member of the group the .deb's udev rule (60-ecmxfd.rules) gives the \
                     devices: `sudo usermod -aG ecmxfd $USER`, log in again; `ls -l /dev/spidev* /dev/gpiochip*` \
                     must show group ecmxfd (else `sudo udevadm trigger`)"
                        .to_string(),
                )
            } else if errno == Some(nix::libc::EBUSY) {
                (
                    format!("another program holds the line ({op}): a running ecmxfd, or a GPIO tool"),
                    "stop it (`sudo systemctl stop ecmxfd`); `gpioinfo` names the line's consumer".to_string(),
                )
            } else if gpio && errno == Some(nix::libc::ENOENT) {
                (
                    format!("{chip} does not exist"),
                    "`gpiodetect` lists the GPIO chips; set link.gpio_chip to the one the lines are on \
                     (Raspberry Pi 5: the RP1 chip, docs/raspberry-pi.md)"
                        .to_string(),
                )
            } else if gpio && not_chip {
                (
                    format!("{chip} is not a GPIO chip"),
                    "`gpiodetect` lists the GPIO chips; set link.gpio_chip to one of them".to_string(),
                )
            } else if gpio && errno == Some(nix::libc::EINVAL) {
                (
                    format!("{chip} has no such line"),
                    format!(
                        "`gpioinfo {chip}` lists its lines; set link.int0_line/int1_line to the offsets the pins are on"
                    ),
                )
            } else if errno == Some(nix::libc::ENOENT) {
                (
                    format!(
                        "the kernel has no SPI device {device}: SPI is not enabled, or the device names another bus or chip select"
                    ),
                    "Raspberry Pi: `sudo raspi-config nonint do_spi 0` (or dtparam=spi=on in \
                     /boot/firmware/config.txt) and reboot; other boards: enable the spidev overlay. \
                     `ls /dev/spidev*` lists the devices; link.device must name one"
                        .to_string(),
                )
            } else if errno == Some(nix::libc::ENOTTY) {
                (
                    format!("{device} is not an SPI device (spidev)"),
                    "set link.device to a /dev/spidevB.C node (`ls /dev/spidev*`)".to_string(),
                )
            } else if op.starts_with("configure") {
                (
                    "the SPI controller refused mode 0 or the clock".to_string(),
                    "lower link.spi_hz; the controller's driver must support SPI mode 0".to_string(),
                )
            } else {
                ("the operating system refused the device".to_string(), NAMED.to_string())
            }
        }
        (StartError::Link(_), _) => ("the link could not be opened".to_string(), NAMED.to_string()),
    };
    fail(what, cause, fix)
}

/// `ecmxfd probe`, the command: refuses while a daemon answers on the
/// configuration's socket (unless `force`), then walks the steps of
/// `source` (the file, or `--sim`) on stdout. Exit status: 0 when every
/// step passed, 1 when one failed, 2 when it could not run.
pub fn command(config: &Config, source: &str, force: bool) -> u8 {
    use std::io::Write as _;
    if !force && let Some(why) = daemon_in_the_way(config) {
        eprintln!("ecmxfd probe: {why}");
        return 2;
    }
    let mut out = std::io::stdout();
    // A reader that went away (`| head`) ends the output, not the process.
    let _ = writeln!(out, "ecmxfd probe ({source})");
    match run(config, &mut out) {
        Ok(true) => 0,
        Ok(false) => 1,
        // The reader went away: nothing left to tell.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => 2,
        Err(e) => {
            eprintln!("ecmxfd probe: {e}");
            2
        }
    }
}

/// Refuses to probe a chip a running daemon is using: the probe's packets
/// would break into its exchange. The daemon is taken to run when its API
/// socket answers. The in-process simulator is the probe's own.
pub fn daemon_in_the_way(config: &Config) -> Option<String> {
    if matches!(config.link, LinkConfig::Sim { .. }) {
        return None;
    }
    let socket = config.api.socket_path();
    UnixStream::connect(&socket).ok().map(|_| {
        format!(
            "ecmxfd is running on this configuration (its API answers on {}): the probe would break into its \
             exchange with the chip. Stop it first (`sudo systemctl stop ecmxfd`), or give --force",
            socket.display()
        )
    })
}

/// Steps 2 to 7 over an open link.
#[derive(Debug)]
pub struct Probe<'c, L> {
    port: Port<L>,
    config: &'c Config,
    board: Board,
}

impl<'c, L: Link> Probe<'c, L> {
    /// A probe of the chip behind `link`, configured as `config` says.
    pub fn new(link: L, config: &'c Config) -> Self {
        let mut port = Port::new(link);
        port.set_ready_timeout(config.ready_timeout().max(READY_TIMEOUT));
        Self { port, config, board: Board::of(config) }
    }

    /// Runs steps 2 to 7 in order, handing each verdict to `report` with
    /// its step number as it comes; after a failure the rest are skipped.
    pub fn run(&mut self, report: &mut impl FnMut(usize, &Verdict)) -> bool {
        let mut ok = true;
        for n in 2..=STEPS.len() {
            let verdict = if ok { self.step(n) } else { Verdict::Skipped };
            ok &= !verdict.failed();
            report(n, &verdict);
        }
        ok
    }

    /// Runs step `n` (2..=7).
    pub fn step(&mut self, n: usize) -> Verdict {
        match n {
            2 => self.int0(),
            3 => self.boundary(),
            4 => self.check_word(),
            5 => self.firmware(),
            6 => self.slave_count(),
            7 => self.states(),
            _ => Verdict::Skipped,
        }
    }

    /// A port error in a step after the link came up.
    fn port_failure(&self, doing: &str, e: &PortError) -> Verdict {
        let (cause, fix) = match e {
            PortError::NotReady(_) => self.int0_silent(),
            PortError::NoAnswer { .. } | PortError::Unsynchronized => self.board.bit_errors(),
            PortError::Link(LinkError::Closed) => (
                "the simulator went away".to_string(),
                "start it again (`ecmxf-sim serve`) and run the probe again".to_string(),
            ),
            _ => ("the link failed".to_string(), NAMED.to_string()),
        };
        fail(format!("{doing}: {e}"), cause, fix)
    }

    /// Why INT0 never says ready, and the fix.
    fn int0_silent(&self) -> (String, String) {
        match &self.board {
            Board::Hardware { int0: Some((chip, line)), .. } => (
                format!(
                    "INT0 never reached its ready level on {} line {line}: another pin is wired or configured \
                     (link.int0_line, link.gpio_chip), the chip is unpowered or held in reset, or a previous run \
                     left it active-low (chip.int0_active_high = false) without a power cycle",
                    chip.display()
                ),
                format!(
                    "`gpiomon -c {} -e both {line}` while the probe runs must show edges; check the line and the \
                     chip's power and reset; power-cycle the chip",
                    chip.display()
                ),
            ),
            Board::Hardware { int0: None, .. } => (
                "the chip answers nothing: it is unpowered or held in reset".to_string(),
                "check the chip's power and reset lines".to_string(),
            ),
            Board::Simulator { socket } => (
                "the simulator holds INT0 (`ecmxf-sim ctl int0 stuck ...`)".to_string(),
                format!("`ecmxf-sim ctl --socket {} int0 stuck off`", socket_shown(socket)),
            ),
        }
    }

    /// Step 2: INT0 says ready, drops when a packet is complete and comes
    /// back. Single zero bytes are clocked until a packet completes (at most
    /// the largest packet): the chip refuses that packet of zeros as bad,
    /// but processes it, which is what INT0 shows.
    pub fn int0(&mut self) -> Verdict {
        let start = Instant::now();
        if let Err(e) = self.port.clock_byte() {
            return match e {
                PortError::NotReady(t) => {
                    let (cause, fix) = self.int0_silent();
                    fail(format!("INT0 never said ready within {t:?}"), cause, fix)
                }
                e => self.port_failure("first byte", &e),
            };
        }
        let first = start.elapsed();
        let before = match self.port.link_mut().int0_edges() {
            Ok(Some(n)) => n,
            Ok(None) => {
                let Board::Hardware { idle_us, .. } = self.board else {
                    return Verdict::Ok("ready (the link cannot see the line)".into());
                };
                return warn(
                    format!(
                        "INT0 not wired (link.int0_line unset): the daemon waits idle_us = {idle_us} us after each transfer instead"
                    ),
                    "without INT0 the host cannot know when the chip is done, which limits how short a cycle can be",
                    "wire INT0 and set link.gpio_chip and link.int0_line (docs/raspberry-pi.md, 1. Wiring)",
                );
            }
            Err(e) => return self.port_failure("reading INT0's edges", &PortError::Link(e)),
        };
        // The first byte may have been the first of the largest packet: its
        // last completes it, and the byte after waits for ready again.
        for _ in 0..=(DATA_MAX + OVERHEAD) {
            if let Err(e) = self.port.clock_byte() {
                return match e {
                    PortError::NotReady(t) => {
                        let (cause, fix) = match &self.board {
                            Board::Simulator { .. } => self.int0_silent(),
                            Board::Hardware { .. } => (
                                "the chip went busy after a packet and did not finish: it reset or lost power"
                                    .to_string(),
                                "check the chip's supply and reset lines (a supply that sags under load)".to_string(),
                            ),
                        };
                        fail(format!("INT0 did not say ready again within {t:?}"), cause, fix)
                    }
                    e => self.port_failure("clocking bytes", &e),
                };
            }
            match self.port.link_mut().int0_edges() {
                Ok(Some(now)) if now >= before + 2 => {
                    return Verdict::Ok(format!(
                        "ready after {first:.1?}; went busy when a packet was complete and ready again ({} edges)",
                        now - before
                    ));
                }
                Ok(_) => {}
                Err(e) => return self.port_failure("reading INT0's edges", &PortError::Link(e)),
            }
        }
        let (cause, fix) = match &self.board {
            Board::Hardware { int0: Some((chip, line)), .. } => (
                format!(
                    "INT0 stays at its ready level while whole packets are clocked: {} line {line} is another pin \
                     (one that sits high), or SCLK or CS do not reach the chip, so it never sees a packet",
                    chip.display()
                ),
                format!(
                    "`gpiomon -c {} -e both {line}` must show two edges per packet; check link.int0_line and the \
                     SCLK/CS wiring",
                    chip.display()
                ),
            ),
            _ => (
                "the simulated chip never went busy after a packet, which a working simulator always does".into(),
                "report it with this output: it is a bug of the simulator or of its link".into(),
            ),
        };
        fail(
            format!("no INT0 edge in {} clocked bytes (a packet is at most that long)", DATA_MAX + OVERHEAD),
            cause,
            fix,
        )
    }

    /// Step 3: finds the packet length in the chip's byte stream, and reads
    /// the check type from the answer that follows.
    pub fn boundary(&mut self) -> Verdict {
        match self.port.synchronize() {
            Ok(()) => Verdict::Ok(format!(
                "{}-byte packets ({}-byte data section), {} check word",
                self.port.data_size() + OVERHEAD,
                self.port.data_size(),
                self.port.check()
            )),
            Err(PortError::Unsynchronized) => self.no_boundary(),
            Err(e) => self.port_failure("synchronising", &e),
        }
    }

    /// No boundary: what the chip's MISO bytes look like says why.
    fn no_boundary(&mut self) -> Verdict {
        let mut sample = [0u8; 16];
        for b in &mut sample {
            match self.port.clock_byte() {
                Ok(v) => *b = v,
                Err(e) => return self.port_failure("sampling MISO", &e),
            }
        }
        let shown = sample.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" ");
        let what = format!("no packet boundary in {} bytes of MISO (last bytes: {shown})", 3 * (DATA_MAX + OVERHEAD));
        let (cause, fix) = match (&self.board, sample) {
            (Board::Hardware { .. }, s) if s.iter().all(|&b| b == 0xFF) => (
                "MISO sits high: it is not connected, the chip is not selected (CS), or it is held in reset".into(),
                "check the MISO and CS wires (docs/raspberry-pi.md, 1. Wiring) and the chip's reset".into(),
            ),
            (Board::Hardware { .. }, s) if s.iter().all(|&b| b == 0) => (
                "MISO sits low: shorted to ground, or the chip is unpowered".into(),
                "check the MISO wire and the chip's supply".into(),
            ),
            (Board::Hardware { .. }, _) => (
                "bytes arrive but never form packets: the SPI mode is not 0, or the clock is too fast for the wiring"
                    .to_string(),
                format!(
                    "ecmxfd asks the controller for SPI mode 0 (CPOL 0, CPHA 0), 8-bit words, MSB first: make sure \
                     no device-tree overlay or SPI driver forces another mode (spi-cpol/spi-cpha/spi-cs-high on \
                     the chip's node); then {}",
                    self.board.bit_errors().1
                ),
            ),
            (Board::Simulator { .. }, _) => self.board.bit_errors(),
        };
        fail(what, cause, fix)
    }

    /// Step 4: switches the check word to CRC-32 (command 25) and the data
    /// section to its configured size (command 23) as bring-up will, then
    /// counts corrupt answers over [`EXCHANGES`] status exchanges: CRC-32
    /// catches the bit errors a clock too fast for the wiring causes.
    pub fn check_word(&mut self) -> Verdict {
        let chip = &self.config.chip;
        if chip.crc32
            && self.port.check() != CheckType::Crc32
            && let Err(e) = self.port.set_check(CheckType::Crc32)
        {
            let (cause, fix) = self.board.bit_errors();
            return fail(
                format!("the chip did not answer in CRC-32 after command 25 ({e})"),
                cause,
                format!("{fix}; chip.crc32 = false would only hide the errors"),
            );
        }
        if self.port.data_size() != chip.data_size
            && let Err(e) = self.port.resize(chip.data_size)
        {
            let (cause, fix) = self.board.bit_errors();
            return fail(
                format!("the chip did not take the {}-byte data section (command 23: {e})", chip.data_size),
                cause,
                format!("{fix}, or a smaller chip.data_size"),
            );
        }
        let before = self.port.stats();
        for _ in 0..EXCHANGES {
            if let Err(e) = self.port.call(&InfoUpdate) {
                return self.port_failure("status exchanges", &e);
            }
        }
        let after = self.port.stats();
        let (corrupt, exchanges) = (after.corrupt - before.corrupt, after.exchanges - before.exchanges);
        let what = format!(
            "{} check word and the {}-byte data section in force; {EXCHANGES} status calls ({exchanges} packets), {corrupt} corrupt answers",
            self.port.check(),
            self.port.data_size()
        );
        if !chip.crc32 {
            return warn(
                what,
                "chip.crc32 = false: the fixed check word detects no bit errors, so corrupt data would be used",
                "set chip.crc32 = true",
            );
        }
        if corrupt * 100 > exchanges * CORRUPT_FAIL_PERCENT {
            let (cause, fix) = self.board.bit_errors();
            return fail(what, cause, format!("{fix}; with this many the cyclic exchange loses input frames"));
        }
        if corrupt > 0 {
            let (cause, fix) = self.board.bit_errors();
            return warn(what, cause, format!("{fix}; each corrupt answer costs a resend"));
        }
        Verdict::Ok(what)
    }

    /// Step 5: the firmware version (command 56).
    pub fn firmware(&mut self) -> Verdict {
        match self.port.call(&FwVersionGet) {
            Ok(a) => Verdict::Ok(format!("version {0} ({0:#04x})", a.header.return_value)),
            Err(e) => self.port_failure("FW_VERSION_GET", &e),
        }
    }

    /// Step 6: initialises the network (ECAT_INIT with the configured DC
    /// timing, as bring-up does), counts the slaves, reads who they are and
    /// compares them with the `[[slave]]` entries.
    pub fn slave_count(&mut self) -> Verdict {
        let no_slaves = || {
            (
                "no slave answers on the chip's EtherCAT port: no cable, the cable in the slave's OUT port \
                 instead of IN, or the slaves unpowered"
                    .to_string(),
                "connect the chip's port to the first slave's IN port and power the slaves; the slave's link LED \
                 must light"
                    .to_string(),
            )
        };
        let count = match bringup::init_network(&mut self.port, self.config) {
            Ok(0) => {
                let (cause, fix) = no_slaves();
                return fail("ECAT_INIT found 0 slaves", cause, fix);
            }
            Ok(n) => n,
            Err(BringUpError::Port(e)) => return self.port_failure("ECAT_INIT", &e),
            Err(_) => {
                let (cause, fix) = no_slaves();
                return fail("ECAT_INIT (initialise the network) failed on the chip", cause, fix);
            }
        };
        let slaves = match bringup::identify(&mut self.port, count) {
            Ok(s) => s,
            Err(e) => return self.port_failure("reading the slaves' identity", &e),
        };
        let listed = slaves.iter().enumerate().map(|(i, s)| format!("{i} {:?}", s.name)).collect::<Vec<_>>();
        let what = format!("{count} slave{}: {}", if count == 1 { "" } else { "s" }, listed.join(", "));
        match bringup::check_identity(self.config, &slaves) {
            Ok(()) => Verdict::Ok(what),
            Err(e) => fail(
                format!("{what}; {e}"),
                "the network differs from the [[slave]] entries: a slave missing, unpowered, in another order or \
                 of another revision",
                "connect and power the slaves as configured, or correct the [[slave]] entries \
                 (`ecmxfctl slaves` shows what is found)",
            ),
        }
    }

    /// Step 7: every slave's state and AL status code (command 15, items 6
    /// and 7), and the network state in the status header.
    pub fn states(&mut self) -> Verdict {
        let network = match self.port.call(&InfoUpdate) {
            Ok(a) => a.header.ecat_state,
            Err(e) => return self.port_failure("reading the network state", &e),
        };
        let count = match self.port.call(&ecmxf_wire::payload::slave_info::SlaveCountGet) {
            Ok(a) => a.header.return_value,
            Err(e) => return self.port_failure("counting the slaves", &e),
        };
        let mut states = Vec::new();
        let mut faults = Vec::new();
        for slave in 0..count {
            let state = match bringup::number(&mut self.port, slave, SlaveInfoCode::State) {
                Ok(v) => EcatState::from_u8(v as u8),
                Err(e) => return self.port_failure(&format!("reading slave {slave}'s state"), &e),
            };
            let code = match bringup::number(&mut self.port, slave, SlaveInfoCode::AlStatus) {
                Ok(v) => v as u16,
                Err(e) => return self.port_failure(&format!("reading slave {slave}'s AL status"), &e),
            };
            let shown = shown_state(state);
            if code != 0 || !matches!(state, EcatState::Init | EcatState::PreOp | EcatState::SafeOp | EcatState::Op) {
                faults.push(format!("slave {slave} in {shown}, AL status {code:#06x} ({})", al_status_text(code)));
            }
            states.push(format!("{slave} {shown}"));
        }
        let what = format!("network {}; slaves: {}", shown_state(network), states.join(", "));
        if faults.is_empty() {
            return Verdict::Ok(what);
        }
        fail(
            format!("{what}; {}", faults.join("; ")),
            "the slave refuses its state: the AL status code says why (e.g. a configuration it does not accept, \
             a watchdog, a hardware fault)",
            "look the code up in the slave's manual; power-cycling the slave clears a latched error",
        )
    }
}

/// A state as EtherCAT users write it: `PREOP+ERR` for 0x12.
fn shown_state(state: EcatState) -> String {
    match state {
        EcatState::Other(v) if v & 0x10 != 0 && EcatState::from_u8(v & !0x10).is_requestable() => {
            format!("{}+ERR", EcatState::from_u8(v & !0x10))
        }
        s => s.to_string(),
    }
}

/// Runs the probe on `config`, printing a line per step to `out` as it
/// goes (and the cause and fix under a failure or warning); `Ok(true)`
/// when no step failed.
pub fn run(config: &Config, out: &mut impl Write) -> io::Result<bool> {
    let print = |out: &mut dyn Write, n: usize, v: &Verdict| -> io::Result<()> {
        let (tag, what, finding) = match v {
            Verdict::Ok(w) => ("ok", w.as_str(), None),
            Verdict::Warn(f) => ("WARN", f.what.as_str(), Some(f)),
            Verdict::Fail(f) => ("FAIL", f.what.as_str(), Some(f)),
            Verdict::Skipped => ("skip", "not run: a step before it failed", None),
        };
        writeln!(out, "{n}. {:<18} {tag:<4}  {what}", STEPS[n - 1])?;
        if let Some(f) = finding {
            writeln!(out, "{:28}cause: {}", "", f.cause)?;
            writeln!(out, "{:28}fix:   {}", "", f.fix)?;
        }
        out.flush()
    };
    let link = match open(config) {
        Ok(link) => link,
        Err(v) => {
            print(out, 1, &v)?;
            for n in 2..=STEPS.len() {
                print(out, n, &Verdict::Skipped)?;
            }
            writeln!(out, "step 1 failed: the cause and fix are under it")?;
            return Ok(false);
        }
    };
    print(out, 1, &Verdict::Ok(link.describe()))?;
    let mut probe = Probe::new(link, config);
    let mut result = Ok(());
    let mut first_failure = None;
    let ok = probe.run(&mut |n, v| {
        if v.failed() && first_failure.is_none() {
            first_failure = Some(n);
        }
        if result.is_ok() {
            result = print(out, n, v);
        }
    });
    result?;
    match first_failure {
        None => writeln!(out, "all {} steps passed: the link works and the network answers", STEPS.len())?,
        Some(n) => writeln!(out, "step {n} failed: the cause and fix are under it")?,
    }
    Ok(ok)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Raspberry Pi configuration: the hints name its line and clock.
    fn rpi(int0_line: Option<u32>) -> Config {
        let mut c = Config::simulator();
        c.link = LinkConfig::Spidev {
            device: "/dev/ecmxf-no-such-spidev".into(),
            spi_hz: 20_000_000,
            gpio_chip: Some("/dev/gpiochip0".into()),
            int0_line,
            int1_line: Some(25),
            debounce_us: None,
            idle_us: 200,
        };
        c
    }

    /// A chip that never speaks: MISO reads `miso(n)` for the n-th byte,
    /// INT0 is ready at once (or never), and the edges are as given.
    struct Mute {
        miso: fn(usize) -> u8,
        clocked: usize,
        ready: bool,
        edges: Option<u64>,
    }

    impl Mute {
        fn new(miso: fn(usize) -> u8) -> Self {
            Self { miso, clocked: 0, ready: true, edges: Some(0) }
        }
    }

    impl Link for Mute {
        fn transfer(&mut self, _tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
            for b in rx {
                *b = (self.miso)(self.clocked);
                self.clocked += 1;
            }
            Ok(())
        }
        fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
            if !self.ready {
                std::thread::sleep(timeout);
            }
            Ok(self.ready)
        }
        fn int1_active(&mut self) -> Result<bool, LinkError> {
            Ok(false)
        }
        fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
            Ok(self.edges)
        }
        fn describe(&self) -> String {
            "mute chip".into()
        }
    }

    #[track_caller]
    fn failed(v: Verdict) -> Finding {
        match v {
            Verdict::Fail(f) => f,
            other => panic!("expected a failure, got {other:?}"),
        }
    }

    #[test]
    fn states_with_the_error_bit_read_as_ethercat_tools_write_them() {
        assert_eq!(shown_state(EcatState::from_u8(0x12)), "PREOP+ERR");
        assert_eq!(shown_state(EcatState::from_u8(0x14)), "SAFEOP+ERR");
        assert_eq!(shown_state(EcatState::Op), "OP");
        assert_eq!(shown_state(EcatState::from_u8(0x30)), "state 0x30");
    }

    #[test]
    fn int0_that_never_moves_fails_step_2_naming_the_line() {
        let config = rpi(Some(24));
        let f = failed(Probe::new(Mute::new(|_| 0xFF), &config).int0());
        assert!(f.what.contains("no INT0 edge in 1440 clocked bytes"), "{f:?}");
        assert!(f.cause.contains("/dev/gpiochip0 line 24 is another pin"), "{f:?}");
        assert!(f.fix.contains("gpiomon -c /dev/gpiochip0 -e both 24"), "{f:?}");
    }

    #[test]
    fn int0_never_ready_fails_step_2_with_power_and_polarity() {
        let config = rpi(Some(24));
        let mut mute = Mute::new(|_| 0xFF);
        mute.ready = false;
        let f = failed(Probe::new(mute, &config).int0());
        assert!(f.what.contains("INT0 never said ready within 1s"), "{f:?}");
        assert!(f.cause.contains("line 24") && f.cause.contains("reset"), "{f:?}");
        assert!(f.cause.contains("chip.int0_active_high"), "{f:?}");
    }

    #[test]
    fn without_int0_step_2_warns_of_the_idle_wait() {
        let config = rpi(None);
        let mut mute = Mute::new(|_| 0xFF);
        mute.edges = None;
        match Probe::new(mute, &config).int0() {
            Verdict::Warn(f) => {
                assert!(f.what.contains("INT0 not wired") && f.what.contains("idle_us = 200 us"), "{f:?}");
                assert!(f.fix.contains("link.int0_line"), "{f:?}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn miso_bytes_say_why_no_boundary_is_found() {
        let config = rpi(Some(24));
        let f = failed(Probe::new(Mute::new(|_| 0xFF), &config).boundary());
        assert!(f.what.contains("no packet boundary in 4320 bytes of MISO (last bytes: ff ff"), "{f:?}");
        assert!(f.cause.contains("MISO sits high"), "{f:?}");
        let f = failed(Probe::new(Mute::new(|_| 0), &config).boundary());
        assert!(f.cause.contains("MISO sits low"), "{f:?}");
        let f = failed(Probe::new(Mute::new(|n| (n * 7) as u8), &config).boundary());
        assert!(f.cause.contains("SPI mode is not 0"), "{f:?}");
        assert!(f.fix.contains("lower link.spi_hz (try 10000000 Hz)"), "{f:?}");
    }

    #[test]
    fn a_device_that_does_not_open_is_explained() {
        let mut config = rpi(Some(24));
        let f = match open(&config) {
            Err(Verdict::Fail(f)) => f,
            Err(other) => panic!("{other:?}"),
            Ok(_) => panic!("/dev/ecmxf-no-such-spidev opened"),
        };
        assert!(f.what.contains("open /dev/ecmxf-no-such-spidev"), "{f:?}");
        assert!(f.cause.contains("no SPI device /dev/ecmxf-no-such-spidev"), "{f:?}");
        assert!(f.fix.contains("dtparam=spi=on"), "{f:?}");

        let file = std::env::temp_dir().join(format!("ecmxf-probe-not-spi-{}", std::process::id()));
        std::fs::write(&file, b"").unwrap();
        if let LinkConfig::Spidev { device, .. } = &mut config.link {
            *device = file.clone();
        }
        let f = match open(&config) {
            Err(Verdict::Fail(f)) => f,
            _ => panic!("a regular file configured as SPI"),
        };
        std::fs::remove_file(&file).unwrap();
        assert!(f.cause.contains("is not an SPI device"), "{f:?}");

        // GPIO errors keep the kernel's errno (or that the path is no GPIO
        // chip); the diagnosis comes from it, whatever the words.
        let gpio = |source: std::io::Error| {
            let e = StartError::Link(LinkError::io("request int0 line 24 on /dev/gpiochip0", source));
            failed(device_failure(&config, &e))
        };
        let os = std::io::Error::from_raw_os_error;
        let f = gpio(os(nix::libc::EBUSY));
        assert!(f.cause.contains("another program holds the line"), "{f:?}");
        assert!(f.fix.contains("systemctl stop ecmxfd"), "{f:?}");
        let f = gpio(os(nix::libc::ENOENT));
        assert!(f.cause.contains("/dev/gpiochip0 does not exist") && f.fix.contains("gpiodetect"), "{f:?}");
        let not_chip = crate::link::hardware::NotGpioChip("/dev/gpiochip0".into(), "is not a character device".into());
        let f = gpio(std::io::Error::other(not_chip));
        assert!(f.cause.contains("is not a GPIO chip"), "{f:?}");
        let f = gpio(os(nix::libc::EINVAL));
        assert!(f.cause.contains("has no such line") && f.fix.contains("gpioinfo /dev/gpiochip0"), "{f:?}");
        let f = gpio(os(nix::libc::EACCES));
        assert!(f.cause.contains("may not open /dev/gpiochip0") && f.fix.contains("usermod -aG ecmxfd"), "{f:?}");
        // Words alone no longer decide: a message that says "busy" with
        // another cause is not taken for a held line.
        let f = gpio(std::io::Error::other("the bus is busy"));
        assert!(!f.cause.contains("another program holds the line"), "{f:?}");
    }

    #[cfg(feature = "sim")]
    mod on_the_simulator {
        use super::*;
        use crate::link::sim::{SimHandle, SimLink};

        fn chip() -> (SimLink, SimHandle) {
            SimLink::new(ecmxf_sim::Chip::new(ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()))
        }

        /// Runs steps 2 up to `last`, each of which must pass.
        fn up_to(probe: &mut Probe<'_, SimLink>, last: usize) {
            for n in 2..=last {
                let v = probe.step(n);
                assert!(matches!(v, Verdict::Ok(_)), "step {n}: {v:?}");
            }
        }

        #[test]
        fn every_step_passes_on_a_working_chip_and_network() {
            let config = Config::simulator();
            let (link, _chip) = chip();
            let mut seen = Vec::new();
            assert!(Probe::new(link, &config).run(&mut |n, v| seen.push((n, v.clone()))));
            let texts: Vec<String> = seen
                .iter()
                .map(|(n, v)| match v {
                    Verdict::Ok(t) => format!("{n} {t}"),
                    other => panic!("step {n}: {other:?}"),
                })
                .collect();
            assert_eq!(texts.len(), 6);
            assert!(texts[1].contains("144-byte packets (112-byte data section), fixed check word"), "{texts:?}");
            assert!(texts[2].contains("CRC-32 check word and the 512-byte data section"), "{texts:?}");
            assert!(texts[2].contains("0 corrupt answers"), "{texts:?}");
            assert!(texts[3].contains("version 36 (0x24)"), "{texts:?}");
            assert!(texts[4].contains(r#"3 slaves: 0 "CORE", 1 "TI CiA402 3-axis", 2 "8io""#), "{texts:?}");
            assert!(texts[5].contains("network PREOP; slaves: 0 PREOP, 1 PREOP, 2 PREOP"), "{texts:?}");
        }

        #[test]
        fn int0_is_seen_toggling_on_a_chip_left_at_the_largest_packet() {
            let config = Config::simulator();
            let (link, _chip) = chip();
            let mut probe = Probe::new(link, &config);
            up_to(&mut probe, 3);
            probe.port.resize(DATA_MAX).unwrap();
            // An earlier run left the chip at 1440-byte packets, at a
            // packet boundary: the most bytes step 2 can need.
            let mut probe = Probe::new(probe.port.into_link(), &config);
            assert!(matches!(probe.int0(), Verdict::Ok(_)));
            assert!(matches!(probe.boundary(), Verdict::Ok(t) if t.starts_with("1440-byte packets")));
        }

        /// Step `n` on a chip where steps 2 to `n - 1` passed, and then
        /// `fault` was injected (`ecmxf-sim ctl` words).
        fn after_fault(config: &Config, fault: &str, n: usize) -> Verdict {
            let (link, chip) = chip();
            let mut probe = Probe::new(link, config);
            up_to(&mut probe, n - 1);
            chip.control(fault).unwrap();
            probe.step(n)
        }

        #[test]
        fn bit_errors_fail_step_4_with_the_clock_to_lower() {
            let f = failed(after_fault(&rpi(Some(24)), "flip miso 0.002", 4));
            assert!(f.cause.contains("bit errors on the SPI wires: a clock of 20 MHz"), "{f:?}");
            assert!(f.fix.contains("lower link.spi_hz (try 10000000 Hz)"), "{f:?}");
        }

        #[test]
        fn a_few_bit_errors_only_warn() {
            match after_fault(&Config::simulator(), "flip miso 0.00005", 4) {
                Verdict::Warn(f) => assert!(f.cause.contains("bit flips injected"), "{f:?}"),
                other => panic!("{other:?}"),
            }
        }

        #[test]
        fn no_answer_fails_step_5() {
            let f = failed(after_fault(&Config::simulator(), "flip miso 1", 5));
            assert!(f.what.contains("FW_VERSION_GET: no intact answer"), "{f:?}");
        }

        #[test]
        fn no_slave_or_another_network_fails_step_6() {
            let (link, chip) = chip();
            let config = Config::simulator();
            let mut probe = Probe::new(link, &config);
            up_to(&mut probe, 5);
            chip.control("unplug 0").unwrap();
            let f = failed(probe.slave_count());
            assert!(f.what.contains("ECAT_INIT (initialise the network) failed"), "{f:?}");
            assert!(f.cause.contains("no slave answers"), "{f:?}");
            chip.control("replug 0").unwrap();
            assert!(matches!(probe.slave_count(), Verdict::Ok(_)), "a latched failure is cleared");

            let mut config = Config::simulator();
            config.slaves = vec![Default::default(); 2];
            let f = failed(after_fault(&config, "status", 6));
            assert!(f.what.contains("3 slaves answer, the configuration lists 2 ([[slave]] entries)"), "{f:?}");
        }

        #[test]
        fn a_slave_in_error_fails_step_7() {
            let f = failed(after_fault(&Config::simulator(), "al-error 1 0x1D", 7));
            assert!(f.what.contains("slave 1 in PREOP, AL status 0x001d (invalid output configuration)"), "{f:?}");
        }
    }
}
