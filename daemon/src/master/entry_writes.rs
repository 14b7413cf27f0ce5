//! Client writes into the output image by entry name or byte offset, as
//! every front end makes them (gRPC `WriteOutputs`, Sparkplug DCMD): staged
//! on a copy of the shadow image, checked whole, then sent as one span
//! under a lease, so they reach the slaves in one frame and a bad write
//! changes nothing. The front end only turns its value into the entry's
//! bytes ([`Staging::entry`] names the entry and its type first).

use std::fmt;

use super::image::{Entry, Image, write_bits};
use super::{LeaseError, Leases, Master, NetworkLayout};

/// Controlword bits the chip's CiA 402 helper drives for an `[[axis]]`
/// (v049 commands 26..30: bits 0-3, and bit 7 for fault resets): the chip
/// overwrites them every cycle, so a client's value there would be lost
/// without a word.
const HELPER_BITS: u16 = 0x008F;

/// Why a write was refused (nothing of the request was applied).
#[derive(Debug)]
pub enum WriteError {
    /// No entry or variable has this name.
    NoEntry(String),
    /// The entry is an input.
    Input(String),
    /// The value's bytes are not the entry's size.
    WrongSize {
        /// The entry.
        name: String,
        /// Its bits.
        bits: u32,
        /// Bytes given.
        given: usize,
    },
    /// A value a sub-byte entry cannot hold.
    TooBig {
        /// The entry.
        name: String,
        /// Its bits.
        bits: u32,
        /// The value.
        value: u8,
    },
    /// Bytes past the end of the output image.
    PastImage {
        /// Where they start.
        offset: usize,
        /// How many.
        len: usize,
        /// The image size.
        size: usize,
    },
    /// The bytes are fed by a client's per-cycle frames (StreamFrames).
    Streamed {
        /// Written span.
        from: usize,
        /// Its end.
        to: usize,
        /// The stream's span start.
        start: usize,
        /// Its length.
        len: usize,
    },
    /// The write sets controlword bits the CiA 402 helper owns.
    HelperBits {
        /// `[[axis]]` number.
        axis: usize,
        /// Its slave.
        slave: u8,
        /// Controlword's byte in the output image.
        at: usize,
        /// The bits set.
        set: u16,
    },
    /// The lease refused it (none, another's slave, engine refusal).
    Lease(LeaseError),
}

impl WriteError {
    /// The request field a front end blames, for the caller's mistakes
    /// ([`WriteError::Streamed`], [`WriteError::HelperBits`] and
    /// [`WriteError::Lease`] are the state's, not a field's).
    pub(crate) fn field(&self) -> Option<&'static str> {
        match self {
            Self::NoEntry(_) | Self::Input(_) => Some("writes.entry"),
            Self::WrongSize { .. } | Self::TooBig { .. } => Some("writes.value"),
            Self::PastImage { .. } => Some("writes.offset"),
            Self::Streamed { .. } | Self::HelperBits { .. } | Self::Lease(_) => None,
        }
    }
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoEntry(name) => write!(f, "no entry {name:?} (see GetLayout for the names)"),
            Self::Input(name) => write!(f, "{name:?} is an input"),
            Self::WrongSize { name, bits, given } => {
                let want = bits.div_ceil(8);
                write!(
                    f,
                    "{given} bytes given for the {bits}-bit entry {name:?}, which takes {want} byte{}",
                    if want == 1 { "" } else { "s" }
                )
            }
            Self::TooBig { name, bits, value } => {
                write!(f, "{value} does not fit the {bits}-bit entry {name:?} (0..={})", (1u32 << bits) - 1)
            }
            Self::PastImage { offset, len, size } => {
                write!(f, "{len} bytes at {offset} exceed the {size}-byte output image")
            }
            Self::Streamed { from, to, start, len } => write!(
                f,
                "output bytes {from}..{to} are fed by a StreamFrames (bytes {start}..{}): send them as frames",
                start + len
            ),
            Self::HelperBits { axis, slave, at, set } => write!(
                f,
                "axis {axis} (slave {slave}, controlword at output byte {at}): bits 0-3 and 7 are driven by the chip's \
                 CiA 402 helper ([[axis]]), and this write sets {set:#06x} of them; use Cia402.Command to \
                 change the drive's state, and write only bits 4-6 and 8-15 here"
            ),
            Self::Lease(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for WriteError {}

/// The output entry `name` (an entry name or variable name) of `image`.
pub fn output_entry<'i>(image: &'i Image, name: &str) -> Result<&'i Entry, WriteError> {
    let e = image.get(name).ok_or_else(|| WriteError::NoEntry(name.to_owned()))?;
    if !e.output {
        return Err(WriteError::Input(name.to_owned()));
    }
    Ok(e)
}

/// A value for an entry of `bits` bits must be exactly its bytes (a bit
/// entry: one byte), and an entry narrower than a byte takes no value its
/// bits cannot hold (a 1-bit entry: 0 or 1). Nothing is cut silently: a
/// write of 2 bytes to a u8, or 1 MiB to a BOOL, is refused whole.
pub fn check_fits(name: &str, bits: u32, bytes: &[u8]) -> Result<(), WriteError> {
    if bytes.len() != bits.div_ceil(8) as usize {
        return Err(WriteError::WrongSize { name: name.to_owned(), bits, given: bytes.len() });
    }
    if bits < 8 && u32::from(bytes[0]) >> bits != 0 {
        return Err(WriteError::TooBig { name: name.to_owned(), bits, value: bytes[0] });
    }
    Ok(())
}

/// Writes being staged on a copy of the output shadow image.
#[derive(Debug)]
pub struct Staging<'m> {
    master: &'m Master,
    /// Held from the first stage to the commit, so two writers never
    /// interleave their stages.
    shadow: std::sync::MutexGuard<'m, Vec<u8>>,
    layout: NetworkLayout,
    staged: Vec<u8>,
    lo: usize,
    hi: usize,
}

impl<'m> Staging<'m> {
    /// Starts from the shadow image (the outputs as clients last wrote them).
    pub fn new(master: &'m Master, image: &Image) -> Self {
        let layout = master.layout();
        let mut shadow = master.output_shadow();
        shadow.resize(image.output_bytes as usize, 0);
        let staged = shadow.clone();
        Self { master, shadow, layout, staged, lo: usize::MAX, hi: 0 }
    }

    /// Stages `bytes` (the entry's value, little-endian) into entry `e`.
    pub fn entry(&mut self, e: &Entry, bytes: &[u8]) -> Result<(), WriteError> {
        check_fits(&e.name, e.bit_length, bytes)?;
        let (b0, b1) = ((e.bit_offset / 8) as usize, (e.bit_offset + e.bit_length).div_ceil(8) as usize);
        self.not_streamed(b0, b1)?;
        write_bits(&mut self.staged, e.bit_offset, e.bit_length, bytes);
        self.touch(b0, b1);
        Ok(())
    }

    /// Stages raw `bytes` at byte `offset` of the output image.
    pub(crate) fn raw(&mut self, offset: usize, bytes: &[u8]) -> Result<(), WriteError> {
        let size = self.staged.len();
        if offset.checked_add(bytes.len()).is_none_or(|end| end > size) {
            return Err(WriteError::PastImage { offset, len: bytes.len(), size });
        }
        self.not_streamed(offset, offset + bytes.len())?;
        self.staged[offset..offset + bytes.len()].copy_from_slice(bytes);
        self.touch(offset, offset + bytes.len());
        Ok(())
    }

    /// Sends the touched span as one write under lease `lease_id` (which
    /// must be `who`'s and own every slave it touches) and keeps it as the
    /// new shadow.
    pub fn commit(mut self, leases: &Leases, lease_id: &str, who: &str) -> Result<(), WriteError> {
        if self.lo >= self.hi {
            return Ok(());
        }
        let (lo, hi) = (self.lo, self.hi);
        self.helper_bits_untouched()?;
        let slaves = &self.layout.slaves;
        let slave_of =
            |b: usize| slaves.iter().position(|s| b >= s.rx_offset && b < s.rx_offset + s.rx_bytes).map(|p| p as u8);
        leases.write(lease_id, who, lo, &self.staged[lo..hi], slave_of).map_err(WriteError::Lease)?;
        *self.shadow = std::mem::take(&mut self.staged);
        Ok(())
    }

    fn touch(&mut self, from: usize, to: usize) {
        self.lo = self.lo.min(from);
        self.hi = self.hi.max(to);
    }

    /// Bytes `from..to` of the output image are no StreamFrames' (its frames
    /// replace them every cycle: a write there would be lost or, while the
    /// stream is dry, break the policy).
    fn not_streamed(&self, from: usize, to: usize) -> Result<(), WriteError> {
        match self.master.frame_claims().overlapping(from, to) {
            None => Ok(()),
            Some((start, len)) => Err(WriteError::Streamed { from, to, start, len }),
        }
    }

    /// Refuses a write that sets a controlword bit the CiA 402 helper owns:
    /// bits 4-6 and 8-15 (new set-point, halt, ...) stay the client's.
    fn helper_bits_untouched(&self) -> Result<(), WriteError> {
        let (staged, lo, hi) = (&self.staged, self.lo, self.hi);
        self.master.with_axes(|axes| {
            for (axis, a) in axes.iter().enumerate() {
                let Some(s) = self.layout.slaves.get(usize::from(a.slave)) else { continue };
                let at = s.rx_offset + usize::from(a.controlword_offset);
                if at + 2 > staged.len() || at + 2 <= lo || at >= hi {
                    continue;
                }
                let set = u16::from_le_bytes([staged[at], staged[at + 1]]) & HELPER_BITS;
                if set != 0 {
                    return Err(WriteError::HelperBits { axis, slave: a.slave, at, set });
                }
            }
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::check_fits;

    /// A bit entry takes one byte holding what its bits can: a 1-bit entry
    /// 0 or 1, a BIT2 entry 0..=3; a byte entry exactly one byte; nothing
    /// is cut to fit.
    #[test]
    fn a_value_must_be_exactly_its_entrys_bytes_and_fit_its_bits() {
        assert!(check_fits("2.0x7000:01", 1, &[1]).is_ok());
        assert!(check_fits("2.0x7000:01", 1, &[0]).is_ok());
        let e = check_fits("2.0x7000:01", 1, &[2]).unwrap_err().to_string();
        assert!(e.contains("2 does not fit the 1-bit entry \"2.0x7000:01\" (0..=1)"), "{e}");
        let e = check_fits("2.0x7000:01", 1, &vec![1; 1 << 20]).unwrap_err().to_string();
        assert!(e.contains("1048576 bytes given for the 1-bit entry \"2.0x7000:01\", which takes 1 byte"), "{e}");
        assert!(check_fits("1.bits", 2, &[3]).is_ok());
        assert!(check_fits("1.bits", 2, &[4]).is_err());
        assert!(check_fits("1.u8", 8, &[0xFF]).is_ok());
        assert!(check_fits("1.u8", 8, &[1, 2]).unwrap_err().to_string().contains("2 bytes given for the 8-bit"));
        assert!(check_fits("1.i16", 16, &[1]).unwrap_err().to_string().contains("which takes 2 bytes"));
        assert!(check_fits("1.u24", 24, &[1, 2, 3]).is_ok());
    }
}
