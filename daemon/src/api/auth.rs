//! Who is calling and what they may do. Three roles, each including the
//! one below: observer (read-only), operator (process data, SDO writes,
//! states, CiA402, peripherals), admin (EEPROM writes, FoE, raw registers,
//! resets). Identity comes from, in order: a bearer token (`authorization:
//! Bearer ...`, any transport), a TLS client certificate (TCP), the Unix
//! peer's uid/gid (SO_PEERCRED). A TCP call with none is UNAUTHENTICATED; a
//! call above the caller's role is PERMISSION_DENIED naming both roles.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use sha2::{Digest, Sha256};
use tonic::transport::server::{TcpConnectInfo, TlsConnectInfo, UdsConnectInfo};
use tonic::{Request, Status};

use crate::config::api::ApiConfig;
pub(crate) use crate::config::api::Role;
use crate::master::Call;

/// A caller, as authenticated.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Caller {
    /// Their role.
    pub role: Role,
    /// Who, for logs and errors ("uid 1000", "token ci-robot").
    pub who: String,
    /// What the master needs of the call: the client, a stable number per
    /// peer (pid, or TCP address) so that one peer's requests take turns
    /// with others' on the chip's blocking slot; and the deadline, fixed
    /// once as an instant when the call is authorized, which every request
    /// and wait of the call then shares.
    pub call: Call,
    /// The time that deadline left when the call came (`grpc-timeout`,
    /// less a margin), for the message when it passes; `None` without one.
    pub budget: Option<Duration>,
    /// What identified them, to ask again after the rules change (a token
    /// revoked by a reload ends the caller's streams and leases).
    pub identity: Identity,
    /// The role the call was authorized for.
    pub needed: Role,
}

/// What identified a caller.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Identity {
    /// A bearer token, by the fingerprint of its secret.
    Token(String),
    /// A TLS client certificate, by its fingerprint.
    Certificate(String),
    /// A Unix peer (SO_PEERCRED).
    Unix {
        /// User.
        uid: u32,
        /// Primary group.
        gid: u32,
    },
}

/// The rules from `[api]`.
#[derive(Debug)]
pub(crate) struct Authenticator {
    own_uid: u32,
    users: HashMap<u32, Option<Role>>,
    groups: HashMap<u32, Option<Role>>,
    tokens: HashMap<String, (Option<Role>, String)>,
    certs: HashMap<String, (Option<Role>, String)>,
    default_role: Option<Role>,
}

fn fingerprint(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

impl Authenticator {
    /// The rules of `config`; `own_uid` (the daemon's) is always admin.
    pub(crate) fn new(config: &ApiConfig, own_uid: u32) -> Self {
        let fp = |list: &[crate::config::api::TokenRole]| {
            list.iter().map(|t| (t.sha256.to_ascii_lowercase(), (t.role.role(), t.name.clone()))).collect()
        };
        Self {
            own_uid,
            users: config.users.iter().map(|u| (u.uid, u.role.role())).collect(),
            groups: config.groups.iter().map(|g| (g.gid, g.role.role())).collect(),
            tokens: fp(&config.tokens),
            certs: fp(&config.client_certs),
            default_role: config.default_role.role(),
        }
    }

    /// Identifies the caller of `request`.
    pub(crate) fn identify<T>(&self, request: &Request<T>) -> Result<Caller, Status> {
        let call = Call::new(client_id(request), None);
        if let Some(value) = request.metadata().get("authorization") {
            let token = value
                .to_str()
                .ok()
                .and_then(|v| v.strip_prefix("Bearer "))
                .ok_or_else(|| Status::unauthenticated("the authorization header must be \"Bearer <token>\""))?;
            let fp = fingerprint(token.trim().as_bytes());
            return match self.tokens.get(&fp) {
                Some((Some(role), name)) => Ok(Caller {
                    role: *role,
                    who: format!("token {name}"),
                    call,
                    budget: None,
                    identity: Identity::Token(fp),
                    needed: Role::Observer,
                }),
                Some((None, name)) => Err(Status::permission_denied(format!("token {name} has no access"))),
                None => Err(Status::unauthenticated("unknown bearer token")),
            };
        }
        if let Some(tls) = request.extensions().get::<TlsConnectInfo<TcpConnectInfo>>() {
            if let Some(cert) = tls.peer_certs().and_then(|c| c.first().cloned()) {
                let fp = fingerprint(cert.as_ref());
                return match self.certs.get(&fp) {
                    Some((Some(role), name)) => Ok(Caller {
                        role: *role,
                        who: format!("certificate {name}"),
                        call,
                        budget: None,
                        identity: Identity::Certificate(fp),
                        needed: Role::Observer,
                    }),
                    Some((None, name)) => Err(Status::permission_denied(format!("certificate {name} has no access"))),
                    None => {
                        Err(Status::unauthenticated(format!("client certificate {fp} is not in [[api.client_cert]]")))
                    }
                };
            }
            return Err(Status::unauthenticated("TCP callers need a bearer token or a client certificate"));
        }
        if let Some(uds) = request.extensions().get::<UdsConnectInfo>() {
            let Some(cred) = uds.peer_cred else {
                return Err(Status::unauthenticated("the peer's credentials could not be read"));
            };
            let (uid, gid) = (cred.uid(), cred.gid());
            return match self.unix_role(uid, gid) {
                Some(role) => Ok(Caller {
                    role,
                    who: format!("uid {uid}"),
                    call,
                    budget: None,
                    identity: Identity::Unix { uid, gid },
                    needed: Role::Observer,
                }),
                None => Err(Status::permission_denied(format!("uid {uid} (gid {gid}) has no access"))),
            };
        }
        Err(Status::unauthenticated("no identity: connect through the Unix socket or with TLS"))
    }

    /// The role of a Unix peer: root and the daemon's own user are admin;
    /// then `[[api.user]]` by uid, `[[api.group]]` by gid, else
    /// `api.default_role`. `None`: no access.
    pub(crate) fn unix_role(&self, uid: u32, gid: u32) -> Option<Role> {
        if uid == 0 || uid == self.own_uid {
            Some(Role::Admin)
        } else if let Some(r) = self.users.get(&uid) {
            *r
        } else if let Some(r) = self.groups.get(&gid) {
            *r
        } else {
            self.default_role
        }
    }

    /// The role `identity` has under these rules (`None`: no access).
    pub(crate) fn role_of(&self, identity: &Identity) -> Option<Role> {
        match identity {
            Identity::Token(fp) => self.tokens.get(fp).and_then(|(role, _)| *role),
            Identity::Certificate(fp) => self.certs.get(fp).and_then(|(role, _)| *role),
            Identity::Unix { uid, gid } => self.unix_role(*uid, *gid),
        }
    }

    /// Identifies the caller and checks they have `needed`.
    pub(crate) fn authorize<T>(&self, request: &Request<T>, needed: Role) -> Result<Caller, Status> {
        let mut caller = self.identify(request)?;
        caller.budget = super::deadline(request)?;
        caller.call.deadline = caller.budget.map(|d| Instant::now() + d);
        caller.needed = needed;
        if caller.role < needed {
            return Err(Status::permission_denied(format!(
                "{} has role {}; this call needs {needed}",
                caller.who, caller.role
            )));
        }
        Ok(caller)
    }
}

fn client_id<T>(request: &Request<T>) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    if let Some(uds) = request.extensions().get::<UdsConnectInfo>() {
        uds.peer_cred.and_then(|c| c.pid()).hash(&mut h);
    } else if let Some(tls) = request.extensions().get::<TlsConnectInfo<TcpConnectInfo>>() {
        tls.get_ref().remote_addr().hash(&mut h);
    }
    // Zero means "no client" to the engine.
    h.finish() | 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::api::{GroupRole, RoleName, UserRole};

    #[test]
    fn unix_peers_get_roles_by_uid_then_gid_then_default() {
        let config = ApiConfig {
            users: vec![UserRole { uid: 1000, role: RoleName::Operator }, UserRole { uid: 1002, role: RoleName::None }],
            groups: vec![GroupRole { gid: 50, role: RoleName::Admin }],
            default_role: RoleName::Observer,
            ..ApiConfig::default()
        };
        let a = Authenticator::new(&config, 999);
        assert_eq!(a.unix_role(0, 0), Some(Role::Admin), "root");
        assert_eq!(a.unix_role(999, 7), Some(Role::Admin), "the daemon's own user");
        assert_eq!(a.unix_role(1000, 50), Some(Role::Operator), "uid wins over gid");
        assert_eq!(a.unix_role(1001, 50), Some(Role::Admin), "by group");
        assert_eq!(a.unix_role(1002, 50), None, "explicitly refused");
        assert_eq!(a.unix_role(1003, 7), Some(Role::Observer), "default");
        let closed = Authenticator::new(&ApiConfig { default_role: RoleName::None, ..ApiConfig::default() }, 999);
        assert_eq!(closed.unix_role(1003, 7), None);
    }

    #[test]
    fn requests_without_any_identity_are_unauthenticated() {
        let a = Authenticator::new(&ApiConfig::default(), 999);
        let e = a.authorize(&Request::new(()), Role::Observer).unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        let mut r = Request::new(());
        r.metadata_mut().insert("authorization", "Basic abc".parse().unwrap());
        assert_eq!(a.authorize(&r, Role::Observer).unwrap_err().code(), tonic::Code::Unauthenticated);
    }
}
