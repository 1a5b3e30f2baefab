//! `fairgrasp deploy`: a trained policy on a FAIRINO controller (or its digital twin), through
//! the safety layer. Dry run by default.

use anyhow::{Context, Result, bail};
use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::fairino::{ClientConfig, FairinoClient};
use fairgrasp_deploy::frame_source::{FrameSource, TcpFrames};
use fairgrasp_deploy::pose_source::{FixedPose, PoseSource, StreamedPose, parse_fixed_pose};
use fairgrasp_deploy::runner::{
    AfterSuccess, DeployOptions, Deployment, EpisodeHost, JsonLog, ModelIo, OperatorHost, TwinHost,
};
use fairgrasp_deploy::safety::SafetyConfig;
use fairgrasp_rl::Policy;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Where the robot is and how to reach it.
#[derive(clap::Args, Clone, Debug)]
pub struct RobotArgs {
    /// The controller's address (192.168.58.2 by default on the robot; 127.0.0.1 for the twin).
    #[arg(long)]
    pub robot: String,
    #[arg(long, default_value_t = 20003)]
    pub rpc_port: u16,
    #[arg(long, default_value_t = 20005)]
    pub cnde_port: u16,
    /// Timeout of every call (ms); MoveJ gets its own, longer one.
    #[arg(long, default_value_t = 200)]
    pub call_timeout_ms: u64,
    /// Send the servo commands over the controller's real-time UDP path (the SDK's
    /// `cmdType = 1`): no reply to wait for, so a slow controller cannot hold the loop back.
    /// Without it they go over XML-RPC, each waiting for its reply.
    #[arg(long)]
    pub servo_udp: bool,
    #[arg(long, default_value_t = fairgrasp_deploy::fairino::udp::DEFAULT_PORT)]
    pub servo_udp_port: u16,
}

impl RobotArgs {
    pub fn connect(&self) -> Result<FairinoClient> {
        let config = ClientConfig {
            rpc_port: self.rpc_port,
            cnde_port: self.cnde_port,
            call_timeout: Duration::from_millis(self.call_timeout_ms),
            servo_udp_port: self.servo_udp.then_some(self.servo_udp_port),
            ..ClientConfig::default()
        };
        FairinoClient::connect(&self.robot, &config)
            .with_context(|| format!("cannot connect to the controller at {}", self.robot))
    }

    pub fn rpc_addr(&self) -> String {
        format!("{}:{}", self.robot, self.rpc_port)
    }
}

#[derive(clap::Args)]
pub struct DeployArgs {
    #[command(flatten)]
    pub robot: RobotArgs,
    /// Model directory or run directory (its best model).
    #[arg(long)]
    pub model: PathBuf,
    /// Calibration file (`fairgrasp calibrate`). Without one the joints map one to one, which
    /// only the twin can be trusted with: a real controller then refuses --live.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Move the arm. Without it: a dry run that reads the robot and prints what it would send.
    #[arg(long)]
    pub live: bool,
    #[arg(long, default_value_t = 1)]
    pub episodes: u32,
    /// Control steps per episode (default: the model's episode length).
    #[arg(long)]
    pub steps: Option<u32>,
    /// Keep acting after the task's success rule has held (object lifted in the closed
    /// gripper for its hold steps), until --steps. By default the episode ends there, as it
    /// did in training.
    #[arg(long)]
    pub full_episodes: bool,
    /// Once the success rule has held: `put-down` lowers the object back to where the gripper
    /// closed on it, opens and withdraws; `hold` keeps the gripper closed (take the object
    /// out before confirming the next episode, whose start opens the gripper at home).
    #[arg(long, value_enum, default_value_t = AfterSuccessArg::PutDown)]
    pub after_success: AfterSuccessArg,
    /// Global speed scale in (0, 1] (overrides the safety file's; 0.25 by default): the
    /// policy's motion slowed in time, like a teach pendant's speed slider.
    #[arg(long)]
    pub speed_scale: Option<f64>,
    /// TOML file with a [safety] table (limits, caps, workspace box, deadline).
    #[arg(long)]
    pub safety: Option<PathBuf>,
    /// A fixed object pose: x,y,z in metres in the robot base frame, optionally ,yaw_deg.
    #[arg(long, conflicts_with_all = ["pose_udp", "pose_tcp"])]
    pub object_pose: Option<String>,
    /// With --object-pose and --live: move the arm although the pose never updates. The policy
    /// then never sees the object move when it nudges or pushes it, and may close on air or
    /// drive into it; live runs refuse a fixed pose without this flag.
    #[arg(long, requires = "object_pose")]
    pub static_object: bool,
    /// Receive object poses as JSON-line datagrams on this address (e.g. 0.0.0.0:20102).
    #[arg(long)]
    pub pose_udp: Option<String>,
    /// Read object poses as JSON lines from this TCP address (the twin's feed: IP:20100).
    #[arg(long)]
    pub pose_tcp: Option<String>,
    /// A camera policy's images: frames from this TCP address (the twin's camera feed at
    /// IP:20101, or your camera's server: examples/camera_feed.py; protocol in
    /// docs/deployment.md). With fairgrasp twin the twin's feed is the default.
    #[arg(long, value_name = "IP:PORT")]
    pub camera_tcp: Option<String>,
    /// The gripper's index on the controller.
    #[arg(long, default_value_t = 1)]
    pub gripper_index: u8,
    /// Every command sent and state received, as JSON lines. An existing file is kept: the
    /// log then goes to the first free NAME.2.jsonl, NAME.3.jsonl, … beside it.
    #[arg(long, default_value = "deploy_log.jsonl")]
    pub log: PathBuf,
    /// First episode seed for the twin's object placement (held-out by default).
    #[arg(long, default_value_t = fairgrasp_rl::train::HELD_OUT_SEED_BASE)]
    pub seed: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AfterSuccessArg {
    PutDown,
    Hold,
}

impl From<AfterSuccessArg> for AfterSuccess {
    fn from(arg: AfterSuccessArg) -> Self {
        match arg {
            AfterSuccessArg::PutDown => AfterSuccess::PutDown,
            AfterSuccessArg::Hold => AfterSuccess::Hold,
        }
    }
}

/// Reads a TOML file whose `[safety]` table overrides the defaults.
pub fn load_safety(path: Option<&Path>) -> Result<SafetyConfig> {
    let Some(path) = path else {
        return Ok(SafetyConfig::default());
    };
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        safety: SafetyConfig,
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let file: File =
        toml::from_str(&text).with_context(|| format!("invalid safety file {}", path.display()))?;
    file.safety
        .validate()
        .with_context(|| format!("invalid safety file {}", path.display()))?;
    Ok(file.safety)
}

/// Ctrl-C sets the flag the loops check every servo period.
pub fn interrupt_flag() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    ctrlc::set_handler(move || f.store(true, Ordering::Relaxed))
        .context("cannot install the Ctrl-C handler")?;
    Ok(flag)
}

pub fn run(args: &DeployArgs) -> Result<()> {
    if args.live && args.object_pose.is_some() && !args.static_object {
        bail!(
            "--object-pose with --live: a fixed pose never updates, so the policy would not see \
             the object move if it pushes it. Stream poses (--pose-udp, --pose-tcp) or, for an \
             object fixed in place, add --static-object"
        );
    }
    let policy = Policy::load(&args.model)
        .with_context(|| format!("cannot load model {}", args.model.display()))?;
    let mut safety = load_safety(args.safety.as_deref())?;
    if let Some(s) = args.speed_scale {
        safety.speed_scale = s;
    }
    let twin = TwinHost::detect(&args.robot.rpc_addr(), args.seed)
        .with_context(|| format!("the controller at {} does not answer", args.robot.robot))?;
    let calibration = match (&args.calib, &twin) {
        (Some(path), _) => Calibration::load(path)?,
        (None, Some(_)) => Calibration::identity(&ModelIo::for_policy(&policy)?.limits_rad),
        (None, None) if !args.live => {
            eprintln!("warning: no --calib; the dry run maps joints one to one");
            Calibration::identity(&ModelIo::for_policy(&policy)?.limits_rad)
        }
        (None, None) => bail!(
            "a real controller needs a calibration file: run `fairgrasp calibrate --robot {}` \
             and pass --calib",
            args.robot.robot
        ),
    };
    let mut pose: Box<dyn PoseSource> = if let Some(text) = &args.object_pose {
        Box::new(FixedPose(parse_fixed_pose(text)?))
    } else if let Some(bind) = &args.pose_udp {
        Box::new(StreamedPose::udp(bind)?)
    } else if let Some(addr) = &args.pose_tcp {
        Box::new(StreamedPose::tcp(addr, Duration::from_secs(1))?)
    } else if twin.is_some() {
        let addr = format!("{}:20100", args.robot.robot);
        Box::new(
            StreamedPose::tcp(&addr, Duration::from_secs(1))
                .with_context(|| format!("the twin's object-pose feed at {addr}"))?,
        )
    } else {
        bail!("where is the object? give --object-pose, --pose-udp or --pose-tcp");
    };
    let camera: Option<Box<dyn FrameSource>> = match (policy.image_space(), &args.camera_tcp) {
        (None, Some(_)) => bail!("--camera-tcp: the model reads no camera images"),
        (None, None) => None,
        (Some(space), given) => {
            let addr = match (given, twin.is_some()) {
                (Some(addr), _) => addr.clone(),
                (None, true) => format!("{}:20101", args.robot.robot),
                (None, false) => bail!(
                    "the model reads camera images ({}): give the camera feed's address \
                     (--camera-tcp IP:PORT; docs/deployment.md)",
                    space.describe()
                ),
            };
            let quiet = Duration::from_secs(2);
            Some(Box::new(
                TcpFrames::connect(&addr, space, Duration::from_secs(1), quiet)
                    .with_context(|| format!("the camera feed at {addr}"))?,
            ))
        }
    };
    let client = args.robot.connect()?;
    let interrupt = interrupt_flag()?;
    let options = DeployOptions {
        live: args.live,
        episodes: args.episodes,
        max_steps: args.steps,
        safety,
        gripper_index: args.gripper_index,
        end_at_success: !args.full_episodes,
        after_success: args.after_success.into(),
        ..DeployOptions::default()
    };
    let log = JsonLog::create(Some(&args.log))?;
    let mut deployment = Deployment::new(
        Box::new(client),
        policy,
        calibration,
        options.clone(),
        log.clone(),
        interrupt.clone(),
    )?;
    if let Some(frames) = camera {
        deployment.set_camera(frames);
    }
    for why in deployment.mismatches() {
        eprintln!("warning: {why}");
    }
    println!(
        "{} on {} ({}): {} episode(s), speed scale {}",
        if args.live { "LIVE" } else { "dry run" },
        args.robot.robot,
        if twin.is_some() {
            "fairgrasp twin"
        } else {
            "controller"
        },
        args.episodes,
        options.safety.speed_scale,
    );
    if let Some(path) = log.path() {
        println!("log: {}", path.display());
    }
    let mut operator = OperatorHost::stdin(interrupt);
    let mut twin_host = twin;
    let host: &mut dyn EpisodeHost = match &mut twin_host {
        Some(t) => t,
        None => &mut operator,
    };
    let report = deployment.run(host, pose.as_mut());
    log.flush();
    if let Some(problem) = log.health() {
        eprintln!("log: {problem}");
    }
    let report = report?;
    let judged: Vec<bool> = report.episodes.iter().filter_map(|e| e.success).collect();
    if !judged.is_empty() {
        println!(
            "grasps judged by the twin: {}/{}",
            judged.iter().filter(|s| **s).count(),
            judged.len()
        );
    }
    if let Some(fault) = report.fault {
        bail!(
            "stopped the arm after {} episode(s): {fault}",
            report.episodes.len()
        );
    }
    Ok(())
}
