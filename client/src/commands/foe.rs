//! `foe read|write`: files over EtherCAT (Foe service), with a progress bar
//! on a terminal. The chip stages files in its 256 KiB flash, so the bar
//! shows staging, then the transfer to the slave.

use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use indicatif::{ProgressBar, ProgressStyle};
use schemars::JsonSchema;
use serde::Serialize;
use tokio_stream::StreamExt;

use crate::cli::FoeCommand;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Out, Report};

/// `ecmxfctl foe read|write --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct FoeReport {
    pub slave: u32,
    /// "read" or "write".
    pub direction: String,
    /// File name on the slave.
    pub name: String,
    /// Local file.
    pub file: String,
    pub bytes: u32,
}

impl Report for FoeReport {
    fn text(&self) -> String {
        match self.direction.as_str() {
            "read" => format!("read {} ({} bytes) from slave {} into {}", self.name, self.bytes, self.slave, self.file),
            _ => format!("wrote {} ({} bytes) to slave {} as {}", self.file, self.bytes, self.slave, self.name),
        }
    }
}

fn bar(out: Out) -> ProgressBar {
    if out.json || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(0);
    b.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    b.enable_steady_tick(Duration::from_millis(120));
    b
}

/// Follows a progress stream to its end; the last message.
async fn follow(
    mut s: tonic::Streaming<pb::FoeProgress>,
    bar: &ProgressBar,
    action: &str,
) -> Result<pb::FoeProgress, CliError> {
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        let m = tokio::select! {
            m = s.next() => m,
            // Dropping the stream cancels the transfer in the daemon.
            _ = &mut ctrl_c => {
                bar.abandon_with_message("cancelled");
                return Err(CliError::rpc(action)(tonic::Status::cancelled("cancelled by Ctrl-C; the transfer was stopped")));
            }
        };
        match m {
            Some(Ok(p)) => {
                bar.set_length(u64::from(p.bytes_total));
                bar.set_position(u64::from(p.bytes_done));
                if p.done {
                    bar.finish_and_clear();
                    return Ok(p);
                }
            }
            Some(Err(st)) => {
                // A refusal before any byte moved leaves no bar behind.
                if bar.length().unwrap_or(0) == 0 {
                    bar.finish_and_clear();
                } else {
                    bar.abandon();
                }
                return Err(CliError::rpc(action)(st));
            }
            None => {
                bar.abandon();
                return Err(CliError::rpc(action)(tonic::Status::unavailable("the daemon ended the transfer early")));
            }
        }
    }
}

/// Runs a `foe` subcommand.
pub async fn run(api: &Api, out: Out, cmd: &FoeCommand) -> Result<(), CliError> {
    match cmd {
        FoeCommand::Read { slave, name, output, password, max_bytes } => {
            let slave = slave.position;
            let file = output.clone().unwrap_or_else(|| Path::new(name).file_name().unwrap_or(name.as_ref()).into());
            let action = format!("FoE read {name:?} from slave {slave}");
            let req = pb::FoeReadRequest { slave, name: name.clone(), password: *password, max_bytes: *max_bytes };
            let s = api.foe().read(api.transfer(req)).await.map_err(CliError::rpc(&action))?.into_inner();
            let b = bar(out);
            b.set_message(format!("reading {name}"));
            let last = follow(s, &b, &action).await?;
            std::fs::write(&file, &last.data).map_err(CliError::file(&file))?;
            out.report(&FoeReport {
                slave,
                direction: "read".into(),
                name: name.clone(),
                file: file.display().to_string(),
                bytes: last.data.len() as u32,
            })?;
        }
        FoeCommand::Write { slave, file, name, password } => {
            let slave = slave.position;
            let data = std::fs::read(file).map_err(CliError::file(file))?;
            let name = match name {
                Some(n) => n.clone(),
                None => file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
            };
            let action = format!("FoE write {name:?} to slave {slave}");
            let bytes = data.len() as u32;
            let req = pb::FoeWriteRequest { slave, name: name.clone(), password: *password, data };
            let s = api.foe().write(api.transfer(req)).await.map_err(CliError::rpc(&action))?.into_inner();
            let b = bar(out);
            b.set_message(format!("writing {name}"));
            follow(s, &b, &action).await?;
            out.report(&FoeReport { slave, direction: "write".into(), name, file: file.display().to_string(), bytes })?;
        }
    }
    Ok(())
}
