//! `alias [-p POS] [--set N]` (IgH `ethercat alias`): the station alias in
//! each slave's SII EEPROM (word 4, ETG.1000.6 Table 2). Setting it writes
//! word 4 and the config area's checksum (word 7, low byte: CRC-8 over
//! words 0..=6, ETG.1000.6 Table 16) in one verified SII write, so the
//! slave does not reject its EEPROM at the next power-up; the ESC loads
//! the new alias into register 0x0012 then, not before.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Report, Table};

/// One slave's alias.
#[derive(Debug, Serialize, JsonSchema)]
pub struct AliasLine {
    pub position: u32,
    /// SII word 4 (after a --set: the value written).
    pub alias: u32,
    /// Before the --set (null without one).
    pub previous: Option<u32>,
    pub name: String,
}

/// `ecmxfctl alias --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct AliasReport {
    pub slaves: Vec<AliasLine>,
}

impl Report for AliasReport {
    fn text(&self) -> String {
        let mut t = Table::new(&["POS", "ALIAS", "NAME"]);
        let mut notes = String::new();
        for s in &self.slaves {
            t.row([s.position.to_string(), s.alias.to_string(), s.name.clone()]);
            if let Some(p) = s.previous {
                notes.push_str(&format!(
                    "slave {}: alias {p} -> {} written to the SII (checksum updated); the slave takes it at its next \
                     power-up\n",
                    s.position, s.alias
                ));
            }
        }
        format!("{t}{notes}")
    }
}

/// Reads the first `words` SII words of a slave.
async fn read_words(api: &Api, slave: u32, words: u32) -> Result<Vec<u8>, CliError> {
    let r = api.sii().read(api.req(pb::SiiReadRequest { slave, word: 0, count: words })).await;
    Ok(r.map_err(CliError::rpc(format!("read SII of slave {slave}")))?.into_inner().data)
}

/// Lists aliases, or sets one (`set`, with a position).
pub async fn run(api: &Api, position: Option<u32>, set: Option<u16>) -> Result<AliasReport, CliError> {
    if set.is_some() && position.is_none() {
        return Err(CliError::Usage("alias --set: give the slave with -p POS (aliases are unique)".into()));
    }
    let slaves = super::slaves::fetch(api, position, false).await?.slaves;
    let mut out = Vec::with_capacity(slaves.len());
    for s in slaves {
        let config = read_words(api, s.position, 8).await?;
        if config.len() < 16 {
            return Err(CliError::Usage(format!("slave {}: its SII config area is short", s.position)));
        }
        let current = u32::from(u16::from_le_bytes([config[8], config[9]]));
        let Some(alias) = set else {
            out.push(AliasLine { position: s.position, alias: current, previous: None, name: s.name });
            continue;
        };
        let mut image = config.clone();
        image[8..10].copy_from_slice(&alias.to_le_bytes());
        image[14] = ecmxf_devices::sii::config_checksum(&image[..14]);
        // Words 4..=7: the alias, two reserved words unchanged, the checksum.
        let req = pb::SiiWriteRequest { slave: s.position, word: 4, data: image[8..16].to_vec() };
        api.sii()
            .write(api.req_for(req, std::time::Duration::from_secs(2)))
            .await
            .map_err(CliError::rpc(format!("write the alias of slave {}", s.position)))?;
        out.push(AliasLine { position: s.position, alias: u32::from(alias), previous: Some(current), name: s.name });
    }
    Ok(AliasReport { slaves: out })
}
