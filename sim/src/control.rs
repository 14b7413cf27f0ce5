//! Run-time control of a simulated chip: fault injection and the outside
//! world, as one-line text commands. The socket server and tests use the
//! same language, documented in sim/README.md.

use crate::chip::Chip;
use crate::net::slave::Device;

/// The commands, for `help`.
pub const HELP: &str = "\
status                          counters, state, FIFO levels
flip mosi|miso RATE             flip one bit in a byte with probability RATE (0..1)
seed N                          seed the bit-flip generator
int0 stuck high|low|off         hold INT0 at a level, or release it
tx-fifo stall|resume            stop (or resume) queuing input frames; all else goes on
rx-fifo starve CYCLES           the next CYCLES DC cycles find the RxFIFO empty (FIFO error, outputs repeat)
unplug SLAVE | replug SLAVE     pull a slave out of the ring / plug it back (powers up in INIT)
al-error SLAVE CODE             force an AL error (drops to SAFE-OP at most)
drive-fault SLAVE AXIS CODE     raise a CiA402 fault with an error code (emergency sent)
clear-fault SLAVE AXIS          remove the fault's cause so a fault reset succeeds
warm-reset                      reset the chip as command 127 does
gpio LINE high|low|float        drive a GPIO pin from outside
qei EDGES                       encoder edges (X4 count)
adc VOLTS                       analog input voltage
io-input SLAVE BYTE             bits ORed into a digital-IO slave's inputs
port-errors SLAVE PORT RX [INVALID [FORWARDED]]  errors counted on a slave's port (0x0300..)
outputs SLAVE                   the output bytes the slave holds (hex) and its state
record SLAVE|all [MAX]          record the output frames played from now (MAX, default 100000)
recorded [FROM [COUNT]]         the recorded frames: cycle, bytes (hex), \"repeat\" when the RxFIFO was empty
record off                      stop recording and forget the frames
mailbox SLAVE                   the slave's mailbox counters: requests, duplicates, answers read, repeats, waiting, chip SDOs
mailbox-lose SLAVE N            the next N answers in its mailbox are read out and lost on the way back
mailbox-emergency SLAVE N       the next N mailbox requests are answered after a CoE emergency
help                            this list";

fn num(s: Option<&str>, what: &str) -> Result<u64, String> {
    let s = s.ok_or_else(|| format!("missing {what}"))?;
    let v = if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        u64::from_str_radix(h, 16)
    } else {
        s.parse()
    };
    v.map_err(|_| format!("{what} {s:?} is not a number"))
}

fn slave_index(chip: &Chip, s: Option<&str>) -> Result<usize, String> {
    let i = num(s, "slave")? as usize;
    if i < chip.net.slaves.len() {
        Ok(i)
    } else {
        Err(format!("no slave {i} (the network has {})", chip.net.slaves.len()))
    }
}

/// Runs one command; `Ok` carries the answer text.
pub fn execute(chip: &mut Chip, line: &str) -> Result<String, String> {
    let mut w = line.split_whitespace();
    let cmd = w.next().ok_or("empty command")?;
    let ok = || Ok("ok".to_string());
    match cmd {
        "help" => Ok(HELP.to_string()),
        "status" => {
            let s = chip.stats;
            Ok(format!(
                "ok time_ns={} packets={} not_ready={} crc_failures={} executed={} fifo_packets={} cycles={} underruns={} rx_fifo={} tx_fifo={} state={} crc_errors={} wkc_errors={} tx_dropped={} length_mismatches={}",
                chip.now_ns,
                s.packets,
                s.not_ready,
                s.crc_failures,
                s.executed,
                s.fifo_packets,
                s.cycles,
                chip.fifo.underruns,
                chip.fifo.rx.len(),
                chip.fifo.tx.len(),
                chip.ecat_state(),
                chip.crc_errors,
                chip.wkc_errors,
                chip.fifo.tx_dropped,
                s.length_mismatches
            ))
        }
        "flip" => {
            let dir = w.next().ok_or("flip needs mosi or miso")?;
            let rate: f64 = w.next().ok_or("flip needs a rate")?.parse().map_err(|_| "rate is not a number")?;
            if !(0.0..=1.0).contains(&rate) {
                return Err(format!("rate {rate} is outside 0..1"));
            }
            match dir {
                "mosi" => chip.faults.flip_mosi = rate,
                "miso" => chip.faults.flip_miso = rate,
                other => return Err(format!("flip {other:?}: say mosi or miso")),
            }
            ok()
        }
        "seed" => {
            chip.faults.seed(num(w.next(), "seed")?);
            ok()
        }
        "int0" => match (w.next(), w.next()) {
            (Some("stuck"), Some("high")) => {
                chip.faults.int0_stuck = Some(true);
                ok()
            }
            (Some("stuck"), Some("low")) => {
                chip.faults.int0_stuck = Some(false);
                ok()
            }
            (Some("stuck"), Some("off")) => {
                chip.faults.int0_stuck = None;
                ok()
            }
            _ => Err("int0 stuck high|low|off".into()),
        },
        "tx-fifo" => match w.next() {
            Some("stall") => {
                chip.faults.tx_stalled = true;
                ok()
            }
            Some("resume") => {
                chip.faults.tx_stalled = false;
                ok()
            }
            _ => Err("tx-fifo stall|resume".into()),
        },
        "rx-fifo" => match w.next() {
            Some("starve") => {
                let n = num(w.next(), "rx-fifo starve CYCLES")?;
                chip.faults.rx_starved_cycles = u32::try_from(n).map_err(|_| format!("{n} cycles is too many"))?;
                ok()
            }
            _ => Err("rx-fifo starve CYCLES".into()),
        },
        "unplug" => {
            let i = slave_index(chip, w.next())?;
            chip.net.unplug(i);
            ok()
        }
        "replug" => {
            let i = slave_index(chip, w.next())?;
            chip.net.replug(i);
            ok()
        }
        "al-error" => {
            let i = slave_index(chip, w.next())?;
            let code = num(w.next(), "AL status code")? as u16;
            chip.net.slaves[i].inject_al_error(code);
            ok()
        }
        "drive-fault" => {
            let i = slave_index(chip, w.next())?;
            let axis = num(w.next(), "axis")? as usize;
            let code = num(w.next(), "error code")? as u16;
            if chip.net.slaves[i].inject_drive_fault(axis, code) {
                ok()
            } else {
                Err(format!("slave {i} has no drive axis {axis}"))
            }
        }
        "clear-fault" => {
            let i = slave_index(chip, w.next())?;
            let axis = num(w.next(), "axis")? as usize;
            if chip.net.slaves[i].clear_drive_fault(axis) {
                ok()
            } else {
                Err(format!("slave {i} has no drive axis {axis}"))
            }
        }
        "warm-reset" => {
            chip.warm_reset();
            ok()
        }
        "gpio" => {
            let line = num(w.next(), "line")? as u8;
            let level = match w.next() {
                Some("high") => Some(true),
                Some("low") => Some(false),
                Some("float") => None,
                _ => return Err("gpio LINE high|low|float".into()),
            };
            if usize::from(line) >= crate::chip::periph::LINES {
                return Err(format!("no GPIO line {line}"));
            }
            let now = chip.now_ns;
            chip.periph.set_input(line, level, now);
            ok()
        }
        "qei" => {
            let edges: i32 = w.next().ok_or("qei needs edges")?.parse().map_err(|_| "edges is not a number")?;
            chip.periph.qei_pulses(edges);
            ok()
        }
        "adc" => {
            let v: f64 = w.next().ok_or("adc needs volts")?.parse().map_err(|_| "volts is not a number")?;
            chip.periph.adc_volts = v;
            ok()
        }
        "io-input" => {
            let i = slave_index(chip, w.next())?;
            let bits = num(w.next(), "byte")? as u8;
            match &mut chip.net.slaves[i].device {
                Device::DigitalIo { forced_inputs } => {
                    *forced_inputs = bits;
                    ok()
                }
                _ => Err(format!("slave {i} is not a digital-IO slave")),
            }
        }
        "port-errors" => {
            // Errors on a slave's port as its ESC counts them (registers
            // 0x0300 + 2 * port: invalid frames, + 1: RX errors; 0x0308 +
            // port: forwarded RX errors), added to what it counted so far.
            let i = slave_index(chip, w.next())?;
            let port = num(w.next(), "port")?;
            if port > 3 {
                return Err(format!("port {port}: an ESC has ports 0..=3"));
            }
            let rx = num(w.next(), "RX errors")?;
            let invalid = w.next().map(|v| num(Some(v), "invalid frames")).transpose()?.unwrap_or(0);
            let forwarded = w.next().map(|v| num(Some(v), "forwarded errors")).transpose()?.unwrap_or(0);
            let r = &mut chip.net.slaves[i].registers;
            let add = |r: &mut Vec<u8>, at: usize, n: u64| r[at] = r[at].saturating_add(n.min(255) as u8);
            add(r, 0x0300 + 2 * port as usize, invalid);
            add(r, 0x0301 + 2 * port as usize, rx);
            add(r, 0x0308 + port as usize, forwarded);
            ok()
        }
        "outputs" => {
            // What reached the slave: what a master wrote, as the slave
            // holds it (to check outputs flow end to end).
            let s = &chip.net.slaves[slave_index(chip, w.next())?];
            let hex: String = s.outputs.iter().map(|b| format!("{b:02x}")).collect();
            Ok(format!("ok state={} outputs={hex}", s.esm.state))
        }
        "record" => match w.next() {
            Some("off") => {
                chip.fifo.played = None;
                ok()
            }
            which => {
                let (start, len, what) = match which {
                    Some("all") => (0, chip.master.outputs.len(), "all".to_string()),
                    other => {
                        let i = slave_index(chip, other)?;
                        let slot = chip.master.slots.iter().find(|s| s.slave == i);
                        let Some(slot) = slot.filter(|s| s.rx_len > 0) else {
                            return Err(format!("slave {i} has no outputs in the mapping"));
                        };
                        (slot.rx_offset, slot.rx_len, format!("slave {i}"))
                    }
                };
                let max = match w.next() {
                    Some(m) => num(Some(m), "max")? as usize,
                    None => 100_000,
                };
                chip.fifo.played = Some(crate::chip::fifo::PlayRecord { start, len, max, ..Default::default() });
                Ok(format!("ok recording {what} bytes={start}..{} max={max}", start + len))
            }
        },
        "recorded" => {
            let Some(r) = &chip.fifo.played else { return Err("not recording; use record SLAVE|all".into()) };
            let from = w.next().map(|v| num(Some(v), "from")).transpose()?.unwrap_or(0) as usize;
            let count = w.next().map(|v| num(Some(v), "count")).transpose()?.unwrap_or(u64::MAX) as usize;
            let mut out = format!("ok frames={} not_kept={}", r.frames.len(), r.not_kept);
            for f in r.frames.iter().skip(from).take(count) {
                let hex: String = f.bytes.iter().map(|b| format!("{b:02x}")).collect();
                out.push_str(&format!("\n{} {hex}{}", f.cycle, if f.repeated { " repeat" } else { "" }));
            }
            Ok(out)
        }
        "mailbox" => {
            let i = slave_index(chip, w.next())?;
            let m = &chip.net.slaves[i].mailboxes;
            let s = m.stats;
            Ok(format!(
                "ok requests={} duplicates={} answers_read={} repeats={} waiting={} chip_sdos={}",
                s.requests,
                s.duplicates,
                s.answers_read,
                s.repeats,
                m.waiting(),
                s.chip_sdos
            ))
        }
        "mailbox-lose" | "mailbox-emergency" => {
            let i = slave_index(chip, w.next())?;
            let n = num(w.next(), "count")? as u32;
            let faults = &mut chip.net.slaves[i].mailboxes.faults;
            if cmd == "mailbox-lose" {
                faults.lose_answers = n;
            } else {
                faults.emergency_first = n;
            }
            ok()
        }
        other => Err(format!("unknown command {other:?}; try help")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ChipConfig, Network};

    #[test]
    fn port_errors_count_as_an_esc_does_and_a_write_clears_them() {
        let mut c = Chip::new(Network::demo(), ChipConfig::default());
        assert!(execute(&mut c, "port-errors 1 2 5 3 1").is_ok());
        assert!(execute(&mut c, "port-errors 1 2 300").is_ok());
        let mut b = [0u8; 14];
        c.net.slaves[1].read_registers(0x0300, &mut b);
        assert_eq!((b[4], b[5], b[10]), (3, 255, 1), "port 2's counters, saturating at 255");
        assert!(execute(&mut c, "port-errors 1 4 1").is_err());
        c.net.slaves[1].write_registers(0x0305, &[9]);
        c.net.slaves[1].read_registers(0x0300, &mut b);
        assert_eq!(b, [0; 14], "a write to any RX error counter clears them all");
    }

    #[test]
    fn commands_act_and_errors_say_why() {
        let mut c = Chip::new(Network::demo(), ChipConfig::default());
        assert_eq!(execute(&mut c, "unplug 2"), Ok("ok".into()));
        assert!(!c.net.slaves[2].present);
        assert!(execute(&mut c, "replug 2").is_ok());
        assert!(c.net.slaves[2].present);
        assert_eq!(execute(&mut c, "unplug 9"), Err("no slave 9 (the network has 3)".into()));
        assert!(execute(&mut c, "flip mosi 2").unwrap_err().contains("outside"));
        assert!(execute(&mut c, "flip miso 0.5").is_ok());
        assert!(execute(&mut c, "int0 stuck low").is_ok());
        assert!(!c.int0_level(0));
        assert!(execute(&mut c, "drive-fault 2 0 0x2310").unwrap_err().contains("no drive axis"));
        assert!(execute(&mut c, "drive-fault 1 2 0x2310").is_ok());
        assert!(execute(&mut c, "al-error 0 0x1B").is_ok());
        assert_eq!(c.net.slaves[0].esm.al_status, 0x1B);
        assert!(execute(&mut c, "io-input 2 0x0F").is_ok());
        assert_eq!(execute(&mut c, "recorded"), Err("not recording; use record SLAVE|all".into()));
        assert!(execute(&mut c, "record 0").unwrap_err().contains("no outputs"), "no mapping yet");
        assert_eq!(execute(&mut c, "record all 2"), Ok("ok recording all bytes=0..0 max=2".into()));
        c.fifo.played.as_mut().unwrap().note(7, &[], false);
        c.fifo.played.as_mut().unwrap().note(8, &[], true);
        c.fifo.played.as_mut().unwrap().note(9, &[], false);
        assert_eq!(execute(&mut c, "recorded"), Ok("ok frames=2 not_kept=1\n7 \n8  repeat".into()));
        assert_eq!(execute(&mut c, "recorded 1"), Ok("ok frames=2 not_kept=1\n8  repeat".into()));
        assert!(execute(&mut c, "record off").is_ok());
        assert!(c.fifo.played.is_none());
        c.net.slaves[2].outputs = vec![0xA5, 0x01];
        assert_eq!(execute(&mut c, "outputs 2"), Ok("ok state=INIT outputs=a501".into()));
        assert!(execute(&mut c, "bogus").unwrap_err().contains("unknown command"));
        assert!(execute(&mut c, "status").unwrap().starts_with("ok time_ns=0"));
        assert!(execute(&mut c, "gpio 25 high").is_err());
        execute(&mut c, "tx-fifo stall").unwrap();
        assert!(c.faults.tx_stalled);
        execute(&mut c, "tx-fifo resume").unwrap();
        assert!(!c.faults.tx_stalled);
        assert!(execute(&mut c, "tx-fifo sometimes").is_err());
        execute(&mut c, "rx-fifo starve 3").unwrap();
        assert_eq!(c.faults.rx_starved_cycles, 3);
        assert!(execute(&mut c, "rx-fifo starve").is_err());
    }
}
