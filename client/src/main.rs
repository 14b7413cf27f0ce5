//! `ecmxfctl`: see the library for the map of modules.
#![forbid(unsafe_code)]

use std::process::ExitCode;

use clap::Parser;
use ecmxfctl::cli::Cli;
use ecmxfctl::error::CliError;

fn main() -> ExitCode {
    let cli = Cli::parse();
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
