//! The ESI files the configuration names (`[[slave]] esi`), parsed once and
//! kept: a Beckhoff terminal family is megabytes of XML, and the process
//! image, `pdos` and `ListObjects` all ask for the same device. Also the
//! ENI (`eni = FILE`), whose slave entries describe their PDOs the way an
//! ESI does (names and types of the entries a slave maps).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use ecmxf_devices::eni::{Eni, EniError};
use ecmxf_devices::esi::{EsiDevice, EsiError, EsiFile};

use super::Master;

/// Parsed ESI files by path.
#[derive(Debug, Default)]
pub(crate) struct EsiLibrary {
    files: Mutex<HashMap<PathBuf, Arc<EsiFile>>>,
    enis: Mutex<HashMap<PathBuf, Arc<Eni>>>,
}

/// One device of a parsed ESI file.
#[derive(Clone, Debug)]
pub(crate) struct EsiRef {
    file: Arc<EsiFile>,
    at: usize,
}

impl EsiRef {
    /// The device.
    pub(crate) fn device(&self) -> &EsiDevice {
        &self.file.devices[self.at]
    }
}

/// Why a device description the configuration names cannot be used:
/// which file, and the cause with its type.
#[derive(Clone, Debug)]
pub(crate) enum DescriptionError {
    /// The file could not be read.
    Read {
        /// The file.
        path: PathBuf,
        /// The OS's error.
        error: Arc<std::io::Error>,
    },
    /// The ESI file does not parse, or has no device for the slave.
    Esi {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        error: EsiError,
    },
    /// The ESI is another vendor's.
    OtherVendor {
        /// The file.
        path: PathBuf,
        /// Its vendor.
        file: u32,
        /// The slave's.
        slave: u32,
    },
    /// The ENI does not parse.
    Eni {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        error: EniError,
    },
    /// The parsing thread stopped (panicked or was cancelled).
    Stopped(PathBuf),
}

impl std::fmt::Display for DescriptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Read { path, error } => write!(f, "ESI {}: {error}", path.display()),
            Self::Esi { path, error } => write!(f, "ESI {}: {error}", path.display()),
            Self::OtherVendor { path, file, slave } => {
                write!(f, "ESI {}: vendor {file:#010x}, the slave's is {slave:#010x}", path.display())
            }
            Self::Eni { path, error } => write!(f, "ENI {}: {error}", path.display()),
            Self::Stopped(path) => write!(f, "{}: parsing stopped", path.display()),
        }
    }
}

impl std::error::Error for DescriptionError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Read { error, .. } => Some(&**error),
            Self::Esi { error, .. } => Some(error),
            Self::Eni { error, .. } => Some(error),
            Self::OtherVendor { .. } | Self::Stopped(_) => None,
        }
    }
}

impl EsiLibrary {
    /// The file at `path`, parsed (on a blocking thread the first time).
    pub(crate) async fn file(&self, path: &Path) -> Result<Arc<EsiFile>, DescriptionError> {
        if let Some(f) = self.files.lock().unwrap_or_else(|e| e.into_inner()).get(path) {
            return Ok(Arc::clone(f));
        }
        let owned = path.to_path_buf();
        let parsed = tokio::task::spawn_blocking(move || {
            let xml = ecmxf_devices::esi::read_xml(&owned)
                .map_err(|e| DescriptionError::Read { path: owned.clone(), error: Arc::new(e) })?;
            EsiFile::parse(&xml).map_err(|error| DescriptionError::Esi { path: owned, error })
        })
        .await
        .map_err(|_| DescriptionError::Stopped(path.to_path_buf()))??;
        for skipped in &parsed.skipped {
            tracing::warn!(esi = %path.display(), "{skipped}");
        }
        let file = Arc::new(parsed);
        self.files.lock().unwrap_or_else(|e| e.into_inner()).insert(path.to_path_buf(), Arc::clone(&file));
        Ok(file)
    }

    /// The device of the file at `path` a slave with this identity is: of
    /// that product, the same revision, else the nearest lower, else the
    /// highest (`EsiFile::for_identity`).
    pub(crate) async fn device(
        &self,
        path: &Path,
        vendor: u32,
        product: u32,
        revision: u32,
    ) -> Result<EsiRef, DescriptionError> {
        let file = self.file(path).await?;
        if file.vendor_id != vendor {
            return Err(DescriptionError::OtherVendor {
                path: path.to_path_buf(),
                file: file.vendor_id,
                slave: vendor,
            });
        }
        // The rule bring-up chooses the init commands by, so names, types
        // and dictionary come from the device whose commands were written.
        let device = file.for_identity(product, revision).ok_or_else(|| DescriptionError::Esi {
            path: path.to_path_buf(),
            error: EsiError::NoSuchDevice { product_code: product, revision: Some(revision) },
        })?;
        let at = file.devices.iter().position(|d| std::ptr::eq(d, device)).unwrap_or(0);
        for w in &device.warnings {
            tracing::warn!(esi = %path.display(), device = %device.type_name, "{w}");
        }
        Ok(EsiRef { file, at })
    }
}

impl EsiLibrary {
    /// The ENI at `path`, parsed (on a blocking thread the first time).
    pub(crate) async fn eni(&self, path: &Path) -> Result<Arc<Eni>, DescriptionError> {
        if let Some(f) = self.enis.lock().unwrap_or_else(|e| e.into_inner()).get(path) {
            return Ok(Arc::clone(f));
        }
        let owned = path.to_path_buf();
        let parsed = tokio::task::spawn_blocking(move || {
            Eni::load(&owned).map_err(|error| DescriptionError::Eni { path: owned, error })
        })
        .await
        .map_err(|_| DescriptionError::Stopped(path.to_path_buf()))??;
        let eni = Arc::new(parsed);
        self.enis.lock().unwrap_or_else(|e| e.into_inner()).insert(path.to_path_buf(), Arc::clone(&eni));
        Ok(eni)
    }
}

impl Master {
    /// The device the configuration's ENI describes at `slave`'s place
    /// (its PDOs with names and types, no dictionary), when the
    /// configuration came from one and that entry has the slave's identity.
    pub(crate) async fn eni_device(&self, slave: u8) -> Option<EsiDevice> {
        let path = self.config.lock().unwrap_or_else(|e| e.into_inner()).eni.clone()?;
        let eni = match self.esi.eni(&path).await {
            Ok(e) => e,
            Err(e) => {
                tracing::warn!(slave, "{e}");
                return None;
            }
        };
        let found = self.layout().slaves.get(usize::from(slave)).cloned()?;
        let entry = eni.slaves.get(usize::from(slave))?;
        (entry.vendor_id == found.vendor_id && entry.product_code == found.product_code).then(|| entry.device())
    }

    /// The ESI device configured for `slave`, matched to the identity the
    /// slave reported: `None` when no ESI is configured for it.
    pub(crate) async fn esi_device(&self, slave: u8) -> Option<Result<EsiRef, DescriptionError>> {
        let path = {
            let config = self.config.lock().unwrap_or_else(|e| e.into_inner());
            config.slaves.get(usize::from(slave)).and_then(|c| c.esi.clone())?
        };
        let found = self.layout().slaves.get(usize::from(slave)).cloned()?;
        Some(self.esi.device(&path, found.vendor_id, found.product_code, found.revision).await)
    }
}
