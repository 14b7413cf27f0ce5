//! `states [SLAVE] [STATE]`: show the EtherCAT state of the network or a
//! slave, or request one (State.GetState / SetState with wait).

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::commands::slaves::al_status;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Report, Table};
use crate::values::{parse_state, state_name};

/// `ecmxfctl states --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct StatesReport {
    /// The slave asked about (null: the whole network).
    pub slave: Option<u32>,
    /// The state now (network: its lowest). INIT, PREOP, BOOT, SAFEOP, OP, ERROR, UNKNOWN.
    pub state: String,
    /// The state requested (null: only shown).
    pub requested: Option<String>,
    /// Per slave (whole network only).
    pub slaves: Vec<SlaveStateReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SlaveStateReport {
    pub position: u32,
    pub state: String,
    pub al_status_code: u32,
    pub al_status_text: String,
}

impl Report for StatesReport {
    fn text(&self) -> String {
        let who = self.slave.map_or("network".to_owned(), |s| format!("slave {s}"));
        let mut out = match &self.requested {
            Some(r) => format!("{who}: requested {r}, now {}\n", self.state),
            None => format!("{who}: {}\n", self.state),
        };
        if !self.slaves.is_empty() {
            let mut t = Table::new(&["POS", "STATE", "AL STATUS"]);
            for s in &self.slaves {
                t.row([s.position.to_string(), s.state.clone(), al_status(s.al_status_code, &s.al_status_text)]);
            }
            out.push_str(&t.to_string());
        }
        out
    }
}

/// Sorts the positional words: a number is the slave, a word the state.
fn split(args: &[String]) -> Result<(Option<u32>, Option<pb::EcatState>), CliError> {
    let mut slave = None;
    let mut state = None;
    for (i, a) in args.iter().enumerate() {
        if let (0, Ok(n)) = (i, a.parse::<u32>()) {
            slave = Some(n);
        } else if let Some(s) = parse_state(a).filter(|_| state.is_none()) {
            state = Some(s);
        } else {
            return Err(CliError::Usage(format!(
                "states: {a:?} is neither a slave position (first) nor a state (init, preop, boot, safeop, op)"
            )));
        }
    }
    Ok((slave, state))
}

/// Shows or requests.
pub async fn run(api: &Api, args: &[String], no_wait: bool) -> Result<StatesReport, CliError> {
    let (slave, want) = split(args)?;
    let mut requested = None;
    if let Some(st) = want {
        let who = slave.map_or("all slaves".to_owned(), |s| format!("slave {s}"));
        let action = format!("request {} for {who}", state_name(st as i32));
        let (timeout_ms, deadline) = api.wait_and_deadline();
        let req = pb::SetStateRequest { slave, state: st as i32, wait: !no_wait, timeout_ms };
        // The daemon answers at `timeout_ms`, within the call's deadline.
        let r = api.state().set_state(api.req_for(req, deadline)).await;
        r.map_err(CliError::rpc(action))?;
        requested = Some(state_name(st as i32).to_owned());
    }
    let r =
        api.state().get_state(api.req(pb::GetStateRequest { slave })).await.map_err(CliError::rpc("read states"))?;
    let r = r.into_inner();
    Ok(StatesReport {
        slave,
        state: state_name(r.state).into(),
        requested,
        slaves: r
            .slaves
            .into_iter()
            .map(|s| SlaveStateReport {
                position: s.position,
                state: state_name(s.state).into(),
                al_status_code: s.al_status_code,
                al_status_text: s.al_status_text,
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positionals_are_sorted_into_slave_and_state() {
        let s = |v: &[&str]| split(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert_eq!(s(&[]).unwrap(), (None, None));
        assert_eq!(s(&["1"]).unwrap(), (Some(1), None));
        assert_eq!(s(&["op"]).unwrap(), (None, Some(pb::EcatState::Op)));
        assert_eq!(s(&["2", "safeop"]).unwrap(), (Some(2), Some(pb::EcatState::SafeOp)));
        assert!(s(&["op", "1"]).is_err());
        assert!(s(&["run"]).unwrap_err().to_string().contains("\"run\""));
    }
}
