//! The twin's XML-RPC methods: the controller's (with the positional arguments the vendor's
//! Python SDK sends, `fairino-cnde.md` §4) and the twin's own `Twin…` ones (see the
//! [module](super) documentation). Every call goes through the injected delays (not the
//! `Twin…` ones) and into the call log.
//!
//! A blocking `MoveJ` (`blendT` < 0) answers when the motion has ended (plus two stream
//! periods, so the CNDE stream already shows it); a blocking `MoveGripper` (`block` = 0) when the
//! fingers stop. Commands answer an int code; getters a flat array `[code, values…]`, padded with zeros when
//! the code is not 0. A wrong number of arguments is code 3, an argument of the wrong type or
//! out of range code 4; an unknown method is an XML-RPC fault (-32601), as from any XML-RPC
//! server.

use super::Shared;
use super::call_log::CallRecord;
use super::controller::Controller;
use super::faults::FaultCommand;
use crate::fairino::error_codes::codes;
use crate::fairino::xmlrpc::{Fault, Handler, Value};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// A blocking call never waits longer than this (s): the twin's stand-in for a client that
/// would hang forever.
const MAX_BLOCK_SECONDS: f64 = 300.0;
/// How often a waiting call looks at the shutdown flag (s).
const WAIT_POLL: Duration = Duration::from_millis(50);
/// How long a blocking MoveJ's reply waits after the motion ended (s).
const STREAM_CATCH_UP: f64 = 0.016;
/// The XML-RPC convention's "method not found".
const FAULT_NO_METHOD: i32 = -32601;

/// The XML-RPC handler of a twin.
pub struct TwinService {
    shared: Arc<Shared>,
}

/// A finished reply.
type Reply = Result<Value, Fault>;

fn code(c: i32) -> Reply {
    Ok(Value::Int(c))
}

/// `[code, values…]`, the values zeroed unless the code is 0.
fn getter(c: i32, values: &[f64]) -> Reply {
    let mut items = vec![Value::Int(c)];
    items.extend(
        values
            .iter()
            .map(|&v| Value::Double(if c == codes::OK { v } else { 0.0 })),
    );
    Ok(Value::Array(items))
}

/// The arguments of one call, read by position.
struct Args<'a>(&'a [Value]);

impl Args<'_> {
    fn count(&self, n: usize) -> Result<(), i32> {
        if self.0.len() == n {
            Ok(())
        } else {
            Err(codes::PARAM_COUNT)
        }
    }

    fn at_least(&self, n: usize) -> Result<(), i32> {
        if self.0.len() >= n {
            Ok(())
        } else {
            Err(codes::PARAM_COUNT)
        }
    }

    fn f64(&self, i: usize) -> Result<f64, i32> {
        self.0
            .get(i)
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite())
            .ok_or(codes::PARAM_VALUE)
    }

    /// An integer (a double with an integral value is taken too).
    fn int(&self, i: usize) -> Result<i64, i32> {
        match self.0.get(i) {
            Some(Value::Int(v)) => Ok(i64::from(*v)),
            Some(Value::Double(d)) if d.fract() == 0.0 && d.abs() < 1e15 => Ok(*d as i64),
            Some(Value::Bool(b)) => Ok(*b as i64),
            _ => Err(codes::PARAM_VALUE),
        }
    }

    fn six(&self, i: usize) -> Result<[f64; 6], i32> {
        let items = self
            .0
            .get(i)
            .and_then(Value::as_array)
            .ok_or(codes::PARAM_VALUE)?;
        if items.len() != 6 {
            return Err(codes::PARAM_VALUE);
        }
        let mut out = [0.0; 6];
        for (o, v) in out.iter_mut().zip(items) {
            *o = v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or(codes::PARAM_VALUE)?;
        }
        Ok(out)
    }

    /// The argument as text (a fault value from another process: a string, a number or a
    /// list of numbers).
    fn text(&self, i: usize) -> Result<String, i32> {
        match self.0.get(i) {
            Some(Value::String(s)) => Ok(s.clone()),
            Some(Value::Int(v)) => Ok(v.to_string()),
            Some(Value::Double(v)) => Ok(v.to_string()),
            Some(Value::Bool(b)) => Ok((*b as u8).to_string()),
            Some(Value::Array(items)) => items
                .iter()
                .map(|v| match v {
                    Value::Int(i) => Ok(i.to_string()),
                    Value::Double(d) => Ok(d.to_string()),
                    Value::String(s) => Ok(s.clone()),
                    _ => Err(codes::PARAM_VALUE),
                })
                .collect::<Result<Vec<_>, _>>()
                .map(|parts| parts.join(",")),
            _ => Err(codes::PARAM_VALUE),
        }
    }
}

/// An XML-RPC value as JSON, for the call log.
pub fn to_json(v: &Value) -> serde_json::Value {
    match v {
        Value::Int(i) => (*i).into(),
        Value::Double(d) => serde_json::Number::from_f64(*d)
            .map(serde_json::Value::Number)
            .unwrap_or_else(|| d.to_string().into()),
        Value::Bool(b) => (*b).into(),
        Value::String(s) => s.clone().into(),
        Value::Array(items) => items.iter().map(to_json).collect(),
        Value::Nil => serde_json::Value::Null,
    }
}

impl TwinService {
    pub(crate) fn new(shared: Arc<Shared>) -> Self {
        Self { shared }
    }

    /// Waits (releasing the controller) until `done` holds, the twin stops or `limit` passes.
    /// Returns whether `done` held.
    fn wait_until(&self, limit: f64, done: impl Fn(&Controller) -> bool) -> bool {
        let shared = &self.shared;
        let deadline = shared.now() + limit;
        let mut c = shared.controller();
        while !done(&c) {
            if shared.shutdown.load(Ordering::SeqCst) || shared.now() > deadline {
                return false;
            }
            c = shared
                .ticked
                .wait_timeout(c, WAIT_POLL)
                .expect("controller lock")
                .0;
        }
        true
    }

    fn dispatch(&self, method: &str, params: &[Value]) -> Reply {
        let a = Args(params);
        let shared = &self.shared;
        let now = shared.now();
        let run = |f: &dyn Fn() -> Result<i32, i32>| code(f().unwrap_or_else(|e| e));
        match method {
            "GetControllerIP" => Ok(Value::Array(vec![
                Value::Int(codes::OK),
                Value::String(shared.controller_ip.clone()),
            ])),
            "RobotEnable" => run(&|| {
                a.count(1)?;
                let on = a.int(0)?;
                if !(0..=1).contains(&on) {
                    return Err(codes::PARAM_VALUE);
                }
                Ok(shared.controller().enable(now, on == 1))
            }),
            "Mode" => run(&|| {
                a.count(1)?;
                Ok(shared.controller().set_mode(now, a.int(0)?))
            }),
            "SetSpeed" => run(&|| {
                a.count(1)?;
                Ok(shared.controller().set_speed(a.f64(0)?))
            }),
            "GetActualJointPosDegree" | "GetActualJointPosRadian" | "GetActualTCPPose" => {
                if let Err(c) = a.count(1).and_then(|_| a.int(0)) {
                    return getter(c, &[0.0; 6]);
                }
                let state = shared.reported_state(0.0);
                let values = match method {
                    "GetActualJointPosDegree" => state.joints_deg,
                    "GetActualJointPosRadian" => state.joints_deg.map(f64::to_radians),
                    _ => state.tcp,
                };
                getter(codes::OK, &values)
            }
            "GetForwardKin" => {
                let result = a
                    .count(1)
                    .and_then(|_| a.six(0))
                    .and_then(|q| shared.controller().forward_kin(&q));
                match result {
                    Ok(pose) => getter(codes::OK, &pose),
                    Err(c) => getter(c, &[0.0; 6]),
                }
            }
            "GetInverseKin" => {
                let result = a.count(3).and_then(|_| {
                    if a.int(0)? != 0 {
                        return Err(codes::PARAM_VALUE);
                    }
                    let pose = a.six(1)?;
                    a.int(2)?;
                    shared.controller().inverse_kin(&pose)
                });
                match result {
                    Ok(q) => getter(codes::OK, &q),
                    Err(c) => getter(c, &[0.0; 6]),
                }
            }
            "GetRobotErrorCode" => {
                let s = shared.reported_state(0.0);
                Ok(Value::Array(vec![
                    Value::Int(codes::OK),
                    Value::Int(s.main_code),
                    Value::Int(s.sub_code),
                ]))
            }
            "MoveJ" => code(self.move_j(now, &a).unwrap_or_else(|e| e)),
            "ServoMoveStart" => run(&|| {
                a.count(0)?;
                Ok(shared.controller().servo_start())
            }),
            "ServoJ" => run(&|| {
                a.at_least(5)?;
                let target = a.six(0)?;
                Ok(shared.controller().servo_j(now, target, a.f64(4)?))
            }),
            "ServoMoveEnd" => run(&|| {
                a.count(0)?;
                Ok(shared.controller().servo_end())
            }),
            "StopMotion" => run(&|| {
                a.count(0)?;
                Ok(shared.controller().stop_motion(now))
            }),
            "ResetAllError" => run(&|| {
                a.count(0)?;
                Ok(shared.controller().reset_errors())
            }),
            "ActGripper" => run(&|| {
                a.count(2)?;
                Ok(shared.controller().act_gripper(a.int(0)?, a.int(1)?))
            }),
            "MoveGripper" => code(self.move_gripper(now, &a).unwrap_or_else(|e| e)),
            "GetGripperMotionDone" => {
                let (fault, status) = shared.controller().gripper_motion_done();
                Ok(Value::Array(vec![
                    Value::Int(codes::OK),
                    Value::Int(fault),
                    Value::Int(status),
                ]))
            }
            "SetGripperConfig" => run(&|| {
                a.count(4)?;
                for i in 0..4 {
                    a.int(i)?;
                }
                Ok(codes::OK)
            }),
            "TwinInfo" => Ok(Value::Array(vec![
                Value::Int(codes::OK),
                Value::String(super::TWIN_NAME.into()),
                Value::String(shared.env_id.clone()),
            ])),
            "TwinReset" => run(&|| {
                a.count(1)?;
                let seed = u64::try_from(a.int(0)?).map_err(|_| codes::PARAM_VALUE)?;
                match shared.reset_episode(seed) {
                    Ok(_) => Ok(codes::OK),
                    Err(e) => {
                        tracing::error!("TwinReset({seed}): {e}");
                        Err(codes::EXECUTION_FAILED)
                    }
                }
            }),
            "TwinEpisodeResult" => {
                let e = shared.world.lock().expect("world lock").episode().clone();
                Ok(Value::Array(vec![
                    Value::Int(codes::OK),
                    Value::Int(e.success as i32),
                    Value::Double(e.max_lift * 1000.0),
                    Value::Int(e.steps as i32),
                    Value::Int(e.failed as i32),
                    Value::Int(e.grasped as i32),
                    Value::Int(e.number as i32),
                ]))
            }
            "TwinTally" => {
                let t = shared.tally();
                Ok(Value::Array(vec![
                    Value::Int(codes::OK),
                    Value::Int(t.episodes as i32),
                    Value::Int(t.successes as i32),
                ]))
            }
            "TwinTracking" => {
                let model = shared.controller().tracking();
                let mut items = vec![Value::Int(codes::OK)];
                for t in model {
                    items.push(Value::Double(t.delay_ms));
                    items.push(Value::Double(t.tau_ms));
                }
                Ok(Value::Array(items))
            }
            "TwinInjectFault" => run(&|| {
                a.count(2)?;
                let name = a.text(0)?;
                let value = a.text(1)?;
                match FaultCommand::parse(&name, &value) {
                    Ok(fault) => {
                        shared.apply(&fault);
                        Ok(codes::OK)
                    }
                    Err(message) => {
                        tracing::warn!("TwinInjectFault: {message}");
                        Err(codes::PARAM_VALUE)
                    }
                }
            }),
            other => Err(Fault::new(
                FAULT_NO_METHOD,
                format!("method `{other}` is not served by the fairgrasp twin"),
            )),
        }
    }

    /// `MoveJ(joint_pos, desc_pos, tool, user, vel, acc, ovl, exaxis_pos, blendT, offset_flag,
    /// offset_pos)`: blocks until the move ends when `blendT` < 0.
    fn move_j(&self, now: f64, a: &Args) -> Result<i32, i32> {
        a.count(11)?;
        let target = a.six(0)?;
        let (vel, acc, ovl, blend) = (a.f64(4)?, a.f64(5)?, a.f64(6)?, a.f64(8)?);
        let ticket = self
            .shared
            .controller()
            .move_j(now, target, vel, acc, ovl)?;
        if blend >= 0.0 {
            return Ok(codes::OK);
        }
        if !self.wait_until(MAX_BLOCK_SECONDS, |c| c.outcome(ticket).is_some()) {
            return Ok(if self.shared.shutdown.load(Ordering::SeqCst) {
                codes::EXECUTION_FAILED
            } else {
                codes::WAIT_TIMEOUT
            });
        }
        let outcome = self.shared.controller().outcome(ticket);
        // Two stream periods, so the state stream reports the arrival before the reply does.
        pause(STREAM_CATCH_UP);
        Ok(outcome.unwrap_or(codes::OK))
    }

    /// `MoveGripper(index, pos, vel, force, maxtime, block, type, rotNum, rotVel, rotTorque)`:
    /// blocks until the fingers stop when `block` is 0.
    fn move_gripper(&self, now: f64, a: &Args) -> Result<i32, i32> {
        a.count(10)?;
        let index = a.int(0)?;
        let percent = [a.int(1)?, a.int(2)?, a.int(3)?];
        let max_time_ms = a.int(4)?;
        let block = a.int(5)?;
        let command = self
            .shared
            .controller()
            .move_gripper(now, index, percent, max_time_ms)?;
        if block == 0 {
            let limit = if max_time_ms > 0 {
                max_time_ms as f64 / 1000.0 + 1.0
            } else {
                31.0
            };
            self.wait_until(limit, |c| !c.gripper_moving(command));
        }
        Ok(codes::OK)
    }

    /// The delays before and after a call of `method`, from the faults in force (s).
    fn delays(&self, method: &str) -> (f64, f64) {
        if method.starts_with("Twin") {
            return (0.0, 0.0);
        }
        let half = self.shared.draw_latency() / 2.0;
        let slow = self
            .shared
            .faults
            .lock()
            .expect("faults lock")
            .take_slow_delay(method)
            / 1000.0;
        (half, half + slow)
    }
}

fn pause(seconds: f64) {
    if seconds > 0.0 {
        std::thread::sleep(Duration::from_secs_f64(seconds));
    }
}

impl TwinService {
    /// A command that expects no reply (the UDP port): the injected latency's one-way half
    /// before it, nothing after; logged as `udp:{method}`.
    pub(crate) fn call_one_way(&self, method: &str, params: Vec<Value>) {
        let arrived = self.shared.now();
        let (before, _) = self.delays(method);
        pause(before);
        let reply = self.dispatch(method, &params);
        self.record(arrived, format!("udp:{method}"), &params, &reply);
    }

    /// Puts a call that arrived at `arrived` into the call log.
    fn record(&self, arrived: f64, method: String, params: &[Value], reply: &Reply) {
        self.shared.calls.record(CallRecord {
            t: arrived,
            method,
            params: params.iter().map(to_json).collect(),
            reply: match reply {
                Ok(v) => to_json(v),
                Err(f) => serde_json::json!({"fault": f.code, "message": f.message}),
            },
            seconds: self.shared.now() - arrived,
        });
    }
}

impl Handler for TwinService {
    fn call(&self, method: &str, params: Vec<Value>) -> Result<Value, Fault> {
        let arrived = self.shared.now();
        let (before, after) = self.delays(method);
        pause(before);
        let reply = self.dispatch(method, &params);
        pause(after);
        self.record(arrived, method.to_string(), &params, &reply);
        reply
    }
}
