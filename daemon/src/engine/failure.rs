//! Why the network last stopped running, kept with its type: the bring-up
//! error itself (shared, since a port error cannot be copied) or the fault
//! that started a recovery. Front ends (status, the systemd notifier, the
//! daemon's exit) read it; none has to parse it back out of a sentence.

use std::fmt;
use std::sync::Arc;

use super::bringup::BringUpError;
use super::supervisor::RecoverCause;

/// The last failure of the network.
#[derive(Clone, Debug)]
pub enum Failure {
    /// Bring-up failed.
    BringUp(Arc<BringUpError>),
    /// A fault sent the running network back to bring-up.
    Recovery(RecoverCause),
}

impl Failure {
    /// Whether only a change of configuration can help (the link budget
    /// refuses the network, an axis is not mapped).
    pub fn is_permanent(&self) -> bool {
        matches!(self, Self::BringUp(e) if e.is_permanent())
    }

    /// The bring-up error, if that is what failed.
    pub fn bring_up(&self) -> Option<&BringUpError> {
        match self {
            Self::BringUp(e) => Some(e),
            Self::Recovery(_) => None,
        }
    }
}

/// Two bring-up failures are the same when they are one error or read the
/// same (a port error has no equality of its own).
impl PartialEq for Failure {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::BringUp(a), Self::BringUp(b)) => Arc::ptr_eq(a, b) || a.to_string() == b.to_string(),
            (Self::Recovery(a), Self::Recovery(b)) => a == b,
            _ => false,
        }
    }
}

impl Eq for Failure {}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BringUp(e) => write!(f, "bring-up: {e}"),
            Self::Recovery(why) => write!(f, "recovery: {why}"),
        }
    }
}
