//! Bring-up from the configuration, in the order of the manual's figure 7
//! (v049 "ECM-XF 初始化EtherCAT網路及從站配置說明"): link (size sync,
//! CRC-32, packet size, INT polarity), init network with DC (1), identity
//! check against the expected network, PRE-OP (12/41), PDO mapping (7, then
//! 2), start-up SDOs (10), CiA402 helper (26/27), FIFO sizes (19, 52/54, 66),
//! SAFE-OP, a prefilled RxFIFO, OP, FIFO on (18). Each failure names the
//! step, and the slave when one is at fault.

use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ControlFlags, ErrorFlags};
use ecmxf_wire::payload::cia402::{Cia402ConfigSet, Cia402Control, Cia402State, Cia402StateSet};
use ecmxf_wire::payload::control::{FwVersionGet, InfoUpdate, WkcErrorLimit, WkcErrorLimitSet};
use ecmxf_wire::payload::ecat_init::{DcSync, DcTiming, EcatInit, EcatInitDc, EcatReconfig};
use ecmxf_wire::payload::fifo::{FifoEnable, FifoInit, FifoPackSizeGet, FifoSetRxCount, FifoSetTxCount};
use ecmxf_wire::payload::interrupt::{IntConfig, IntPolarity, IntSetEnable};
use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoDirection, PdoFifoOp};
use ecmxf_wire::payload::raw::{DatagramCommand, DatagramHead, RawGet, RawRequest};
use ecmxf_wire::payload::slave_info::{SlaveCountGet, SlaveInfo, SlaveInfoCode, SlaveInfoGet};
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use ecmxf_wire::{CheckType, EcatState};

use tracing::warn;

use crate::config::{Config, InitTransition, TargetState};
use crate::link::Link;
use crate::port::{Port, PortError};

/// Each `[[axis]]`'s controlword (2 bytes at its offset in the slave's
/// outputs) and statusword (in its inputs) lie within that slave's process
/// data; a slave not on the ring is the census's business, not this.
fn axes_fit(axes: &[crate::config::AxisConfig], slaves: &[SlaveSummary]) -> Result<(), BringUpError> {
    for (n, a) in axes.iter().enumerate() {
        let Some(s) = slaves.get(usize::from(a.slave)) else { continue };
        let (cw, sw) = (usize::from(a.controlword_offset), usize::from(a.statusword_offset));
        if s.rx_bytes < cw + 2 || s.tx_bytes < sw + 2 {
            return Err(BringUpError::AxisUnmapped(format!(
                "axis[{n}]: slave {} ({}) has {} output and {} input bytes: no controlword at output byte {cw} or \
                 no statusword at input byte {sw} for the chip's CiA 402 helper; fix [[axis]] (or the slave's \
                 PDO mapping)",
                a.slave, s.name, s.rx_bytes, s.tx_bytes
            )));
        }
    }
    Ok(())
}

/// Every `[[axis]]` names a slave that answered: when one is gone (a
/// slave unplugged, powered off, a cable cut), the slaves missing are what
/// went wrong, and they are named before the chip's CiA 402 helper refuses
/// an axis on one of them. `seen`: the most slaves a run had before.
fn axes_present(axes: &[crate::config::AxisConfig], found: usize, seen: usize) -> Result<(), BringUpError> {
    let Some((axis, slave)) =
        axes.iter().enumerate().map(|(n, a)| (n, usize::from(a.slave))).find(|&(_, slave)| slave >= found)
    else {
        return Ok(());
    };
    Err(BringUpError::SlavesMissing { found, before: seen.max(slave + 1), axis, slave })
}

use super::layout::{NetworkLayout, SlaveSummary};

mod calls;
mod error;
mod esi_choice;
mod pdos;
pub(crate) use calls::blocking;
use calls::{FAILED_ON_CHIP, SLOW, sdo_download};
pub use error::BringUpError;
pub(crate) use error::describe_states;
use error::step;
use pdos::map_pdos;

/// How long all slaves get to reach a state.
const STATE_TIMEOUT: Duration = Duration::from_secs(5);

/// Asks every slave for `state` and waits for it; when that fails, reads
/// each slave's state and AL status code so the error names the slaves
/// that are not there and why (the chip's own error bit alone gave
/// "ECAT_STATE_CHECK: failed on the chip", which named no one).
fn enter<L: Link>(port: &mut Port<L>, state: EcatState, slaves: usize) -> Result<(), BringUpError> {
    match blocking(port, &StateCheck { target: SlaveSelector::All, state }, STATE_TIMEOUT) {
        Err(BringUpError::Step { detail, .. }) if detail == FAILED_ON_CHIP => {
            let found = slave_states(port, slaves);
            let slaves = found.into_iter().filter(|&(_, s, code)| s != state || code != 0).collect();
            Err(BringUpError::StateRefused { asked: state, slaves })
        }
        other => other,
    }
}

/// (position, state, AL status code) of the first `slaves` slaves, as they
/// answer now (command 21); a slave that does not answer is left out.
pub(crate) fn slave_states<L: Link>(port: &mut Port<L>, slaves: usize) -> Vec<(u8, EcatState, u16)> {
    let mut out = Vec::new();
    for i in 0..slaves.min(usize::from(u8::MAX)) as u8 {
        let mut read = |item| port.ask(&SlaveInfoGet { slave: i, item }).ok()?.number();
        if let (Some(state), Some(code)) = (read(SlaveInfoCode::State), read(SlaveInfoCode::AlStatus)) {
            out.push((i, EcatState::from_u8(state as u8), code as u16));
        }
    }
    out
}

/// One numeric item of a slave (command 21; [`SlaveInfo::number`]); 0 when
/// the answer does not decode.
pub fn number<L: Link>(port: &mut Port<L>, slave: u8, item: SlaveInfoCode) -> Result<u32, PortError> {
    let req = SlaveInfoGet { slave, item };
    Ok(port.call(&req)?.answer_to(&req).ok().and_then(|i| i.number()).unwrap_or(0))
}

/// A slave's name (command 21, its SII string), up to the first NUL.
fn name<L: Link>(port: &mut Port<L>, slave: u8) -> Result<String, PortError> {
    let req = SlaveInfoGet { slave, item: SlaveInfoCode::Name };
    Ok(match port.call(&req)?.answer_to(&req) {
        Ok(SlaveInfo::Name(bytes)) => String::from_utf8_lossy(bytes).into_owned(),
        _ => String::new(),
    })
}

/// Clears the chip's latched errors, initialises the network with the
/// configured DC timing (command 1, ECAT_INIT: slaves to PRE-OP) and returns
/// how many slaves answered.
pub fn init_network<L: Link>(port: &mut Port<L>, config: &Config) -> Result<u8, BringUpError> {
    // Errors latched by whatever ran before (a failed command of an earlier
    // run) would read as this command's.
    port.pending_control |= ControlFlags::CLEAR_ALL_ERRORS;
    port.call(&InfoUpdate)?;
    let c = &config.cycle;
    let dc = DcTiming {
        assign_activate: c.dc_assign_activate,
        sync0_ns: if c.dc_assign_activate != 0 { c.sync0_us * 1000 } else { 0 },
        sync1_ns: 0,
        shift_ns: c.shift_ns,
    };
    blocking(port, &EcatInit { special_slaves: false, master_shift: false, disable_lrw: false, dc }, SLOW)
        .map_err(|e| step("ECAT_INIT", format!("{e} (are slaves connected and powered?)")))?;
    Ok(port.ask(&SlaveCountGet)?.0)
}

/// Reads the identity (vendor, product, revision, name) of the first
/// `count` slaves in ring order.
pub fn identify<L: Link>(port: &mut Port<L>, count: u8) -> Result<Vec<SlaveSummary>, PortError> {
    let mut slaves = Vec::new();
    for i in 0..count {
        let s = SlaveSummary {
            vendor_id: number(port, i, SlaveInfoCode::VendorId)?,
            product_code: number(port, i, SlaveInfoCode::ProductCode)?,
            revision: number(port, i, SlaveInfoCode::Revision)?,
            name: name(port, i)?,
            ..SlaveSummary::default()
        };
        slaves.push(s);
    }
    Ok(slaves)
}

/// Compares the slaves found with the `[[slave]]` entries (none: any
/// network is accepted; an entry's absent ids match anything).
pub fn check_identity(config: &Config, slaves: &[SlaveSummary]) -> Result<(), BringUpError> {
    if !config.slaves.is_empty() && config.slaves.len() != slaves.len() {
        return Err(BringUpError::Count { found: slaves.len(), expected: config.expected_slaves() });
    }
    for (i, (want, got)) in config.slaves.iter().zip(slaves).enumerate() {
        let differs = want.vendor_id.is_some_and(|v| v != got.vendor_id)
            || want.product_code.is_some_and(|p| p != got.product_code)
            || want.revision.is_some_and(|r| r != got.revision);
        if differs {
            let show = |v: Option<u32>| v.map_or("any".to_string(), |v| format!("{v:#010x}"));
            return Err(BringUpError::Identity {
                position: i,
                expected: format!(
                    "{}vendor {} product {} revision {}",
                    want.name.as_ref().map(|n| format!("{n:?}: ")).unwrap_or_default(),
                    show(want.vendor_id),
                    show(want.product_code),
                    show(want.revision)
                ),
                found: format!(
                    "{:?}: vendor {:#010x} product {:#010x} revision {:#010x}",
                    got.name, got.vendor_id, got.product_code, got.revision
                ),
            });
        }
    }
    Ok(())
}

/// Brings the network up as `config` says, phase by phase (the manual's
/// figure 7). `held` are the outputs clients wrote before a recovery (none
/// at the first bring-up): the RxFIFO is prefilled with them, slave by
/// slave, so the slaves enter OP with what the lease holders last wrote,
/// not zeros.
pub(crate) fn bring_up<L: Link>(
    port: &mut Port<L>,
    config: &Config,
    held: &super::held::HeldOutputs,
    seen: usize,
) -> Result<NetworkLayout, BringUpError> {
    let firmware = link_setup(port, config)?;
    // 1. Init network with DC; identity check.
    let count = init_network(port, config)?;
    let mut slaves = identify(port, count)?;
    check_identity(config, &slaves)?;
    // A multi-device ESI's init commands are those of the device the slave
    // says it is: from here on the run's configuration has them.
    let chosen = esi_choice::esi_device_sdos(config, &slaves)?;
    let config = &*chosen;
    axes_present(&config.axes, slaves.len(), seen)?;
    if config.cycle.wkc_error_limit != 255 {
        port.call(&WkcErrorLimitSet(WkcErrorLimit(config.cycle.wkc_error_limit.max(1))))?;
    }
    // 2. PRE-OP, and the start-up SDOs of INIT -> PRE-OP (the mailbox
    // works from here).
    enter(port, EcatState::PreOp, usize::from(count))?;
    let mut remap = startup_sdos(port, config, InitTransition::Ip)?;
    // 3. PDO mapping; 4. the start-up SDOs of PRE-OP -> SAFE-OP (an ENI's
    // PDO assignment among them: the chip reads the mapping again); per-
    // slave DC; 5./6. CiA402 helper.
    map_pdos(port, config)?;
    remap |= startup_sdos(port, config, InitTransition::Ps)?;
    if remap {
        blocking(port, &EcatReconfig, SLOW).map_err(|e| step("ECAT_RECONFIG after PDO objects", e.to_string()))?;
    }
    slave_dc(port, config)?;
    cia402_helper(port, config)?;
    // 7. FIFO plan, then where each slave's data sits in the frames.
    let fifo = fifo_plan(port, config)?;
    place_slaves(port, &mut slaves)?;
    axes_fit(&config.axes, &slaves)?;
    // 8. SAFE-OP and OP as the target says.
    let state = reach_target(port, config, &slaves, &fifo, held)?;
    Ok(NetworkLayout {
        firmware,
        slaves,
        rx_size: fifo.rx_size,
        tx_size: fifo.tx_size,
        state,
        fifo_rx_depth: fifo.rx_depth,
        fifo_tx_depth: fifo.tx_depth,
        fifo_low: fifo.low,
        fifo_high: fifo.high,
        packet_ns: fifo.packet_ns,
    })
}

/// Link: finds where the chip is, then CRC-32, the packet size and the
/// interrupt polarity; returns the firmware version.
fn link_setup<L: Link>(port: &mut Port<L>, config: &Config) -> Result<u8, BringUpError> {
    port.find_chip()?;
    if config.chip.crc32 && port.check() != CheckType::Crc32 {
        port.set_check(CheckType::Crc32)?;
    }
    if port.data_size() != config.chip.data_size {
        port.resize(config.chip.data_size)?;
    }
    let firmware = port.call(&FwVersionGet)?.header.return_value;
    let mut polarity = IntPolarity::empty();
    polarity.set(IntPolarity::INT0_ACTIVE_HIGH, config.chip.int0_active_high);
    polarity.set(IntPolarity::INT1_ACTIVE_HIGH, config.chip.int1_active_high);
    port.call(&IntSetEnable(IntConfig { polarity, ..IntConfig::default() }))?;
    port.link_mut().set_polarity(config.chip.int0_active_high, config.chip.int1_active_high);
    Ok(firmware)
}

/// 3b. Per-slave DC settings (DCSYNC each, then ECAT_INIT_DC applies them).
fn slave_dc<L: Link>(port: &mut Port<L>, config: &Config) -> Result<(), BringUpError> {
    let c = &config.cycle;
    let mut dc_changed = false;
    for (i, s) in config.slaves.iter().enumerate() {
        if s.dc_assign_activate.is_none() && s.dc_shift_ns.is_none() {
            continue;
        }
        let assign_activate = s.dc_assign_activate.unwrap_or(c.dc_assign_activate);
        let timing = DcTiming {
            assign_activate,
            sync0_ns: if assign_activate != 0 { c.sync0_us * 1000 } else { 0 },
            sync1_ns: 0,
            shift_ns: s.dc_shift_ns.unwrap_or(c.shift_ns),
        };
        blocking(port, &DcSync { slave: i as u8, dc: timing }, SLOW)
            .map_err(|e| step("DC settings", format!("slave {i}: {e}")))?;
        dc_changed = true;
    }
    if dc_changed {
        blocking(port, &EcatInitDc, SLOW).map_err(|e| step("ECAT_INIT_DC", e.to_string()))?;
    }
    Ok(())
}

/// The register writes of one transition (an ENI's watchdog settings,
/// config/eni.rs), before its SDOs: one APWR each, by raw datagram
/// (RAW_ECAT_FUNC_REQ 137 / GET 138) to the slave's position, which must
/// answer (working counter 1).
fn startup_registers<L: Link>(port: &mut Port<L>, config: &Config, at: InitTransition) -> Result<(), BringUpError> {
    for (i, s) in config.slaves.iter().enumerate() {
        for r in s.registers.iter().filter(|r| r.transition == at) {
            let head = DatagramHead {
                command: DatagramCommand::Apwr,
                length: r.data.len() as u16,
                // Auto-increment addressing: position n is -n.
                adp: (i as u16).wrapping_neg(),
                ado: r.ado,
                logical: 0,
                timeout_us: 10_000,
            };
            let fail = |why: String| {
                step(
                    "start-up register",
                    format!("slave {i} {:#06x} (transition {}, {}): {why}", r.ado, at.letters(), r.origin),
                )
            };
            blocking(port, &RawRequest { head, data: &r.data }, SLOW).map_err(|e| fail(e.to_string()))?;
            match port.call(&RawGet)?.answer_to(&RawGet) {
                Ok(reply) if reply.working_counter == 1 => {}
                Ok(reply) => return Err(fail(format!("working counter {}, not 1", reply.working_counter))),
                Err(e) => return Err(fail(format!("unreadable answer: {e}"))),
            }
        }
    }
    Ok(())
}

/// Step 4: the start-up SDOs of one transition, slave by slave, in the
/// order the configuration (or its ENI) lists them. A run of writes to PDO
/// assignment and mapping objects (an ENI's PDO init commands) is written
/// as a whole by [`pdos::write_pdo_objects`]: what the slave holds already
/// is not written again. Returns whether a PDO object was written.
fn startup_sdos<L: Link>(port: &mut Port<L>, config: &Config, at: InitTransition) -> Result<bool, BringUpError> {
    startup_registers(port, config, at)?;
    let mut pdo_objects = false;
    for (i, s) in config.slaves.iter().enumerate() {
        let sdos: Vec<&crate::config::StartupSdo> = s.sdos.iter().filter(|s| s.transition == at).collect();
        let refused = |sdo: &crate::config::StartupSdo, code| {
            let from = if sdo.origin.is_empty() { String::new() } else { format!(", {}", sdo.origin) };
            step(
                "start-up SDO",
                format!(
                    "slave {i} {:#06x}:{:02x} (transition {}{from}): {code}",
                    sdo.index,
                    sdo.subindex,
                    at.letters()
                ),
            )
        };
        let mut k = 0;
        while k < sdos.len() {
            let run = sdos[k..].iter().take_while(|s| pdos::is_pdo_object(s.index)).count();
            if run > 0 {
                let writes: Vec<pdos::PdoWrite> = sdos[k..k + run]
                    .iter()
                    .map(|s| pdos::PdoWrite {
                        index: s.index,
                        subindex: s.subindex,
                        complete_access: s.complete_access,
                        data: s.payload(),
                        timeout: Duration::from_millis(u64::from(s.timeout_ms.unwrap_or(1000))),
                    })
                    .collect();
                match pdos::write_pdo_objects(port, i as u8, &writes)? {
                    Ok(wrote) => pdo_objects |= wrote,
                    Err((n, code)) => return Err(refused(sdos[k + n], code)),
                }
                k += run;
                continue;
            }
            let sdo = sdos[k];
            let timeout = Duration::from_millis(u64::from(sdo.timeout_ms.unwrap_or(1000)));
            let object = (sdo.index, sdo.subindex, sdo.complete_access);
            if let Err(code) = sdo_download(port, i as u8, object, &sdo.payload(), timeout)? {
                return Err(refused(sdo, code));
            }
            k += 1;
        }
    }
    Ok(pdo_objects)
}

/// 5./6. The chip's CiA402 helper for each `[[axis]]`, every axis disabled.
fn cia402_helper<L: Link>(port: &mut Port<L>, config: &Config) -> Result<(), BringUpError> {
    for (n, a) in config.axes.iter().enumerate() {
        let mut control = Cia402Control::ENABLE;
        control.set(Cia402Control::AUTO_FAULT_RESET, a.auto_fault_reset);
        let r = port.call(&Cia402ConfigSet {
            axis: n as u8,
            controlword_offset: a.controlword_offset,
            statusword_offset: a.statusword_offset,
            control,
            slave: a.slave,
        })?;
        if r.header.errors.contains(ErrorFlags::COMMAND_ERROR) {
            port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
            return Err(step("CiA402 helper", format!("axis {n} on slave {} refused", a.slave)));
        }
        // Restart interlock (IEC 60204-1 9.2.5.4.2; every drive safety
        // guide): a machine must not start moving by itself when power or
        // the network comes back. Axes come up disabled after every
        // bring-up, the first one and each recovery, re-init or warm reset
        // alike; a client enables them (Cia402.Command ENABLE). There is no
        // opt-out: a drive that re-enables itself after an unexplained fault
        // moves with whatever setpoint it last had.
        port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::SwitchOnDisabled })?;
    }
    Ok(())
}

/// The FIFO plan bring-up set: frame sizes, depths and marks in force.
struct FifoPlan {
    rx_size: usize,
    tx_size: usize,
    rx_depth: u8,
    tx_depth: u8,
    low: u8,
    high: u8,
    packet_ns: u64,
}

/// Step 7: frame sizes from the chip, the link budget for them (a network
/// the link can never carry is refused for good), depths fitted to the
/// FIFO memory, FIFO_INIT.
fn fifo_plan<L: Link>(port: &mut Port<L>, config: &Config) -> Result<FifoPlan, BringUpError> {
    let c = &config.cycle;
    let mut frame_size = |direction| -> Result<usize, PortError> {
        let req = FifoPackSizeGet(direction);
        Ok(port.call(&req)?.answer_to(&req).map_or(0, |r| usize::from(r.0)))
    };
    let (rx_size, tx_size) = (frame_size(PdoDirection::Outputs)?, frame_size(PdoDirection::Inputs)?);
    let (cycle_ns, data_size) = (u64::from(c.sync0_us) * 1000, port.data_size());
    let check =
        |packet: Duration| super::link_budget::check(data_size, rx_size, tx_size, packet.as_nanos() as u64, cycle_ns);
    let budget = match check(packet_time(port)?) {
        // Too slow as measured: for good only if the packet's bits at the
        // link's own clock (a bound no host stall moves) are too slow as
        // well; otherwise a loaded host may have slowed the measurement,
        // and the bring-up is tried again.
        Err(super::link_budget::BudgetError::TooSlow(measured)) => {
            let bound = port
                .link_mut()
                .clock_hz()
                .map(|hz| Duration::from_nanos(super::link_budget::clocked_ns(data_size, hz)));
            match bound.map(check) {
                Some(Err(e)) => return Err(BringUpError::Refused(e)),
                _ => {
                    let e = super::link_budget::BudgetError::TooSlow(measured);
                    return Err(step("link budget", format!("{e} (as measured now; tried again)")));
                }
            }
        }
        other => other.map_err(BringUpError::Refused)?,
    };
    // A budget the packets as measured now cannot hold (the offline check
    // had only the clock's bound): said, not refused, as a loaded host may
    // have slowed the measurement.
    if let Some(why) = c.output_latency_us.and_then(|us| {
        super::link_budget::latency_refusal(us, budget.packet_ns, cycle_ns, config.realtime.host_stall_ns())
    }) {
        warn!("cycle.output_latency_us: {why}");
    }
    if budget.load() > super::link_budget::WARN_LOAD {
        warn!(
            load_percent = (budget.load() * 100.0) as u32,
            packet_us = budget.packet_ns / 1000,
            frames_per_packet = budget.frames_per_packet,
            "the cyclic exchange takes most of the SPI link; SDO and other requests will be slow"
        );
    }
    let (rx_depth, tx_depth, low, high) =
        super::cyclic::fit_fifo(c.fifo_rx_depth, c.fifo_low, c.fifo_high, c.fifo_tx_depth, rx_size, tx_size);
    if (rx_depth, tx_depth) != (c.fifo_rx_depth, c.fifo_tx_depth) {
        warn!(rx_depth, tx_depth, low, high, "FIFO depths fitted to the 16 KiB FIFO memory");
    }
    port.call(&FifoSetRxCount(rx_depth))?;
    port.call(&FifoSetTxCount(tx_depth))?;
    blocking(port, &FifoInit, SLOW)
        .map_err(|e| step("FIFO_INIT", format!("{e}: {rx_depth} x {rx_size} + {tx_depth} x {tx_size} bytes")))?;
    Ok(FifoPlan { rx_size, tx_size, rx_depth, tx_depth, low, high, packet_ns: budget.packet_ns })
}

/// Each slave's bytes and where they sit in the output and input frames.
fn place_slaves<L: Link>(port: &mut Port<L>, slaves: &mut [SlaveSummary]) -> Result<(), BringUpError> {
    let (mut ro, mut to) = (0, 0);
    for (i, s) in slaves.iter_mut().enumerate() {
        s.rx_bytes = number(port, i as u8, SlaveInfoCode::OutputBytes)? as usize;
        s.tx_bytes = number(port, i as u8, SlaveInfoCode::InputBytes)? as usize;
        s.rx_offset = ro;
        s.tx_offset = to;
        ro += s.rx_bytes;
        to += s.tx_bytes;
    }
    Ok(())
}

/// Step 8: SAFE-OP unless the target is PRE-OP; for OP, the RxFIFO prefilled
/// with the held outputs to its high mark first (outputs must be waiting
/// when the slaves enter OP), then OP and the FIFO output on. Returns the
/// state reached.
fn reach_target<L: Link>(
    port: &mut Port<L>,
    config: &Config,
    slaves: &[SlaveSummary],
    fifo: &FifoPlan,
    held: &super::held::HeldOutputs,
) -> Result<EcatState, BringUpError> {
    let target = config.cycle.target_state;
    if target == TargetState::PreOp {
        return Ok(EcatState::PreOp);
    }
    enter(port, EcatState::SafeOp, slaves.len())?;
    if target == TargetState::SafeOp {
        return Ok(EcatState::SafeOp);
    }
    // The start-up SDOs of SAFE-OP -> OP.
    startup_sdos(port, config, InitTransition::So)?;
    let rx_size = fifo.rx_size;
    let per_packet = port.data_size().checked_div(rx_size).unwrap_or(0);
    let plan = super::cyclic::Plan {
        rx_size,
        tx_size: fifo.tx_size,
        cycle: config.cycle.dc_cycle(),
        low: fifo.low,
        high: fifo.high,
        tx_depth: fifo.tx_depth,
        budget: config.cycle.output_latency(),
    };
    let mut left = plan.prefill();
    let frames = held.image_for(slaves, rx_size).repeat(per_packet.max(1));
    while left > 0 && per_packet > 0 {
        let n = left.min(per_packet);
        port.call(&PdoFifoOp { op: FifoOpFlags::WRITE, frames: n as u8, outputs: &frames[..n * rx_size] })?;
        left -= n;
    }
    enter(port, EcatState::Op, slaves.len())?;
    port.call(&FifoEnable(true))?;
    Ok(EcatState::Op)
}

/// The time one packet takes on this link, as measured: the median of five
/// status packets (clocking, the chip's processing, the host's wake-up).
fn packet_time<L: Link>(port: &mut Port<L>) -> Result<Duration, PortError> {
    let mut times = [Duration::ZERO; 5];
    for t in &mut times {
        let start = Instant::now();
        port.send_once(&InfoUpdate)?;
        *t = start.elapsed();
    }
    times.sort();
    Ok(times[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(slave: u8) -> crate::config::AxisConfig {
        crate::config::AxisConfig { slave, controlword_offset: 0, statusword_offset: 0, auto_fault_reset: false }
    }

    /// Slave 5 of 10 unplugged, axes on slaves 1 and 9: the missing slaves
    /// are the error, named before any axis the helper would refuse.
    #[test]
    fn slaves_an_axis_needs_are_named_missing_first() {
        let axes = [axis(1), axis(9)];
        assert!(axes_present(&axes, 10, 10).is_ok());
        let e = axes_present(&axes, 5, 10).unwrap_err();
        assert!(!e.is_permanent(), "a replug brings them back");
        assert_eq!(
            e.to_string(),
            "slaves 5-9 are missing: 5 slaves answer, 10 did before (unplugged, powered off, or the cable after slave \
             4 cut?); axis[1] drives slave 9"
        );
        let first = axes_present(&[axis(0)], 0, 0).unwrap_err().to_string();
        assert!(first.starts_with("slave 0 is missing: 0 slaves answer, 1 did before"), "{first}");
        assert!(first.contains("the cable to the first slave"), "{first}");
    }
}
