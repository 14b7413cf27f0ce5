//! A value read from a slave once and kept while the same device sits at
//! that position: the mailbox protocols, the mailbox geometry, the station
//! address. A device of another identity at the position is read anew.

use std::collections::HashMap;
use std::sync::Mutex;

use super::Identity;

/// Values by ring position, each with the identity it was read from.
#[derive(Debug)]
pub(crate) struct PerSlave<T>(Mutex<HashMap<u8, (Identity, T)>>);

impl<T> Default for PerSlave<T> {
    fn default() -> Self {
        Self(Mutex::default())
    }
}

impl<T: Copy> PerSlave<T> {
    /// The value kept for `slave`, if it was read from `identity`.
    pub(crate) fn get(&self, slave: u8, identity: Identity) -> Option<T> {
        let kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        kept.get(&slave).filter(|(id, _)| *id == identity).map(|(_, v)| *v)
    }

    /// The value kept for any slave of `identity`: for what a device's
    /// identity fixes (its SII's header is written per product and
    /// revision, as its ESI describes it per revision), a twin elsewhere
    /// on the line answers for it. An unknown identity (all zero) has no
    /// twins.
    pub(crate) fn of_identity(&self, identity: Identity) -> Option<T> {
        if identity == (0, 0, 0) {
            return None;
        }
        let kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        kept.values().find(|(id, _)| *id == identity).map(|(_, v)| *v)
    }

    /// Keeps `value` as read from `identity` at `slave`.
    pub(crate) fn put(&self, slave: u8, identity: Identity, value: T) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).insert(slave, (identity, value));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_twin_answers_for_its_identity_and_an_unknown_one_for_none() {
        let kept = PerSlave::<u16>::default();
        kept.put(3, (2, 0x10, 1), 0x0C);
        kept.put(4, (0, 0, 0), 0x04);
        assert_eq!(kept.get(5, (2, 0x10, 1)), None, "not read at 5");
        assert_eq!(kept.of_identity((2, 0x10, 1)), Some(0x0C));
        assert_eq!(kept.of_identity((2, 0x10, 2)), None, "another revision");
        assert_eq!(kept.of_identity((0, 0, 0)), None, "an unknown identity has no twins");
    }
}
