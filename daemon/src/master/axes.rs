//! CiA 402 axes (`[[axis]]`): the operations front ends call.
//!
//! Each axis is driven through the chip's CiA 402 helper (v049
//! 402_STATE_SET 27, 402_STATE_GET 28, 402_CTL_SET 29, 402_GET_STATUSWORD
//! 74), which walks the drive's state machine in the process image by
//! itself. The drive's other objects (mode, targets, actual values) go
//! through the process image when they are mapped, else by SDO.
//!
//! A front end looks an axis up once ([`Master::axis`]) and hands the
//! [`Axis`] to the operations, so one request acts on the `[[axis]]` entry
//! it checked.

use std::fmt;
use std::time::{Duration, Instant};

/// A drive state as the helper reports and takes it; its `Display` is the
/// state's CiA 402 name ("OPERATION ENABLED"), as messages show it.
pub(crate) use ecmxf_wire::payload::cia402::Cia402State;
use ecmxf_wire::payload::cia402::{Cia402Control, Cia402CtlSet, Cia402StateSet};

use super::entry_writes::{Staging, WriteError};
use super::image::{Entry, Image, read_bits};
use super::objects::{axis_index, lookup};
use super::value::{DataType, Value, ValueError};
use super::{Call, EngineError, Immediate, Master, NetworkLayout};
use crate::config::AxisConfig;

/// How long a command waits for the drive to arrive when the caller gives
/// no time.
pub(crate) const COMMAND_WAIT: Duration = Duration::from_secs(5);

/// How long a mode change waits for the drive to show the mode when the
/// caller gives no deadline: a drive takes it over within a few cycles.
const MODE_WAIT: Duration = Duration::from_secs(2);

// CiA 402 objects of axis 0 (ETG.6010): axis n's are at + 0x800 n.
const ERROR_CODE: u16 = 0x603F;
const STATUSWORD: u16 = 0x6041;
const MODES_OF_OPERATION: u16 = 0x6060;
const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
const POSITION_ACTUAL: u16 = 0x6064;
const VELOCITY_ACTUAL: u16 = 0x606C;
const TARGET_TORQUE: u16 = 0x6071;
const TORQUE_ACTUAL: u16 = 0x6077;
const TARGET_POSITION: u16 = 0x607A;
const TARGET_VELOCITY: u16 = 0x60FF;

/// An `[[axis]]` entry as [`Master::axis`] found it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Axis {
    /// Its number: the helper's axis, the entry's place among `[[axis]]`.
    pub number: u8,
    /// Its configuration.
    pub config: AxisConfig,
}

/// An axis as [`Master::axes`] lists it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AxisInfo {
    /// Its number.
    pub number: u32,
    /// Its configuration.
    pub config: AxisConfig,
    /// The axis' number within its slave (objects at 0x6000 + 0x800 n);
    /// 0 when unknown.
    pub slave_axis: u8,
}

/// An axis' state and actual values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct AxisStatus {
    /// Its number.
    pub axis: u8,
    /// The state, as the helper reads it.
    pub state: Cia402State,
    /// The statusword (0x6041), as the helper reads it.
    pub statusword: u16,
    /// Modes of operation display (0x6061).
    pub mode_display: i32,
    /// Position actual value (0x6064).
    pub position_actual: i64,
    /// Velocity actual value (0x606C).
    pub velocity_actual: i64,
    /// Torque actual value (0x6077).
    pub torque_actual: i64,
    /// Error code (0x603F).
    pub error_code: u32,
}

/// What a client asks of an axis' state machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum AxisCommand {
    /// To OPERATION ENABLED (through a fault reset from FAULT).
    Enable,
    /// To SWITCH ON DISABLED.
    Disable,
    /// To READY TO SWITCH ON.
    Shutdown,
    /// To QUICK STOP ACTIVE.
    QuickStop,
    /// One fault reset, then SWITCH ON DISABLED.
    FaultReset,
}

impl AxisCommand {
    /// The state the helper is asked to walk the drive to.
    pub(crate) fn target(self) -> Cia402State {
        match self {
            Self::Enable => Cia402State::OperationEnabled,
            Self::Disable | Self::FaultReset => Cia402State::SwitchOnDisabled,
            Self::Shutdown => Cia402State::ReadyToSwitchOn,
            Self::QuickStop => Cia402State::QuickStopActive,
        }
    }
}

/// A set-point for an axis' mode of operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum AxisTarget {
    /// Target position (0x607A).
    Position(i64),
    /// Target velocity (0x60FF).
    Velocity(i64),
    /// Target torque (0x6071).
    Torque(i64),
}

impl AxisTarget {
    /// The object (axis 0's index) and the value.
    fn object(self) -> (u16, i64) {
        match self {
            Self::Position(v) => (TARGET_POSITION, v),
            Self::Velocity(v) => (TARGET_VELOCITY, v),
            Self::Torque(v) => (TARGET_TORQUE, v),
        }
    }
}

/// Why an axis operation failed.
#[derive(Debug)]
pub enum AxisError {
    /// No `[[axis]]` entry has this number.
    NotConfigured {
        /// The number asked for.
        axis: u32,
        /// `[[axis]]` entries configured.
        configured: usize,
    },
    /// A chip command or SDO transfer failed.
    Engine(EngineError),
    /// The write into the process image was refused (the lease, a frame
    /// stream owning the bytes...).
    Write(WriteError),
    /// The value does not fit the object's type.
    Value {
        /// The process-image entry written, `None` for an SDO.
        entry: Option<String>,
        /// Why.
        error: ValueError,
    },
    /// Half the wait is gone and the drive is still in FAULT: its cause
    /// is still there, and waiting longer would not change that.
    StaysInFault {
        /// The axis.
        axis: u8,
        /// Its error code (0x603F).
        error_code: i64,
    },
    /// The drive did not arrive in the state asked for in time.
    NotArrived {
        /// The axis.
        axis: u8,
        /// Its state at the deadline.
        state: Cia402State,
        /// The state asked for.
        target: Cia402State,
    },
    /// The drive did not show the mode asked for in time.
    ModeNotShown {
        /// The axis.
        axis: u8,
        /// The mode it shows (0x6061).
        shown: i32,
        /// The mode asked for.
        mode: i8,
    },
}

impl AxisError {
    /// The request field a front end blames, for the caller's mistakes.
    pub(crate) fn field(&self) -> Option<&'static str> {
        match self {
            Self::NotConfigured { .. } => Some("axis"),
            // Named as a write of the entry (WriteOutputs) would name it.
            Self::Value { entry: Some(_), .. } => Some("writes.value"),
            Self::Value { entry: None, .. } => Some("value"),
            Self::Write(e) => e.field(),
            Self::Engine(_) | Self::StaysInFault { .. } | Self::NotArrived { .. } | Self::ModeNotShown { .. } => None,
        }
    }
}

impl fmt::Display for AxisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotConfigured { axis, configured } => {
                write!(f, "axis {axis} is not configured ({configured} [[axis]] entries)")
            }
            Self::Engine(e) => e.fmt(f),
            Self::Write(e) => e.fmt(f),
            Self::Value { entry: Some(name), error } => write!(f, "entry {name:?}: {error}"),
            Self::Value { entry: None, error } => error.fmt(f),
            Self::StaysInFault { axis, error_code } => {
                write!(f, "axis {axis} stays in FAULT (error code {error_code:#06x}): its cause is still there")
            }
            Self::NotArrived { axis, state, target } => {
                write!(f, "axis {axis} is {state}, not {target}, at the deadline")
            }
            Self::ModeNotShown { axis, shown, mode } => {
                write!(f, "axis {axis} shows mode {shown} (0x6061), not {mode}, at the deadline")
            }
        }
    }
}

impl std::error::Error for AxisError {}

impl From<EngineError> for AxisError {
    fn from(e: EngineError) -> Self {
        Self::Engine(e)
    }
}

impl From<WriteError> for AxisError {
    fn from(e: WriteError) -> Self {
        Self::Write(e)
    }
}

/// The axis' number within its slave (objects at 0x6000 + 0x800 n), from
/// the object mapped at its statusword offset; 0 when unknown. An `[[axis]]`
/// entry names its statusword's byte, not the axis within a multi-axis
/// drive: the object mapped there tells it.
fn slave_axis(image: &Image, layout: &NetworkLayout, a: &AxisConfig) -> u8 {
    let Some(s) = layout.slaves.get(usize::from(a.slave)) else { return 0 };
    let bit = ((s.tx_offset + usize::from(a.statusword_offset)) * 8) as u32;
    image
        .entries
        .iter()
        .find(|e| {
            !e.output
                && e.bit_offset == bit
                && (STATUSWORD..0xA000).contains(&e.index)
                && (e.index - STATUSWORD) % 0x800 == 0
        })
        .map_or(0, |e| ((e.index - STATUSWORD) / 0x800) as u8)
}

/// An object's value as an integer, from its bytes read as type `t`: 0
/// when fewer bytes came than the type has, or when it is no integer (the
/// status reports every value as a number); bytes past the type's size
/// are not the object's.
fn integer(t: DataType, raw: &[u8]) -> i64 {
    let Some(raw) = raw.get(..t.bytes()) else { return 0 };
    Value::decode(t, raw).as_i64().unwrap_or(0)
}

/// The type of a CiA 402 object by SDO: the standard's, else INTEGER32,
/// the type of most of the profile's values.
fn object_type(index: u16) -> DataType {
    lookup(index, 0).map_or(DataType::Int32, |(o, _)| o.data_type)
}

impl Master {
    /// `[[axis]]` entry `n`, for the operations below.
    pub(crate) fn axis(&self, n: u32) -> Result<Axis, AxisError> {
        self.with_axes(|axes| match axes.get(n as usize) {
            Some(a) => Ok(Axis { number: n as u8, config: a.clone() }),
            None => Err(AxisError::NotConfigured { axis: n, configured: axes.len() }),
        })
    }

    /// The configured axes, each with its number within its slave (which
    /// the process image tells).
    pub(crate) async fn axes(&self, call: Call) -> Result<Vec<AxisInfo>, EngineError> {
        let image = self.image(call).await?;
        let layout = self.layout();
        Ok(self.with_axes(|axes| {
            axes.iter()
                .enumerate()
                .map(|(n, a)| AxisInfo {
                    number: n as u32,
                    config: a.clone(),
                    slave_axis: slave_axis(&image, &layout, a),
                })
                .collect()
        }))
    }

    /// The axis' state (from the helper) and its actual values.
    pub(crate) async fn axis_status(&self, axis: &Axis, call: Call) -> Result<AxisStatus, EngineError> {
        let image = self.image(call).await?;
        let a = &axis.config;
        let k = slave_axis(&image, &self.layout(), a);
        let state = self.drive_state(axis.number, call).await?;
        let (_, sw) = self.immediate(Immediate::Cia402Statusword(axis.number), call).await?;
        Ok(AxisStatus {
            axis: axis.number,
            state,
            statusword: u16::from_le_bytes([sw.first().copied().unwrap_or(0), sw.get(1).copied().unwrap_or(0)]),
            mode_display: self.axis_value(&image, a, k, MODES_OF_OPERATION_DISPLAY, call).await? as i32,
            position_actual: self.axis_value(&image, a, k, POSITION_ACTUAL, call).await?,
            velocity_actual: self.axis_value(&image, a, k, VELOCITY_ACTUAL, call).await?,
            torque_actual: self.axis_value(&image, a, k, TORQUE_ACTUAL, call).await?,
            error_code: self.axis_value(&image, a, k, ERROR_CODE, call).await? as u32,
        })
    }

    /// Asks the helper to walk the axis to the command's state and, with
    /// `wait`, waits until the drive is there, all before `call`'s
    /// deadline (none: [`COMMAND_WAIT`]); then the axis' status.
    pub(crate) async fn axis_command(
        &self,
        axis: &Axis,
        command: AxisCommand,
        wait: bool,
        call: Call,
    ) -> Result<AxisStatus, AxisError> {
        let call = call.or_within(COMMAND_WAIT);
        let budget = call.left().unwrap_or_default();
        let end = Instant::now() + budget;
        let (n, target) = (axis.number, command.target());
        // Walking the state machine for the caller: from FAULT, enabling
        // starts with a fault reset, as FAULT_RESET itself does.
        let faulted = self.drive_state(n, call).await? == Cia402State::Fault;
        if command == AxisCommand::FaultReset || (command == AxisCommand::Enable && faulted) {
            self.fault_reset(axis, call).await?;
        }
        self.immediate(Immediate::Cia402StateSet(Cia402StateSet { axis: n, state: target }), call).await?;
        if wait {
            loop {
                let now = self.drive_state(n, call).await?;
                // A quick stop may end in SWITCH ON DISABLED (option code).
                let arrived =
                    now == target || (target == Cia402State::QuickStopActive && now == Cia402State::SwitchOnDisabled);
                if arrived {
                    break;
                }
                if now == Cia402State::Fault && Instant::now() + budget / 2 >= end {
                    let image = self.image(call).await?;
                    let k = slave_axis(&image, &self.layout(), &axis.config);
                    let error_code = self.axis_value(&image, &axis.config, k, ERROR_CODE, call).await?;
                    return Err(AxisError::StaysInFault { axis: n, error_code });
                }
                if Instant::now() >= end {
                    return Err(AxisError::NotArrived { axis: n, state: now, target });
                }
                // The drive's state changes only with an input frame. At the
                // deadline the state last read is the answer: a read after it
                // would only say the deadline passed.
                self.next_inputs(end.saturating_duration_since(Instant::now())).await;
                if Instant::now() >= end {
                    return Err(AxisError::NotArrived { axis: n, state: now, target });
                }
            }
        }
        Ok(self.axis_status(axis, call).await?)
    }

    /// Sets the axis' mode of operation (0x6060) under `lease_id` (`who`'s) and
    /// waits, before `call`'s deadline (none: [`MODE_WAIT`]), until the
    /// drive shows it (0x6061); then the axis' status.
    pub(crate) async fn set_axis_mode(
        &self,
        axis: &Axis,
        mode: i8,
        lease_id: &str,
        who: &str,
        call: Call,
    ) -> Result<AxisStatus, AxisError> {
        self.write_axis_object(axis, MODES_OF_OPERATION, mode.into(), lease_id, who, call).await?;
        let call = call.or_within(MODE_WAIT);
        let end = Instant::now() + call.left().unwrap_or_default();
        let mut shown = None;
        loop {
            // Each look asks the chip (and SDOs for what is not mapped): the
            // deadline can end one midway, and then the mode last read is
            // the answer, as at the deadline below.
            let s = match (self.axis_status(axis, call).await, shown) {
                (Ok(s), _) => s,
                (Err(EngineError::Timeout), Some(shown)) => {
                    return Err(AxisError::ModeNotShown { axis: axis.number, shown, mode });
                }
                (Err(e), _) => return Err(e.into()),
            };
            shown = Some(s.mode_display);
            if s.mode_display == i32::from(mode) {
                return Ok(s);
            }
            if Instant::now() >= end {
                return Err(AxisError::ModeNotShown { axis: axis.number, shown: s.mode_display, mode });
            }
            self.next_inputs(end.saturating_duration_since(Instant::now())).await;
            // At the deadline the mode last read is the answer (as above).
            if Instant::now() >= end {
                return Err(AxisError::ModeNotShown { axis: axis.number, shown: s.mode_display, mode });
            }
        }
    }

    /// Writes a set-point of the axis under `lease_id`: true when through
    /// the process image, false when by SDO.
    pub(crate) async fn set_axis_target(
        &self,
        axis: &Axis,
        target: AxisTarget,
        lease_id: &str,
        who: &str,
        call: Call,
    ) -> Result<bool, AxisError> {
        let (base, value) = target.object();
        self.write_axis_object(axis, base, value, lease_id, who, call).await
    }

    /// Writes CiA 402 object `base` (axis 0's index) of the axis: into the
    /// process image when mapped (under `lease_id`), else by SDO, which a
    /// mapped object would have overwritten. True when through the image.
    async fn write_axis_object(
        &self,
        axis: &Axis,
        base: u16,
        value: i64,
        lease_id: &str,
        who: &str,
        call: Call,
    ) -> Result<bool, AxisError> {
        let image = self.image(call).await?;
        let a = &axis.config;
        let index = axis_index(base, slave_axis(&image, &self.layout(), a));
        if let Some(e) = image.find(a.slave, index, true) {
            self.write_axis_entry(&image, e, value, lease_id, who)?;
            return Ok(true);
        }
        let ty = object_type(index);
        let bytes = Value::Int(value).encode(ty, ty.bits()).map_err(|error| AxisError::Value { entry: None, error })?;
        self.sdo_write(a.slave, index, 0, false, bytes, call).await?;
        Ok(false)
    }

    /// Writes `value` into output entry `e` as one client write does: on
    /// the shadow image, sent under `lease_id` (the staging holds the
    /// shadow image's lock, so this stays apart from any await).
    fn write_axis_entry(
        &self,
        image: &Image,
        e: &Entry,
        value: i64,
        lease_id: &str,
        who: &str,
    ) -> Result<(), AxisError> {
        let bytes = Value::Int(value)
            .encode(e.data_type, e.bit_length)
            .map_err(|error| AxisError::Value { entry: Some(e.name.clone()), error })?;
        let mut staging = Staging::new(self, image);
        staging.entry(e, &bytes)?;
        staging.commit(self.leases(), lease_id, who)?;
        Ok(())
    }

    /// One fault reset through the helper (402_CTL_SET with bit3; the
    /// chip raises controlword bit7 once and clears the request itself).
    async fn fault_reset(&self, axis: &Axis, call: Call) -> Result<(), EngineError> {
        let mut control = Cia402Control::ENABLE | Cia402Control::FAULT_RESET;
        control.set(Cia402Control::AUTO_FAULT_RESET, axis.config.auto_fault_reset);
        let axis_count = self.with_axes(|axes| axes.len() as u8);
        let set = Cia402CtlSet { axis: axis.number, control, axis_count, slave: axis.config.slave };
        self.immediate(Immediate::Cia402CtlSet(set), call).await?;
        Ok(())
    }

    /// The axis' state as the helper reads it (402_STATE_GET).
    async fn drive_state(&self, axis: u8, call: Call) -> Result<Cia402State, EngineError> {
        let (v, _) = self.immediate(Immediate::Cia402StateGet(axis), call).await?;
        Ok(Cia402State::from_u8(v))
    }

    /// CiA 402 object `base` of slave axis `k`: from the newest input frame
    /// when mapped, else by SDO.
    async fn axis_value(
        &self,
        image: &Image,
        a: &AxisConfig,
        k: u8,
        base: u16,
        call: Call,
    ) -> Result<i64, EngineError> {
        let index = axis_index(base, k);
        if let (Some(e), Some(frame)) = (image.find(a.slave, index, false), self.latest_inputs()) {
            return Ok(integer(e.data_type, &read_bits(&frame.data, e.bit_offset, e.bit_length)));
        }
        match self.sdo_read(a.slave, index, 0, false, call).await {
            Ok(raw) => Ok(integer(object_type(index), &raw)),
            // Not every drive has every object (a CST drive has no target
            // position...): report 0, not an error.
            Err(EngineError::SdoAbort { .. }) => Ok(0),
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_read_as_their_type_and_no_further() {
        assert_eq!(integer(DataType::Int8, &[0xF7]), -9);
        assert_eq!(integer(DataType::UInt16, &[0x10, 0x23, 0xFF, 0xFF]), 0x2310);
        assert_eq!(integer(DataType::Int32, &[1, 0]), 0, "a short answer is no value");
        assert_eq!(integer(DataType::VisibleString(0), b"x"), 0);
    }

    #[test]
    fn messages_name_the_axis_and_states() {
        let e = AxisError::NotArrived {
            axis: 0,
            state: Cia402State::SwitchOnDisabled,
            target: Cia402State::OperationEnabled,
        };
        assert_eq!(e.to_string(), "axis 0 is SWITCH ON DISABLED, not OPERATION ENABLED, at the deadline");
        let e = AxisError::StaysInFault { axis: 0, error_code: 0x2310 };
        assert!(e.to_string().contains("(error code 0x2310)"), "{e}");
        assert_eq!(AxisError::NotConfigured { axis: 3, configured: 1 }.field(), Some("axis"));
    }
}
