//! TLS for `mqtts://` brokers: rustls on ring (the provider tonic uses
//! here), the CA from `sparkplug.ca_file` or the system's roots, and a
//! client certificate where the broker asks for one. Built once at start,
//! so a certificate that does not parse stops the daemon with its name.

use std::path::Path;
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

use crate::config::SparkplugConfig;

/// The rustls client configuration for `config`'s mqtts:// brokers
/// (`None`: no broker uses TLS).
pub(super) fn client_config(config: &SparkplugConfig) -> Result<Option<Arc<rustls::ClientConfig>>, String> {
    if !config.broker.iter().any(|b| b.tls) {
        return Ok(None);
    }
    let mut roots = rustls::RootCertStore::empty();
    match &config.ca_file {
        Some(path) => {
            for cert in certificates(path, "sparkplug.ca_file")? {
                roots.add(cert).map_err(|e| format!("sparkplug.ca_file {}: {e}", path.display()))?;
            }
        }
        None => {
            let found = rustls_native_certs::load_native_certs();
            for cert in found.certs {
                // A system root rustls cannot use is skipped, as browsers do.
                let _ = roots.add(cert);
            }
            if roots.is_empty() {
                return Err("sparkplug: no system CA certificates found; set sparkplug.ca_file".into());
            }
        }
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("sparkplug TLS: {e}"))?
        .with_root_certificates(roots);
    let config = match (&config.client_cert, &config.client_key) {
        (Some(cert), Some(key)) => {
            let chain = certificates(cert, "sparkplug.client_cert")?;
            let key = PrivateKeyDer::from_pem_file(key)
                .map_err(|e| format!("sparkplug.client_key {}: {e}", key.display()))?;
            builder.with_client_auth_cert(chain, key).map_err(|e| format!("sparkplug.client_cert: {e}"))?
        }
        _ => builder.with_no_client_auth(),
    };
    Ok(Some(Arc::new(config)))
}

fn certificates(path: &Path, key: &str) -> Result<Vec<CertificateDer<'static>>, String> {
    let certs = CertificateDer::pem_file_iter(path)
        .and_then(|i| i.collect::<Result<Vec<_>, _>>())
        .map_err(|e| format!("{key} {}: {e}", path.display()))?;
    if certs.is_empty() {
        return Err(format!("{key} {}: no PEM certificate in it", path.display()));
    }
    Ok(certs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(extra: &str) -> SparkplugConfig {
        let text = format!("broker = \"mqtts://b\"\ngroup_id = \"g\"\n{extra}");
        toml::from_str(&text).unwrap()
    }

    #[test]
    fn certificate_files_that_do_not_load_are_named() {
        let dir = std::env::temp_dir().join(format!("ecmxf-spb-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let junk = dir.join("junk.pem");
        std::fs::write(&junk, "not a certificate\n").unwrap();
        let e = client_config(&config(&format!("ca_file = \"{}\"", junk.display()))).unwrap_err();
        assert!(e.contains("sparkplug.ca_file") && e.contains("junk.pem") && e.contains("no PEM certificate"), "{e}");
        let plain: SparkplugConfig = toml::from_str("broker = \"mqtt://b\"\ngroup_id = \"g\"").unwrap();
        assert!(client_config(&plain).unwrap().is_none(), "no TLS without an mqtts:// broker");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
