//! Whose turn a request is: each [`Job`](super::Job) carries its client's
//! number, which the front end put in the `master::Call` it queued the
//! work with, so the `FairQueue` can give clients turns.

/// The daemon's own work (the process-image layout it builds after each
/// bring-up): its line gets every other turn whatever the number of busy
/// clients, so work no caller's deadline bounds is done in a bounded time
/// and still leaves clients half of the slot. Even, so no API client id
/// (always odd, see `api::auth`) can be it.
pub const DAEMON_CLIENT: u64 = u64::MAX - 1;
