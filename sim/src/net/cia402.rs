//! One CiA402 axis: the drive state machine (FSA) as the v049 appendix and
//! the TI/Neuromeka documents give it, driven by the controlword 0x6040, with
//! simple motion dynamics for modes 8 (CSP), 9 (CSV) and 10 (CST).
//!
//! The axis keeps no copy of the process data: every cycle it reads its
//! command objects from the object dictionary (where the process image has
//! just put them) and writes its feedback objects back. Further axes of one
//! device sit at +0x800 per axis (TI document, "CiA402 Object Dictionary").

use ecmxf_wire::payload::cia402::Cia402State;

use super::od::{Access, DataType, Entry, Mappable, Object, ObjectDictionary};

/// Object indices of the first axis.
pub mod idx {
    /// Error code (UINT, RO).
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword.
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword.
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code.
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Modes of operation.
    pub const MODE: u16 = 0x6060;
    /// Modes of operation display.
    pub const MODE_DISPLAY: u16 = 0x6061;
    /// Position actual value.
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Velocity actual value.
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    /// Target torque.
    pub const TARGET_TORQUE: u16 = 0x6071;
    /// Max torque.
    pub const MAX_TORQUE: u16 = 0x6072;
    /// Torque actual value.
    pub const TORQUE_ACTUAL: u16 = 0x6077;
    /// Target position.
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Max motor speed (rpm).
    pub const MAX_SPEED: u16 = 0x6080;
    /// Profile acceleration (counts/s^2).
    pub const ACCELERATION: u16 = 0x6083;
    /// Quick stop deceleration (counts/s^2).
    pub const QUICK_STOP_DECEL: u16 = 0x6085;
    /// Target velocity.
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Supported drive modes (bit n-1 = mode n).
    pub const SUPPORTED_MODES: u16 = 0x6502;
}

/// Offset between the object ranges of two axes of one device.
pub const AXIS_STRIDE: u16 = 0x800;
/// Encoder counts per motor revolution (Neuromeka CORE: 65536).
pub const COUNTS_PER_REV: f64 = 65536.0;
/// Error code of a process-data (sync manager watchdog) loss.
pub const ERROR_PD_TIMEOUT: u16 = 0x8700;
/// Time the fault reaction takes before FAULT.
pub const FAULT_REACTION_NS: u64 = 5_000_000;
/// Position window for "target reached", counts.
pub const POSITION_WINDOW: f64 = 100.0;
/// Acceleration and quick-stop deceleration where the dictionary gives
/// none, counts/s^2 (one revolution per second, reached in 0.1 s).
pub const DEFAULT_ACCELERATION: f64 = 10.0 * COUNTS_PER_REV;

/// The objects a CiA 402 axis needs to be told its mode and to show it
/// (0x6060, 0x6061, 0x6502 at each axis' base), added where a drive's file
/// maps a controlword and a statusword but its dictionary lacks them (an
/// ESI without `<Dictionary>`, an SII): the real drive has them, being a
/// drive. Each is marked in `beyond_file`.
pub fn add_profile_objects(od: &mut ObjectDictionary) {
    use ecmxf_devices::od::BeyondFile;
    for k in 0..8u16 {
        let b = k * AXIS_STRIDE;
        if od.object(idx::CONTROLWORD + b).is_none() || od.object(idx::STATUSWORD + b).is_none() {
            continue;
        }
        let supported = (1i64 << 7) | (1 << 8) | (1 << 9);
        for (index, name, t, access, m, v) in [
            (idx::MODE, "Modes of operation", DataType::Int8, Access::RW, Mappable::Rx, 0),
            (idx::MODE_DISPLAY, "Modes of operation display", DataType::Int8, Access::RO, Mappable::Tx, 0),
            (idx::SUPPORTED_MODES, "Supported drive modes", DataType::UInt32, Access::RO, Mappable::No, supported),
        ] {
            if od.object(index + b).is_none() {
                od.insert(index + b, Object::var(name, Entry::new(name, t, access).mappable(m).default_int(v)));
                od.beyond_file.insert((index + b, 0), BeyondFile::ProfileAdded);
            }
        }
    }
}

/// The axes a device's dictionary describes (CiA 402: a controlword and a
/// statusword at 0x6040/0x6041, further axes 0x800 above): a drive built
/// from an ESI or SII file runs the same state machine and motion as the
/// built-in drives, driven through whatever PDO mapping its file gives.
/// Its modes are those of 0x6502 the model moves in (8 CSP, 9 CSV, 10
/// CST), all three where the file does not say.
pub fn axes_in(od: &ObjectDictionary) -> Vec<Axis> {
    (0..8u16)
        .filter(|k| {
            let b = k * AXIS_STRIDE;
            od.object(idx::CONTROLWORD + b).is_some() && od.object(idx::STATUSWORD + b).is_some()
        })
        .map(|k| {
            let b = k * AXIS_STRIDE;
            let supported = od.int(idx::SUPPORTED_MODES + b, 0);
            let mut modes: Vec<i8> = [8i8, 9, 10].into_iter().filter(|m| supported & (1 << (m - 1)) != 0).collect();
            if modes.is_empty() {
                modes = vec![8, 9, 10];
            }
            let asked = od.int(idx::MODE + b, 0) as i8;
            let default_mode = if modes.contains(&asked) { asked } else { modes[0] };
            Axis::new(k, AxisSpec { modes, default_mode, ..AxisSpec::default() })
        })
        .collect()
}

/// A controlword command (CiA402 Table "device control commands").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Command {
    Shutdown,
    SwitchOn,
    SwitchOnEnable,
    DisableVoltage,
    QuickStop,
    None,
}

fn decode_command(cw: u16) -> Command {
    if cw & 0x0002 == 0 {
        Command::DisableVoltage
    } else if cw & 0x0006 == 0x0002 {
        Command::QuickStop
    } else if cw & 0x0087 == 0x0006 {
        Command::Shutdown
    } else if cw & 0x008F == 0x0007 {
        Command::SwitchOn
    } else if cw & 0x008F == 0x000F {
        Command::SwitchOnEnable
    } else {
        Command::None
    }
}

/// Static description of an axis.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisSpec {
    /// Modes of operation accepted (e.g. `[8, 9, 10]`, Neuromeka: `[10]`).
    pub modes: Vec<i8>,
    /// Default mode after power-up.
    pub default_mode: i8,
    /// Max torque default (0x6072).
    pub max_torque: i64,
    /// Max motor speed default in rpm (0x6080).
    pub max_speed_rpm: i64,
    /// Acceleration produced by one unit of torque, counts/s^2.
    pub counts_per_s2_per_torque: f64,
}

impl Default for AxisSpec {
    fn default() -> Self {
        Self {
            modes: vec![8, 9, 10],
            default_mode: 8,
            max_torque: 2048,
            max_speed_rpm: 4600,
            counts_per_s2_per_torque: 2000.0,
        }
    }
}

/// Adds an axis' objects to a dictionary, at `0x800 * axis` above the first
/// axis' indices.
pub fn add_objects(od: &mut ObjectDictionary, axis: u16, spec: &AxisSpec) {
    let b = axis * AXIS_STRIDE;
    let var = |name: &str, t: DataType, a: Access, m: Mappable, v: i64| {
        Object::var(name, Entry::new(name, t, a).mappable(m).default_int(v))
    };
    let supported: i64 = spec.modes.iter().map(|m| 1i64 << (*m as i64 - 1)).sum();
    let min_mode = spec.modes.iter().copied().min().unwrap_or(0).into();
    let max_mode = spec.modes.iter().copied().max().unwrap_or(0).into();
    od.insert(idx::ERROR_CODE + b, var("Error code", DataType::UInt16, Access::RO, Mappable::Tx, 0));
    od.insert(idx::CONTROLWORD + b, var("Controlword", DataType::UInt16, Access::RW, Mappable::Rx, 0));
    od.insert(idx::STATUSWORD + b, var("Statusword", DataType::UInt16, Access::RO, Mappable::Tx, 0));
    od.insert(idx::QUICK_STOP_OPTION + b, var("Quick stop option code", DataType::Int16, Access::RW, Mappable::No, 2));
    let mut mode = Entry::new("Modes of operation", DataType::Int8, Access::RW)
        .mappable(Mappable::Rx)
        .default_int(spec.default_mode.into());
    mode = mode.range(min_mode, max_mode);
    od.insert(idx::MODE + b, Object::var("Modes of operation", mode));
    od.insert(
        idx::MODE_DISPLAY + b,
        var("Modes of operation display", DataType::Int8, Access::RO, Mappable::Tx, spec.default_mode.into()),
    );
    od.insert(idx::POSITION_ACTUAL + b, var("Position actual value", DataType::Int32, Access::RO, Mappable::Tx, 0));
    od.insert(idx::VELOCITY_ACTUAL + b, var("Velocity actual value", DataType::Int32, Access::RO, Mappable::Tx, 0));
    od.insert(idx::TARGET_TORQUE + b, var("Target torque", DataType::Int16, Access::RW, Mappable::Rx, 0));
    od.insert(idx::MAX_TORQUE + b, var("Max torque", DataType::UInt16, Access::RW, Mappable::Rx, spec.max_torque));
    od.insert(idx::TORQUE_ACTUAL + b, var("Torque actual value", DataType::Int16, Access::RO, Mappable::Tx, 0));
    od.insert(idx::TARGET_POSITION + b, var("Target position", DataType::Int32, Access::RW, Mappable::Rx, 0));
    od.insert(
        idx::MAX_SPEED + b,
        var("Max motor speed", DataType::UInt32, Access::RW, Mappable::No, spec.max_speed_rpm),
    );
    od.insert(
        idx::ACCELERATION + b,
        var("Profile acceleration", DataType::UInt32, Access::RW, Mappable::No, 10_000_000),
    );
    od.insert(
        idx::QUICK_STOP_DECEL + b,
        var("Quick stop deceleration", DataType::UInt32, Access::RW, Mappable::No, 20_000_000),
    );
    od.insert(idx::TARGET_VELOCITY + b, var("Target velocity", DataType::Int32, Access::RW, Mappable::Rx, 0));
    od.insert(
        idx::SUPPORTED_MODES + b,
        var("Supported drive modes", DataType::UInt32, Access::RO, Mappable::No, supported),
    );
}

/// One axis' dynamic state.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    base: u16,
    spec: AxisSpec,
    /// The FSA state.
    pub state: Cia402State,
    last_controlword: u16,
    /// Latched error code (0x603F), cleared by a successful fault reset.
    fault: Option<u16>,
    /// Whether the fault's cause is still present (a reset fails while it is).
    cause_present: bool,
    reaction_left_ns: u64,
    position: f64,
    velocity: f64,
    torque: f64,
    mode: i8,
}

impl Axis {
    /// Axis number `axis` of a device.
    pub fn new(axis: u16, spec: AxisSpec) -> Self {
        let mode = spec.default_mode;
        Self {
            base: axis * AXIS_STRIDE,
            spec,
            state: Cia402State::NotReadyToSwitchOn,
            last_controlword: 0,
            fault: None,
            cause_present: false,
            reaction_left_ns: 0,
            position: 0.0,
            velocity: 0.0,
            torque: 0.0,
            mode,
        }
    }

    /// The axis' static description.
    pub fn spec(&self) -> &AxisSpec {
        &self.spec
    }

    /// The active error code, if the drive has a fault pending or latched.
    pub fn fault(&self) -> Option<u16> {
        self.fault
    }

    /// Raises a drive fault whose cause stays present until
    /// [`Axis::clear_fault_cause`] (or that clears at once when `transient`).
    /// Returns the error code when this is a new fault, for the emergency
    /// message.
    pub fn raise_fault(&mut self, code: u16, transient: bool) -> Option<u16> {
        self.cause_present = !transient;
        if matches!(self.state, Cia402State::Fault | Cia402State::FaultReactionActive) {
            return None;
        }
        self.fault = Some(code);
        self.state = Cia402State::FaultReactionActive;
        self.reaction_left_ns = FAULT_REACTION_NS;
        Some(code)
    }

    /// Removes the fault's cause, so a fault reset can succeed.
    pub fn clear_fault_cause(&mut self) {
        self.cause_present = false;
    }

    /// One cycle of `dt_ns`. `communicating` is false while the slave is not
    /// at least PRE-OP (the FSA waits in NOT READY TO SWITCH ON).
    pub fn step(&mut self, od: &mut ObjectDictionary, dt_ns: u64, communicating: bool) {
        use Cia402State as S;
        let b = self.base;
        let cw = od.int(idx::CONTROLWORD + b, 0) as u16;
        let fault_reset_edge = cw & 0x80 != 0 && self.last_controlword & 0x80 == 0;
        self.last_controlword = cw;
        let cmd = decode_command(cw);

        let requested_mode = od.int(idx::MODE + b, 0) as i8;
        if self.spec.modes.contains(&requested_mode) {
            self.mode = requested_mode;
        }

        self.state = match self.state {
            S::NotReadyToSwitchOn if communicating => S::SwitchOnDisabled,
            S::SwitchOnDisabled => match cmd {
                Command::Shutdown => S::ReadyToSwitchOn,
                _ => S::SwitchOnDisabled,
            },
            S::ReadyToSwitchOn => match cmd {
                Command::SwitchOn => S::SwitchedOn,
                Command::SwitchOnEnable => S::OperationEnabled,
                Command::DisableVoltage | Command::QuickStop => S::SwitchOnDisabled,
                _ => S::ReadyToSwitchOn,
            },
            S::SwitchedOn => match cmd {
                Command::SwitchOnEnable => S::OperationEnabled,
                Command::Shutdown => S::ReadyToSwitchOn,
                Command::DisableVoltage | Command::QuickStop => S::SwitchOnDisabled,
                _ => S::SwitchedOn,
            },
            S::OperationEnabled => match cmd {
                Command::SwitchOn => S::SwitchedOn,
                Command::Shutdown => S::ReadyToSwitchOn,
                Command::DisableVoltage => S::SwitchOnDisabled,
                Command::QuickStop => S::QuickStopActive,
                _ => S::OperationEnabled,
            },
            S::QuickStopActive => {
                let option = od.int(idx::QUICK_STOP_OPTION + b, 0);
                if cmd == Command::DisableVoltage || self.velocity == 0.0 && !(5..=8).contains(&option) {
                    S::SwitchOnDisabled
                } else if cmd == Command::SwitchOnEnable && (5..=8).contains(&option) {
                    S::OperationEnabled
                } else {
                    S::QuickStopActive
                }
            }
            S::FaultReactionActive => {
                self.reaction_left_ns = self.reaction_left_ns.saturating_sub(dt_ns);
                if self.reaction_left_ns == 0 { S::Fault } else { S::FaultReactionActive }
            }
            S::Fault if fault_reset_edge && !self.cause_present => {
                self.fault = None;
                S::SwitchOnDisabled
            }
            other => other,
        };

        self.move_axis(od, dt_ns as f64 / 1e9);
        self.publish(od);
    }

    fn move_axis(&mut self, od: &ObjectDictionary, dt: f64) {
        use Cia402State as S;
        let b = self.base;
        // A limit the device's description leaves at 0 (or out) is the
        // spec's: a drive built from a file still moves.
        let or = |v: i64, default: f64| if v > 0 { v as f64 } else { default };
        let vmax = or(od.int(idx::MAX_SPEED + b, 0), self.spec.max_speed_rpm as f64) * COUNTS_PER_REV / 60.0;
        let accel = or(od.int(idx::ACCELERATION + b, 0), DEFAULT_ACCELERATION);
        let decel = or(od.int(idx::QUICK_STOP_DECEL + b, 0), DEFAULT_ACCELERATION);
        let ramp_to = |v: f64, target: f64, a: f64| {
            let dv = (target - v).clamp(-a * dt, a * dt);
            v + dv
        };
        match self.state {
            S::OperationEnabled => match self.mode {
                8 => {
                    let target = od.int(idx::TARGET_POSITION + b, 0) as f64;
                    let step = (target - self.position).clamp(-vmax * dt, vmax * dt);
                    self.velocity = if dt > 0.0 { step / dt } else { 0.0 };
                    self.position += step;
                    self.torque = 0.0;
                }
                9 => {
                    let target = (od.int(idx::TARGET_VELOCITY + b, 0) as f64).clamp(-vmax, vmax);
                    self.velocity = ramp_to(self.velocity, target, accel);
                    self.position += self.velocity * dt;
                    self.torque = 0.0;
                }
                _ => {
                    let tmax = or(od.int(idx::MAX_TORQUE + b, 0), self.spec.max_torque as f64);
                    self.torque = (od.int(idx::TARGET_TORQUE + b, 0) as f64).clamp(-tmax, tmax);
                    // Viscous friction keeps the speed bounded.
                    let a = self.torque * self.spec.counts_per_s2_per_torque - 5.0 * self.velocity;
                    self.velocity = (self.velocity + a * dt).clamp(-vmax, vmax);
                    self.position += self.velocity * dt;
                }
            },
            S::QuickStopActive | S::FaultReactionActive => {
                self.velocity = ramp_to(self.velocity, 0.0, decel);
                self.position += self.velocity * dt;
                self.torque = 0.0;
            }
            _ => {
                self.velocity = 0.0;
                self.torque = 0.0;
            }
        }
    }

    /// The statusword: the state's bits (v049 appendix table), bit4 voltage
    /// enabled while the power stage is on, bit9 remote, bit10 target
    /// reached, bit12 "following the command value" in cyclic modes.
    pub fn statusword(&self, od: &ObjectDictionary) -> u16 {
        use Cia402State as S;
        let mut sw = u16::from(self.state.to_u8());
        if matches!(self.state, S::SwitchedOn | S::OperationEnabled | S::QuickStopActive | S::FaultReactionActive) {
            sw |= 1 << 4;
        }
        sw |= 1 << 9;
        let b = self.base;
        let reached = match self.mode {
            8 => (od.int(idx::TARGET_POSITION + b, 0) as f64 - self.position).abs() <= POSITION_WINDOW,
            9 => (od.int(idx::TARGET_VELOCITY + b, 0) as f64 - self.velocity).abs() <= 1.0,
            _ => true,
        };
        if reached {
            sw |= 1 << 10;
        }
        if self.state == S::OperationEnabled {
            sw |= 1 << 12;
        }
        sw
    }

    fn publish(&self, od: &mut ObjectDictionary) {
        let b = self.base;
        let sw = self.statusword(od);
        od.set_int(idx::STATUSWORD + b, 0, sw.into());
        od.set_int(idx::MODE_DISPLAY + b, 0, self.mode.into());
        od.set_int(idx::POSITION_ACTUAL + b, 0, self.position.round() as i64);
        od.set_int(idx::VELOCITY_ACTUAL + b, 0, self.velocity.round() as i64);
        od.set_int(idx::TORQUE_ACTUAL + b, 0, self.torque.round() as i64);
        od.set_int(idx::ERROR_CODE + b, 0, self.fault.unwrap_or(0).into());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Cia402State as S;

    const DT: u64 = 1_000_000;

    fn drive(modes: Vec<i8>) -> (ObjectDictionary, Axis) {
        let spec = AxisSpec { default_mode: modes[0], modes, ..AxisSpec::default() };
        let mut od = ObjectDictionary::new();
        add_objects(&mut od, 0, &spec);
        (od, Axis::new(0, spec))
    }

    fn cw(od: &mut ObjectDictionary, a: &mut Axis, value: u16) -> Cia402State {
        od.set_int(idx::CONTROLWORD, 0, value.into());
        a.step(od, DT, true);
        a.state
    }

    /// Brings a fresh axis to `target` along the normal path.
    fn reach(target: Cia402State) -> (ObjectDictionary, Axis) {
        let (mut od, mut a) = drive(vec![8, 9, 10]);
        a.step(&mut od, DT, true); // transition 1
        let path: &[(u16, Cia402State)] =
            &[(0x06, S::ReadyToSwitchOn), (0x07, S::SwitchedOn), (0x0F, S::OperationEnabled)];
        if target == S::SwitchOnDisabled {
            return (od, a);
        }
        for (value, state) in path {
            assert_eq!(cw(&mut od, &mut a, *value), *state);
            if *state == target {
                return (od, a);
            }
        }
        unreachable!("{target:?} is not on the enable path");
    }

    #[test]
    fn transitions_0_and_1_wait_for_communication() {
        let (mut od, mut a) = drive(vec![8]);
        a.step(&mut od, DT, false);
        assert_eq!(a.state, S::NotReadyToSwitchOn);
        assert_eq!(od.int(idx::STATUSWORD, 0) & 0x6F, 0x00);
        a.step(&mut od, DT, true);
        assert_eq!(a.state, S::SwitchOnDisabled);
        assert_eq!(od.int(idx::STATUSWORD, 0) & 0x6F, 0x40);
    }

    #[test]
    fn the_whole_transition_table() {
        // (from, controlword, to, transition number)
        let table: &[(Cia402State, u16, Cia402State, u8)] = &[
            (S::SwitchOnDisabled, 0x06, S::ReadyToSwitchOn, 2),
            (S::ReadyToSwitchOn, 0x07, S::SwitchedOn, 3),
            (S::SwitchedOn, 0x0F, S::OperationEnabled, 4),
            (S::OperationEnabled, 0x07, S::SwitchedOn, 5),
            (S::SwitchedOn, 0x06, S::ReadyToSwitchOn, 6),
            (S::ReadyToSwitchOn, 0x00, S::SwitchOnDisabled, 7),
            (S::ReadyToSwitchOn, 0x02, S::SwitchOnDisabled, 7),
            (S::OperationEnabled, 0x06, S::ReadyToSwitchOn, 8),
            (S::OperationEnabled, 0x00, S::SwitchOnDisabled, 9),
            (S::SwitchedOn, 0x00, S::SwitchOnDisabled, 10),
            (S::SwitchedOn, 0x02, S::SwitchOnDisabled, 10),
            (S::OperationEnabled, 0x02, S::QuickStopActive, 11),
            // Commands that do not apply leave the state alone.
            (S::SwitchOnDisabled, 0x07, S::SwitchOnDisabled, 0),
            (S::SwitchOnDisabled, 0x0F, S::SwitchOnDisabled, 0),
            (S::ReadyToSwitchOn, 0x06, S::ReadyToSwitchOn, 0),
        ];
        for &(from, value, to, n) in table {
            let (mut od, mut a) = reach(from);
            assert_eq!(cw(&mut od, &mut a, value), to, "transition {n}: {from:?} --{value:#06x}--> {to:?}");
            assert_eq!(od.int(idx::STATUSWORD, 0) as u8 & 0x6F, to.to_u8() & 0x6F, "statusword after transition {n}");
        }
        // 3 + 4 in one step: ready to switch on with 0x0F.
        let (mut od, mut a) = reach(S::ReadyToSwitchOn);
        assert_eq!(cw(&mut od, &mut a, 0x0F), S::OperationEnabled);
    }

    #[test]
    fn quick_stop_ramps_down_then_transition_12() {
        let (mut od, mut a) = reach(S::OperationEnabled);
        od.set_int(idx::MODE, 0, 9);
        od.set_int(idx::TARGET_VELOCITY, 0, 100_000);
        for _ in 0..50 {
            cw(&mut od, &mut a, 0x0F);
        }
        assert!(od.int(idx::VELOCITY_ACTUAL, 0) > 0);
        assert_eq!(cw(&mut od, &mut a, 0x02), S::QuickStopActive);
        assert_eq!(od.int(idx::STATUSWORD, 0) & 0x6F, 0x07);
        let mut steps = 0;
        while a.state == S::QuickStopActive {
            cw(&mut od, &mut a, 0x02);
            steps += 1;
            assert!(steps < 1000);
        }
        assert_eq!(a.state, S::SwitchOnDisabled, "transition 12 after standstill");
        assert_eq!(od.int(idx::VELOCITY_ACTUAL, 0), 0);
    }

    #[test]
    fn quick_stop_option_5_allows_transition_16() {
        let (mut od, mut a) = reach(S::OperationEnabled);
        od.set_int(idx::QUICK_STOP_OPTION, 0, 6);
        assert_eq!(cw(&mut od, &mut a, 0x02), S::QuickStopActive);
        assert_eq!(cw(&mut od, &mut a, 0x02), S::QuickStopActive, "option 5..8 stays in quick stop");
        assert_eq!(cw(&mut od, &mut a, 0x0F), S::OperationEnabled, "transition 16");
    }

    #[test]
    fn fault_13_14_and_reset_15() {
        let (mut od, mut a) = reach(S::OperationEnabled);
        assert_eq!(a.raise_fault(0x2310, false), Some(0x2310));
        assert_eq!(a.raise_fault(0x3110, false), None, "one fault at a time");
        assert_eq!(cw(&mut od, &mut a, 0x0F), S::FaultReactionActive, "transition 13");
        assert_eq!(od.int(idx::STATUSWORD, 0) & 0x4F, 0x0F);
        assert_eq!(od.int(idx::ERROR_CODE, 0), 0x2310);
        for _ in 0..FAULT_REACTION_NS / DT {
            cw(&mut od, &mut a, 0x0F);
        }
        assert_eq!(a.state, S::Fault, "transition 14");
        assert_eq!(od.int(idx::STATUSWORD, 0) & 0x4F, 0x08);
        // Reset while the cause persists fails.
        cw(&mut od, &mut a, 0x00);
        assert_eq!(cw(&mut od, &mut a, 0x80), S::Fault);
        a.clear_fault_cause();
        // Needs a rising edge of bit 7.
        assert_eq!(cw(&mut od, &mut a, 0x80), S::Fault);
        cw(&mut od, &mut a, 0x00);
        assert_eq!(cw(&mut od, &mut a, 0x80), S::SwitchOnDisabled, "transition 15");
        assert_eq!(od.int(idx::ERROR_CODE, 0), 0);
    }

    #[test]
    fn modes_move_the_axis() {
        // CSP: follows the target position, bounded by max speed.
        let (mut od, mut a) = reach(S::OperationEnabled);
        od.set_int(idx::MODE, 0, 8);
        od.set_int(idx::TARGET_POSITION, 0, 10_000);
        for _ in 0..10 {
            cw(&mut od, &mut a, 0x0F);
        }
        assert_eq!(od.int(idx::POSITION_ACTUAL, 0), 10_000);
        assert_eq!(od.int(idx::MODE_DISPLAY, 0), 8);
        assert!(od.int(idx::STATUSWORD, 0) & (1 << 10) != 0, "target reached");
        // CST: torque accelerates it, clipped by max torque.
        od.set_int(idx::MODE, 0, 10);
        od.set_int(idx::TARGET_TORQUE, 0, 30_000);
        for _ in 0..10 {
            cw(&mut od, &mut a, 0x0F);
        }
        assert_eq!(od.int(idx::TORQUE_ACTUAL, 0), 2048);
        assert!(od.int(idx::VELOCITY_ACTUAL, 0) > 0);
        // Disabled: no motion.
        cw(&mut od, &mut a, 0x06);
        assert_eq!(od.int(idx::VELOCITY_ACTUAL, 0), 0);
        assert_eq!(od.int(idx::TORQUE_ACTUAL, 0), 0);
    }

    #[test]
    fn unsupported_modes_are_ignored() {
        let (mut od, mut a) = drive(vec![10]);
        a.step(&mut od, DT, true);
        od.set_int(idx::MODE, 0, 8);
        a.step(&mut od, DT, true);
        assert_eq!(od.int(idx::MODE_DISPLAY, 0), 10);
        assert_eq!(od.int(idx::SUPPORTED_MODES, 0), 1 << 9);
    }
}
