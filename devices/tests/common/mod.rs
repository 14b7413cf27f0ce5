//! What the fixture-driven tests of this crate share.

use std::path::PathBuf;

/// ../shared/fixtures, or `None` (the test says so and passes) when it is
/// absent, unless ECMXF_REQUIRE_FIXTURES is set (CI), where that fails.
pub fn fixtures() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures");
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(std::env::var_os("ECMXF_REQUIRE_FIXTURES").is_none(), "fixtures missing: {}", dir.display());
    eprintln!("skipped: {} not present", dir.display());
    None
}
