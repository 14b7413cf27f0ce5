//! Every slave read for a listing (`ecmxfctl slaves`, the web page): its
//! state and AL status live, its addresses and distributed clock as this
//! run set them.
//!
//! Each item is one SLV_INFO_GET (v049 15) on the blocking slot's turn,
//! two exchanges; asked one after another from here, each also waits for
//! the engine to take the next, and 128 slaves took over a second. So a
//! listing keeps [`READS_IN_FLIGHT`] items queued, and what only bring-up
//! changes (ECAT_INIT assigns the addresses, bring-up sets the clocks) is
//! read once per run ([`SetupCache`]): a listing then reads two items per
//! slave instead of eight.

use std::sync::{Arc, Mutex};

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::slave_info::SlaveInfoCode;
use futures_util::{StreamExt, TryStreamExt, stream};

use super::{Call, Identity, Master, Phase};
use crate::engine::error::EngineError;

/// Items one listing keeps queued for the chip: enough that the slot
/// never waits for the next, few enough to leave most of the engine's
/// request queue to other clients.
const READS_IN_FLIGHT: usize = 16;

/// A slave as read live from the chip.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct SlaveReading {
    /// Its EtherCAT state.
    pub state: EcatState,
    /// Its AL status code.
    pub al_status: u16,
    /// Its identity and name, when asked for fresh ones.
    pub identity: Option<(Identity, String)>,
    /// Its addresses and distributed clock, as this run set them.
    pub setup: SlaveSetup,
}

/// What bring-up set on a slave and a run does not change.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct SlaveSetup {
    /// Station alias.
    pub alias: u32,
    /// Configured station address.
    pub configured_address: u32,
    /// Whether it has distributed clocks.
    pub dc_supported: bool,
    /// Whether its distributed clock is active.
    pub dc_active: bool,
    /// SYNC0 cycle, ns.
    pub dc_cycle_ns: u32,
    /// SYNC0 shift, ns.
    pub dc_shift_ns: i32,
}

/// The items of a [`SlaveSetup`], in its fields' order.
const SETUP_ITEMS: [SlaveInfoCode; 6] = [
    SlaveInfoCode::Alias,
    SlaveInfoCode::ConfiguredAddress,
    SlaveInfoCode::HasDc,
    SlaveInfoCode::DcActive,
    SlaveInfoCode::DcCycle,
    SlaveInfoCode::DcShift,
];

/// The items read live in every listing; with a fresh identity, also
/// these after them.
const LIVE_ITEMS: [SlaveInfoCode; 2] = [SlaveInfoCode::State, SlaveInfoCode::AlStatus];
const IDENTITY_ITEMS: [SlaveInfoCode; 3] =
    [SlaveInfoCode::VendorId, SlaveInfoCode::ProductCode, SlaveInfoCode::Revision];

/// Which run: a new configuration or a recovery (a reinit is one) starts
/// another, and bring-up may then set other addresses or clocks.
type RunKey = (u64, u64, usize);

/// The setups of the run in force, and the one read of them at a time.
#[derive(Debug, Default)]
pub(crate) struct SetupCache {
    held: Mutex<Option<(RunKey, Arc<[SlaveSetup]>)>>,
    /// Held while they are read: a listing that comes meanwhile waits for
    /// that read instead of asking the chip the same again.
    reading: tokio::sync::Mutex<()>,
}

impl SetupCache {
    fn get(&self, key: RunKey) -> Option<Arc<[SlaveSetup]>> {
        let held = self.held.lock().unwrap_or_else(|e| e.into_inner());
        held.as_ref().filter(|(k, _)| *k == key).map(|(_, s)| Arc::clone(s))
    }

    fn put(&self, key: RunKey, setups: Arc<[SlaveSetup]>) {
        *self.held.lock().unwrap_or_else(|e| e.into_inner()) = Some((key, setups));
    }
}

impl Master {
    fn run_key(&self) -> RunKey {
        let s = self.status();
        (s.config_generation, s.recoveries, self.layout().slaves.len())
    }

    /// `items` of every slave `0..slaves`, slave by slave, at most
    /// [`READS_IN_FLIGHT`] queued at once.
    async fn numbers(&self, slaves: usize, items: &[SlaveInfoCode], call: Call) -> Result<Vec<u32>, EngineError> {
        // Collected first: a borrowing iterator would make the future
        // generic over lifetimes, which async handlers cannot be.
        let asked: Vec<(u8, SlaveInfoCode)> =
            (0..slaves).flat_map(|s| items.iter().map(move |&item| (s as u8, item))).collect();
        stream::iter(asked)
            .map(|(slave, item)| self.slave_number(slave, item, call))
            .buffered(READS_IN_FLIGHT)
            .try_collect()
            .await
    }

    /// Every slave's setup in this run: kept from the run's first listing
    /// ([`SetupCache`]), or read now.
    async fn setups(&self, slaves: usize, fresh: bool, call: Call) -> Result<Arc<[SlaveSetup]>, EngineError> {
        let key = self.run_key();
        if let Some(s) = self.slave_setups.get(key).filter(|_| !fresh) {
            return Ok(s);
        }
        let _reading = match call.deadline {
            Some(end) => tokio::time::timeout_at(end.into(), self.slave_setups.reading.lock())
                .await
                .map_err(|_| EngineError::Timeout)?,
            None => self.slave_setups.reading.lock().await,
        };
        // Read by the one this waited for.
        if let Some(s) = self.slave_setups.get(key).filter(|_| !fresh) {
            return Ok(s);
        }
        let n = self.numbers(slaves, &SETUP_ITEMS, call).await?;
        let setups: Arc<[SlaveSetup]> = n
            .chunks_exact(SETUP_ITEMS.len())
            .map(|v| SlaveSetup {
                alias: v[0],
                configured_address: v[1],
                dc_supported: v[2] != 0,
                dc_active: v[3] != 0,
                dc_cycle_ns: v[4],
                dc_shift_ns: v[5] as i32,
            })
            .collect();
        // Kept only if no new run began while they were read.
        if self.run_key() == key {
            self.slave_setups.put(key, Arc::clone(&setups));
        }
        Ok(setups)
    }

    /// The daemon's reader of each run's setups, for as long as it runs:
    /// once the network runs and its process image is out (the layout
    /// goes first), so that no listing waits for them. Waits on status
    /// and image changes; idle otherwise.
    pub async fn keep_slave_setups_read(self: Arc<Self>) {
        let mut status = self.watch_status();
        let mut images = self.watch_images();
        loop {
            let seen = status.borrow_and_update().key();
            let key = self.run_key();
            let due = self.status().phase == Phase::Running
                && key.2 > 0
                && self.current_image().is_some()
                && self.slave_setups.get(key).is_none();
            if due {
                if let Err(e) = self.setups(key.2, false, Call::daemon()).await {
                    tracing::debug!("slave addresses and clocks not read: {e}");
                }
            }
            tokio::select! {
                r = status.wait_for(|s| s.key() != seen) => if r.is_err() { return },
                r = images.changed() => if r.is_err() { return },
            }
        }
    }

    /// Slaves `0..slaves` as a listing shows them: state and AL status
    /// read live, the setup of this run ([`SlaveSetup`]); with
    /// `fresh_identity` (a scan), the identity and name read live too and
    /// the setup read again.
    pub(crate) async fn slave_readings(
        &self,
        slaves: usize,
        fresh_identity: bool,
        call: Call,
    ) -> Result<Vec<SlaveReading>, EngineError> {
        let setups = self.setups(slaves, fresh_identity, call).await?;
        let live = self.numbers(slaves, &LIVE_ITEMS, call).await?;
        let identities = if fresh_identity {
            let ids = self.numbers(slaves, &IDENTITY_ITEMS, call).await?;
            let names: Vec<String> = stream::iter(0..slaves)
                .map(|s| self.slave_name(s as u8, call))
                .buffered(READS_IN_FLIGHT)
                .try_collect()
                .await?;
            Some((ids, names))
        } else {
            None
        };
        Ok((0..slaves)
            .map(|i| {
                let setup = setups.get(i).copied().unwrap_or_default();
                let identity = identities.as_ref().map(|(ids, names)| {
                    let id = &ids[i * IDENTITY_ITEMS.len()..(i + 1) * IDENTITY_ITEMS.len()];
                    ((id[0], id[1], id[2]), names[i].clone())
                });
                SlaveReading {
                    state: EcatState::from_u8(live[i * LIVE_ITEMS.len()] as u8),
                    al_status: live[i * LIVE_ITEMS.len() + 1] as u16,
                    identity,
                    setup,
                }
            })
            .collect())
    }
}
