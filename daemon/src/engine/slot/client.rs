//! Whose turn a request is: the API runs each caller's work inside
//! [`as_client`], and the master stamps every [`Job`](super::Job) it
//! builds with that client's number ([`current_client`]), so the
//! `FairQueue` can give clients turns.

tokio::task_local! {
    /// The client the current task works for (see [`as_client`]).
    static CLIENT: u64;
}

/// The daemon's own work (the process-image layout it builds after each
/// bring-up): its line gets every other turn whatever the number of busy
/// clients, so work no caller's deadline bounds is done in a bounded time
/// and still leaves clients half of the slot. Even, so no API client id
/// (always odd, see `api::auth`) can be it.
pub const DAEMON_CLIENT: u64 = u64::MAX - 1;

/// Runs `work` on behalf of client `id` (non-zero: a connection, a peer):
/// its requests to the chip's blocking slot take turns with other clients'
/// instead of queuing behind them. Requests made outside any client share
/// one turn.
pub async fn as_client<F: std::future::Future>(id: u64, work: F) -> F::Output {
    CLIENT.scope(id, work).await
}

/// The client the current task works for; 0 outside [`as_client`].
pub(crate) fn current_client() -> u64 {
    CLIENT.try_with(|c| *c).unwrap_or(0)
}
