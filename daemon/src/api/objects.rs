//! The standard objects the daemon knows by name and type: CiA 301
//! communication objects and the CiA 402 drive profile (ETG.6010; axis n's
//! objects are at +0x800 x n). They name process-image entries, type SDO
//! values when the client gives no type, and are what `ListObjects` probes
//! on a slave without an ESI.

use ecmxf_proto::v1::DataType;

/// One known object (or subindex).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KnownObject {
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
pub const KNOWN: &[KnownObject] = &[
    o(0x1000, 0, "device_type", T::Unsigned32, "ro"),
    o(0x1001, 0, "error_register", T::Unsigned8, "ro"),
    o(0x1008, 0, "device_name", T::VisibleString, "ro"),
    o(0x1009, 0, "hardware_version", T::VisibleString, "ro"),
    o(0x100A, 0, "software_version", T::VisibleString, "ro"),
    o(0x1018, 0, "identity.count", T::Unsigned8, "ro"),
    o(0x1018, 1, "identity.vendor_id", T::Unsigned32, "ro"),
    o(0x1018, 2, "identity.product_code", T::Unsigned32, "ro"),
    o(0x1018, 3, "identity.revision", T::Unsigned32, "ro"),
    o(0x1018, 4, "identity.serial", T::Unsigned32, "ro"),
    o(0x1C12, 0, "rx_pdo_assign.count", T::Unsigned8, "rw"),
    o(0x1C13, 0, "tx_pdo_assign.count", T::Unsigned8, "rw"),
    o(0x1C32, 1, "output_sync.mode", T::Unsigned16, "rw"),
    o(0x1C33, 1, "input_sync.mode", T::Unsigned16, "rw"),
    a(0x603F, "error_code", T::Unsigned16, "ro"),
    a(0x6040, "controlword", T::Unsigned16, "rw"),
    a(0x6041, "statusword", T::Unsigned16, "ro"),
    a(0x605A, "quick_stop_option_code", T::Integer16, "rw"),
    a(0x6060, "modes_of_operation", T::Integer8, "rw"),
    a(0x6061, "modes_of_operation_display", T::Integer8, "ro"),
    a(0x6064, "position_actual", T::Integer32, "ro"),
    a(0x606C, "velocity_actual", T::Integer32, "ro"),
    a(0x6071, "target_torque", T::Integer16, "rw"),
    a(0x6072, "max_torque", T::Unsigned16, "rw"),
    a(0x6077, "torque_actual", T::Integer16, "ro"),
    a(0x607A, "target_position", T::Integer32, "rw"),
    a(0x60B1, "velocity_offset", T::Integer32, "rw"),
    a(0x60B2, "torque_offset", T::Integer16, "rw"),
    a(0x60FF, "target_velocity", T::Integer32, "rw"),
    a(0x6502, "supported_drive_modes", T::Unsigned32, "ro"),
];

/// What the table says of `index:subindex`: the object and, for CiA 402
/// objects, the axis (0 for the first).
pub fn lookup(index: u16, subindex: u8) -> Option<(KnownObject, u8)> {
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

/// The process-image name of an entry of `slave`: "1.statusword",
/// "1.axis2.target_position", "2.0x6000:01".
pub fn entry_name(slave: u8, index: u16, subindex: u8) -> String {
    match lookup(index, subindex) {
        Some((k, 0)) => format!("{slave}.{}", k.name),
        Some((k, axis)) => format!("{slave}.axis{axis}.{}", k.name),
        None => format!("{slave}.{index:#06x}:{subindex:02x}"),
    }
}

/// The index of CiA 402 object `base` (axis 0's) for `axis`.
pub fn axis_index(base: u16, axis: u8) -> u16 {
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
        assert_eq!(lookup(0x1018, 2).map(|(k, _)| k.data_type), Some(DataType::Unsigned32));
    }
}
