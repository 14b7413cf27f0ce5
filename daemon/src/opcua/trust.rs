//! Client certificates the administrator trusts (docs/opcua.md,
//! "Certificates"): any certificate file put in `pki/trusted/` (DER or
//! PEM, named as the administrator likes, e.g. `scada.der`), as OPC UA
//! tools and other servers take it.
//!
//! The stack looks a certificate up in `trusted/` under one name only (its
//! common name and thumbprint, the name it gives files in `rejected/`), so
//! moving a rejected file over works and copying `scada.der` there would
//! not. [`admit`] keeps a copy of each trusted certificate under that
//! name: the gate calls it when a client has said Hello, before its
//! connection reaches the stack, so a certificate put there while the
//! daemon runs counts from the next connection on, and nothing watches or
//! polls the folder in between. The administrator's files are left as
//! they are.

use std::path::Path;

use opcua::crypto::{CertificateStore, X509};
use tracing::{info, warn};

/// Gives every certificate in `dir` (`pki/trusted`) a copy under the
/// stack's name for it.
pub(super) fn admit(dir: &Path) {
    let Ok(files) = std::fs::read_dir(dir) else { return };
    for file in files.flatten() {
        let path = file.path();
        let Ok(bytes) = std::fs::read(&path) else { continue };
        let Some(cert) = certificate(&bytes) else { continue };
        let name = CertificateStore::cert_file_name(&cert);
        if path.file_name().is_some_and(|n| n == name.as_str()) || dir.join(&name).exists() {
            continue;
        }
        let Ok(der) = cert.to_der() else { continue };
        match std::fs::write(dir.join(&name), der) {
            Ok(()) => {
                info!(file = %path.display(), subject = %cert.subject_name(), "opcua: client certificate trusted")
            }
            Err(e) => warn!(file = %path.display(), "opcua: client certificate not taken: {e}"),
        }
    }
}

/// A certificate file's certificate, DER or PEM.
fn certificate(bytes: &[u8]) -> Option<X509> {
    X509::from_der(bytes).or_else(|_| X509::from_pem(bytes)).ok()
}
