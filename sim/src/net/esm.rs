//! The EtherCAT state machine of one slave (ETG.1000.6 6.4; docs/protocol.md
//! §19): up one step at a time, down by any jump, BOOT only from
//! and back to INIT, refusals with the AL status code a real slave gives.

use std::fmt;

use ecmxf_wire::EcatState;

/// AL status code: no error.
pub const AL_OK: u16 = 0x0000;
/// Invalid requested state change.
pub const AL_INVALID_STATE_CHANGE: u16 = 0x0011;
/// Unknown requested state.
pub const AL_UNKNOWN_STATE: u16 = 0x0012;
/// Invalid mailbox configuration.
pub const AL_INVALID_MAILBOX: u16 = 0x0016;
/// Sync manager watchdog: outputs not refreshed in time.
pub const AL_SM_WATCHDOG: u16 = 0x001B;
/// Invalid output configuration.
pub const AL_INVALID_OUTPUTS: u16 = 0x001D;
/// Invalid input configuration.
pub const AL_INVALID_INPUTS: u16 = 0x001E;
/// Invalid DC sync configuration.
pub const AL_INVALID_DC_SYNC: u16 = 0x0030;
/// Invalid sync cycle time.
pub const AL_INVALID_SYNC_CYCLE: u16 = 0x0035;

pub use ecmxf_wire::al_status_text;

/// A slave's state (register 0x0130 bits 3..0).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AlState {
    /// 1.
    Init,
    /// 2.
    PreOp,
    /// 3.
    Boot,
    /// 4.
    SafeOp,
    /// 8.
    Op,
}

impl AlState {
    /// The AL state code.
    pub fn code(self) -> u8 {
        match self {
            Self::Init => 1,
            Self::PreOp => 2,
            Self::Boot => 3,
            Self::SafeOp => 4,
            Self::Op => 8,
        }
    }

    /// From the AL state code.
    pub fn from_code(v: u8) -> Option<Self> {
        match v {
            1 => Some(Self::Init),
            2 => Some(Self::PreOp),
            3 => Some(Self::Boot),
            4 => Some(Self::SafeOp),
            8 => Some(Self::Op),
            _ => None,
        }
    }

    /// As the chip reports it.
    pub fn to_ecat(self) -> EcatState {
        EcatState::from_u8(self.code())
    }

    /// Rank on the INIT < PRE-OP < SAFE-OP < OP ladder (BOOT beside INIT).
    fn rank(self) -> u8 {
        match self {
            Self::Init | Self::Boot => 0,
            Self::PreOp => 1,
            Self::SafeOp => 2,
            Self::Op => 3,
        }
    }
}

impl fmt::Display for AlState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Init => "INIT",
            Self::PreOp => "PREOP",
            Self::Boot => "BOOT",
            Self::SafeOp => "SAFEOP",
            Self::Op => "OP",
        })
    }
}

/// What a slave checks before it enters a state; the network supplies the
/// answers from its configuration.
pub trait TransitionCheck {
    /// `Err(al_code)` refuses entering `to` from `from`.
    fn check(&self, from: AlState, to: AlState) -> Result<(), u16>;
}

/// The state, the error indication and the AL status code (registers 0x0130
/// and 0x0134).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Esm {
    /// Current state.
    pub state: AlState,
    /// Error indication (0x0130 bit4).
    pub error: bool,
    /// AL status code.
    pub al_status: u16,
}

impl Default for Esm {
    fn default() -> Self {
        Self { state: AlState::Init, error: false, al_status: AL_OK }
    }
}

impl Esm {
    /// Handles an AL control request for `requested` (raw code). A request
    /// acknowledges a pending error. Returns whether the state was reached.
    pub fn request(&mut self, requested: u8, check: &dyn TransitionCheck) -> bool {
        self.error = false;
        self.al_status = AL_OK;
        let Some(to) = AlState::from_code(requested) else {
            return self.refuse(AL_UNKNOWN_STATE);
        };
        let from = self.state;
        if to == from {
            return true;
        }
        let allowed = match (from, to) {
            (AlState::Init, AlState::Boot) | (AlState::Boot, AlState::Init) => true,
            (AlState::Boot, _) | (_, AlState::Boot) => false,
            _ => to.rank() <= from.rank() || to.rank() == from.rank() + 1,
        };
        if !allowed {
            return self.refuse(AL_INVALID_STATE_CHANGE);
        }
        if to.rank() > from.rank() {
            if let Err(code) = check.check(from, to) {
                return self.refuse(code);
            }
        }
        self.state = to;
        true
    }

    /// A local error drops the slave to `to` with an AL status code (e.g. the
    /// SM watchdog: OP -> SAFE-OP + 0x001B).
    pub fn fail(&mut self, to: AlState, code: u16) {
        if to < self.state {
            self.state = to;
        }
        self.error = true;
        self.al_status = code;
    }

    fn refuse(&mut self, code: u16) -> bool {
        self.error = true;
        self.al_status = code;
        false
    }

    /// Register 0x0130 (AL status): state code | error bit4.
    pub fn al_status_register(&self) -> u16 {
        u16::from(self.state.code()) | if self.error { 0x10 } else { 0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Allow;
    impl TransitionCheck for Allow {
        fn check(&self, _: AlState, _: AlState) -> Result<(), u16> {
            Ok(())
        }
    }
    struct RefuseSafeOp;
    impl TransitionCheck for RefuseSafeOp {
        fn check(&self, _: AlState, to: AlState) -> Result<(), u16> {
            if to == AlState::SafeOp { Err(AL_INVALID_OUTPUTS) } else { Ok(()) }
        }
    }

    #[test]
    fn up_one_step_at_a_time() {
        let mut e = Esm::default();
        assert!(!e.request(8, &Allow));
        assert_eq!((e.state, e.error, e.al_status), (AlState::Init, true, AL_INVALID_STATE_CHANGE));
        assert!(!e.request(4, &Allow));
        assert!(e.request(2, &Allow) && !e.error);
        assert!(e.request(4, &Allow));
        assert!(e.request(8, &Allow));
        assert_eq!(e.al_status_register(), 8);
    }

    #[test]
    fn down_by_any_jump() {
        let mut e = Esm { state: AlState::Op, ..Esm::default() };
        assert!(e.request(1, &Allow));
        assert_eq!(e.state, AlState::Init);
        let mut e = Esm { state: AlState::Op, ..Esm::default() };
        assert!(e.request(2, &Allow));
    }

    #[test]
    fn boot_only_from_init() {
        let mut e = Esm { state: AlState::PreOp, ..Esm::default() };
        assert!(!e.request(3, &Allow));
        assert_eq!(e.al_status, AL_INVALID_STATE_CHANGE);
        let mut e = Esm::default();
        assert!(e.request(3, &Allow));
        assert!(!e.request(2, &Allow));
        assert!(e.request(1, &Allow));
    }

    #[test]
    fn unknown_state_and_refusals() {
        let mut e = Esm::default();
        assert!(!e.request(5, &Allow));
        assert_eq!(e.al_status, AL_UNKNOWN_STATE);
        assert_eq!(e.al_status_register(), 0x11);
        assert!(e.request(2, &RefuseSafeOp));
        assert!(!e.request(4, &RefuseSafeOp));
        assert_eq!((e.state, e.al_status), (AlState::PreOp, AL_INVALID_OUTPUTS));
    }

    #[test]
    fn watchdog_drops_to_safeop() {
        let mut e = Esm { state: AlState::Op, ..Esm::default() };
        e.fail(AlState::SafeOp, AL_SM_WATCHDOG);
        assert_eq!((e.state, e.error, e.al_status), (AlState::SafeOp, true, 0x001B));
        assert_eq!(e.al_status_register(), 0x14);
        assert_eq!(al_status_text(0x001B), "sync manager watchdog");
    }
}
