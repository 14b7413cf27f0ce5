//! `ecmxfctl`: see the library for the map of modules.
#![forbid(unsafe_code)]

use std::process::ExitCode;

use clap::Parser;
use clap::error::ErrorKind;
use ecmxfctl::cli::{Cli, split_object_address};
use ecmxfctl::error::CliError;

fn main() -> ExitCode {
    let args = split_object_address(std::env::args_os().collect());
    let cli = match Cli::try_parse_from(&args) {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e, &args),
    };
    let json = cli.json;
    let rt = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("ecmxfctl: cannot start: {e}");
            return ExitCode::from(ecmxfctl::error::exit::FAILED);
        }
    };
    match rt.block_on(ecmxfctl::run(cli)) {
        Ok(()) => ExitCode::SUCCESS,
        // `ecmxfctl ... | head` closing the pipe is not an error.
        Err(CliError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            if json {
                let r = ecmxfctl::ErrorReport::of(&e);
                eprintln!("{}", serde_json::to_string(&r).unwrap_or_default());
            } else {
                eprintln!("ecmxfctl: {e}");
                for (k, v) in e.details() {
                    eprintln!("  {k}: {v}");
                }
                if let Some(h) = e.hint() {
                    eprintln!("  hint: {h}");
                }
            }
            ExitCode::from(e.exit_code())
        }
    }
}

/// A command line clap refused: with `--json` the JSON error object
/// (kind USAGE, exit code 2) that scripts parse, as for every other error;
/// else clap's own text. Help and version requests print as clap does.
fn usage_error(e: &clap::Error, args: &[std::ffi::OsString]) -> ExitCode {
    let json = args.iter().skip(1).take_while(|a| *a != "--").any(|a| a == "--json");
    if !json || matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
        e.exit();
    }
    let text = e.render().to_string();
    // clap's text: "error: what\n\nUsage: ...\n\nFor more information, try '--help'."
    let mut parts = text.split("\n\n").map(str::trim);
    let message = parts.next().unwrap_or_default().trim_start_matches("error: ").replace("\n ", "");
    let usage = parts.find(|p| p.starts_with("Usage: "));
    let report = ecmxfctl::ErrorReport::usage(message, usage);
    eprintln!("{}", serde_json::to_string(&report).unwrap_or_default());
    ExitCode::from(ecmxfctl::error::exit::USAGE)
}
