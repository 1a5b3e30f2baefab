//! `fairgrasp.PolicyDriver`: a saved model run exactly as the deployment loop runs it
//! (`crates/deploy/src/runner/mod.rs`, `Deployment::episode`), minus the network, so that
//! another simulator can stand where the robot stands (`bench/sim2sim`).
//!
//! Per control step the caller hands in what a controller reports (joints and speeds in
//! degrees, the gripper in whole percent, all in the simulator's joint frame) and the object's
//! pose (base frame); the driver builds the state with the env's own [`StateEstimator`], checks
//! the task's success rule over its hold steps, builds the observation ([`ModelIo::observe`]),
//! acts deterministically, maps the action as the env does ([`ModelIo::env_action`],
//! [`ModelIo::apply`]) and streams the step's joint targets through a [`JointRamp`] configured
//! like training's `[control.servo]` ([`ModelIo::servo`]): `servo_ticks` set points per control
//! step, which the caller's simulator holds for one servo period each. What the deployment adds
//! on top (calibration, the safety filter's soft limits and workspace box, the watchdog, the
//! speed scale) belongs to the real arm and is left out: the readings are taken at speed scale 1
//! in the simulator's joint frame.

use crate::errors::{ModelError, env_error, poisoned, rl_error};
use fairgrasp_deploy::DeployError;
use fairgrasp_deploy::runner::{DeployOptions, ModelIo};
use fairgrasp_deploy::safety::SafetyConfig;
use fairgrasp_env::arm::servo::servo_ticks;
use fairgrasp_env::arm::{
    ArmState, Command, ControllerReading, JointRamp, StateEstimator, SuccessJudge,
};
use fairgrasp_env::sim::pick::SuccessRule;
use fairgrasp_env::sim::rapier3d::na::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use fairgrasp_env::{Env as _, GraspConfig, GraspEnv};
use fairgrasp_rl::Policy as NativePolicy;
use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use std::path::PathBuf;
use std::sync::Mutex;

/// A deployment error as a Python exception: a model the loop cannot run is a `ModelError`.
fn deploy_error(e: DeployError) -> PyErr {
    let message = e.to_string();
    match e {
        DeployError::Config { .. } => ModelError::new_err(message),
        DeployError::Env(e) => env_error(e),
        DeployError::Rl(e) => rl_error(e),
        DeployError::Io(_) => PyOSError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

/// One set of readings, checked.
struct Reading {
    controller: ControllerReading,
    joints_rad: Vec<f64>,
    object: Isometry3<f64>,
}

/// `value` as `n` finite float64 values; a `ValueError` naming `what` otherwise.
fn f64_values(value: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<f64>> {
    let wrong = |got: String| {
        PyValueError::new_err(format!(
            "invalid {what}: expected {n} finite numbers, got {got}"
        ))
    };
    let numpy = value.py().import("numpy")?;
    let converted = numpy
        .call_method1("asarray", (value, numpy.getattr("float64")?))
        .map_err(|e| wrong(format!("a value numpy cannot read as numbers ({e})")))?;
    let array: PyReadonlyArrayDyn<'_, f64> = converted.extract()?;
    let dims = array.shape().to_vec();
    if dims != [n] {
        return Err(wrong(format!("shape {dims:?}")));
    }
    let values: Vec<f64> = array.as_array().iter().copied().collect();
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(wrong(format!("value {i} = {}", values[i])));
    }
    Ok(values)
}

impl Reading {
    fn new(
        dof: usize,
        joints_deg: &Bound<'_, PyAny>,
        joint_speeds_deg: &Bound<'_, PyAny>,
        gripper_percent: &Bound<'_, PyAny>,
        object_pos: &Bound<'_, PyAny>,
        object_quat_xyzw: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let joints_deg = f64_values(joints_deg, "joints_deg", dof)?;
        let joint_speeds_deg = f64_values(joint_speeds_deg, "joint_speeds_deg", dof)?;
        let percent: i64 = gripper_percent.extract().map_err(|_| {
            PyValueError::new_err(format!(
                "invalid gripper_percent: expected a whole number 0–100 (the controller's \
                 reading), got {gripper_percent}"
            ))
        })?;
        if !(0..=100).contains(&percent) {
            return Err(PyValueError::new_err(format!(
                "invalid gripper_percent: expected a whole number 0–100, got {percent}"
            )));
        }
        let p = f64_values(object_pos, "object_pos", 3)?;
        let q = f64_values(object_quat_xyzw, "object_quat_xyzw", 4)?;
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(PyValueError::new_err(format!(
                "invalid object_quat_xyzw: expected a unit quaternion (x, y, z, w), its norm is \
                 {norm}"
            )));
        }
        let object = Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2])),
        );
        Ok(Self {
            joints_rad: joints_deg.iter().map(|v| v.to_radians()).collect(),
            controller: ControllerReading {
                joints_deg,
                joint_speeds_deg,
                gripper_percent: percent as u8,
            },
            object,
        })
    }
}

/// What one control step gives: the set points (rad), the gripper command and whether the
/// success rule has held for its hold steps (then there are no set points: the episode ended).
struct Output {
    set_points: Vec<Vec<f64>>,
    gripper_open: bool,
    held: bool,
}

/// The loop's state within an episode (the locals of `Deployment::episode`).
struct Episode {
    estimator: StateEstimator,
    state: ArmState,
    command: Command,
    /// The previous action as the observation shows it.
    shown: Vec<f32>,
    /// The gripper command before this step's action (what the estimator is told).
    closing: bool,
    /// The task's success rule, as the deployment loop applies it.
    success: Box<dyn SuccessJudge>,
    steps: u32,
    ended: bool,
    ik_failures: u32,
    /// The latest act's observation and the policy's action (as `fairgrasp eval --trace`
    /// writes them).
    last: Option<(Vec<f32>, Vec<f32>)>,
}

struct Driver {
    policy: NativePolicy,
    io: ModelIo,
    ramp: JointRamp,
    ticks: u32,
    env_id: String,
    table: toml::Table,
    /// The figures of the model's success rule, for the caller's own judge.
    rule: SuccessRule,
    /// Built at the first `placement` call: the model's own env, as `fairgrasp eval` builds it.
    placement_env: Option<GraspEnv>,
    episode: Option<Episode>,
}

impl Driver {
    fn load(path: &std::path::Path) -> PyResult<Self> {
        let policy = NativePolicy::load(path).map_err(rl_error)?;
        let io = ModelIo::for_policy(&policy).map_err(deploy_error)?;
        let table = policy.env_settings(&[]).map_err(rl_error)?;
        // ModelIo accepted the model, so its env is the grasp task's.
        let config: GraspConfig =
            fairgrasp_env::config::from_table(table.clone()).map_err(env_error)?;
        let servo = io.servo();
        let ticks = servo_ticks(io.control_period as f32, servo.period_ms);
        let limits: Vec<(f64, f64)> = (io.limits_rad.iter())
            .map(|&(lo, hi)| (lo as f64, hi as f64))
            .collect();
        let ramp = JointRamp::new(
            &limits,
            (servo.max_joint_speed_deg_s as f64).to_radians(),
            (servo.max_joint_acc_deg_s2 as f64).to_radians(),
            io.control_period / ticks as f64,
        );
        Ok(Self {
            env_id: policy.env_id().to_string(),
            policy,
            io,
            ramp,
            ticks,
            table,
            rule: config.task.success_rule(),
            placement_env: None,
            episode: None,
        })
    }

    fn dof(&self) -> usize {
        self.io.limits_rad.len()
    }

    /// The deployment's episode start and its step 0: the start reading estimated with no time
    /// elapsed, the ramp started at the measured joints, the hold command, then the first act.
    fn begin(&mut self, reading: Reading) -> PyResult<Output> {
        let mut estimator = StateEstimator::new();
        let state = estimator.estimate(
            &self.io.facts,
            &reading.controller,
            reading.object,
            false,
            0.0,
        );
        let command = self.io.hold(&state);
        self.ramp.start(&reading.joints_rad);
        self.episode = Some(Episode {
            estimator,
            state,
            command,
            shown: vec![0.0; self.policy.act_dim()],
            closing: false,
            success: self.io.success_judge(),
            steps: 0,
            ended: false,
            ik_failures: 0,
            last: None,
        });
        self.act()
    }

    /// A later step: the reading one control period after the previous one.
    fn step(&mut self, reading: Reading) -> PyResult<Output> {
        let dt = self.io.control_period;
        let episode = self.episode.as_mut().ok_or_else(|| {
            PyRuntimeError::new_err("call begin() to start an episode before step()")
        })?;
        if episode.ended {
            return Err(PyRuntimeError::new_err(
                "the episode has ended (the success rule held); call begin() to start another",
            ));
        }
        episode.state = episode.estimator.estimate(
            &self.io.facts,
            &reading.controller,
            reading.object,
            episode.closing,
            dt,
        );
        if episode.success.update(&episode.state) {
            episode.ended = true;
            return Ok(Output {
                set_points: Vec::new(),
                gripper_open: episode.command.gripper_open,
                held: true,
            });
        }
        self.act()
    }

    /// Observe, act, map, ramp: the rest of a control step.
    fn act(&mut self) -> PyResult<Output> {
        let episode = self.episode.as_mut().expect("begin() made the episode");
        let obs = self.io.observe(&episode.state, &episode.shown, 1.0);
        let output = self.policy.act(&obs, true).map_err(rl_error)?;
        if let Some(i) = output.iter().position(|v| !v.is_finite()) {
            return Err(PyRuntimeError::new_err(format!(
                "non-finite policy output: value {i} is {}",
                output[i]
            )));
        }
        let (action, shown) = self.io.env_action(&output).map_err(deploy_error)?;
        episode.shown = shown;
        episode.last = Some((obs, output));
        if !self.io.apply(&episode.state, &action, &mut episode.command) {
            episode.ik_failures += 1;
        }
        episode.closing = !episode.command.gripper_open;
        let target: Vec<f64> = (episode.command.arm_target.iter())
            .map(|&v| v as f64)
            .collect();
        let set_points = (0..self.ticks)
            .map(|_| self.ramp.next(&target).expect("begin() started the ramp"))
            .collect();
        episode.steps += 1;
        Ok(Output {
            set_points,
            gripper_open: episode.command.gripper_open,
            held: false,
        })
    }

    /// One more control step towards the present joint targets without acting: what the
    /// deployment streams for `hold_after_success` steps once the success rule has held.
    fn hold(&mut self) -> PyResult<Vec<Vec<f64>>> {
        let episode = self.episode.as_ref().ok_or_else(|| {
            PyRuntimeError::new_err("call begin() to start an episode before hold()")
        })?;
        let target: Vec<f64> = (episode.command.arm_target.iter())
            .map(|&v| v as f64)
            .collect();
        Ok((0..self.ticks)
            .map(|_| self.ramp.next(&target).expect("begin() started the ramp"))
            .collect())
    }

    /// Episode `seed`'s object as the model's own env lays it out (`fairgrasp eval` resets the
    /// same env with the same seed): its pose (base frame), size and material.
    fn placement(&mut self, seed: u64) -> fairgrasp_env::Result<Placement> {
        if self.placement_env.is_none() {
            let config: GraspConfig = fairgrasp_env::config::from_table(self.table.clone())?;
            self.placement_env = Some(GraspEnv::new(config)?);
        }
        let env = self.placement_env.as_mut().expect("built above");
        let (_, info) = env.reset(Some(seed))?;
        let state = env
            .state()
            .ok_or_else(|| fairgrasp_env::EnvError::Usage("no state after reset".into()))?;
        let object = &state.objects[0];
        let nominal = &env.config().scene.objects[0];
        let t = object.pose.translation.vector;
        let q = object.pose.rotation.quaternion();
        Ok(Placement {
            position: [t.x, t.y, t.z],
            orientation_xyzw: [q.i, q.j, q.k, q.w],
            half_extents: object.half_extents.map(|v| v as f64),
            rest_z: object.rest_z,
            mass: info
                .extras
                .get("param/object0_mass")
                .unwrap_or(nominal.mass) as f64,
            friction: info
                .extras
                .get("param/object0_friction")
                .unwrap_or(nominal.friction) as f64,
        })
    }
}

struct Placement {
    position: [f64; 3],
    orientation_xyzw: [f64; 4],
    half_extents: [f64; 3],
    rest_z: f64,
    mass: f64,
    friction: f64,
}

/// A saved `FaArmGrasp-v0` model driven as `fairgrasp deploy` drives it, by readings from any
/// simulator (see the [module](self)).
#[pyclass(module = "fairgrasp._native", name = "PolicyDriver")]
pub struct PolicyDriver {
    inner: Mutex<Driver>,
}

impl PolicyDriver {
    fn with<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Driver) -> PyResult<T> + Send,
    ) -> PyResult<T> {
        py.detach(|| {
            let mut driver = self.inner.lock().map_err(|_| poisoned("policy driver"))?;
            f(&mut driver)
        })
    }

    fn read<T>(&self, f: impl FnOnce(&Driver) -> T) -> PyResult<T> {
        let driver = self.inner.lock().map_err(|_| poisoned("policy driver"))?;
        Ok(f(&driver))
    }

    /// Reads the five reading arguments (joints, speeds, gripper, object position and
    /// quaternion), runs `act` on them and returns its output as Python's tuple.
    fn act_on<'py>(
        &self,
        py: Python<'py>,
        [joints, speeds, gripper, position, quaternion]: [&Bound<'py, PyAny>; 5],
        act: fn(&mut Driver, Reading) -> PyResult<Output>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let dof = self.read(Driver::dof)?;
        let reading = Reading::new(dof, joints, speeds, gripper, position, quaternion)?;
        let output = self.with(py, move |d| act(d, reading))?;
        Self::output(py, output)
    }

    fn output<'py>(py: Python<'py>, output: Output) -> PyResult<Bound<'py, PyTuple>> {
        let set_points = PyList::new(py, output.set_points)?;
        PyTuple::new(
            py,
            [
                set_points.into_any(),
                pyo3::types::PyBool::new(py, output.gripper_open)
                    .to_owned()
                    .into_any(),
                pyo3::types::PyBool::new(py, output.held)
                    .to_owned()
                    .into_any(),
            ],
        )
    }
}

#[pymethods]
impl PolicyDriver {
    /// Loads a model directory (or a run directory, for its best model) written by
    /// `fairgrasp train` for `FaArmGrasp-v0`; a missing, corrupt or undeployable model raises
    /// `ModelError` naming the problem.
    #[new]
    fn new(py: Python<'_>, model: PathBuf) -> PyResult<Self> {
        let driver = py.detach(|| Driver::load(&model))?;
        Ok(Self {
            inner: Mutex::new(driver),
        })
    }

    /// Starts an episode from the readings at rest (the deployment's start state) and returns
    /// its first step: `(set_points_rad, gripper_open, False)`, `servo_ticks` set points of six
    /// joints each.
    fn begin<'py>(
        &self,
        py: Python<'py>,
        joints_deg: &Bound<'py, PyAny>,
        joint_speeds_deg: &Bound<'py, PyAny>,
        gripper_percent: &Bound<'py, PyAny>,
        object_pos: &Bound<'py, PyAny>,
        object_quat_xyzw: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let readings = [
            joints_deg,
            joint_speeds_deg,
            gripper_percent,
            object_pos,
            object_quat_xyzw,
        ];
        self.act_on(py, readings, Driver::begin)
    }

    /// One control step from readings taken one control period after the previous ones:
    /// `(set_points_rad, gripper_open, success_rule_held)`. When the task's success rule has
    /// held on the estimated state for its hold steps the episode ends, as the deployment's
    /// does: no set points, `success_rule_held` True.
    fn step<'py>(
        &self,
        py: Python<'py>,
        joints_deg: &Bound<'py, PyAny>,
        joint_speeds_deg: &Bound<'py, PyAny>,
        gripper_percent: &Bound<'py, PyAny>,
        object_pos: &Bound<'py, PyAny>,
        object_quat_xyzw: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let readings = [
            joints_deg,
            joint_speeds_deg,
            gripper_percent,
            object_pos,
            object_quat_xyzw,
        ];
        self.act_on(py, readings, Driver::step)
    }

    /// One more control step's set points (rad) towards the present joint targets, without
    /// acting: after the success rule held, `fairgrasp deploy` streams `hold_after_success` of
    /// these (arm held at its last target, gripper as commanded) before it ends the episode.
    fn hold<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let set_points = self.with(py, |d| d.hold())?;
        PyList::new(py, set_points)
    }

    /// Control steps the deployment holds the arm after the success rule held
    /// (`DeployOptions::hold_after_success`'s default).
    #[getter]
    fn hold_after_success(&self) -> u32 {
        DeployOptions::default().hold_after_success
    }

    /// Episode `seed`'s object as `fairgrasp eval` lays it out with this model's env: a dict of
    /// `position` (base frame, m), `orientation_xyzw`, `half_extents` (m), `rest_z` (base frame,
    /// m), `mass` (kg) and `friction`.
    fn placement<'py>(&self, py: Python<'py>, seed: u64) -> PyResult<Bound<'py, PyDict>> {
        let p = self.with(py, move |d| d.placement(seed).map_err(env_error))?;
        let dict = PyDict::new(py);
        dict.set_item("position", p.position.to_vec())?;
        dict.set_item("orientation_xyzw", p.orientation_xyzw.to_vec())?;
        dict.set_item("half_extents", p.half_extents.to_vec())?;
        dict.set_item("rest_z", p.rest_z)?;
        dict.set_item("mass", p.mass)?;
        dict.set_item("friction", p.friction)?;
        Ok(dict)
    }

    /// The model's home pose (rad, simulator joint frame): where its episodes start.
    #[getter]
    fn home_rad(&self) -> PyResult<Vec<f64>> {
        self.read(|d| d.io.nominal.q.iter().map(|&v| v as f64).collect())
    }

    /// The policy's control period (s).
    #[getter]
    fn control_period(&self) -> PyResult<f64> {
        self.read(|d| d.io.control_period)
    }

    /// Set points per control step (`[control.servo]`'s period into the control period).
    #[getter]
    fn servo_ticks(&self) -> PyResult<u32> {
        self.read(|d| d.ticks)
    }

    /// The servo period (s): the control period over `servo_ticks`.
    #[getter]
    fn servo_period(&self) -> PyResult<f64> {
        self.read(|d| d.ramp.caps().2)
    }

    /// The ramp's joint speed and acceleration caps (rad/s, rad/s²).
    #[getter]
    fn ramp_caps(&self) -> PyResult<(f64, f64)> {
        self.read(|d| (d.ramp.caps().0, d.ramp.caps().1))
    }

    /// The joint limits the ramp keeps to (rad): `[(lower, upper)] * 6`.
    #[getter]
    fn joint_limits_rad(&self) -> PyResult<Vec<(f64, f64)>> {
        self.read(|d| {
            let (lo, hi) = d.ramp.limits();
            lo.iter().copied().zip(hi.iter().copied()).collect()
        })
    }

    /// The model's episode length (control steps).
    #[getter]
    fn max_steps(&self) -> PyResult<u32> {
        self.read(|d| d.io.max_steps)
    }

    /// Consecutive control steps the success rule must hold.
    #[getter]
    fn success_hold_steps(&self) -> PyResult<u32> {
        self.read(|d| d.rule.hold_steps)
    }

    /// The success rule's lift (m above the object's resting height) and largest TCP–object
    /// distance (m).
    #[getter]
    fn success_rule(&self) -> PyResult<(f64, f64)> {
        self.read(|d| (d.rule.min_lift, d.rule.max_offset))
    }

    /// The gripper's largest opening (m): 100 % of the controller's reading.
    #[getter]
    fn gripper_max_opening(&self) -> PyResult<f64> {
        self.read(|d| d.io.facts.gripper_max_opening as f64)
    }

    /// Control steps acted in this episode.
    #[getter]
    fn steps(&self) -> PyResult<u32> {
        self.read(|d| d.episode.as_ref().map_or(0, |e| e.steps))
    }

    /// Control steps of this episode whose Cartesian target had no inverse kinematics.
    #[getter]
    fn ik_failures(&self) -> PyResult<u32> {
        self.read(|d| d.episode.as_ref().map_or(0, |e| e.ik_failures))
    }

    /// The latest step's observation and the policy's action, `(obs, action)` as lists (the
    /// line `fairgrasp eval --trace` writes for a step); None before an episode's first act.
    fn last_step(&self) -> PyResult<Option<(Vec<f32>, Vec<f32>)>> {
        self.read(|d| d.episode.as_ref().and_then(|e| e.last.clone()))
    }

    /// The last estimated state's success-rule values: `grasped`, `lift` (m), `distance` (m),
    /// `opening` (m), `pad_contacts`; None before an episode.
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let values = self.read(|d| {
            d.episode.as_ref().map(|e| {
                let s = &e.state;
                (
                    s.grasped(0),
                    s.lift(0),
                    s.tcp_to_object(0).norm(),
                    s.gripper_opening as f64,
                    s.objects[0].pad_contacts,
                )
            })
        })?;
        let Some((grasped, lift, distance, opening, pads)) = values else {
            return Ok(None);
        };
        let dict = PyDict::new(py);
        dict.set_item("grasped", grasped)?;
        dict.set_item("lift", lift)?;
        dict.set_item("distance", distance)?;
        dict.set_item("opening", opening)?;
        dict.set_item("pad_contacts", pads.to_vec())?;
        Ok(Some(dict))
    }

    /// Why the arm will not move as the policy learnt under the deployment's default safety
    /// settings, if it will not (a model trained without `[control.servo]`); else None.
    #[getter]
    fn motion_mismatch(&self) -> PyResult<Option<String>> {
        self.read(|d| d.io.motion_mismatch(&SafetyConfig::default()))
    }

    /// Why the policy reads the world differently from how it learnt, if it does (a model
    /// trained without `[readings]`); else None.
    #[getter]
    fn observation_mismatch(&self) -> PyResult<Option<String>> {
        self.read(|d| d.io.observation_mismatch())
    }

    #[getter]
    fn env_id(&self) -> PyResult<String> {
        self.read(|d| d.env_id.clone())
    }

    /// Every setting of the model's env, defaults filled in, as TOML text (the physical
    /// figures a second simulator takes).
    fn config_toml(&self) -> PyResult<String> {
        let (id, table) = self.read(|d| (d.env_id.clone(), d.table.clone()))?;
        fairgrasp_env::registry::config_toml(&id, &table).map_err(env_error)
    }

    fn __repr__(&self) -> PyResult<String> {
        self.read(|d| {
            format!(
                "PolicyDriver({} on {}, {} set points per {:.4} s step)",
                d.policy.meta().algo.algo(),
                d.env_id,
                d.ticks,
                d.io.control_period
            )
        })
    }
}
