//! The engine thread's entry: it moves from phase to phase, each in its
//! own file ([`bringing_up`], [`running`], [`recovering`]), over the
//! state they all share ([`Core`]), until one of them says stop.
//!
//! [`bringing_up`]: super::bringing_up
//! [`running`]: super::running
//! [`recovering`]: super::recovering

use super::bringing_up;
use super::core::{Core, Inbound, Outbound, Shared};
use super::next::Next;
use super::recovering::Recovering;
use super::running;
use crate::config::Config;
use crate::link::Link;

/// The engine, built on the caller's thread and run on its own.
#[derive(Debug)]
pub(super) struct Engine<L> {
    core: Core<L>,
}

impl<L: Link> Engine<L> {
    /// An engine over `link`, fed by `inbound`, publishing to `outbound`
    /// and to what it shares with its handle.
    pub(super) fn new(link: L, config: Config, inbound: Inbound, outbound: Outbound, shared: Shared) -> Self {
        Self { core: Core::new(link, config, inbound, outbound, shared) }
    }

    /// Runs until stopped: bring-up, cyclic exchange, recovery.
    pub(super) fn run(mut self) {
        let core = &mut self.core;
        let mut recovering = Recovering::new(&core.config);
        let mut first = true;
        let mut next = Next::BringUp;
        loop {
            next = match next {
                Next::BringUp => {
                    let next = bringing_up::bring_up(core, first);
                    first = false;
                    next
                }
                Next::Run(layout) => {
                    recovering.network_up(&core.config);
                    running::run(core, layout)
                }
                Next::Retry { reopen } => recovering.retry(core, reopen),
                Next::Recover(why) => recovering.recover(core, why),
                Next::Stop => return core.stopped(),
            };
        }
    }
}
