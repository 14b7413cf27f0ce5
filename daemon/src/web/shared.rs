//! What the dashboard's handlers and tasks share: one value per concern,
//! each with its behaviour in the module of that concern (`overview`,
//! `slaves`, `plots`, `control`, `visitors`). The state is declared here,
//! apart, so those modules and `mod.rs` (which builds it) never import one
//! another in a circle.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde_json::Value;
use tokio::sync::{Notify, broadcast, watch};

use crate::config::api::Role;
use crate::master::{EcatState, InputFrame, Master};

/// Every handler's state.
pub(crate) struct Shared {
    pub(super) master: Arc<Master>,
    pub(super) visitors: Visitors,
    pub(super) overview: Feed,
    pub(super) slaves: SlaveTable,
    pub(super) plots: Sampler,
    pub(super) control: WebLeases,
}

/// The state as handlers hold it.
pub(crate) type Web = Arc<Shared>;

/// What the live feed shares (`overview`).
pub(crate) struct Feed {
    /// The newest summary (JSON text); its receivers are the browsers
    /// watching.
    pub(super) overview: watch::Sender<Arc<str>>,
    /// Each event as JSON text.
    pub(super) events: broadcast::Sender<Arc<str>>,
    /// The latest events, oldest first.
    pub(super) log: Mutex<VecDeque<Value>>,
    /// What each slave last reported (AL status events) since the network
    /// last came up.
    pub(super) reported: Mutex<HashMap<u8, (EcatState, u16)>>,
    /// The emergencies received, oldest first: (slave, as the page shows it).
    pub(super) emergencies: Mutex<VecDeque<(u8, Value)>>,
    /// A browser started watching.
    pub(super) wanted: Notify,
    /// The link and FIFO figures once a second over the last
    /// [`overview::TREND_KEPT`] seconds, for charts that open with their
    /// past (from the engine's status: no chip reads), oldest first.
    pub(super) trend: Mutex<VecDeque<TrendPoint>>,
}

/// One second of the overview's charts.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub(crate) struct TrendPoint {
    /// The daemon's clock, ns (the overview's `time_ns`).
    pub(super) time_ns: u64,
    /// SPI exchanges since the start.
    pub(super) exchanges: u64,
    /// FIFO alarms since the start.
    pub(super) fifo_alarms: u64,
    /// RxFIFO and TxFIFO levels, frames.
    pub(super) rx_fifo: u8,
    pub(super) tx_fifo: u8,
}

/// What the chip said of the slaves, shared by every browser (`slaves`).
#[derive(Default)]
pub(crate) struct SlaveTable {
    /// The list last read, and when.
    pub(super) list: tokio::sync::Mutex<Option<(Instant, Arc<Value>)>>,
    /// Each slave's SII, decoded, once read (`None`: being read).
    pub(super) sii: Mutex<HashMap<u8, Option<Arc<Value>>>>,
    /// The names of the slaves the network had, by position: the longest
    /// line seen since the start, so a lost slave is drawn where it was.
    pub(super) names: Mutex<Vec<String>>,
}

/// The frames taken for the plots (`plots`).
pub(crate) struct Sampler {
    /// The newest input frame, 50 times a second while a plot is open,
    /// with the outputs as front ends had written them then.
    pub(super) frames: broadcast::Sender<Arc<Sample>>,
    /// A plot opened.
    pub(super) wanted: Notify,
}

/// What a plot point is read from.
pub(crate) struct Sample {
    /// An input frame.
    pub(super) inputs: Arc<InputFrame>,
    /// The output image when it was taken.
    pub(super) outputs: Vec<u8>,
}

/// A lease a session holds on one slave's outputs.
pub(super) struct Held {
    pub(super) who: String,
    pub(super) lease: String,
}

/// The output leases dashboard sessions hold, by (session, slave)
/// (`control`).
pub(crate) struct WebLeases {
    pub(super) master: Arc<Master>,
    pub(super) held: Mutex<HashMap<(u64, u8), Held>>,
}

/// A logged-in browser.
#[derive(Clone, Debug)]
pub(super) struct Session {
    pub(super) name: String,
    pub(super) role: Role,
    pub(super) number: u64,
    pub(super) used: Instant,
}

/// The tokens that log in, and the sessions they opened (`visitors`).
pub(crate) struct Visitors {
    /// What a visitor who has not logged in may do.
    pub(super) anonymous: Option<Role>,
    /// SHA-256 (hex) of a token -> its role (none: refused) and name.
    pub(super) tokens: HashMap<String, (Option<Role>, String)>,
    /// Open sessions by cookie value.
    pub(super) sessions: Mutex<HashMap<String, Session>>,
    /// The next session's number.
    pub(super) next: AtomicU64,
    /// Whether the dashboard is served over HTTPS (the origin pages have).
    pub(super) https: bool,
    /// Sessions with a page open (its live feed): how many pages, and when
    /// the last one closed.
    pub(super) present: Mutex<HashMap<u64, (usize, Instant)>>,
    /// Failed logins not yet logged, and when the last line was.
    pub(super) failed: Mutex<(u64, Option<Instant>)>,
    /// SHA-256 (hex) of a client certificate -> its role (none: refused)
    /// and name (`[[api.client_cert]]`).
    pub(super) certificates: HashMap<String, (Option<Role>, String)>,
    /// The session number of each certificate seen (a browser with a
    /// certificate is one session for as long as the daemon runs).
    pub(super) certificate_sessions: Mutex<HashMap<String, u64>>,
}
