//! ecmxfd's hardware link (`link.backend = "spidev"`) on emulated kernel
//! devices: the preload library of sim/hw-emu stands in for
//! `/dev/spidev0.0` and `/dev/gpiochip0` and talks to a served simulator,
//! so the daemon runs the code a Raspberry Pi runs (spidev ioctls, GPIO v2
//! line requests and edge events) with nothing else changed.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use crate::{Simulator, repo};

/// The preload library of this build: `target/<profile>/deps/
/// libecmxf_hw_emu.so`, built fresh by `cargo test` (this package
/// dev-depends on ecmxf-hw-emu, whose lib is a cdylib and an rlib).
pub fn emu_library() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let mut dir = exe.parent().expect("target directory").to_path_buf();
    if !dir.ends_with("deps") {
        dir = dir.join("deps");
    }
    let lib = dir.join("libecmxf_hw_emu.so");
    if !lib.exists() {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let ok = Command::new(cargo).args(["build", "-p", "ecmxf-hw-emu"]).current_dir(repo()).status();
        assert!(ok.is_ok_and(|s| s.success()), "building ecmxf-hw-emu failed");
    }
    assert!(lib.exists(), "{} not built", lib.display());
    lib
}

/// The environment that puts a process on the emulated devices of `sim`,
/// wired as config/ecmxfd-rpi.toml says, plus `more` (faults:
/// `ECMXF_EMU_DENY`, `ECMXF_EMU_MISO`, `ECMXF_EMU_FORCE_MODE`).
pub fn emulation(sim: &Simulator, more: &[(&str, &str)]) -> Vec<(String, OsString)> {
    let mut env = vec![
        ("LD_PRELOAD".to_string(), emu_library().into_os_string()),
        ("ECMXF_SIM_SOCKET".to_string(), sim.socket.clone().into_os_string()),
    ];
    env.extend(more.iter().map(|(k, v)| (k.to_string(), OsString::from(v))));
    env
}

/// The `[link]` table of config/ecmxfd-rpi.toml, as the file has it (the
/// lines between `[link]` and the next table).
pub fn rpi_link() -> String {
    let text = std::fs::read_to_string(repo().join("config/ecmxfd-rpi.toml")).expect("config/ecmxfd-rpi.toml");
    let start = text.find("[link]\n").expect("a [link] table") + "[link]\n".len();
    let end = text[start..].find("\n[").map_or(text.len(), |e| start + e + 1);
    text[start..end].to_string()
}

/// Which daemon binary runs on the emulated hardware.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Build {
    /// `target/<profile>/ecmxfd` as `cargo test` builds it (with the
    /// simulator linked in, unused here).
    Default,
    /// `cargo build -p ecmxfd --no-default-features`: no simulator in it,
    /// as the hardware .deb ships it.
    NoSim,
}

impl Build {
    /// The binary.
    pub fn binary(self) -> PathBuf {
        match self {
            Self::Default => crate::daemon_binary(),
            Self::NoSim => no_sim_daemon(),
        }
    }
}

/// The daemon built without the simulator, as `target/<profile>/ecmxfd-no-sim`.
/// Built once per test process: cargo puts it where the default build's
/// binary is, so it is copied aside and the default one put back (both
/// stay in cargo's cache: later runs only copy). Callers hold
/// [`crate::SERIAL`], so no other test starts the binary meanwhile.
pub fn no_sim_daemon() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            let default = crate::daemon_binary();
            let aside = default.with_file_name("ecmxfd-no-sim");
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let profile: &[&str] = if cfg!(debug_assertions) { &[] } else { &["--release"] };
            let build = |features: &[&str]| {
                let out = Command::new(&cargo)
                    .args(["build", "-p", "ecmxfd", "--bin", "ecmxfd"])
                    .args(features)
                    .args(profile)
                    .current_dir(repo())
                    .output()
                    .expect("run cargo build");
                assert!(out.status.success(), "cargo build {features:?}: {}", String::from_utf8_lossy(&out.stderr));
            };
            build(&["--no-default-features"]);
            std::fs::copy(&default, &aside).expect("copy the no-sim daemon aside");
            build(&[]);
            let version = Command::new(&aside).arg("--version").output().expect("run ecmxfd-no-sim");
            assert!(version.status.success(), "ecmxfd-no-sim --version");
            aside
        })
        .clone()
}
