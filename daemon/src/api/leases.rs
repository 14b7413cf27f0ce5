//! Output leases: only one client at a time owns a slave's outputs. A lease
//! holds one of the engine's counted output writers, so when the last lease
//! goes (released, expired without keep-alive, or its stream closed) the
//! engine applies `outputs.on_last_writer_gone` — the configured safe action.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use tonic::Status;

use crate::master::{Master, OutputWriter};

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

fn to_pb(id: &str, h: &Held) -> pb::Lease {
    pb::Lease {
        id: id.to_owned(),
        slaves: h.slaves.iter().map(|&s| s.into()).collect(),
        ttl_ms: h.ttl.as_millis() as u32,
    }
}

impl Leases {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Held>> {
        self.held.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes `slaves` (all when empty) for `who`.
    pub fn acquire(&self, master: &Master, slaves: &[u32], ttl: Duration, who: &str) -> Result<pb::Lease, Status> {
        let count = master.layout().slaves.len();
        let wanted: Vec<u8> = if slaves.is_empty() {
            (0..count as u8).collect()
        } else {
            let mut v = Vec::with_capacity(slaves.len());
            for &s in slaves {
                v.push(super::convert::existing_slave(s, count, "slaves")?);
            }
            v.sort_unstable();
            v.dedup();
            v
        };
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        for (id, h) in held.iter() {
            if let Some(s) = wanted.iter().find(|s| h.slaves.contains(s)) {
                return Err(Status::permission_denied(format!(
                    "the outputs of slave {s} are leased by {} (lease {id}); wait for it to be released or expire",
                    h.who
                )));
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
        let out = to_pb(&id, &h);
        tracing::info!(lease = %id, who, slaves = ?h.slaves, "output lease taken");
        held.insert(id, h);
        Ok(out)
    }

    /// Extends a lease by its time-to-live.
    pub fn keep_alive(&self, id: &str) -> Result<pb::Lease, Status> {
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        let h = held.get_mut(id).ok_or_else(|| not_found(id))?;
        h.expires = Instant::now() + h.ttl;
        Ok(to_pb(id, h))
    }

    /// Gives a lease up.
    pub fn release(&self, id: &str) -> Result<(), Status> {
        let gone = self.lock().remove(id).ok_or_else(|| not_found(id))?;
        tracing::info!(lease = %id, who = %gone.who, "output lease released");
        Ok(())
    }

    /// Writes `bytes` at `offset` of the output image under lease `id`,
    /// which must own every slave the bytes touch (`slave_of` maps a byte
    /// offset to its slave). Also keeps the lease alive.
    pub fn write(
        &self,
        id: &str,
        offset: usize,
        bytes: &[u8],
        slave_of: impl Fn(usize) -> Option<u8>,
    ) -> Result<(), Status> {
        let mut held = self.lock();
        self.expire(&mut held, Instant::now());
        let h = held.get_mut(id).ok_or_else(|| {
            Status::permission_denied(format!(
                "writing outputs needs a lease: {id:?} is not one (released, expired, or never taken; see AcquireLease)"
            ))
        })?;
        for at in offset..offset + bytes.len() {
            match slave_of(at) {
                Some(s) if h.slaves.contains(&s) => {}
                Some(s) => {
                    return Err(Status::permission_denied(format!(
                        "output byte {at} belongs to slave {s}, which lease {id} does not own"
                    )));
                }
                None => {
                    return Err(super::status::bad_argument("offset", format!("output byte {at} belongs to no slave")));
                }
            }
        }
        h.expires = Instant::now() + h.ttl;
        h.writer.write(offset, bytes).map_err(super::status::to_status)
    }

    /// Whether lease `id` exists and owns `slave`.
    pub fn owns(&self, id: &str, slave: u8) -> bool {
        self.lock().get(id).is_some_and(|h| h.slaves.contains(&slave))
    }

    /// Drops expired leases (their writers go with them).
    pub fn sweep(&self) {
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

fn not_found(id: &str) -> Status {
    Status::not_found(format!("no lease {id:?} (released, expired, or never taken)"))
}

/// A word that makes lease ids hard to guess (not secret: roles decide
/// access; this only keeps a stale id from matching a new lease).
fn rand_word(n: u64) -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(n);
    h.finish() as u32
}
