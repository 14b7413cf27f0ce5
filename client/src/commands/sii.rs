//! `sii read|write|dump|decode`: the slave's SII EEPROM (Sii.Read / Write /
//! Decode). Writes keep what they overwrite in a backup file and are
//! verified word by word by the daemon.

use std::io::{IsTerminal, Read as _, Write as _};
use std::path::PathBuf;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::cli::SiiCommand;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Out, Report, Table};
use crate::values::{Hex, parse_hex_bytes};

/// `ecmxfctl sii read --json` and `sii dump --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SiiDataReport {
    pub slave: u32,
    /// First word address.
    pub word: u32,
    /// Bytes (2 per word, little-endian words) as hex.
    pub data: Hex,
    /// Where the binary went (dump -o), else null.
    pub file: Option<String>,
    #[serde(skip)]
    #[schemars(skip)]
    bytes: Vec<u8>,
}

impl Report for SiiDataReport {
    fn text(&self) -> String {
        if let Some(f) = &self.file {
            return format!("slave {}: {} bytes of SII written to {f}", self.slave, self.bytes.len());
        }
        hexdump(2 * self.word as usize, &self.bytes)
    }
}

/// Classic hex dump: byte address, 16 bytes, printable ASCII.
pub fn hexdump(base: usize, b: &[u8]) -> String {
    let mut out = String::new();
    for (i, chunk) in b.chunks(16).enumerate() {
        let hexes: Vec<String> = chunk.iter().map(|x| format!("{x:02x}")).collect();
        let ascii: String = chunk.iter().map(|&x| if (0x20..0x7f).contains(&x) { x as char } else { '.' }).collect();
        out.push_str(&format!("{:06x}  {:<47}  {ascii}\n", base + 16 * i, hexes.join(" ")));
    }
    out
}

/// `ecmxfctl sii write --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SiiWriteReport {
    pub slave: u32,
    pub word: u32,
    /// Words written and verified.
    pub words_written: u32,
    /// The file holding what was there before.
    pub backup_file: String,
}

impl Report for SiiWriteReport {
    fn text(&self) -> String {
        format!(
            "slave {}: wrote and verified {} words at word {:#06x}; previous contents saved to {}",
            self.slave, self.words_written, self.word, self.backup_file
        )
    }
}

/// `ecmxfctl sii decode --json` (see SiiDecodeResponse in proto/ecmxf/v1/sdo.proto).
#[derive(Debug, Serialize, JsonSchema)]
pub struct SiiDecodeReport {
    pub slave: u32,
    pub vendor_id: u32,
    pub product_code: u32,
    pub revision: u32,
    pub serial: u32,
    pub checksum_ok: bool,
    pub name: String,
    pub group: String,
    pub order: String,
    pub size_bytes: u32,
    pub version: u32,
    /// Mailbox protocol names: AoE, EoE, CoE, FoE, SoE, VoE.
    pub mailbox_protocols: Vec<String>,
    pub mailbox: MailboxReport,
    pub bootstrap_mailbox: MailboxReport,
    pub ebus_current_ma: i32,
    pub strings: Vec<String>,
    /// FMMU usage codes.
    pub fmmu: Vec<u32>,
    pub sync_managers: Vec<SyncManagerReport>,
    pub rx_pdos: Vec<SiiPdoReport>,
    pub tx_pdos: Vec<SiiPdoReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct MailboxReport {
    pub rx_offset: u32,
    pub rx_size: u32,
    pub tx_offset: u32,
    pub tx_size: u32,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SyncManagerReport {
    pub start: u32,
    pub length: u32,
    pub control: u32,
    pub enable: u32,
    /// 1 mailbox out, 2 mailbox in, 3 process data out, 4 process data in.
    pub kind: u32,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SiiPdoReport {
    pub index: u32,
    /// 255: none.
    pub sync_manager: u32,
    pub name: String,
    pub entries: Vec<SiiPdoEntryReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SiiPdoEntryReport {
    pub index: u32,
    pub subindex: u32,
    pub name: String,
    /// CiA 301 data type code.
    pub data_type: u32,
    pub bit_length: u32,
}

fn mailbox(m: Option<pb::SiiMailbox>) -> MailboxReport {
    let m = m.unwrap_or_default();
    MailboxReport { rx_offset: m.rx_offset, rx_size: m.rx_size, tx_offset: m.tx_offset, tx_size: m.tx_size }
}

fn pdos(v: Vec<pb::SiiPdo>) -> Vec<SiiPdoReport> {
    v.into_iter()
        .map(|p| SiiPdoReport {
            index: p.index,
            sync_manager: p.sync_manager,
            name: p.name,
            entries: p
                .entries
                .into_iter()
                .map(|e| SiiPdoEntryReport {
                    index: e.index,
                    subindex: e.subindex,
                    name: e.name,
                    data_type: e.data_type,
                    bit_length: e.bit_length,
                })
                .collect(),
        })
        .collect()
}

fn protocols(bits: u32) -> Vec<String> {
    [(1, "AoE"), (2, "EoE"), (4, "CoE"), (8, "FoE"), (16, "SoE"), (32, "VoE")]
        .into_iter()
        .filter(|(b, _)| bits & b != 0)
        .map(|(_, n)| n.to_owned())
        .collect()
}

impl Report for SiiDecodeReport {
    fn text(&self) -> String {
        let mut f = Fields::default();
        let mb = |m: &MailboxReport| {
            format!("out {:#06x}+{}, in {:#06x}+{}", m.rx_offset, m.rx_size, m.tx_offset, m.tx_size)
        };
        f.add("Slave", self.slave)
            .add("Name", &self.name)
            .add("Group", &self.group)
            .add("Order", &self.order)
            .add("Vendor", format!("{:#010x}", self.vendor_id))
            .add("Product", format!("{:#010x}", self.product_code))
            .add("Revision", format!("{:#010x}", self.revision))
            .add("Serial", format!("{:#010x}", self.serial))
            .add("Checksum", if self.checksum_ok { "ok" } else { "BAD" })
            .add("EEPROM size", format!("{} bytes", self.size_bytes))
            .add("Version", self.version)
            .add("Mailbox", mb(&self.mailbox))
            .add("Bootstrap mailbox", mb(&self.bootstrap_mailbox))
            .add("Protocols", self.mailbox_protocols.join(" "))
            .add("E-bus current", format!("{} mA", self.ebus_current_ma))
            .add("FMMU", self.fmmu.iter().map(|u| u.to_string()).collect::<Vec<_>>().join(" "));
        let mut out = f.to_string();
        let mut sm = Table::new(&["SM", "START", "LENGTH", "CONTROL", "ENABLE", "KIND"]);
        for (i, s) in self.sync_managers.iter().enumerate() {
            let kind = match s.kind {
                1 => "mailbox out",
                2 => "mailbox in",
                3 => "outputs",
                4 => "inputs",
                _ => "unused",
            };
            sm.row([
                i.to_string(),
                format!("{:#06x}", s.start),
                s.length.to_string(),
                format!("{:#04x}", s.control),
                format!("{:#04x}", s.enable),
                kind.to_owned(),
            ]);
        }
        out.push('\n');
        out.push_str(&sm.to_string());
        for (dir, list) in [("RxPDO", &self.rx_pdos), ("TxPDO", &self.tx_pdos)] {
            for p in list {
                out.push_str(&format!("\n{dir} {:#06x} \"{}\" (SM {})\n", p.index, p.name, p.sync_manager));
                let mut t = Table::new(&["  OBJECT", "BITS", "NAME"]);
                for e in &p.entries {
                    t.row([format!("  {:#06x}:{:02x}", e.index, e.subindex), e.bit_length.to_string(), e.name.clone()]);
                }
                out.push_str(&t.to_string());
            }
        }
        if !self.strings.is_empty() {
            out.push_str("\nStrings:\n");
            for (i, s) in self.strings.iter().enumerate() {
                out.push_str(&format!("  {}: {s:?}\n", i + 1));
            }
        }
        out
    }
}

/// How long reading `words` may take at least: a word costs about 0.9 ms
/// on the chip (a full 4096-word EEPROM: 3.6 s, more than the default
/// `--timeout`), so twice that plus a second; a longer --timeout wins.
fn read_budget(words: u32) -> Duration {
    Duration::from_secs(1) + Duration::from_micros(1800) * words
}

/// Runs a `sii` subcommand and prints its result.
pub async fn run(api: &Api, out: Out, cmd: &SiiCommand) -> Result<(), CliError> {
    match cmd {
        SiiCommand::Read { slave, word, count } => {
            let slave = slave.position;
            let req = api.req_for(pb::SiiReadRequest { slave, word: *word, count: *count }, read_budget(*count));
            let r = api.sii().read(req).await;
            let data = r.map_err(CliError::rpc(format!("read SII of slave {slave}")))?.into_inner().data;
            out.report(&SiiDataReport { slave, word: *word, data: Hex::of(&data), file: None, bytes: data })?;
        }
        SiiCommand::Dump { slave, output } => {
            let slave = slave.position;
            let r = api.sii().decode(api.req_for(pb::SiiDecodeRequest { slave }, Duration::from_secs(20))).await;
            let image = r.map_err(CliError::rpc(format!("read SII of slave {slave}")))?.into_inner().image;
            let stdout = std::io::stdout();
            match output {
                Some(p) => {
                    std::fs::write(p, &image).map_err(CliError::file(p))?;
                    let file = Some(p.display().to_string());
                    out.report(&SiiDataReport { slave, word: 0, data: Hex::of(&image), file, bytes: image })?;
                }
                // Binary to a pipe or file, as `ethercat sii_read` does.
                None if !out.json && !stdout.is_terminal() => stdout.lock().write_all(&image)?,
                None => {
                    out.report(&SiiDataReport { slave, word: 0, data: Hex::of(&image), file: None, bytes: image })?
                }
            }
        }
        SiiCommand::Decode { slave } => {
            let slave = slave.position;
            let r = api.sii().decode(api.req_for(pb::SiiDecodeRequest { slave }, Duration::from_secs(20))).await;
            let d = r.map_err(CliError::rpc(format!("decode SII of slave {slave}")))?.into_inner();
            out.report(&SiiDecodeReport {
                slave,
                vendor_id: d.vendor_id,
                product_code: d.product_code,
                revision: d.revision,
                serial: d.serial,
                checksum_ok: d.checksum_ok,
                name: d.name,
                group: d.group,
                order: d.order,
                size_bytes: d.size_bytes,
                version: d.version,
                mailbox_protocols: protocols(d.mailbox_protocols),
                mailbox: mailbox(d.mailbox),
                bootstrap_mailbox: mailbox(d.bootstrap_mailbox),
                ebus_current_ma: d.ebus_current_ma,
                strings: d.strings,
                fmmu: d.fmmu,
                sync_managers: d
                    .sync_managers
                    .into_iter()
                    .map(|s| SyncManagerReport {
                        start: s.start,
                        length: s.length,
                        control: s.control,
                        enable: s.enable,
                        kind: s.kind,
                    })
                    .collect(),
                rx_pdos: pdos(d.rx_pdos),
                tx_pdos: pdos(d.tx_pdos),
            })?;
        }
        SiiCommand::Write { slave, file, hex, word, backup } => {
            let slave = slave.position;
            let data = match (file, hex) {
                (_, Some(h)) => parse_hex_bytes(h).map_err(|e| CliError::Usage(format!("--hex: {e}")))?,
                (Some(p), None) if p.as_os_str() == "-" => {
                    let mut b = Vec::new();
                    std::io::stdin().read_to_end(&mut b).map_err(CliError::file(p))?;
                    b
                }
                (Some(p), None) => std::fs::read(p).map_err(CliError::file(p))?,
                (None, None) => return Err(CliError::Usage("sii write: give a FILE or --hex".into())),
            };
            if data.is_empty() || data.len() % 2 != 0 || data.len() > 8192 {
                return Err(CliError::Usage(format!(
                    "sii write: {} bytes given; the SII is written in 16-bit words: an even number of bytes, 2..=8192",
                    data.len()
                )));
            }
            let backup_path = backup.clone().unwrap_or_else(|| {
                let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
                PathBuf::from(format!("sii-backup-{slave}-{}.bin", utc_stamp(t)))
            });
            let words_written = write_words(api, out, slave, *word, &data, &backup_path).await?;
            out.report(&SiiWriteReport {
                slave,
                word: *word,
                words_written,
                backup_file: backup_path.display().to_string(),
            })?;
        }
    }
    Ok(())
}

/// Words per Sii.Write call: progress shows between calls, about 1.6 s
/// apart on hardware (the EEPROM takes some 200 ms a word).
const WRITE_CHUNK_WORDS: usize = 8;

/// Writes `data` from `word` on: first the whole range's old contents
/// into `backup` (so it is complete even if a write fails part way, and
/// nothing is written if it cannot be kept), then the words in chunks
/// with a progress bar on a terminal. The words written.
async fn write_words(
    api: &Api,
    out: Out,
    slave: u32,
    word: u32,
    data: &[u8],
    backup: &std::path::Path,
) -> Result<u32, CliError> {
    let words = (data.len() / 2) as u32;
    let req = api.req_for(pb::SiiReadRequest { slave, word, count: words }, read_budget(words));
    let r = api.sii().read(req).await;
    let old = r.map_err(CliError::rpc(format!("read SII of slave {slave} for its backup")))?.into_inner().data;
    std::fs::write(backup, &old).map_err(CliError::file(backup))?;
    let bar = if out.json || !std::io::stderr().is_terminal() {
        indicatif::ProgressBar::hidden()
    } else {
        let b = indicatif::ProgressBar::new(u64::from(words));
        b.set_style(
            indicatif::ProgressStyle::with_template("writing SII [{bar:40}] {pos}/{len} words, eta {eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        b
    };
    let mut written = 0u32;
    for chunk in data.chunks(2 * WRITE_CHUNK_WORDS) {
        let at = word + written;
        let n = (chunk.len() / 2) as u64;
        let req =
            api.req_for(pb::SiiWriteRequest { slave, word: at, data: chunk.to_vec() }, Duration::from_millis(200 * n));
        match api.sii().write(req).await {
            Ok(r) => written += r.into_inner().words_written,
            Err(s) => {
                bar.abandon();
                return Err(CliError::rpc(format!(
                    "write SII of slave {slave} at word {at:#06x} ({written} of {words} words written and verified \
                     before it; {} holds the whole range as it was)",
                    backup.display()
                ))(s));
            }
        }
        bar.set_position(u64::from(written));
    }
    bar.finish_and_clear();
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hexdump_shows_addresses_bytes_and_ascii() {
        let d = hexdump(0x10, b"ECM-XF\x00\x01");
        assert_eq!(d, "000010  45 43 4d 2d 58 46 00 01                          ECM-XF..\n");
        assert_eq!(protocols(0x0C), vec!["CoE", "FoE"]);
    }
}

/// `secs` since the Unix epoch as an ISO 8601 basic UTC time,
/// `20261128T195300Z` (a file name sorts by it and says when).
fn utc_stamp(secs: u64) -> String {
    let (days, rest) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days (H. Hinnant's days_from_civil, inverted).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}{month:02}{day:02}T{:02}{:02}{:02}Z", rest / 3600, rest % 3600 / 60, rest % 60)
}

#[cfg(test)]
mod stamp_tests {
    #[test]
    fn utc_stamps_read_as_dates() {
        assert_eq!(super::utc_stamp(0), "19700101T000000Z");
        assert_eq!(super::utc_stamp(951_782_400), "20000229T000000Z");
        assert_eq!(super::utc_stamp(1_795_864_748), "20261128T111908Z");
    }
}
