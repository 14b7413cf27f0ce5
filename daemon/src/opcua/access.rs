//! Who an OPC UA session is and what its user may do (docs/opcua.md,
//! "Users and roles"): the daemon's roles, as `[api]` gives them to gRPC
//! callers, from the session's user identity token.
//!
//! - Anonymous: `opcua.anonymous` (observer unless the file says
//!   otherwise; "none" refuses anonymous sessions).
//! - User name and password: `[[opcua.user]]`, the password checked
//!   against its SHA-256; offered on the encrypted endpoints only, so a
//!   password never travels in clear.
//! - X.509 user certificate: `[[opcua.certificate_user]]` by thumbprint
//!   (the stack has checked the token's signature with it).
//!
//! The role shapes what clients see before they try: output variables are
//! writable in a user's UserAccessLevel only from operator on, and methods
//! executable only for the role they need.

use std::collections::HashMap;

use async_trait::async_trait;
use opcua::crypto::{SecurityPolicy, Thumbprint};
use opcua::server::address_space::AccessLevel;
use opcua::server::authenticator::{
    AuthManager, CoreServerPermissions, Password, UserToken, user_pass_security_policy_id,
};
use opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerEndpoint};
use opcua::types::{Error, NodeId, StatusCode, UAString, UserTokenPolicy, UserTokenType};
use sha2::{Digest, Sha256};

use super::methods::Kind;
use crate::config::opcua::bare_hex;
use crate::config::{OpcuaConfig, Role};

/// The policy ids clients name in their identity tokens (the stack's own
/// for anonymous and certificate tokens).
const POLICY_ANONYMOUS: &str = "anonymous";
const POLICY_X509: &str = "x509";

/// The user token id every secure endpoint lists for named users (the
/// stack wants each id it is given to exist; who they are is decided
/// here, not by its table).
pub(super) const NAMED_USERS: &str = "named";

/// The roles of the server's users.
pub(crate) struct Access {
    anonymous: Option<Role>,
    /// By name: the SHA-256 of the password, lower-case hex.
    passwords: HashMap<String, String>,
    /// By lower-case hex SHA-1 thumbprint: the user's name.
    certificates: HashMap<String, String>,
    /// Roles by user name (the user token of a named user: what leases
    /// and the log call it).
    roles: HashMap<String, Option<Role>>,
}

impl Access {
    pub(super) fn new(config: &OpcuaConfig) -> Self {
        let mut passwords = HashMap::new();
        let mut certificates = HashMap::new();
        let mut roles = HashMap::new();
        for u in &config.users {
            passwords.insert(u.name.clone(), u.password_sha256.to_ascii_lowercase());
            roles.insert(u.name.clone(), u.role.role());
        }
        for u in &config.certificate_users {
            certificates.insert(bare_hex(&u.thumbprint), u.name.clone());
            roles.insert(u.name.clone(), u.role.role());
        }
        Self { anonymous: config.anonymous.role(), passwords, certificates, roles }
    }

    /// The role of a session's user (`None`: no access).
    pub(super) fn role(&self, token: &UserToken) -> Option<Role> {
        if token.is_anonymous() { self.anonymous } else { self.roles.get(&token.0).copied().flatten() }
    }

    /// Whether anonymous sessions are taken.
    pub(super) fn takes_anonymous(&self) -> bool {
        self.anonymous.is_some()
    }

    /// User `name`, once it proved who it is: refused with the role "none".
    fn admitted(&self, name: &str) -> Result<UserToken, Error> {
        match self.roles.get(name).copied().flatten() {
            Some(_) => Ok(UserToken(name.to_string())),
            None => Err(rejected(format!("user {name:?} has the role \"none\""))),
        }
    }
}

fn rejected(why: impl Into<String>) -> Error {
    Error::new(StatusCode::BadIdentityTokenRejected, why.into())
}

fn secure(endpoint: &ServerEndpoint) -> bool {
    endpoint.security_policy() != SecurityPolicy::None
}

/// Compares without stopping at the first difference, so the time taken
/// says nothing of how much of a guess was right.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

#[async_trait]
impl AuthManager for Access {
    async fn authenticate_anonymous_token(&self, endpoint: &ServerEndpoint) -> Result<(), Error> {
        if self.anonymous.is_none() || !endpoint.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID) {
            return Err(rejected("anonymous sessions are refused (opcua.anonymous = \"none\")"));
        }
        Ok(())
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        if !secure(endpoint) {
            return Err(rejected("a password is taken on the encrypted endpoints only"));
        }
        let given: String = Sha256::digest(password.get().as_bytes()).iter().map(|b| format!("{b:02x}")).collect();
        match self.passwords.get(username) {
            Some(hash) if same(hash.as_bytes(), given.as_bytes()) => self.admitted(username),
            _ => {
                tracing::warn!(user = username, "OPC UA session refused: unknown user or wrong password");
                Err(rejected(format!("cannot authenticate {username:?}")))
            }
        }
    }

    async fn authenticate_x509_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        signing_thumbprint: &Thumbprint,
    ) -> Result<UserToken, Error> {
        if !secure(endpoint) {
            return Err(rejected("a user certificate is taken on the encrypted endpoints only"));
        }
        match self.certificates.get(&signing_thumbprint.as_hex_string().to_ascii_lowercase()) {
            Some(name) => self.admitted(name),
            None => {
                tracing::warn!(
                    thumbprint = %signing_thumbprint.as_hex_string(),
                    "OPC UA session refused: a user certificate no [[opcua.certificate_user]] names"
                );
                Err(rejected("no [[opcua.certificate_user]] has this certificate's thumbprint"))
            }
        }
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = Vec::new();
        let policy = |id: UAString, token_type, uri: UAString| UserTokenPolicy {
            policy_id: id,
            token_type,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: uri,
        };
        if self.anonymous.is_some() && endpoint.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID) {
            policies.push(policy(POLICY_ANONYMOUS.into(), UserTokenType::Anonymous, UAString::null()));
        }
        if secure(endpoint) && endpoint.user_token_ids.contains(NAMED_USERS) {
            if !self.passwords.is_empty() {
                let id = user_pass_security_policy_id(endpoint);
                policies.push(policy(id, UserTokenType::UserName, UAString::null()));
            }
            if !self.certificates.is_empty() {
                let uri = UAString::from(endpoint.security_policy().to_uri());
                policies.push(policy(POLICY_X509.into(), UserTokenType::Certificate, uri));
            }
        }
        policies
    }

    fn effective_user_access_level(&self, token: &UserToken, level: AccessLevel, _node: &NodeId) -> AccessLevel {
        if self.role(token) >= Some(Role::Operator) { level } else { level - AccessLevel::CURRENT_WRITE }
    }

    fn is_user_executable(&self, token: &UserToken, method: &NodeId) -> bool {
        let name = method.identifier.to_string();
        let needs = Kind::all().find(|k| name.ends_with(&format!(".{}", k.name()))).map(|k| k.needs());
        match needs {
            Some(role) => self.role(token) >= Some(role),
            // The stack's own methods (GetMonitoredItems...).
            None => true,
        }
    }

    fn core_permissions(&self, token: &UserToken) -> CoreServerPermissions {
        CoreServerPermissions { read_diagnostics: self.role(token) >= Some(Role::Operator) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::api::RoleName;
    use crate::config::opcua::{OpcuaCertificateUser, OpcuaUser};

    fn access(anonymous: RoleName) -> Access {
        let mut c = OpcuaConfig::loopback();
        c.anonymous = anonymous;
        c.users.push(OpcuaUser {
            name: "op".into(),
            // printf %s secret | sha256sum
            password_sha256: "2bb80d537b1da3e38bd30361aa855686bde0eacd7162fef6a25fe97bf527a25b".into(),
            role: RoleName::Operator,
        });
        c.certificate_users.push(OpcuaCertificateUser {
            name: "plc".into(),
            thumbprint: ["0A"; 20].join(":"),
            role: RoleName::Admin,
        });
        Access::new(&c)
    }

    fn endpoint(policy: SecurityPolicy) -> ServerEndpoint {
        let ids = [ANONYMOUS_USER_TOKEN_ID.to_string(), NAMED_USERS.to_string()];
        ServerEndpoint::new("/", policy, opcua::types::MessageSecurityMode::SignAndEncrypt, &ids)
    }

    #[tokio::test]
    async fn a_password_names_its_user_on_an_encrypted_endpoint_only() {
        let a = access(RoleName::Observer);
        let secure = endpoint(SecurityPolicy::Basic256Sha256);
        let token = a.authenticate_username_identity_token(&secure, "op", &Password::new("secret".into())).await;
        assert_eq!(a.role(&token.unwrap()), Some(Role::Operator));
        let wrong = a.authenticate_username_identity_token(&secure, "op", &Password::new("secreT".into())).await;
        assert!(wrong.is_err());
        let plain = ServerEndpoint::new_none("/", &[ANONYMOUS_USER_TOKEN_ID.to_string(), NAMED_USERS.to_string()]);
        let clear = a.authenticate_username_identity_token(&plain, "op", &Password::new("secret".into())).await;
        assert!(clear.is_err(), "no password in clear");
        let offered: Vec<_> = a.user_token_policies(&plain).iter().map(|p| p.token_type).collect();
        assert_eq!(offered, [UserTokenType::Anonymous]);
        let offered: Vec<_> = a.user_token_policies(&secure).iter().map(|p| p.token_type).collect();
        assert_eq!(offered, [UserTokenType::Anonymous, UserTokenType::UserName, UserTokenType::Certificate]);
    }

    #[tokio::test]
    async fn a_certificate_is_its_thumbprint_and_anonymous_is_what_the_file_says() {
        let a = access(RoleName::None);
        let secure = endpoint(SecurityPolicy::Basic256Sha256);
        let t = a.authenticate_x509_identity_token(&secure, &Thumbprint::new(&[0x0A; 20])).await.unwrap();
        assert_eq!(a.role(&t), Some(Role::Admin));
        assert!(a.authenticate_x509_identity_token(&secure, &Thumbprint::new(&[0x0B; 20])).await.is_err());
        assert!(a.authenticate_anonymous_token(&secure).await.is_err());
        assert_eq!(a.role(&UserToken(ANONYMOUS_USER_TOKEN_ID.into())), None);
        let observer = access(RoleName::Observer);
        let anonymous = UserToken(ANONYMOUS_USER_TOKEN_ID.into());
        let level = AccessLevel::CURRENT_READ | AccessLevel::CURRENT_WRITE;
        let id = NodeId::new(2, "EtherCAT.Slaves.2.out.x");
        assert_eq!(
            observer.effective_user_access_level(&anonymous, level, &id).bits(),
            AccessLevel::CURRENT_READ.bits()
        );
        assert_eq!(observer.effective_user_access_level(&t, level, &id).bits(), level.bits());
        assert!(observer.is_user_executable(&anonymous, &NodeId::new(2, "EtherCAT.Slaves.2.SdoUpload")));
        assert!(!observer.is_user_executable(&anonymous, &NodeId::new(2, "EtherCAT.Slaves.2.SdoDownload")));
    }
}
