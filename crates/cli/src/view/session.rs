//! The viewer's session: one environment, its mode (policy, random, manual), play/pause, and
//! the renderer. It lives on its own thread; the HTTP thread sends it [`Request`]s.

use super::camera::Orbit;
use super::camera::RgbFrame;
use super::scene_env::SceneEnv;
use super::twin::TwinView;
use anyhow::{Context, Result, bail};
use fairgrasp_env::core::Info;
use fairgrasp_render::{Camera, Renderer};
use fairgrasp_rl::Policy;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;
use serde_json::{Value, json};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    Policy,
    Random,
    Manual,
    /// Show the digital twin's arm (`--twin`); the simulation does not step.
    Twin,
}

/// A command from the page (`POST /control`).
#[derive(Debug, Deserialize)]
#[serde(tag = "cmd", rename_all = "lowercase", deny_unknown_fields)]
pub enum Control {
    Play,
    Pause,
    Step,
    Reset,
    Mode {
        mode: Mode,
    },
    /// Joint targets in degrees, one per arm joint (manual mode).
    Joints {
        degrees: Vec<f64>,
    },
    Gripper {
        open: bool,
    },
}

/// What the HTTP thread asks; each carries where the answer goes.
pub enum Request {
    Control(Control, Sender<Result<(), String>>),
    State(Sender<Value>),
    /// An RGB frame (width, height, bytes) seen from the orbit.
    Frame(Orbit, Sender<Result<RgbFrame, String>>),
}

/// Most control steps one `joints` command runs while paused (6 rad at the default 0.05 rad a
/// step), so the arm gets there before the next frame.
const JOG_STEPS: u32 = 120;

pub struct Session {
    env: Box<dyn SceneEnv>,
    id: String,
    policy: Option<Policy>,
    rng: ChaCha8Rng,
    seed: u64,
    mode: Mode,
    playing: bool,
    obs: Vec<f32>,
    info: Option<Info>,
    reward: f32,
    episode_return: f32,
    episode: u32,
    episode_step: u32,
    total_steps: u64,
    done: bool,
    targets: Vec<f32>,
    gripper_open: bool,
    renderer: Option<Renderer>,
    size: (u32, u32),
    twin: Option<TwinView>,
}

impl Session {
    pub fn new(
        env: Box<dyn SceneEnv>,
        id: String,
        policy: Option<Policy>,
        seed: u64,
        size: (u32, u32),
        twin: Option<TwinView>,
    ) -> Result<Self> {
        let mode = if twin.is_some() {
            Mode::Twin
        } else if policy.is_some() {
            Mode::Policy
        } else {
            Mode::Random
        };
        let mut session = Self {
            env,
            id,
            policy,
            rng: ChaCha8Rng::seed_from_u64(seed),
            seed,
            mode,
            playing: false,
            obs: Vec::new(),
            info: None,
            reward: 0.0,
            episode_return: 0.0,
            episode: 0,
            episode_step: 0,
            total_steps: 0,
            done: false,
            targets: Vec::new(),
            gripper_open: true,
            renderer: None,
            size,
            twin,
        };
        session.reset()?;
        Ok(session)
    }

    /// Serves requests until every sender is gone; steps at the control rate while playing.
    pub fn run(mut self, requests: Receiver<Request>) {
        let period = Duration::from_secs_f32(self.env.scene().control_period().max(1e-3));
        let mut next = Instant::now();
        loop {
            let wait = if self.playing {
                next.saturating_duration_since(Instant::now())
            } else {
                Duration::from_secs(3600)
            };
            match requests.recv_timeout(wait) {
                Ok(request) => self.answer(request),
                Err(RecvTimeoutError::Timeout) => {
                    if self.playing {
                        if let Err(e) = self.step() {
                            tracing::warn!("step failed, pausing: {e:#}");
                            self.playing = false;
                        }
                        next = Instant::now() + period;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    fn answer(&mut self, request: Request) {
        // A dropped receiver means the client went away; nothing to do about it.
        match request {
            Request::Control(control, reply) => {
                let _ = reply.send(self.control(control).map_err(|e| format!("{e:#}")));
            }
            Request::State(reply) => {
                let _ = reply.send(self.state());
            }
            Request::Frame(orbit, reply) => {
                let _ = reply.send(self.frame(&orbit).map_err(|e| format!("{e:#}")));
            }
        }
    }

    fn control(&mut self, control: Control) -> Result<()> {
        match control {
            Control::Play => self.playing = true,
            Control::Pause => self.playing = false,
            Control::Step => {
                self.playing = false;
                self.step()?;
            }
            Control::Reset => self.reset()?,
            Control::Mode { mode } => {
                if mode == Mode::Policy && self.policy.is_none() {
                    bail!("policy mode needs a model (--model)");
                }
                if mode == Mode::Twin && self.twin.is_none() {
                    bail!("twin mode needs a twin (--twin ADDR)");
                }
                if mode == Mode::Manual && !self.env.joint_actions() {
                    bail!("manual mode needs joint actions (control.action_mode = \"joint\")");
                }
                self.mode = mode;
                self.sync_targets();
            }
            Control::Joints { degrees } => {
                if self.mode != Mode::Manual {
                    bail!(
                        "joint targets apply in manual mode; send {{\"cmd\":\"mode\",\"mode\":\"manual\"}} first"
                    );
                }
                let limits = self.env.scene().arm_limits();
                if degrees.len() != limits.len() {
                    bail!(
                        "expected {} joint angles, got {}",
                        limits.len(),
                        degrees.len()
                    );
                }
                for (i, (d, (lo, hi))) in degrees.iter().zip(&limits).enumerate() {
                    if !d.is_finite() {
                        bail!("joint {} angle must be finite", i + 1);
                    }
                    self.targets[i] = (d.to_radians() as f32).clamp(*lo, *hi);
                }
                self.jog()?;
            }
            Control::Gripper { open } => {
                self.gripper_open = open;
                if self.mode == Mode::Manual {
                    self.jog()?;
                }
            }
        }
        Ok(())
    }

    /// Manual mode while paused: step until the arm reaches the targets (or a few dozen steps).
    fn jog(&mut self) -> Result<()> {
        if self.playing {
            return Ok(());
        }
        for _ in 0..JOG_STEPS {
            self.step()?;
            let q = self.env.scene().arm_positions();
            if q.iter()
                .zip(&self.targets)
                .all(|(a, b)| (a - b).abs() < 0.005)
            {
                break;
            }
        }
        Ok(())
    }

    fn sync_targets(&mut self) {
        self.targets = self.env.scene().arm_positions();
    }

    fn reset(&mut self) -> Result<()> {
        let seed = self.seed.wrapping_add(self.episode as u64);
        let (obs, info) = self.env.reset(Some(seed))?;
        self.obs = obs;
        self.info = Some(info);
        self.episode += 1;
        self.episode_step = 0;
        self.reward = 0.0;
        self.episode_return = 0.0;
        self.done = false;
        self.gripper_open = true;
        self.sync_targets();
        Ok(())
    }

    fn step(&mut self) -> Result<()> {
        if self.mode == Mode::Twin {
            // The twin moves by itself; there is nothing to step here.
            return Ok(());
        }
        if self.done {
            // The ended episode's last state stayed on screen until now. A user jogging the
            // arm keeps their targets across the reset.
            let kept =
                (self.mode == Mode::Manual).then(|| (self.targets.clone(), self.gripper_open));
            self.reset()?;
            if let Some((targets, open)) = kept {
                (self.targets, self.gripper_open) = (targets, open);
            }
        }
        let space = self.env.action_space().clone();
        let mut action = match self.mode {
            Mode::Policy => {
                let policy = self.policy.as_mut().context("no model loaded")?;
                // Policies act in [-1, 1]; map to the env's bounds like RescaleAction.
                let a = policy.act_with_images(&self.obs, self.env.image(), true)?;
                a.iter()
                    .zip(space.low.iter().zip(&space.high))
                    .map(|(a, (lo, hi))| lo + (a.clamp(-1.0, 1.0) + 1.0) * 0.5 * (hi - lo))
                    .collect()
            }
            Mode::Random | Mode::Twin => space.sample(&mut self.rng),
            Mode::Manual => {
                let q = self.env.scene().arm_positions();
                let mut a: Vec<f32> = self.targets.iter().zip(&q).map(|(t, q)| t - q).collect();
                a.push(if self.gripper_open { 1.0 } else { -1.0 });
                a
            }
        };
        space.clip(&mut action);
        let step = self.env.step(&action)?;
        self.obs = step.obs;
        self.reward = step.reward;
        self.episode_return += step.reward;
        self.episode_step += 1;
        self.total_steps += 1;
        self.done = step.terminated || step.truncated;
        self.info = Some(step.info);
        Ok(())
    }

    fn frame(&mut self, orbit: &Orbit) -> Result<RgbFrame> {
        if let (Mode::Twin, Some(twin)) = (self.mode, self.twin.as_mut()) {
            return twin.frame(orbit, self.size);
        }
        let config = orbit.camera(self.size.0, self.size.1);
        let scene = self.env.scene();
        let renderer = match &mut self.renderer {
            Some(r) => {
                r.set_camera(Camera::new(config)?);
                r
            }
            None => self.renderer.insert(Renderer::with_config(scene, config)?),
        };
        renderer.render(scene)?;
        Ok((renderer.width(), renderer.height(), renderer.rgb().to_vec()))
    }

    fn state(&mut self) -> Value {
        if let (Mode::Twin, Some(twin)) = (self.mode, self.twin.as_mut()) {
            // A stalled stream shows the last angles read; the frame request reports the error.
            let _ = twin.update();
        }
        let scene = self.env.scene();
        let names = scene.arm_joint_names();
        let mut q = scene.arm_positions();
        if let (Mode::Twin, Some(twin)) = (self.mode, self.twin.as_ref()) {
            for (q, d) in q.iter_mut().zip(twin.joints_deg()) {
                *q = d.to_radians() as f32;
            }
        }
        let joints: Vec<Value> = names
            .iter()
            .zip(scene.arm_limits())
            .enumerate()
            .map(|(i, (name, (lo, hi)))| {
                json!({
                    "name": name,
                    "degrees": q[i].to_degrees(),
                    "target_degrees": self.targets.get(i).map(|t| t.to_degrees()),
                    "min_degrees": lo.to_degrees(),
                    "max_degrees": hi.to_degrees(),
                })
            })
            .collect();
        let named = |v: &fairgrasp_env::NamedValues| -> Value {
            v.iter()
                .map(|(k, x)| (k.to_string(), json!(x)))
                .collect::<serde_json::Map<_, _>>()
                .into()
        };
        let info = self.info.as_ref();
        let mut modes = vec!["random"];
        if self.policy.is_some() {
            modes.insert(0, "policy");
        }
        if self.env.joint_actions() {
            modes.push("manual");
        }
        if self.twin.is_some() {
            modes.push("twin");
        }
        json!({
            "env": self.id,
            "mode": match self.mode { Mode::Policy => "policy", Mode::Random => "random", Mode::Manual => "manual", Mode::Twin => "twin" },
            "modes": modes,
            "playing": self.playing,
            "episode": self.episode,
            "step": self.episode_step,
            "total_steps": self.total_steps,
            "reward": self.reward,
            "episode_return": self.episode_return,
            "done": self.done,
            "success": info.map(|i| i.success).unwrap_or(false),
            "reward_terms": info.map(|i| named(&i.reward_terms)).unwrap_or(Value::Null),
            "extras": info.map(|i| named(&i.extras)).unwrap_or(Value::Null),
            "joints": joints,
            "gripper_open": self.gripper_open,
            "gripper_opening": scene.gripper_opening(),
            "frame": {"width": self.size.0, "height": self.size.1},
            "twin": self.twin.as_ref().map(|t| t.addr()),
        })
    }
}
