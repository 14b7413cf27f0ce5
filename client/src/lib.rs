//! `ecmxfctl`: command-line diagnostics for ecmxfd, a thin client of the
//! `ecmxf.v1` gRPC API.
//!
//! - [`cli`]: the command line (clap), source of completions and man pages.
//! - [`connect`]: Unix socket or TCP+TLS, token or client certificate.
//! - [`commands`]: one module per command, each with its report types.
//! - [`top`]: the live terminal view.
//! - [`output`]: tables or JSON from the same report value.
//! - [`schema`]: the JSON schemas of every report.
//! - [`values`]: names and number formats shared by all commands.
//! - [`error`]: errors, messages and exit codes.
#![forbid(unsafe_code)]

pub mod cli;
pub mod commands;
pub mod connect;
pub mod error;
pub mod output;
pub mod schema;
pub mod top;
pub mod values;

use clap::CommandFactory;

use cli::{Cli, Command};
use commands::{
    alias, cia402, config, crc, cstruct, data, debug, diag, domains, foe, graph, master, pdo, peripherals, reg, sdo,
    sii, slaves, states, version,
};
use error::CliError;
// Defined beside the errors it reports; named here by the binary.
pub use error::{ErrorBody, ErrorReport};
use output::Out;

/// Runs a parsed command line.
pub async fn run(cli: Cli) -> Result<(), CliError> {
    let out = Out { json: cli.json };
    // Commands that need no daemon.
    match &cli.command {
        Command::Completions { shell } => {
            clap_complete::generate(*shell, &mut Cli::command(), "ecmxfctl", &mut std::io::stdout());
            return Ok(());
        }
        Command::Man { dir } => return write_man_pages(dir),
        Command::NotCarried { .. } => {
            let verb = std::env::args().skip(1).find(|a| ["eoe", "soe", "ip"].contains(&a.as_str()));
            return Err(CliError::Usage(format!(
                "`{}`: the ECM-XF speaks the CoE and FoE mailbox protocols only: no EoE (so no `ip` \
                 settings) and no SoE; reach a slave's mailbox with upload, download and sdos (CoE) or foe",
                verb.unwrap_or_else(|| "eoe".into())
            )));
        }
        Command::Xml { .. } => {
            return Err(CliError::Usage(
                "`xml`: the network's description as an ETG.2100 file ecmxfd takes back is `ecmxfctl config \
                 --format eni` (slaves, PDOs, init commands, DC, process image); `ecmxfctl config` writes it as an \
                 ecmxfd configuration"
                    .into(),
            ));
        }
        Command::JsonSchema { command } => {
            let doc = schema::document();
            let v = if command.is_empty() {
                doc
            } else {
                let name = command.join(" ");
                doc["commands"].get(&name).cloned().ok_or_else(|| {
                    let names: Vec<&str> = schema::all().iter().map(|(n, _)| *n).collect();
                    CliError::Usage(format!("no schema for {name:?}; commands: {}", names.join(", ")))
                })?
            };
            println!("{}", serde_json::to_string_pretty(&v).map_err(std::io::Error::other)?);
            return Ok(());
        }
        _ => {}
    }
    let api = connect::connect(&cli.connect, cli.timeout).await?;
    match &cli.command {
        Command::Master => out.report(&master::fetch(&api).await?)?,
        Command::Slaves { position, verbose, scan } => {
            let mut r = slaves::fetch(&api, *position, *scan).await?;
            r.verbose = *verbose;
            out.report(&r)?;
        }
        Command::States { args, position, no_wait } => {
            let args: Vec<String> = position.iter().map(u32::to_string).chain(args.iter().cloned()).collect();
            out.report(&states::run(&api, &args, *no_wait).await?)?
        }
        Command::Upload(u) => out.report(&sdo::upload(&api, u).await?)?,
        Command::Download(d) => out.report(&sdo::download(&api, d).await?)?,
        Command::Sdos { slave, source } => out.report(&sdo::sdos(&api, slave.position, *source).await?)?,
        Command::Sii(c) => sii::run(&api, out, c).await?,
        Command::Pdos { position } => out.report(&pdo::fetch(&api, *position).await?)?,
        Command::Data { entries, variables, raw } => {
            let names: Vec<String> = entries.iter().chain(variables).cloned().collect();
            out.report(&data::data(&api, &names, *raw).await?)?
        }
        Command::Watch(w) => data::watch(&api, out, w).await?,
        Command::Cia402(c) => cia402::run(&api, out, c).await?,
        Command::Gpio(c) => peripherals::gpio(&api, out, c).await?,
        Command::Adc { differential } => out.report(&peripherals::adc(&api, *differential).await?)?,
        Command::Dac { value } => out.report(&peripherals::dac(&api, *value).await?)?,
        Command::Qei { action } => out.report(&peripherals::qei(&api, *action).await?)?,
        Command::Foe(c) => foe::run(&api, out, c).await?,
        Command::Reg(c) => reg::run(&api, out, c).await?,
        Command::Emergencies { count } => out.report(&diag::emergencies(&api, *count).await?)?,
        Command::Events { count, duration } => diag::events(&api, out, *count, *duration).await?,
        Command::Diag => {
            let r = diag::diag(&api).await?;
            out.report(&r)?;
            if !r.healthy {
                return Err(CliError::Unhealthy(format!("{} problem(s) found", r.problems.len())));
            }
        }
        Command::Top(t) => top::run(&api, out, t).await?,
        Command::Rescan => out.report(&slaves::rescan(&api).await?)?,
        Command::Graph => out.report(&graph::fetch(&api).await?)?,
        Command::Config { format } => out.report(&config::fetch(&api, *format).await?)?,
        Command::Crc { position, reset } => out.report(&crc::run(&api, *position, *reset).await?)?,
        Command::Alias { position, set } => out.report(&alias::run(&api, *position, *set).await?)?,
        Command::Cstruct { position } => out.report(&cstruct::fetch(&api, *position).await?)?,
        Command::Domains { verbose } => out.report(&domains::fetch(&api, *verbose).await?)?,
        Command::Debug { level } => out.report(&debug::run(&api, level.as_deref()).await?)?,
        Command::Version => out.report(&version::fetch(&api).await?)?,
        Command::Completions { .. }
        | Command::Man { .. }
        | Command::JsonSchema { .. }
        | Command::NotCarried { .. }
        | Command::Xml { .. } => {}
    }
    Ok(())
}

fn write_man_pages(dir: &std::path::Path) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(CliError::file(dir))?;
    let cmd = Cli::command();
    let mut written = Vec::new();
    let mut page = |c: &clap::Command, name: String| -> Result<(), CliError> {
        let path = dir.join(format!("{name}.1"));
        let mut buf = Vec::new();
        clap_mangen::Man::new(c.clone().name(name.clone())).render(&mut buf).map_err(CliError::Output)?;
        std::fs::write(&path, buf).map_err(CliError::file(&path))?;
        written.push(path);
        Ok(())
    };
    page(&cmd, "ecmxfctl".into())?;
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        page(sub, format!("ecmxfctl-{}", sub.get_name()))?;
    }
    for p in written {
        println!("{}", p.display());
    }
    Ok(())
}
