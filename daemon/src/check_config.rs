//! `ecmxfd --check-config FILE`: the configuration read, its files loaded
//! and checked as a start would, and the link budget of the network it
//! describes, without touching a chip. Each mistake names its key and
//! line; the exit status is the one a start would end with.

use std::io::Write;
use std::path::Path;

use crate::config::{Config, ConfigError, LinkConfig};
use crate::master::link_budget::{BudgetError, LinkBudget};

/// Exit status of a configuration mistake.
pub const EXIT_CONFIG: u8 = 2;

/// Checks the configuration at `path`, reports to `out` (notes, the
/// verdict, the link budget) and `err` (the mistake), and returns the exit
/// status: 0, [`EXIT_CONFIG`] for a mistake,
/// [`crate::lifecycle::EXIT_REFUSED`] for a network that can never run.
/// A reader that went away (`| head`) only shortens the report.
pub fn check_config(path: &Path, out: &mut dyn Write, err: &mut dyn Write) -> u8 {
    let (c, notes, budget) = match load(path) {
        Ok(v) => v,
        Err(e) => {
            let _ = writeln!(err, "{e}");
            return EXIT_CONFIG;
        }
    };
    for n in &notes {
        let _ = writeln!(out, "note: {n}");
    }
    let link = match &c.link {
        LinkConfig::Sim { .. } => "in-process simulator".to_string(),
        LinkConfig::SimSocket { socket } => format!("simulator socket {}", socket.display()),
        LinkConfig::Spidev { device, .. } => format!("{}", device.display()),
    };
    let latency = match c.cycle.output_latency_us {
        Some(us) => format!(", output latency budget {us} us"),
        None => String::new(),
    };
    let budget = match budget {
        Ok(Ok(b)) => Ok(b),
        Ok(Err(e)) => {
            let _ = writeln!(err, "{}: the network cannot run: link budget: {e}", path.display());
            return crate::lifecycle::EXIT_REFUSED;
        }
        Err(why) => Err(why),
    };
    let _ = writeln!(
        out,
        "{}: ok ({link}, {} expected slaves, {} us cycle{latency})",
        path.display(),
        c.slaves.len(),
        c.cycle.sync0_us
    );
    let _ = match budget {
        Ok(b) => writeln!(
            out,
            "link budget: the process data needs {:.0}% of the SPI link ({} cycle(s) of frames a packet, {:.0} \
             exchanges/s at least)",
            b.load() * 100.0,
            b.frames_per_packet,
            b.min_exchanges_per_s()
        ),
        Err(why) => writeln!(
            out,
            "link budget: not known offline ({why}: the slaves' own mapping is read at bring-up, which checks it)"
        ),
    };
    if let Some(w) = &c.web {
        let _ = writeln!(out, "web: {}", w.summary(c.api.tokens.len(), c.api.client_certs.len()));
    }
    if let Some(o) = &c.opcua {
        let _ = writeln!(out, "opcua: {}", o.summary());
    }
    0
}

/// The offline link budget, or why the frame sizes are known only from
/// the slaves.
type Budget = Result<Result<LinkBudget, BudgetError>, String>;

type Checked = (Config, Vec<String>, Budget);

/// The configuration, its notes and its offline link budget (`None` where
/// the frame sizes are known only from the slaves).
fn load(path: &Path) -> Result<Checked, ConfigError> {
    let c = Config::load(path)?;
    let (notes, simulated) = checked(&c, path)?;
    let budget = link_budget(&c, simulated);
    Ok((c, notes, budget))
}

/// What a start checks before it touches the chip: the mistakes
/// `--check-config` exits [`EXIT_CONFIG`] for (the configuration, the
/// files it names, the simulator's network and the axes on it), so a start
/// fails the same way, with the key named, and systemd does not restart a
/// configuration that can never load. `path` is the configuration file
/// (`--sim` for the built-in one). A link budget the network can never
/// meet is left to bring-up, which refuses it once with
/// [`crate::lifecycle::EXIT_REFUSED`], the status the check gives it.
pub fn preflight(c: &Config, path: &Path) -> Result<(), (u8, String)> {
    checked(c, path).map(|_| ()).map_err(|e| (EXIT_CONFIG, e.to_string()))
}

/// The simulated network's frame sizes and packet time, where the link is
/// the in-process simulator ([`simulated_frames`]).
type Simulated = Option<(usize, usize, u64)>;

/// The notes of a loaded configuration and its simulated network's frames.
/// The link budget is `--check-config`'s alone ([`link_budget`]): a start
/// leaves it to bring-up, and would read every `[[slave]] esi` file again
/// for it.
fn checked(c: &Config, path: &Path) -> Result<(Vec<String>, Simulated), ConfigError> {
    let notes = c.check_files(path)?;
    // The Sparkplug node's certificates and credentials load as at start.
    if let Some(s) = &c.sparkplug {
        crate::sparkplug::prepare(s).map_err(|e| ConfigError::Invalid {
            file: path.into(),
            key: "sparkplug".into(),
            message: e.to_string(),
        })?;
    }
    let simulated = simulated_frames(c, path)?;
    latency_fits(c, path, simulated.map(|(_, _, packet_ns)| packet_ns))?;
    Ok((notes, simulated))
}

/// `cycle.output_latency_us` against the link's floor
/// ([`crate::master::link_budget::min_output_latency_ns`]) where the packet
/// time is known offline: the bits at the configured SPI clock (the
/// chip's processing and the host come on top, so what is refused here
/// can never hold), or the simulated chip's clock and processing time.
fn latency_fits(c: &Config, path: &Path, simulated_packet_ns: Option<u64>) -> Result<(), ConfigError> {
    let Some(budget_us) = c.cycle.output_latency_us else { return Ok(()) };
    let packet_ns = match (&c.link, simulated_packet_ns) {
        (LinkConfig::Spidev { spi_hz, .. }, _) => {
            crate::master::link_budget::clocked_ns(c.chip.data_size, u64::from(*spi_hz))
        }
        (_, Some(ns)) => ns,
        _ => return Ok(()),
    };
    let cycle_ns = u64::from(c.cycle.sync0_us) * 1000;
    match crate::master::link_budget::latency_refusal(budget_us, packet_ns, cycle_ns, c.realtime.host_stall_ns()) {
        None => Ok(()),
        Some(message) => {
            Err(ConfigError::Invalid { file: path.into(), key: "cycle.output_latency_us".into(), message })
        }
    }
}

/// The link budget of the network the configuration describes: the frame
/// sizes of its ENI (which lists every slave's PDOs), else of the simulated
/// network it runs on (its file, or the demo network `--sim` runs:
/// `simulated`, checked against the configuration by
/// [`simulated_frames`]), else of its `[[slave]]` list (config/slave_frames.rs),
/// with the packet time its link gives; where only the slaves can tell
/// (their mapping is read at bring-up), why. What bring-up would refuse,
/// said offline.
fn link_budget(c: &Config, simulated: Simulated) -> Budget {
    let (rx, tx) = match (c.eni_frames, simulated) {
        (Some(frames), _) => frames,
        (None, Some((rx, tx, _))) => (rx, tx),
        (None, None) if c.eni.is_some() => {
            return Err("the ENI does not give every slave's process data".into());
        }
        (None, None) => c.slave_frames()?,
    };
    let data_size = c.chip.data_size;
    let packet_ns = match (&c.link, simulated) {
        (_, Some((_, _, packet_ns))) => packet_ns,
        // The bits on the wire: a lower bound, the chip's processing on top.
        (LinkConfig::Spidev { spi_hz, .. }, None) => {
            crate::master::link_budget::clocked_ns(data_size, u64::from(*spi_hz))
        }
        _ => return Err("the simulator's network is not known offline".into()),
    };
    Ok(crate::master::link_budget::check(data_size, rx, tx, packet_ns, u64::from(c.cycle.sync0_us) * 1000))
}

/// The simulated network's frame sizes (each slave's default mapping) and
/// the packet time its SPI clock gives, after checking it against the
/// configuration; `None` when the link is not the in-process simulator.
#[cfg(feature = "sim")]
fn simulated_frames(c: &Config, path: &Path) -> Result<Simulated, ConfigError> {
    let Some((net, chip)) = crate::config::sim_network::load(c, path)? else { return Ok(None) };
    crate::config::sim_network::check_count(c, &net, path)?;
    crate::config::sim_network::check_axes(c, &net, path)?;
    let rx: usize = net.slaves.iter().map(|s| s.rx.bytes()).sum();
    let tx: usize = net.slaves.iter().map(|s| s.tx.bytes()).sum();
    let packet_ns = crate::master::link_budget::clocked_ns(c.chip.data_size, chip.spi_hz) + chip.processing_ns;
    Ok(Some((rx, tx, packet_ns)))
}

#[cfg(not(feature = "sim"))]
fn simulated_frames(_: &Config, _: &Path) -> Result<Simulated, ConfigError> {
    Ok(None)
}
