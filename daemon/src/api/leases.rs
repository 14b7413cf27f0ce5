//! Output leases as the API shows them: the table itself is the master's
//! ([`crate::master::Leases`]); this maps a lease to its message and a
//! refusal to its code.

use ecmxf_proto::v1 as pb;
use tonic::Status;

use crate::master::{Lease, LeaseError};

/// The message of a lease.
pub(crate) fn to_pb(l: &Lease) -> pb::Lease {
    pb::Lease {
        id: l.id.clone(),
        slaves: l.slaves.iter().map(|&s| s.into()).collect(),
        ttl_ms: l.ttl.as_millis() as u32,
    }
}

/// The code of a refusal: another holder, a write outside the lease or
/// under no lease is PERMISSION_DENIED; an unknown id NOT_FOUND; a byte of
/// no slave INVALID_ARGUMENT (`offset`); the engine's own errors as usual.
pub(crate) fn status(e: LeaseError) -> Status {
    match e {
        LeaseError::Write(e) => super::status::to_status(e),
        LeaseError::NoSlave(_) => super::status::bad_argument("offset", e.to_string()),
        LeaseError::Unknown(_) => Status::not_found(e.to_string()),
        LeaseError::Held { .. }
        | LeaseError::NotALease(_)
        | LeaseError::NotOwned { .. }
        | LeaseError::NotHolder { .. } => Status::permission_denied(e.to_string()),
    }
}
