//! Who sets up and judges each episode: the twin over its own XML-RPC methods, or the
//! operator at a real robot.

use super::EpisodeHost;
use crate::error::{DeployError, Result};
use crate::fairino::xmlrpc::{Value, XmlRpcClient};
use std::io::BufRead;
use std::time::Duration;

/// The digital twin: `TwinReset(seed)` places a new object before each episode and
/// `TwinEpisodeResult()` judges it by the task's rule.
pub struct TwinHost {
    rpc: XmlRpcClient,
    seed: u64,
}

impl TwinHost {
    /// Asks the controller at `addr` (`ip:port`) whether it is a fairgrasp twin: `Ok(None)` when
    /// it answers but is not one (a real controller), an error when it does not answer.
    pub fn detect(addr: &str, seed: u64) -> Result<Option<Self>> {
        let rpc = XmlRpcClient::new(addr, Duration::from_secs(2));
        match rpc.call("TwinInfo", &[]) {
            Ok(Value::Array(items))
                if items.get(1).and_then(Value::as_str) == Some(crate::twin::TWIN_NAME) =>
            {
                Ok(Some(Self { rpc, seed }))
            }
            Ok(_) => Ok(None),
            // A real controller answers an unknown method with a fault.
            Err(DeployError::Network { .. }) => Err(DeployError::Network {
                call: "TwinInfo".into(),
                addr: addr.into(),
                message: "no answer".into(),
            }),
            Err(_) => Ok(None),
        }
    }
}

impl EpisodeHost for TwinHost {
    fn begin(&mut self, index: u32) -> Result<()> {
        let seed = self.seed + index as u64;
        match self.rpc.call("TwinReset", &[Value::Int(seed as i32)])? {
            Value::Int(0) => Ok(()),
            other => Err(DeployError::Protocol(format!(
                "TwinReset({seed}) answered {other:?}"
            ))),
        }
    }

    fn outcome(&mut self) -> Result<Option<bool>> {
        match self.rpc.call("TwinEpisodeResult", &[])? {
            Value::Array(items) if items.first().and_then(Value::as_i64) == Some(0) => {
                Ok(items.get(1).and_then(Value::as_i64).map(|s| s != 0))
            }
            other => Err(DeployError::Protocol(format!(
                "TwinEpisodeResult answered {other:?}"
            ))),
        }
    }
}

/// A real robot: the operator places the object and presses Enter; nobody judges.
pub struct OperatorHost;

impl EpisodeHost for OperatorHost {
    fn begin(&mut self, index: u32) -> Result<()> {
        println!(
            "episode {}: place the object in the workspace, keep clear of the arm, then press \
             Enter (Ctrl-C aborts)",
            index + 1
        );
        let mut line = String::new();
        std::io::stdin().lock().read_line(&mut line)?;
        Ok(())
    }

    fn outcome(&mut self) -> Result<Option<bool>> {
        Ok(None)
    }
}
