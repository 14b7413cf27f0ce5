//! Output writes from OPC UA sessions (docs/opcua.md, "Writing outputs"):
//! an operator's write to an output variable goes out under an output
//! lease the session takes for that slave, the same lease table gRPC and
//! Sparkplug write through. The lease is bound to the session and its
//! user: another session (another operator, or the same user's second
//! client) is refused while it is held, with the holder named, and it is
//! released when the session closes or ends, kept alive while it lives
//! (an HMI writes when an operator clicks, not every lease time-to-live).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use opcua::server::node_manager::RequestContext;
use opcua::types::{DataValue, StatusCode};

use super::refusal::Refusal;
use super::values::encode;
use crate::master::entry_writes::{Staging, WriteError};
use crate::master::image::{Entry, Image};
use crate::master::{LeaseError, Master};

/// An output variable: entry `index` of `image`.
#[derive(Clone)]
pub(super) struct OutputTarget {
    image: Arc<Image>,
    index: usize,
}

impl OutputTarget {
    pub(super) fn new(image: Arc<Image>, index: usize) -> Self {
        Self { image, index }
    }

    fn entry(&self) -> Option<&Entry> {
        self.image.entries.get(self.index)
    }

    /// The entry's name, for the log.
    pub(super) fn name(&self) -> &str {
        self.entry().map_or("", |e| e.name.as_str())
    }
}

/// A lease a session holds on one slave's outputs.
struct Held {
    /// Whether the session still lives with the lease's user (it holds
    /// the session weakly: a lease never keeps a closed session alive).
    alive: Box<dyn Fn() -> bool + Send>,
    user: String,
    who: String,
    lease: String,
}

/// The output leases OPC UA sessions hold, by (session id, slave).
pub(crate) struct SessionLeases {
    master: Arc<Master>,
    held: Mutex<HashMap<(u32, u8), Held>>,
}

impl SessionLeases {
    pub(super) fn new(master: Arc<Master>) -> Self {
        Self { master, held: Mutex::new(HashMap::new()) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(u32, u8), Held>> {
        self.held.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Writes `value` to `target` for the session of `ctx` (whose user
    /// may write: the manager checked the user's access level).
    pub(super) async fn write(
        &self,
        ctx: &RequestContext,
        target: &OutputTarget,
        value: &DataValue,
    ) -> Result<(), Refusal> {
        let user = ctx.user_token().0.clone();
        let Some(e) = target.entry() else { return Err(Refusal::new(StatusCode::BadNodeIdUnknown, "no such entry")) };
        let v = value.value.as_ref().ok_or_else(|| Refusal::new(StatusCode::BadNothingToDo, "no value given"))?;
        let bytes = encode(e.data_type, e.bit_length, v)
            .map_err(|why| Refusal::new(StatusCode::BadOutOfRange, format!("{}: {why}", e.name)))?;
        if !self.master.current_image().and_then(Result::ok).is_some_and(|i| Arc::ptr_eq(&i, &target.image)) {
            return Err(Refusal::new(
                StatusCode::BadNodeIdUnknown,
                format!("{}: the process image was laid out again; browse anew", e.name),
            ));
        }
        let session = ctx.session_id;
        let who = holder(&user, session);
        for attempt in 0..2 {
            let lease = self.lease(ctx, &user, &who, e.slave)?;
            let mut staging = Staging::new(&self.master, &target.image);
            staging.entry(e, &bytes).map_err(|w| Refusal::new(StatusCode::BadOutOfRange, w.to_string()))?;
            match staging.commit(self.master.leases(), &lease, &who) {
                Ok(()) => return Ok(()),
                // The lease lapsed (the daemon stalled past its
                // time-to-live): take a new one, once.
                Err(WriteError::Lease(LeaseError::NotALease(_))) if attempt == 0 => {
                    self.lock().remove(&(session, e.slave));
                }
                Err(WriteError::Lease(l @ LeaseError::Held { .. })) => return Err(Refusal::denied(l.to_string())),
                Err(w) => return Err(Refusal::new(StatusCode::BadInvalidState, w.to_string())),
            }
        }
        Err(Refusal::new(StatusCode::BadInvalidState, "the output lease could not be kept"))
    }

    /// The session's lease on `slave` (taken now if it has none) and the
    /// holder it is written under, for writes the master makes on the
    /// session's behalf (an axis' mode of operation).
    pub(super) fn session_lease(&self, ctx: &RequestContext, slave: u8) -> Result<(String, String), Refusal> {
        let user = ctx.user_token().0.clone();
        let who = holder(&user, ctx.session_id);
        let lease = self.lease(ctx, &user, &who, slave)?;
        Ok((lease, who))
    }

    /// The session's lease on `slave`, taken now if it has none.
    fn lease(&self, ctx: &RequestContext, user: &str, who: &str, slave: u8) -> Result<String, Refusal> {
        let key = (ctx.session_id, slave);
        let mut held = self.lock();
        // A session that changed its user (ActivateSession again) writes
        // under a lease of the new one.
        if let Some(h) = held.get(&key).filter(|h| h.user == user) {
            return Ok(h.lease.clone());
        }
        if let Some(old) = held.remove(&key) {
            let _ = self.master.leases().release(&old.lease, &old.who, false);
        }
        let lease = self.master.acquire_lease(&[slave], None, who).map_err(|e| Refusal::denied(e.to_string()))?;
        let session = Arc::downgrade(&ctx.session);
        let owner = user.to_string();
        let alive = move || {
            session.upgrade().is_some_and(|s| {
                let s = s.read();
                s.is_activated() && s.user_token().is_some_and(|t| t.0 == owner)
            })
        };
        held.insert(
            key,
            Held { alive: Box::new(alive), user: user.to_string(), who: who.to_string(), lease: lease.id.clone() },
        );
        Ok(lease.id)
    }

    /// Releases the leases of sessions that ended (closed, timed out, or
    /// activated with another user) and keeps the others alive: called
    /// more often than the leases' time-to-live.
    pub(super) fn keep(&self) {
        let mut held = self.lock();
        held.retain(|_, h| {
            if !(h.alive)() {
                let _ = self.master.leases().release(&h.lease, &h.who, false);
                return false;
            }
            self.master.leases().keep_alive(&h.lease, &h.who).is_ok()
        });
    }

    /// Whether any session holds a lease (the keeper runs only then).
    pub(super) fn any(&self) -> bool {
        !self.lock().is_empty()
    }
}

/// The name a session's leases are held under: the user and the session,
/// so another session of the same user is another holder.
fn holder(user: &str, session: u32) -> String {
    format!("opcua:{user} (session {session})")
}
