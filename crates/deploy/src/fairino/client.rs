//! [`FairinoClient`]: a [`RobotLink`] to a FAIRINO controller (or the twin) over XML-RPC
//! for commands and getters and the CNDE stream for state. Each command goes out with
//! exactly the arguments the vendor SDK sends (fairino-cnde.md §4), so the controller
//! cannot tell us from the SDK.

use super::cnde::{CndeClient, DEFAULT_PERIOD_MS, default_state_names};
use super::error_codes::error_code_meaning;
use super::udp::{self, ServoSender};
use super::xmlrpc::{Value, XmlRpcClient};
use crate::robot::{RobotCommand, RobotLink, SideLine, StampedState};
use crate::{DeployError, Result};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Ports and timeouts of a [`FairinoClient`].
#[derive(Clone, Debug, PartialEq)]
pub struct ClientConfig {
    /// XML-RPC port (20003 on the controller).
    pub rpc_port: u16,
    /// CNDE state stream port (20005 on the controller).
    pub cnde_port: u16,
    /// Timeout of every XML-RPC call but MoveJ.
    pub call_timeout: Duration,
    /// Timeout of connecting (CNDE handshake, first state, first call).
    pub connect_timeout: Duration,
    /// Timeout of a blocking MoveJ: the whole motion must end within it.
    pub move_timeout: Duration,
    /// CNDE period (ms, 8-1000).
    pub period_ms: u16,
    /// CNDE state names to ask for (the vendor SDK's default set by default).
    pub state_names: Vec<String>,
    /// `Some(port)`: servo commands (`ServoMoveStart`, `ServoJ`, `ServoMoveEnd`) go over the
    /// controller's real-time UDP path (20007 on the controller, the SDK's `cmdType = 1`),
    /// fire-and-forget; `None`: over XML-RPC, each waiting for its reply.
    pub servo_udp_port: Option<u16>,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            rpc_port: 20003,
            cnde_port: 20005,
            call_timeout: Duration::from_millis(200),
            connect_timeout: Duration::from_secs(1),
            move_timeout: Duration::from_secs(60),
            period_ms: DEFAULT_PERIOD_MS,
            state_names: default_state_names(),
            servo_udp_port: None,
        }
    }
}

/// A connected controller. Clones share the connection (the stream, the servo socket) and
/// may call from other threads.
#[derive(Clone)]
pub struct FairinoClient {
    rpc: XmlRpcClient,
    cnde: Arc<CndeClient>,
    servo_udp: Option<Arc<Mutex<ServoSender>>>,
    config: ClientConfig,
}

fn host_port(ip: &str, port: u16) -> String {
    if ip.contains(':') && !ip.starts_with('[') {
        format!("[{ip}]:{port}")
    } else {
        format!("{ip}:{port}")
    }
}

impl FairinoClient {
    /// Connects as the vendor SDK does: the CNDE stream first (config, start, first state),
    /// then an XML-RPC probe (`GetControllerIP`). Nothing is retried.
    pub fn connect(ip: &str, config: &ClientConfig) -> Result<FairinoClient> {
        if ip.trim().is_empty() {
            return Err(DeployError::config("robot address", "empty"));
        }
        let cnde = CndeClient::connect(
            &host_port(ip, config.cnde_port),
            &config.state_names,
            config.period_ms,
            config.connect_timeout,
        )?;
        let rpc = XmlRpcClient::new(&host_port(ip, config.rpc_port), config.call_timeout);
        rpc.call_with_timeout("GetControllerIP", &[], config.connect_timeout)?;
        let servo_udp = match config.servo_udp_port {
            Some(port) => Some(Arc::new(Mutex::new(ServoSender::connect(
                &host_port(ip, port),
                config.call_timeout,
            )?))),
            None => None,
        };
        Ok(FairinoClient {
            rpc,
            cnde: Arc::new(cnde),
            servo_udp,
            config: config.clone(),
        })
    }

    /// The XML-RPC client. Clone it to send (say) StopMotion from another thread while
    /// this one waits on a MoveJ.
    pub fn rpc(&self) -> &XmlRpcClient {
        &self.rpc
    }

    /// The configuration it connected with.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// The newest state from the stream (see [`CndeClient::latest`]).
    pub fn state(&self) -> Result<StampedState> {
        self.cnde.latest()
    }

    /// Joint angles (deg), read over XML-RPC.
    pub fn joints_deg(&self) -> Result<[f64; 6]> {
        self.query6("GetActualJointPosDegree", &[Value::Int(1)])
    }

    /// TCP pose (mm, deg), read over XML-RPC.
    pub fn tcp_pose(&self) -> Result<[f64; 6]> {
        self.query6("GetActualTCPPose", &[Value::Int(1)])
    }

    /// The controller's forward kinematics of `joints_deg`: the TCP pose (mm, deg).
    pub fn forward_kin(&self, joints_deg: &[f64; 6]) -> Result<[f64; 6]> {
        finite("GetForwardKin", joints_deg)?;
        self.query6("GetForwardKin", &[Value::doubles(joints_deg)])
    }

    /// The controller's own IP address.
    pub fn controller_ip(&self) -> Result<String> {
        let method = "GetControllerIP";
        let items = self.query(method, &[], self.config.call_timeout)?;
        items
            .get(1)
            .and_then(Value::as_str)
            .map(str::to_string)
            .ok_or_else(|| self.protocol(method, "expected [err, \"ip\"]"))
    }

    /// Any call, its reply unchecked (for methods this client does not wrap).
    pub fn call_raw(&self, method: &str, params: &[Value]) -> Result<Value> {
        self.rpc.call(method, params)
    }

    fn protocol(&self, method: &str, message: &str) -> DeployError {
        DeployError::Protocol(format!("{method} to {}: {message}", self.rpc.addr()))
    }

    /// A getter's reply `[err, v1, …]`, checked for err = 0.
    fn query(&self, method: &str, params: &[Value], timeout: Duration) -> Result<Vec<Value>> {
        let reply = self.rpc.call_with_timeout(method, params, timeout)?;
        let items = match reply {
            Value::Array(items) => items,
            // Tolerate a bare error code in place of the array.
            Value::Int(code) if code != 0 => return Err(controller(method, code.into())),
            other => {
                return Err(self.protocol(
                    method,
                    &format!("expected an array [err, …], got {}", other.type_name()),
                ));
            }
        };
        match items.first().and_then(Value::as_i64) {
            Some(0) => Ok(items),
            Some(code) => Err(controller(method, code)),
            None => Err(self.protocol(method, "the reply does not start with an int error code")),
        }
    }

    /// A getter returning six numbers after the error code.
    fn query6(&self, method: &str, params: &[Value]) -> Result<[f64; 6]> {
        let items = self.query(method, params, self.config.call_timeout)?;
        six_numbers(&items[1..]).ok_or_else(|| {
            self.protocol(
                method,
                &format!("expected [err, six numbers], got {} items", items.len()),
            )
        })
    }

    /// A command's reply: an int error code, 0 for success.
    fn command(&self, method: &str, params: &[Value], timeout: Duration) -> Result<()> {
        match self.rpc.call_with_timeout(method, params, timeout)? {
            Value::Int(0) => Ok(()),
            Value::Int(code) => Err(controller(method, code.into())),
            other => Err(self.protocol(
                method,
                &format!("expected an int error code, got {}", other.type_name()),
            )),
        }
    }

    /// Sends one command with the vendor SDK's arguments and checks its error code.
    pub fn send_command(&self, command: &RobotCommand) -> Result<()> {
        let method = command.method();
        if command.moves() {
            // As the vendor SDK: no motion while a safety stop is reported (code 99),
            // and none at all without a live state stream.
            let state = self.cnde.latest()?.state;
            if state.safety_stop.iter().any(|&stop| stop) {
                return Err(controller(method, 99));
            }
        }
        if let Some(sender) = &self.servo_udp {
            let udp_command = match command {
                RobotCommand::ServoMoveStart => {
                    Some((udp::SERVO_MOVE_START, "ServoMoveStart()".to_string()))
                }
                RobotCommand::ServoMoveEnd => {
                    Some((udp::SERVO_MOVE_END, "ServoMoveEnd()".to_string()))
                }
                RobotCommand::ServoJ { joints_deg, cmd_t } => {
                    finite(method, joints_deg)?;
                    finite(method, &[*cmd_t])?;
                    Some((udp::SERVO_J, udp::servo_j_content(joints_deg, *cmd_t)))
                }
                _ => None,
            };
            if let Some((id, content)) = udp_command {
                return sender.lock().expect("UDP sender lock").send(id, &content);
            }
        }
        let call = self.config.call_timeout;
        match command {
            RobotCommand::RobotEnable { enable } => {
                self.command(method, &[Value::Int((*enable).into())], call)
            }
            RobotCommand::Mode { mode } => {
                self.command(method, &[Value::Int((*mode).into())], call)
            }
            RobotCommand::SetSpeed { percent } => {
                self.command(method, &[Value::Int((*percent).into())], call)
            }
            RobotCommand::MoveJ {
                joints_deg,
                speed_percent,
                acc_percent,
            } => {
                finite(method, joints_deg)?;
                finite(method, &[*speed_percent, *acc_percent])?;
                // The SDK asks the controller for the Cartesian target first and passes
                // its answer through as desc_pos.
                let fk = self.query("GetForwardKin", &[Value::doubles(joints_deg)], call)?;
                let desc_pos = &fk[1..];
                if desc_pos.len() != 6 || desc_pos.iter().any(|v| v.as_f64().is_none()) {
                    return Err(self.protocol("GetForwardKin", "expected [err, six numbers]"));
                }
                let params = [
                    Value::doubles(joints_deg),
                    Value::Array(desc_pos.to_vec()),
                    Value::Int(0),                 // tool
                    Value::Int(0),                 // user (work object)
                    Value::Double(*speed_percent), // vel
                    Value::Double(*acc_percent),   // acc
                    Value::Double(100.0),          // ovl
                    Value::doubles(&[0.0; 4]),     // external axes
                    Value::Double(-1.0),           // blendT: -1 blocks until the motion ends
                    Value::Int(0),                 // offset_flag
                    Value::doubles(&[0.0; 6]),     // offset_pos
                ];
                self.command(method, &params, self.config.move_timeout)
            }
            RobotCommand::ServoJ { joints_deg, cmd_t } => {
                finite(method, joints_deg)?;
                finite(method, &[*cmd_t])?;
                let params = [
                    Value::doubles(joints_deg),
                    Value::doubles(&[0.0; 4]), // axisPos
                    Value::Double(0.0),        // acc
                    Value::Double(0.0),        // vel
                    Value::Double(*cmd_t),
                    Value::Double(0.0), // filterT
                    Value::Double(0.0), // gain
                    Value::Int(0),      // id
                ];
                self.command(method, &params, call)
            }
            RobotCommand::ActGripper { index, activate } => self.command(
                method,
                &[Value::Int((*index).into()), Value::Int((*activate).into())],
                call,
            ),
            RobotCommand::MoveGripper {
                index,
                position_percent,
                speed_percent,
                force_percent,
                max_time_ms,
            } => {
                let max_time = i32::try_from(*max_time_ms).map_err(|_| {
                    DeployError::config("MoveGripper max_time_ms", "does not fit an int")
                })?;
                let params = [
                    Value::Int((*index).into()),
                    Value::Int((*position_percent).into()),
                    Value::Int((*speed_percent).into()),
                    Value::Int((*force_percent).into()),
                    Value::Int(max_time),
                    Value::Int(1),      // block: 0 blocks, 1 returns at once
                    Value::Int(0),      // type: parallel gripper
                    Value::Double(0.0), // rotNum
                    Value::Int(0),      // rotVel
                    Value::Int(0),      // rotTorque
                ];
                self.command(method, &params, call)
            }
            RobotCommand::ServoMoveStart
            | RobotCommand::ServoMoveEnd
            | RobotCommand::StopMotion
            | RobotCommand::ResetAllError => self.command(method, &[], call),
        }
    }
}

impl RobotLink for FairinoClient {
    fn latest_state(&self) -> Result<StampedState> {
        self.state()
    }

    fn send(&mut self, command: &RobotCommand) -> Result<()> {
        self.send_command(command)
    }

    fn side_line(&self) -> Option<Arc<dyn SideLine>> {
        Some(Arc::new(self.clone()))
    }
}

impl SideLine for FairinoClient {
    fn send(&self, command: &RobotCommand) -> Result<()> {
        self.send_command(command)
    }
}

fn controller(method: &str, code: i64) -> DeployError {
    DeployError::Controller {
        call: method.to_string(),
        code,
        meaning: error_code_meaning(code).to_string(),
    }
}

/// Never put a NaN or an infinity on the wire to a robot.
fn finite(method: &str, values: &[f64]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(DeployError::config(
            method,
            format!("refusing to send non-finite values {values:?}"),
        ))
    }
}

fn six_numbers(items: &[Value]) -> Option<[f64; 6]> {
    if items.len() != 6 {
        return None;
    }
    let mut out = [0.0; 6];
    for (slot, item) in out.iter_mut().zip(items) {
        *slot = item.as_f64()?;
    }
    Some(out)
}
