//! Output leases: only one client at a time owns a slave's outputs. A lease
//! holds one of the engine's counted output writers, so when the last lease
//! goes (released, expired without keep-alive, or its stream closed) the
//! engine applies `outputs.on_last_writer_gone` — the configured safe action.
//! Domain state of the master, not of the API: any front end (gRPC, MQTT, a
//! mailbox gateway) shares the one table; the API maps [`Lease`] and
//! [`LeaseError`] to its messages and codes.

use std::collections::HashMap;
use std::fmt;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::{EngineError, Master, OutputWriter};

/// A lease as clients see it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lease {
    /// Its id.
    pub id: String,
    /// The slaves whose outputs it owns.
    pub slaves: Vec<u8>,
    /// How long it lives without a keep-alive.
    pub ttl: Duration,
}

/// Why a lease operation was refused.
#[derive(Debug)]
pub enum LeaseError {
    /// Another lease holds a slave asked for.
    Held {
        /// The slave.
        slave: u8,
        /// Who holds it.
        who: String,
        /// Its lease.
        id: String,
    },
    /// No lease has this id (released, expired, or never taken).
    Unknown(String),
    /// The lease is another identity's: only the identity that took it
    /// writes under it, renews or releases it (an admin may break it).
    NotHolder {
        /// The lease.
        id: String,
        /// Who took it.
        holder: String,
        /// Who asked.
        who: String,
    },
    /// A write under an id that is no lease.
    NotALease(String),
    /// A written byte belongs to a slave the lease does not own.
    NotOwned {
        /// The byte of the output image.
        byte: usize,
        /// Its slave.
        slave: u8,
        /// The lease.
        id: String,
    },
    /// A written byte belongs to no slave.
    NoSlave(usize),
    /// The engine refused the write.
    Write(EngineError),
}

impl fmt::Display for LeaseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Write(e) => write!(f, "{e}"),
            Self::Held { slave, who, id } => write!(
                f,
                "the outputs of slave {slave} are leased by {who} (lease {id}); wait for it to be released or expire"
            ),
            Self::Unknown(id) => write!(f, "no lease {id:?} (released, expired, or never taken)"),
            Self::NotHolder { id, holder, who } => write!(
                f,
                "lease {id} is held by {holder}, not {who}: only the identity that took a lease writes under it, \
                 renews or releases it"
            ),
            Self::NotALease(id) => write!(
                f,
                "writing outputs needs a lease: {id:?} is not one (released, expired, or never taken; see AcquireLease)"
            ),
            Self::NotOwned { byte, slave, id } => {
                write!(f, "output byte {byte} belongs to slave {slave}, which lease {id} does not own")
            }
            Self::NoSlave(byte) => write!(f, "output byte {byte} belongs to no slave"),
        }
    }
}

impl std::error::Error for LeaseError {}

#[derive(Debug)]
struct Held {
    slaves: Vec<u8>,
    ttl: Duration,
    expires: Instant,
    who: String,
    writer: OutputWriter,
}

/// The lease table.
#[derive(Debug, Default)]
pub struct Leases {
    held: Mutex<HashMap<String, Held>>,
    next: std::sync::atomic::AtomicU64,
}

fn lease(id: &str, h: &Held) -> Lease {
    Lease { id: id.to_owned(), slaves: h.slaves.clone(), ttl: h.ttl }
}

impl Leases {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Held>> {
        self.held.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes `slaves` (positions on the ring; all when empty) for `who`.
    pub(crate) fn acquire(
        &self,
        master: &Master,
        slaves: &[u8],
        ttl: Duration,
        who: &str,
    ) -> Result<Lease, LeaseError> {
        let wanted: Vec<u8> = if slaves.is_empty() {
            (0..master.layout().slaves.len() as u8).collect()
        } else {
            let mut v = slaves.to_vec();
            v.sort_unstable();
            v.dedup();
            v
        };
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        for (id, h) in held.iter() {
            if let Some(s) = wanted.iter().find(|s| h.slaves.contains(s)) {
                return Err(LeaseError::Held { slave: *s, who: h.who.clone(), id: id.clone() });
            }
        }
        let n = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let id = format!("lease-{n}-{:08x}", rand_word(n));
        let h = Held {
            slaves: wanted,
            ttl,
            expires: Instant::now() + ttl,
            who: who.to_owned(),
            writer: master.output_writer(),
        };
        let out = lease(&id, &h);
        tracing::info!(lease = %id, who, slaves = ?h.slaves, "output lease taken");
        held.insert(id, h);
        Ok(out)
    }

    /// Extends lease `id` by its time-to-live, for its holder `who`.
    pub(crate) fn keep_alive(&self, id: &str, who: &str) -> Result<Lease, LeaseError> {
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        let h = held.get_mut(id).ok_or_else(|| LeaseError::Unknown(id.to_owned()))?;
        holder_is(id, h, who)?;
        h.expires = Instant::now() + h.ttl;
        Ok(lease(id, h))
    }

    /// Gives lease `id` up, for its holder `who`; `may_break`: `who` may
    /// release another identity's lease (an admin), which is logged with
    /// both identities.
    pub(crate) fn release(&self, id: &str, who: &str, may_break: bool) -> Result<(), LeaseError> {
        let mut held = self.lock();
        let h = held.get(id).ok_or_else(|| LeaseError::Unknown(id.to_owned()))?;
        if h.who != who {
            if !may_break {
                return Err(LeaseError::NotHolder { id: id.to_owned(), holder: h.who.clone(), who: who.to_owned() });
            }
            tracing::warn!(lease = %id, holder = %h.who, by = who, "output lease broken by an admin");
        }
        let gone = held.remove(id).ok_or_else(|| LeaseError::Unknown(id.to_owned()))?;
        tracing::info!(lease = %id, who = %gone.who, "output lease released");
        Ok(())
    }

    /// Writes `bytes` at `offset` of the output image under lease `id`,
    /// which must be `who`'s and own every slave the bytes touch
    /// (`slave_of` maps a byte offset to its slave). Also keeps the lease
    /// alive.
    pub fn write(
        &self,
        id: &str,
        who: &str,
        offset: usize,
        bytes: &[u8],
        slave_of: impl Fn(usize) -> Option<u8>,
    ) -> Result<(), LeaseError> {
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        let h = held.get_mut(id).ok_or_else(|| LeaseError::NotALease(id.to_owned()))?;
        holder_is(id, h, who)?;
        for at in offset..offset + bytes.len() {
            match slave_of(at) {
                Some(s) if h.slaves.contains(&s) => {}
                Some(slave) => return Err(LeaseError::NotOwned { byte: at, slave, id: id.to_owned() }),
                None => return Err(LeaseError::NoSlave(at)),
            }
        }
        h.expires = Instant::now() + h.ttl;
        h.writer.write(offset, bytes).map_err(LeaseError::Write)
    }

    /// Whether lease `id` exists, is `who`'s and owns `slave`.
    pub(crate) fn owns(&self, id: &str, who: &str, slave: u8) -> bool {
        self.lock().get(id).is_some_and(|h| h.who == who && h.slaves.contains(&slave))
    }

    /// Ends every lease whose holder `allowed` no longer accepts (their
    /// writers go with them); returns (lease, holder) of each.
    pub(crate) fn end_unless(&self, allowed: impl Fn(&str) -> bool) -> Vec<(String, String)> {
        let mut held = self.lock();
        let mut ended = Vec::new();
        held.retain(|id, h| {
            let keep = allowed(&h.who);
            if !keep {
                ended.push((id.clone(), h.who.clone()));
            }
            keep
        });
        ended
    }

    /// Who holds leases now.
    pub(crate) fn holders(&self) -> std::collections::HashSet<String> {
        self.lock().values().map(|h| h.who.clone()).collect()
    }

    /// Drops expired leases (their writers go with them).
    pub(crate) fn sweep(&self) {
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
    }

    fn expire(&self, held: &mut HashMap<String, Held>, now: Instant) {
        held.retain(|id, h| {
            let alive = h.expires > now;
            if !alive {
                tracing::warn!(lease = %id, who = %h.who, "output lease expired without keep-alive");
            }
            alive
        });
    }
}

/// Refuses `who` for lease `id` unless it took it: a lease id alone (which
/// a refusal to another client names) gives no right to its outputs.
fn holder_is(id: &str, h: &Held, who: &str) -> Result<(), LeaseError> {
    if h.who == who {
        return Ok(());
    }
    Err(LeaseError::NotHolder { id: id.to_owned(), holder: h.who.clone(), who: who.to_owned() })
}

/// A word that makes lease ids hard to guess (not secret: roles decide
/// access; this only keeps a stale id from matching a new lease).
fn rand_word(n: u64) -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(n);
    h.finish() as u32
}
