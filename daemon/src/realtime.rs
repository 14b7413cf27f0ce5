//! Making the engine's thread real-time: SCHED_FIFO priority
//! (`thread-priority`), CPU affinity and `mlockall` (`nix`). Each step that
//! the system refuses (an unprivileged user, a container) is a warning, not
//! a failure: the daemon runs, with worse timing, and says so.

use thread_priority::{
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
    set_thread_priority_and_policy, thread_native_id,
};
use tracing::{info, warn};

use crate::config::RealtimeConfig;

/// What could be applied.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Applied {
    /// SCHED_FIFO set.
    pub priority: bool,
    /// Pinned to the CPU.
    pub affinity: bool,
    /// Memory locked.
    pub memory_locked: bool,
}

/// Applies `config` to the calling thread (and the process, for memory).
pub fn apply(config: &RealtimeConfig) -> Applied {
    let mut applied = Applied::default();
    if config.lock_memory {
        use nix::sys::mman::{MlockAllFlags, mlockall};
        match mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE) {
            Ok(()) => applied.memory_locked = true,
            Err(e) => {
                warn!(error = %e, "mlockall refused: pages may be swapped out (run with CAP_IPC_LOCK or LimitMEMLOCK=infinity)")
            }
        }
    }
    if let Some(cpu) = config.cpu {
        use nix::sched::{CpuSet, sched_setaffinity};
        use nix::unistd::Pid;
        let mut set = CpuSet::new();
        match set.set(cpu).and_then(|()| sched_setaffinity(Pid::from_raw(0), &set)) {
            Ok(()) => applied.affinity = true,
            Err(e) => warn!(error = %e, cpu, "CPU affinity refused"),
        }
    }
    if config.priority > 0 {
        let result = ThreadPriorityValue::try_from(config.priority).map_err(|e| format!("{e:?}")).and_then(|v| {
            set_thread_priority_and_policy(
                thread_native_id(),
                ThreadPriority::Crossplatform(v),
                ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
            )
            .map_err(|e| format!("{e:?}"))
        });
        match result {
            Ok(()) => applied.priority = true,
            Err(e) => {
                warn!(error = %e, priority = config.priority, "SCHED_FIFO refused: running without real-time priority (needs CAP_SYS_NICE or LimitRTPRIO)")
            }
        }
    }
    info!(?applied, "real-time settings");
    applied
}

/// The host's CLOCK_MONOTONIC in ns (what `Instant` reads on Linux), as a
/// number other processes on the host can compare with.
pub fn monotonic_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(t) => (t.tv_sec() as u64).saturating_mul(1_000_000_000).saturating_add(t.tv_nsec() as u64),
        Err(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_not_failures() {
        // Whatever this machine allows, applying must return, not panic.
        let a = apply(&RealtimeConfig { priority: 1, cpu: Some(0), lock_memory: false, spin_us: 0, host_stall_us: 0 });
        assert!(!a.memory_locked);
    }
}
