//! An XML-RPC client on `ureq`: one bounded attempt per call, never a retry (the vendor
//! SDK retries forever; a robot must not).

use super::value::{Value, call_to_xml, excerpt, parse_response};
use crate::{DeployError, Result};
use std::time::Duration;

/// Largest reply accepted; controller replies are a few hundred bytes.
const MAX_REPLY: u64 = 1 << 20;

/// A client for one server (`ip:port`). Cheap to clone: clones share the connection pool,
/// so a second thread can send a StopMotion while the first waits on a MoveJ.
#[derive(Clone)]
pub struct XmlRpcClient {
    agent: ureq::Agent,
    url: String,
    addr: String,
    timeout: Duration,
}

impl XmlRpcClient {
    /// A client for `addr` ("ip:port"): every call, connect included, ends within `timeout`.
    pub fn new(addr: &str, timeout: Duration) -> XmlRpcClient {
        let agent = ureq::Agent::config_builder()
            .timeout_global(Some(timeout))
            .timeout_connect(Some(timeout))
            // A proxy from the environment must never stand between us and the arm.
            .proxy(None)
            .max_redirects(0)
            .http_status_as_error(false)
            .user_agent("fairgrasp-deploy")
            .build()
            .new_agent();
        XmlRpcClient {
            agent,
            url: format!("http://{addr}/RPC2"),
            addr: addr.to_string(),
            timeout,
        }
    }

    /// The server's address, as given.
    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// The timeout of [`XmlRpcClient::call`].
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Calls `method(params)` and returns its value. Errors name the method and the
    /// address: [`DeployError::Network`] when the server cannot be reached or does not
    /// answer in time, [`DeployError::Protocol`] for a reply that is not XML-RPC and for
    /// a fault (with its code and text).
    pub fn call(&self, method: &str, params: &[Value]) -> Result<Value> {
        self.call_with_timeout(method, params, self.timeout)
    }

    /// [`XmlRpcClient::call`] with its own timeout (a blocking MoveJ needs longer).
    pub fn call_with_timeout(
        &self,
        method: &str,
        params: &[Value],
        timeout: Duration,
    ) -> Result<Value> {
        let body = call_to_xml(method, params).map_err(|e| self.protocol(method, &e))?;
        let mut response = self
            .agent
            .post(&self.url)
            .header("Content-Type", "text/xml")
            .config()
            .timeout_global(Some(timeout))
            .build()
            .send(body.as_str())
            .map_err(|e| self.transport_error(method, e))?;
        let status = response.status();
        let text = response
            .body_mut()
            .with_config()
            .limit(MAX_REPLY)
            .read_to_string()
            .map_err(|e| self.transport_error(method, e))?;
        if !status.is_success() {
            return Err(self.protocol(method, &format!("HTTP status {status}: {}", excerpt(&text))));
        }
        match parse_response(&text) {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(fault)) => Err(self.protocol(method, &fault.to_string())),
            Err(e) => Err(self.protocol(method, &e)),
        }
    }

    fn protocol(&self, method: &str, message: &str) -> DeployError {
        DeployError::Protocol(format!("{method} to {}: {message}", self.addr))
    }

    fn transport_error(&self, method: &str, error: ureq::Error) -> DeployError {
        match error {
            ureq::Error::Protocol(_)
            | ureq::Error::Http(_)
            | ureq::Error::LargeResponseHeader(..)
            | ureq::Error::BodyExceedsLimit(_)
            | ureq::Error::StatusCode(_) => self.protocol(method, &error.to_string()),
            ureq::Error::Timeout(_) => DeployError::Network {
                call: method.to_string(),
                addr: self.addr.clone(),
                message: format!("no reply in time ({error})"),
            },
            other => DeployError::Network {
                call: method.to_string(),
                addr: self.addr.clone(),
                message: other.to_string(),
            },
        }
    }
}
