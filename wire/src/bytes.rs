//! Bounds-checked little-endian cursors over a data section.
//!
//! Every multi-byte field of the ECM-XF protocol is little-endian (manual v049,
//! 封包格式: the start word 0xA1A2A3A4 travels as A4 A3 A2 A1).

use crate::error::{EncodeError, PayloadError};

/// Reads fields in order, naming the field that was missing on failure.
pub(crate) struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    pub(crate) fn bytes(&mut self, field: &'static str, n: usize) -> Result<&'a [u8], PayloadError> {
        let end = self.pos.checked_add(n).filter(|&end| end <= self.data.len());
        let Some(end) = end else {
            return Err(PayloadError::TooShort {
                field,
                needed: self.pos.saturating_add(n),
                available: self.data.len(),
            });
        };
        let out = &self.data[self.pos..end];
        self.pos = end;
        Ok(out)
    }

    pub(crate) fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], PayloadError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.bytes(field, N)?);
        Ok(out)
    }

    pub(crate) fn u8(&mut self, field: &'static str) -> Result<u8, PayloadError> {
        Ok(self.array::<1>(field)?[0])
    }

    pub(crate) fn u16(&mut self, field: &'static str) -> Result<u16, PayloadError> {
        Ok(u16::from_le_bytes(self.array(field)?))
    }

    pub(crate) fn u32(&mut self, field: &'static str) -> Result<u32, PayloadError> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    pub(crate) fn i32(&mut self, field: &'static str) -> Result<i32, PayloadError> {
        Ok(i32::from_le_bytes(self.array(field)?))
    }

    /// Everything not read yet.
    pub(crate) fn rest(&mut self) -> &'a [u8] {
        let out = &self.data[self.pos..];
        self.pos = self.data.len();
        out
    }
}

/// Writes fields in order into a data section, failing when it is too small.
pub(crate) struct Writer<'a> {
    data: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    pub(crate) fn new(data: &'a mut [u8]) -> Self {
        Self { data, pos: 0 }
    }

    pub(crate) fn bytes(&mut self, src: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + src.len();
        if end > self.data.len() {
            return Err(EncodeError::PayloadTooLarge { needed: end, capacity: self.data.len() });
        }
        self.data[self.pos..end].copy_from_slice(src);
        self.pos = end;
        Ok(())
    }

    pub(crate) fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.bytes(&[v])
    }

    pub(crate) fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }

    pub(crate) fn u32(&mut self, v: u32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }

    pub(crate) fn i32(&mut self, v: i32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }

    /// Bytes written so far, as the header's data-length field wants it.
    pub(crate) fn len_u16(&self) -> u16 {
        // A data section is at most 1408 bytes, so this never truncates.
        self.pos as u16
    }
}

/// Fails with [`EncodeError::FieldOutOfRange`] unless `min <= value <= max`.
pub(crate) fn check_range(field: &'static str, value: u32, min: u32, max: u32) -> Result<(), EncodeError> {
    if value < min || value > max { Err(EncodeError::FieldOutOfRange { field, value, min, max }) } else { Ok(()) }
}

/// Fails with [`PayloadError::InvalidValue`] unless `min <= value <= max`.
pub(crate) fn expect_range(field: &'static str, value: u32, min: u32, max: u32) -> Result<(), PayloadError> {
    if value < min || value > max { Err(PayloadError::InvalidValue { field, value }) } else { Ok(()) }
}
