//! The in-process simulator as a link, against the wall clock: simulated
//! time is the time since the link was made. The chip sits behind a mutex
//! only so tests and fault injection can reach it through [`SimHandle`];
//! the engine's thread is its only regular user.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ecmxf_sim::Chip;

use super::{Link, LinkError};

/// How much of a wait for the modelled chip is yielded rather than slept.
const SLEEP_MARGIN: Duration = Duration::from_micros(50);

/// The link.
#[derive(Debug)]
pub struct SimLink {
    shared: Arc<Shared>,
    int0: super::LevelChanges,
}

#[derive(Debug)]
struct Shared {
    chip: Mutex<Chip>,
    epoch: Instant,
}

impl Shared {
    fn now_ns(&self) -> u64 {
        self.epoch.elapsed().as_nanos() as u64
    }

    fn chip(&self) -> MutexGuard<'_, Chip> {
        // A panic elsewhere while holding the lock leaves a usable chip.
        self.chip.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Reaches the simulated chip from outside the engine: fault injection,
/// driving inputs, inspecting counters.
#[derive(Clone, Debug)]
pub struct SimHandle {
    shared: Arc<Shared>,
}

impl SimHandle {
    /// Runs `f` on the chip, brought up to now.
    pub fn with_chip<T>(&self, f: impl FnOnce(&mut Chip) -> T) -> T {
        let mut c = self.shared.chip();
        c.advance_to(self.shared.now_ns());
        f(&mut c)
    }

    /// A control command (see sim/README.md).
    pub fn control(&self, command: &str) -> Result<String, String> {
        self.with_chip(|c| ecmxf_sim::control::execute(c, command))
    }
}

impl SimLink {
    /// A link to `chip`, and a handle to it.
    pub fn new(chip: Chip) -> (Self, SimHandle) {
        let shared = Arc::new(Shared { chip: Mutex::new(chip), epoch: Instant::now() });
        (Self { shared: Arc::clone(&shared), int0: super::LevelChanges::default() }, SimHandle { shared })
    }
}

impl Link for SimLink {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        let now = self.shared.now_ns();
        let mut chip = self.shared.chip();
        chip.transfer(now, tx, rx);
        let after = self.shared.now_ns().max(chip.now_ns);
        self.int0.saw(chip.ready(after) && chip.faults.int0_stuck.is_none());
        Ok(())
    }

    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            let ready_in = {
                let mut c = self.shared.chip();
                let now = self.shared.now_ns();
                c.advance_to(now);
                if c.ready(now) && c.faults.int0_stuck.is_none() {
                    drop(c);
                    self.int0.saw(true);
                    return Ok(true);
                }
                if c.faults.int0_stuck.is_some() {
                    Duration::from_micros(100)
                } else {
                    Duration::from_nanos(c.ready_at().saturating_sub(now))
                }
            };
            let now = Instant::now();
            if now >= deadline {
                return Ok(false);
            }
            // Sleep through most of the wait (the modelled transfer and
            // processing: about 250 us for a 544-byte packet at 20 MHz), the
            // way a host blocks in the spidev ioctl, and yield for the last
            // stretch, which covers a sleep's usual overshoot. Yielding
            // through the whole wait made `ecmxfd --sim` idle at 41 % of a
            // core (perf: sched_yield).
            let left = ready_in.min(deadline - now);
            if left > SLEEP_MARGIN * 2 {
                std::thread::sleep(left - SLEEP_MARGIN);
            } else {
                std::thread::yield_now();
            }
        }
    }

    fn int1_active(&mut self) -> Result<bool, LinkError> {
        let now = self.shared.now_ns();
        let mut c = self.shared.chip();
        c.advance_to(now);
        Ok(c.int1_active())
    }

    fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
        Ok(Some(self.int0.count()))
    }

    fn clock_hz(&self) -> Option<u64> {
        Some(self.shared.chip().config.spi_hz)
    }

    fn describe(&self) -> String {
        "in-process simulator".into()
    }
}
