//! What the node reads of the daemon at one instant: owned copies of the
//! engine's published snapshots (status, layout, laid-out image, newest
//! input frame, output shadow) and the AL states slaves reported, that a
//! [`View`] borrows for the node's decisions. Nothing here waits for the
//! engine.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::master::EcatState;

use super::SharedStats;
use super::node::View;
use crate::master::image::Image;
use crate::master::{EventKind, Master, Phase};

/// Owned copies of what the node reads at one instant ([`View`] borrows
/// them).
pub(super) struct Seen {
    now_ms: u64,
    snapshot: crate::master::Snapshot,
    flowing: bool,
    health: String,
    layout: crate::master::NetworkLayout,
    image: Option<Arc<Image>>,
    inputs: Option<Arc<crate::master::InputFrame>>,
    inputs_ms: u64,
    outputs: Vec<u8>,
    cycle_us: u32,
    exchange_rate: f64,
}

/// SPI exchanges per second, over at least a second.
#[derive(Debug, Default)]
pub(super) struct RateMeter {
    last: Option<(u64, std::time::Instant)>,
    rate: f64,
}

impl RateMeter {
    /// The rate with the counter at `exchanges` at `now`: recomputed once a
    /// second has passed since the last sample it kept, else the last.
    pub(super) fn sample(&mut self, exchanges: u64, now: std::time::Instant) -> f64 {
        match self.last {
            Some((n, t)) if now.duration_since(t) >= Duration::from_secs(1) => {
                self.rate = exchanges.saturating_sub(n) as f64 / now.duration_since(t).as_secs_f64();
                self.last = Some((exchanges, now));
            }
            Some(_) => {}
            None => self.last = Some((exchanges, now)),
        }
        self.rate
    }
}

impl Seen {
    /// The daemon now, from its published snapshots.
    pub(super) fn now(m: &Master, meter: &mut RateMeter) -> Self {
        let snapshot = m.status();
        let exchange_rate = meter.sample(snapshot.exchanges, std::time::Instant::now());
        let verdict = m.verdict(&snapshot);
        let image = match m.current_image() {
            Some(Ok(image)) => Some(image),
            // Not laid out (no PDO source): devices still born, without
            // process data.
            Some(Err(_)) => Some(Arc::new(Image::default())),
            None => None,
        };
        let now = now_ms();
        let inputs = m.latest_inputs();
        // The frame's age on the engine's clock, taken off the wall clock.
        let inputs_ms =
            inputs.as_ref().map_or(now, |f| now.saturating_sub(m.now_ns().saturating_sub(f.time_ns) / 1_000_000));
        Self {
            now_ms: now,
            inputs_ms,
            snapshot,
            flowing: verdict.flowing(),
            health: verdict.health.word().into(),
            layout: m.layout(),
            image,
            inputs,
            outputs: m.output_shadow().clone(),
            cycle_us: m.config().cycle.sync0_us,
            exchange_rate,
        }
    }

    /// The view the node decides on.
    pub(super) fn view<'a>(&'a self, al: &'a BTreeMap<u8, (EcatState, u16)>, stats: &SharedStats) -> View<'a> {
        View {
            now_ms: self.now_ms,
            snapshot: &self.snapshot,
            flowing: self.flowing,
            health: &self.health,
            layout: &self.layout,
            image: self.image.as_ref(),
            inputs: self.inputs.as_ref().map_or(&[][..], |f| &f.data),
            inputs_ms: self.inputs_ms,
            outputs: &self.outputs,
            al,
            cycle_us: self.cycle_us,
            exchange_rate: self.exchange_rate,
            counts: super::counts(stats),
        }
    }
}

/// What births and deaths hang on in a snapshot.
pub(super) fn status_key(s: &crate::master::Snapshot) -> (Phase, EcatState, u64, u64, u64) {
    let (phase, state, generation, recoveries) = s.key();
    (phase, state, generation, recoveries, s.slaves)
}

/// Keeps the AL states slaves reported since the network last came up;
/// whether that changed anything.
pub(super) fn track_al(al: &mut BTreeMap<u8, (EcatState, u16)>, kind: &EventKind) -> bool {
    match kind {
        EventKind::AlStatus { slave, state, code } => al.insert(*slave, (*state, *code)) != Some((*state, *code)),
        EventKind::Phase(Phase::Running) | EventKind::Recovered { .. } => {
            let had = !al.is_empty();
            al.clear();
            had
        }
        EventKind::ProcessData { .. } | EventKind::EcatState { .. } => true,
        _ => false,
    }
}

/// The health in one or two words (the node metric `Engine/Health`).
pub(super) fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_is_taken_over_a_second_at_least() {
        let mut m = RateMeter::default();
        let t0 = std::time::Instant::now();
        assert_eq!(m.sample(100, t0), 0.0);
        assert_eq!(m.sample(5000, t0 + Duration::from_millis(500)), 0.0, "not a second yet");
        assert_eq!(m.sample(2100, t0 + Duration::from_secs(2)), 1000.0);
        assert_eq!(m.sample(2200, t0 + Duration::from_millis(2100)), 1000.0);
    }

    #[test]
    fn al_states_are_kept_until_the_network_runs_again() {
        let mut al = BTreeMap::new();
        let error = EventKind::AlStatus { slave: 1, state: EcatState::SafeOp, code: 0x001A };
        assert!(track_al(&mut al, &error));
        assert!(!track_al(&mut al, &error), "the same state again changes nothing");
        assert_eq!(al.get(&1), Some(&(EcatState::SafeOp, 0x001A)));
        assert!(track_al(&mut al, &EventKind::Phase(Phase::Running)));
        assert!(al.is_empty());
        assert!(!track_al(&mut al, &EventKind::FifoUnderrun));
    }
}
