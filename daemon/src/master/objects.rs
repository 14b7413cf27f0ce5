//! The standard objects the daemon knows by name and type: CiA 301
//! communication objects and the CiA 402 drive profile (ETG.6010; axis n's
//! objects are at +0x800 x n). They name process-image entries, type SDO
//! values when the client gives no type, and are what `ListObjects` probes
//! on a slave without an ESI.

use ecmxf_devices::od::DataType;

/// One known object (or subindex).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct KnownObject {
    /// Index (of axis 0 for CiA 402 objects).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Name, snake_case.
    pub name: &'static str,
    /// Type.
    pub data_type: DataType,
    /// "ro", "rw".
    pub access: &'static str,
    /// A CiA 402 axis object (repeats every 0x800 for further axes).
    pub per_axis: bool,
}

const fn o(index: u16, subindex: u8, name: &'static str, data_type: DataType, access: &'static str) -> KnownObject {
    KnownObject { index, subindex, name, data_type, access, per_axis: false }
}

const fn a(index: u16, name: &'static str, data_type: DataType, access: &'static str) -> KnownObject {
    KnownObject { index, subindex: 0, name, data_type, access, per_axis: true }
}

use DataType as T;

/// The table.
pub(crate) const KNOWN: &[KnownObject] = &[
    o(0x1000, 0, "device_type", T::UInt32, "ro"),
    o(0x1001, 0, "error_register", T::UInt8, "ro"),
    o(0x1008, 0, "device_name", T::VisibleString(0), "ro"),
    o(0x1009, 0, "hardware_version", T::VisibleString(0), "ro"),
    o(0x100A, 0, "software_version", T::VisibleString(0), "ro"),
    o(0x1018, 0, "identity.count", T::UInt8, "ro"),
    o(0x1018, 1, "identity.vendor_id", T::UInt32, "ro"),
    o(0x1018, 2, "identity.product_code", T::UInt32, "ro"),
    o(0x1018, 3, "identity.revision", T::UInt32, "ro"),
    o(0x1018, 4, "identity.serial", T::UInt32, "ro"),
    o(0x1010, 1, "store_parameters.all", T::UInt32, "rw"),
    o(0x1011, 1, "restore_parameters.all", T::UInt32, "rw"),
    o(0x10F1, 1, "error_settings.local_error_reaction", T::UInt32, "rw"),
    o(0x10F1, 2, "error_settings.sync_error_counter_limit", T::UInt16, "rw"),
    o(0x1C00, 0, "sync_manager_types.count", T::UInt8, "ro"),
    o(0x1C12, 0, "rx_pdo_assign.count", T::UInt8, "rw"),
    o(0x1C13, 0, "tx_pdo_assign.count", T::UInt8, "rw"),
    o(0x1C32, 1, "output_sync.mode", T::UInt16, "rw"),
    o(0x1C32, 2, "output_sync.cycle_time", T::UInt32, "rw"),
    o(0x1C32, 3, "output_sync.shift_time", T::UInt32, "rw"),
    o(0x1C32, 4, "output_sync.supported_modes", T::UInt16, "ro"),
    o(0x1C32, 5, "output_sync.min_cycle_time", T::UInt32, "ro"),
    o(0x1C32, 6, "output_sync.calc_copy_time", T::UInt32, "ro"),
    o(0x1C33, 1, "input_sync.mode", T::UInt16, "rw"),
    o(0x1C33, 2, "input_sync.cycle_time", T::UInt32, "rw"),
    o(0x1C33, 3, "input_sync.shift_time", T::UInt32, "rw"),
    o(0x1C33, 4, "input_sync.supported_modes", T::UInt16, "ro"),
    o(0x1C33, 5, "input_sync.min_cycle_time", T::UInt32, "ro"),
    o(0x1C33, 6, "input_sync.calc_copy_time", T::UInt32, "ro"),
    a(0x603F, "error_code", T::UInt16, "ro"),
    a(0x6040, "controlword", T::UInt16, "rw"),
    a(0x6041, "statusword", T::UInt16, "ro"),
    a(0x6007, "abort_connection_option_code", T::Int16, "rw"),
    a(0x605A, "quick_stop_option_code", T::Int16, "rw"),
    a(0x605B, "shutdown_option_code", T::Int16, "rw"),
    a(0x605C, "disable_operation_option_code", T::Int16, "rw"),
    a(0x605D, "halt_option_code", T::Int16, "rw"),
    a(0x605E, "fault_reaction_option_code", T::Int16, "rw"),
    a(0x6060, "modes_of_operation", T::Int8, "rw"),
    a(0x6061, "modes_of_operation_display", T::Int8, "ro"),
    a(0x6062, "position_demand", T::Int32, "ro"),
    a(0x6063, "position_actual_internal", T::Int32, "ro"),
    a(0x6064, "position_actual", T::Int32, "ro"),
    a(0x6065, "following_error_window", T::UInt32, "rw"),
    a(0x6066, "following_error_timeout", T::UInt16, "rw"),
    a(0x6067, "position_window", T::UInt32, "rw"),
    a(0x6068, "position_window_time", T::UInt16, "rw"),
    a(0x606B, "velocity_demand", T::Int32, "ro"),
    a(0x606C, "velocity_actual", T::Int32, "ro"),
    a(0x606D, "velocity_window", T::UInt16, "rw"),
    a(0x606E, "velocity_window_time", T::UInt16, "rw"),
    a(0x6071, "target_torque", T::Int16, "rw"),
    a(0x6072, "max_torque", T::UInt16, "rw"),
    a(0x6073, "max_current", T::UInt16, "rw"),
    a(0x6074, "torque_demand", T::Int16, "ro"),
    a(0x6075, "motor_rated_current", T::UInt32, "rw"),
    a(0x6076, "motor_rated_torque", T::UInt32, "rw"),
    a(0x6077, "torque_actual", T::Int16, "ro"),
    a(0x6078, "current_actual", T::Int16, "ro"),
    a(0x6079, "dc_link_voltage", T::UInt32, "ro"),
    a(0x607A, "target_position", T::Int32, "rw"),
    a(0x607C, "home_offset", T::Int32, "rw"),
    a(0x607E, "polarity", T::UInt8, "rw"),
    a(0x607F, "max_profile_velocity", T::UInt32, "rw"),
    a(0x6080, "max_motor_speed", T::UInt32, "rw"),
    a(0x6081, "profile_velocity", T::UInt32, "rw"),
    a(0x6082, "end_velocity", T::UInt32, "rw"),
    a(0x6083, "profile_acceleration", T::UInt32, "rw"),
    a(0x6084, "profile_deceleration", T::UInt32, "rw"),
    a(0x6085, "quick_stop_deceleration", T::UInt32, "rw"),
    a(0x6086, "motion_profile_type", T::Int16, "rw"),
    a(0x6087, "torque_slope", T::UInt32, "rw"),
    a(0x6088, "torque_profile_type", T::Int16, "rw"),
    a(0x6098, "homing_method", T::Int8, "rw"),
    a(0x609A, "homing_acceleration", T::UInt32, "rw"),
    a(0x60B1, "velocity_offset", T::Int32, "rw"),
    a(0x60B2, "torque_offset", T::Int16, "rw"),
    a(0x60B8, "touch_probe_function", T::UInt16, "rw"),
    a(0x60B9, "touch_probe_status", T::UInt16, "ro"),
    a(0x60BA, "touch_probe_1_positive_edge", T::Int32, "ro"),
    a(0x60BB, "touch_probe_1_negative_edge", T::Int32, "ro"),
    a(0x60E0, "positive_torque_limit", T::UInt16, "rw"),
    a(0x60E1, "negative_torque_limit", T::UInt16, "rw"),
    a(0x60F4, "following_error_actual", T::Int32, "ro"),
    a(0x60FA, "control_effort", T::Int32, "ro"),
    a(0x60FC, "position_demand_internal", T::Int32, "ro"),
    a(0x60FD, "digital_inputs", T::UInt32, "ro"),
    a(0x60FF, "target_velocity", T::Int32, "rw"),
    a(0x6502, "supported_drive_modes", T::UInt32, "ro"),
];

/// What the table says of `index:subindex`: the object and, for CiA 402
/// objects, the axis (0 for the first).
pub(crate) fn lookup(index: u16, subindex: u8) -> Option<(KnownObject, u8)> {
    if let Some(k) = KNOWN.iter().find(|k| !k.per_axis && k.index == index && k.subindex == subindex) {
        return Some((*k, 0));
    }
    if !(0x6000..0xA000).contains(&index) || subindex != 0 {
        return None;
    }
    let axis = (index - 0x6000) / 0x800;
    let base = index - axis * 0x800;
    KNOWN.iter().find(|k| k.per_axis && k.index == base).map(|k| (*k, axis as u8))
}

impl super::Master {
    /// The type of `index:subindex` of `slave` where the daemon knows it:
    /// as the device described it (SDO Information, when read before),
    /// else as its ESI's dictionary has it, else as the standard table.
    /// A value written there is checked against it
    /// ([`super::value::as_type`], [`super::value::Value::encode`]).
    pub(crate) async fn object_type(&self, slave: u8, index: u16, subindex: u8) -> Option<DataType> {
        if let Some(t) = self.known_device_dictionary(slave).and_then(|d| d.data_type(index, subindex)) {
            return Some(t);
        }
        if let Some(Ok(esi)) = self.esi_device(slave).await
            && let Some(e) = esi.device().dictionary.entry(index, subindex)
        {
            return Some(e.dtype);
        }
        lookup(index, subindex).map(|(k, _)| k.data_type)
    }
}

/// The process-image name of an entry of `slave`: "1.statusword",
/// "1.axis2.target_position", "2.0x6000:01".
pub(crate) fn entry_name(slave: u8, index: u16, subindex: u8) -> String {
    match lookup(index, subindex) {
        Some((k, 0)) => format!("{slave}.{}", k.name),
        Some((k, axis)) => format!("{slave}.axis{axis}.{}", k.name),
        None => format!("{slave}.{index:#06x}:{subindex:02x}"),
    }
}

/// The index of CiA 402 object `base` (axis 0's) for `axis`.
pub(crate) fn axis_index(base: u16, axis: u8) -> u16 {
    base + 0x800 * u16::from(axis)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_cover_axes_and_unknown_objects() {
        assert_eq!(entry_name(1, 0x6041, 0), "1.statusword");
        assert_eq!(entry_name(1, 0x707A, 0), "1.axis2.target_position");
        assert_eq!(entry_name(2, 0x6000, 1), "2.0x6000:01");
        assert_eq!(lookup(0x6864, 0).map(|(k, a)| (k.name, a)), Some(("position_actual", 1)));
        assert_eq!(lookup(0x1018, 2).map(|(k, _)| k.data_type), Some(DataType::UInt32));
    }
}
