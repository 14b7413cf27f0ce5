//! The SDO rules a real slave enforces on its object dictionary
//! (ETG.1000.6 / CiA301): access rights per EtherCAT state, sizes, value
//! ranges, complete access, and the abort codes a master sees when it gets
//! any of these wrong. The dictionary itself is a device description
//! ([`ecmxf_devices::od`]).

use ecmxf_wire::payload::sdo::SdoAbortCode;

pub use ecmxf_devices::od::*;

use super::esm::AlState;

/// SDO outcome: data or an abort code.
pub type SdoResult<T> = Result<T, SdoAbortCode>;

/// Whether a complete access starting at `sub` is possible (ETG.1000.6:
/// only records and arrays, from subindex 0 or 1).
fn allows_complete_access(object: &Object, sub: u8) -> SdoResult<()> {
    if object.kind == ObjectKind::Var {
        return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
    }
    if sub > 1 {
        return Err(SdoAbortCode::SUBINDEX_MISSING);
    }
    Ok(())
}

/// Whether `e` may be read in `state`: never-readable entries abort as
/// write-only, others outside their states as the wrong state.
fn readable(e: &Entry, state: AlState) -> SdoResult<()> {
    if e.access.read.contains(state.to_ecat()) {
        Ok(())
    } else if e.access.read == StateSet::NONE {
        Err(SdoAbortCode::WRITE_ONLY)
    } else {
        Err(SdoAbortCode::WRONG_STATE)
    }
}

/// A slave answering SDO requests from its dictionary.
pub trait SdoServer {
    /// SDO upload as a slave answers it.
    fn upload(&self, index: u16, sub: u8, complete: bool, state: AlState) -> SdoResult<Vec<u8>>;

    /// SDO download as a slave answers it. `validate` sees the whole new
    /// value of an entry before it is stored, for object-specific rules (PDO
    /// mapping checks); it may refuse with an abort code.
    fn download(
        &mut self,
        index: u16,
        sub: u8,
        complete: bool,
        data: &[u8],
        state: AlState,
        validate: impl FnMut(&ObjectDictionary, u16, u8, &[u8]) -> SdoResult<()>,
    ) -> SdoResult<()>;
}

impl SdoServer for ObjectDictionary {
    fn upload(&self, index: u16, sub: u8, complete: bool, state: AlState) -> SdoResult<Vec<u8>> {
        let obj = self.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        if complete {
            if self.no_complete_access {
                return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
            }
            allows_complete_access(obj, sub)?;
            let count = obj.entries.get(&0).map_or(0, |e| e.int() as u8);
            let mut out = Vec::new();
            for (s, e) in obj.entries.range(sub..) {
                if *s > count && *s != 0 {
                    break;
                }
                readable(e, state)?;
                out.extend_from_slice(&e.value);
                // Subindex 0 travels as 16 bits in complete access
                // (ETG.1000.6 5.6.2.1).
                if *s == 0 {
                    out.push(0);
                }
            }
            return Ok(out);
        }
        let e = obj.entries.get(&sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
        readable(e, state)?;
        Ok(e.value.clone())
    }

    fn download(
        &mut self,
        index: u16,
        sub: u8,
        complete: bool,
        data: &[u8],
        state: AlState,
        mut validate: impl FnMut(&ObjectDictionary, u16, u8, &[u8]) -> SdoResult<()>,
    ) -> SdoResult<()> {
        let obj = self.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        if complete {
            if self.no_complete_access {
                return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
            }
            allows_complete_access(obj, sub)?;
            // Split the data over the entries, subindex 0 as 16 bits.
            let mut writes: Vec<(u8, Vec<u8>)> = Vec::new();
            let mut rest = data;
            for (s, e) in obj.entries.range(sub..) {
                let n = if *s == 0 { 2 } else { e.dtype.bytes() };
                if rest.len() < n {
                    if rest.is_empty() && *s != 0 {
                        break;
                    }
                    return Err(SdoAbortCode::LENGTH_TOO_LOW);
                }
                let v = if *s == 0 { vec![rest[0]] } else { rest[..n].to_vec() };
                writes.push((*s, v));
                rest = &rest[n..];
            }
            if !rest.is_empty() {
                return Err(SdoAbortCode::LENGTH_TOO_HIGH);
            }
            for (s, v) in &writes {
                check_write(self, index, *s, v, state)?;
            }
            // The object-specific rules judge the new value as a whole, in
            // the order a master writing one subindex at a time follows
            // (ETG.1000.6 5.6.7: count to 0, the entries, then the count):
            // checked against the old entries, a new assignment's count
            // would name PDOs not yet written.
            let mut trial = self.clone();
            if writes.first().is_some_and(|(s, _)| *s == 0) {
                if let Some(e) = trial.entry_mut(index, 0) {
                    e.value = vec![0];
                }
            }
            let (count, entries): (Vec<_>, Vec<_>) = writes.into_iter().partition(|(s, _)| *s == 0);
            for (s, v) in entries.into_iter().chain(count) {
                validate(&trial, index, s, &v)?;
                if let Some(e) = trial.entry_mut(index, s) {
                    e.value = v;
                }
            }
            *self = trial;
            return Ok(());
        }
        check_write(self, index, sub, data, state)?;
        validate(self, index, sub, data)?;
        let e = self.entry_mut(index, sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
        if e.dtype.is_fixed_size() {
            e.value = data.to_vec();
        } else {
            let mut v = data.to_vec();
            v.resize(e.dtype.bytes(), 0);
            e.value = v;
        }
        Ok(())
    }
}

fn check_write(od: &ObjectDictionary, index: u16, sub: u8, data: &[u8], state: AlState) -> SdoResult<()> {
    let e = od.entry(index, sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
    if e.access.write == StateSet::NONE {
        return Err(SdoAbortCode::READ_ONLY);
    }
    if !e.access.write.contains(state.to_ecat()) {
        return Err(SdoAbortCode::WRONG_STATE);
    }
    let want = e.dtype.bytes();
    if e.dtype.is_fixed_size() {
        if data.len() > want {
            return Err(SdoAbortCode::LENGTH_TOO_HIGH);
        }
        if data.len() < want {
            return Err(SdoAbortCode::LENGTH_TOO_LOW);
        }
    } else if data.len() > want {
        return Err(SdoAbortCode::LENGTH_TOO_HIGH);
    }
    if let Some((min, max)) = e.range {
        let mut probe = e.clone();
        probe.value = data.to_vec();
        let v = probe.int();
        if v > max {
            return Err(SdoAbortCode::VALUE_TOO_HIGH);
        }
        if v < min {
            return Err(SdoAbortCode::VALUE_TOO_LOW);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn od() -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.insert(
            0x1000,
            Object::var(
                "Device type",
                Entry::new("Device type", DataType::UInt32, Access::RO).default_int(0x0002_0192),
            ),
        );
        od.insert(
            0x6060,
            Object::var(
                "Modes of operation",
                Entry::new("Mode", DataType::Int8, Access::RW).range(8, 10).default_int(8),
            ),
        );
        od.insert(0x2000, Object::var("Secret", Entry::new("Secret", DataType::UInt16, Access::WO)));
        od.insert(
            0x1C12,
            Object::record(
                "RxPDO assign",
                ObjectKind::Array,
                Access::RW_PREOP,
                vec![Entry::new("Subindex 001", DataType::UInt16, Access::RW_PREOP).default_int(0x1600)],
            ),
        );
        od.insert(
            0x1008,
            Object::var("Name", Entry::new("Name", DataType::VisibleString(8), Access::RO).default_bytes(b"Drive")),
        );
        od
    }

    fn ok(_: &ObjectDictionary, _: u16, _: u8, _: &[u8]) -> SdoResult<()> {
        Ok(())
    }

    #[test]
    fn upload_rules() {
        let od = od();
        assert_eq!(od.upload(0x1000, 0, false, AlState::PreOp), Ok(vec![0x92, 0x01, 0x02, 0x00]));
        assert_eq!(od.upload(0x1234, 0, false, AlState::PreOp), Err(SdoAbortCode::OBJECT_MISSING));
        assert_eq!(od.upload(0x1000, 1, false, AlState::PreOp), Err(SdoAbortCode::SUBINDEX_MISSING));
        assert_eq!(od.upload(0x2000, 0, false, AlState::PreOp), Err(SdoAbortCode::WRITE_ONLY));
        assert_eq!(od.upload(0x1000, 0, true, AlState::PreOp), Err(SdoAbortCode::NO_COMPLETE_ACCESS));
        assert_eq!(od.upload(0x1C12, 0, true, AlState::PreOp), Ok(vec![1, 0, 0x00, 0x16]));
        assert_eq!(od.upload(0x1C12, 1, true, AlState::PreOp), Ok(vec![0x00, 0x16]));
    }

    #[test]
    fn download_rules() {
        let mut od = od();
        assert_eq!(od.download(0x1000, 0, false, &[0; 4], AlState::PreOp, ok), Err(SdoAbortCode::READ_ONLY));
        assert_eq!(od.download(0x6060, 0, false, &[9, 0], AlState::Op, ok), Err(SdoAbortCode::LENGTH_TOO_HIGH));
        assert_eq!(od.download(0x6060, 0, false, &[], AlState::Op, ok), Err(SdoAbortCode::LENGTH_TOO_LOW));
        assert_eq!(od.download(0x6060, 0, false, &[11], AlState::Op, ok), Err(SdoAbortCode::VALUE_TOO_HIGH));
        assert_eq!(od.download(0x6060, 0, false, &[0xFF], AlState::Op, ok), Err(SdoAbortCode::VALUE_TOO_LOW));
        assert_eq!(od.download(0x6060, 0, false, &[9], AlState::Op, ok), Ok(()));
        assert_eq!(od.int(0x6060, 0), 9);
        assert_eq!(od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::SafeOp, ok), Err(SdoAbortCode::WRONG_STATE));
        assert_eq!(od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::PreOp, ok), Ok(()));
        assert_eq!(od.download(0x1C12, 0, true, &[1, 0, 0x02, 0x16], AlState::PreOp, ok), Ok(()));
        assert_eq!(od.int(0x1C12, 1), 0x1602);
        assert_eq!(
            od.download(0x1C12, 0, true, &[1, 0, 0x02, 0x16, 0], AlState::PreOp, ok),
            Err(SdoAbortCode::LENGTH_TOO_HIGH)
        );
        assert_eq!(od.download(0x1008, 0, false, b"Too long name", AlState::PreOp, ok), Err(SdoAbortCode::READ_ONLY));
        let refuse = |_: &ObjectDictionary, _: u16, _: u8, _: &[u8]| Err(SdoAbortCode::NOT_MAPPABLE);
        assert_eq!(
            od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::PreOp, refuse),
            Err(SdoAbortCode::NOT_MAPPABLE)
        );
        assert_eq!(od.int(0x1C12, 1), 0x1602, "refused write changed nothing");
    }

    #[test]
    fn no_sdo_in_init() {
        let od = od();
        assert_eq!(od.upload(0x1000, 0, false, AlState::Init), Err(SdoAbortCode::WRONG_STATE));
    }
}
