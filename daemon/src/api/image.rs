//! The process image as the API shows it: the master's [`Image`] as a
//! `ProcessImage` message, and entry values as `Value`s (typed with the
//! entry's CoE type, raw bytes when that does not decode).

use ecmxf_proto::v1 as pb;

use super::convert::{decode_value, pb_type};
use crate::master::image::{Entry, Image, read_bits};

/// The message form.
pub(crate) fn to_pb(image: &Image) -> pb::ProcessImage {
    pb::ProcessImage {
        output_bytes: image.output_bytes,
        input_bytes: image.input_bytes,
        cycle_us: image.cycle_us,
        entries: image
            .entries
            .iter()
            .map(|e| pb::ImageEntry {
                name: e.name.clone(),
                slave: e.slave.into(),
                index: e.index.into(),
                subindex: e.subindex.into(),
                direction: if e.output { pb::Direction::Output } else { pb::Direction::Input } as i32,
                bit_offset: e.bit_offset,
                bit_length: e.bit_length,
                data_type: pb_type(e.data_type) as i32,
                label: e.label.clone(),
                variable: e.variable.clone(),
            })
            .collect(),
        notes: image.notes.clone(),
    }
}

/// An entry's type as the API names it.
pub(crate) fn entry_type(e: &Entry) -> pb::DataType {
    pb_type(e.data_type)
}

/// An entry's value in an image.
pub(crate) fn entry_value(e: &Entry, image: &[u8]) -> pb::Value {
    let raw = read_bits(image, e.bit_offset, e.bit_length);
    decode_value(entry_type(e), &raw).ok().flatten().unwrap_or(pb::Value { kind: Some(pb::value::Kind::Raw(raw)) })
}
