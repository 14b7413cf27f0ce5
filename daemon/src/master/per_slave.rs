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

    /// Keeps `value` as read from `identity` at `slave`.
    pub(crate) fn put(&self, slave: u8, identity: Identity, value: T) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).insert(slave, (identity, value));
    }
}
