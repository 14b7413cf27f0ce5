//! What the daemon's fixture-driven tests share.

use std::path::{Path, PathBuf};

/// ../shared/fixtures, or `None` (the test skips, saying so) when it is
/// missing, unless ECMXF_REQUIRE_FIXTURES is set (CI), where that fails.
pub fn fixtures() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures");
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(std::env::var_os("ECMXF_REQUIRE_FIXTURES").is_none(), "{} missing", dir.display());
    eprintln!("skipped: {} missing", dir.display());
    None
}
