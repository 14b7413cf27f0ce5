//! Snapshots of `ecmxfctl`'s tables (insta): the text a user reads is part
//! of the interface, so a change to it shows up in review as a diff of
//! tests/tests/snapshots/. Live numbers (counters, FIFO levels, paths) are
//! redacted; everything else on the simulator is deterministic.
//! To accept an intended change: `INSTA_UPDATE=always cargo test -p ecmxf-e2e --test cli_snapshots`.

use ecmxf_e2e::{Daemon, TI_AXIS, run};

fn snap(d: &Daemon, name: &str, args: &[&str]) {
    let out = d.ctl(args).ok().to_owned();
    let mut settings = insta::Settings::clone_current();
    settings.set_snapshot_suffix(name);
    settings.set_description(format!("ecmxfctl {}", args.join(" ")));
    settings.set_omit_expression(true);
    // Counters and levels move while the bus runs.
    settings.add_filter(
        r"(?m)^(Exchanges|Transactions|Input frames|Output frames|CRC errors|WKC errors|Ring overflows|Process data|Corrupt answers|Not-ready answers|Input batches lost|FIFO alarms|Recoveries|Max FIFO gap|FIFO levels|Config generation):(\s+).*$",
        "$1:$2[live]",
    );
    // `domains`: the input age and the FIFO levels.
    settings.add_filter(r"input age [0-9.]+ ms", "input age [live] ms");
    settings.add_filter(r"WkcErrors [0-9]+", "WkcErrors [live]");
    settings.add_filter(r"FIFO rx [0-9]+/([0-9]+) tx [0-9]+", "FIFO rx [live]/$1 tx [live]");
    settings.bind(|| insta::assert_snapshot!("ecmxfctl", out));
}

#[test]
fn tables_read_as_they_did() {
    run(async {
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config("backend = \"sim\"", TI_AXIS));
        d.connect().await;
        snap(&d, "master", &["master"]);
        snap(&d, "slaves", &["slaves"]);
        snap(&d, "graph", &["graph"]);
        snap(&d, "slaves_verbose", &["slaves", "-v"]);
        snap(&d, "states", &["states"]);
        // The devices name their entries after the first image is out.
        let named = "process image entries named by their devices";
        assert!(d.logged(named, std::time::Duration::from_secs(10)).await, "{}", d.log());
        snap(&d, "pdos", &["pdos"]);
        snap(&d, "sdos", &["sdos", "-p", "2"]);
        snap(&d, "cstruct", &["cstruct", "-p", "2"]);
        snap(&d, "domains", &["domains"]);
        snap(&d, "debug", &["debug"]);
        snap(&d, "sii_decode", &["sii", "decode", "-p", "1"]);
        snap(&d, "sii_read", &["sii", "read", "-p", "1", "--count", "16"]);
        snap(&d, "upload", &["upload", "-p", "1", "0x6041"]);
        snap(&d, "cia402_status", &["cia402", "status"]);
        snap(&d, "reg_read", &["reg", "read", "-p", "0", "0x0130", "--type", "uint16"]);
        snap(&d, "gpio_get", &["gpio", "get"]);
        snap(&d, "emergencies", &["emergencies"]);
        d.stop();
    });
}

#[test]
fn help_reads_as_it_did() {
    let out = ecmxf_e2e::ctl(&["--help"]);
    insta::assert_snapshot!("help", out.ok());
}
