//! `fairgrasp twin`: the simulated FAIRINO controller on the controller's own ports, until
//! Ctrl-C. Prints each judged episode and the running tally.

use anyhow::{Context, Result};
use fairgrasp_deploy::twin::controller::StartState;
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::{EpisodeResult, Twin, TwinConfig};
use fairgrasp_env::config::{apply_override, read_table};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(clap::Args, Debug)]
pub struct TwinArgs {
    /// The arm task staged: its scene and its success rule (default: the model's, else
    /// FaArmGrasp-v0).
    #[arg(long = "env")]
    pub env: Option<String>,
    /// Stage the environment this model was trained on (its scene and task settings).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// TOML file with the environment's settings (instead of a model's).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override a setting: `--set scene.objects.0.mass=0.2`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Address to serve on. Loopback by default; anything else exposes a robot controller's
    /// interface to the network.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    #[arg(long, default_value_t = 20003)]
    pub rpc_port: u16,
    #[arg(long, default_value_t = 20005)]
    pub cnde_port: u16,
    /// UDP port of the real-time servo commands (the SDK's `cmdType = 1`).
    #[arg(long, default_value_t = fairgrasp_deploy::fairino::udp::DEFAULT_PORT)]
    pub servo_udp_port: u16,
    /// Serve no real-time servo port.
    #[arg(long)]
    pub no_servo_udp: bool,
    /// TCP port of the object-pose feed (JSON lines, robot base frame).
    #[arg(long, default_value_t = 20100)]
    pub pose_port: u16,
    /// Serve no object-pose feed over TCP.
    #[arg(long)]
    pub no_pose_feed: bool,
    /// TCP port of the camera feed, served when the staged environment observes camera images
    /// (a camera policy's model): frames of docs/deployment.md's protocol.
    #[arg(long, default_value_t = 20101)]
    pub camera_port: u16,
    /// Serve no camera feed.
    #[arg(long)]
    pub no_camera_feed: bool,
    /// Also send the object pose as UDP datagrams to this address.
    #[arg(long, value_name = "IP:PORT")]
    pub pose_udp: Option<SocketAddr>,
    /// Delay every XML-RPC reply by this much (ms).
    #[arg(long, default_value_t = 0.0)]
    pub latency_ms: f64,
    /// Gaussian noise on the reported joint angles (standard deviation, degrees).
    #[arg(long, default_value_t = 0.0)]
    pub joint_noise_deg: f64,
    /// Any other fault from the start, `NAME=VALUE` (repeatable): stream_latency_ms,
    /// pose_noise_mm, slow, stall, error, estop, safety_stop, latency_jitter_ms,
    /// latency_outliers, drop_frames, late_frames, tracking, following_error_deg,
    /// servoj_speed_tolerance, brake_decel_deg_s2, collision_level_n, collision (see the twin's
    /// documentation).
    #[arg(long = "fault", value_name = "NAME=VALUE")]
    pub faults: Vec<String>,
    /// A controller as strict as a real one on a real network: drives 8 ms behind their set
    /// points with a 15 ms lag, replies jittering (2 ms, one in 200 a further 30 ms late), one
    /// CNDE frame in 100 lost and one in 100 held 20 ms, collision detection at 150 N.
    /// `--fault` flags given too apply after.
    #[arg(long)]
    pub strict: bool,
    /// The drives' delay and lag from a `fairgrasp sysid` file: the twin's arm then follows
    /// its set points as the identified arm does. Applies after --strict; --fault after it.
    #[arg(long, value_name = "SYSID.toml")]
    pub drives: Option<PathBuf>,
    /// Seed of the first cube placement and of the injected noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write every XML-RPC call received as JSON lines to this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Start with the drives disabled (RobotEnable(1) needed before motion).
    #[arg(long)]
    pub start_disabled: bool,
    /// Start in manual mode (Mode(0) needed before remote motion).
    #[arg(long)]
    pub start_manual: bool,
    /// Start with the gripper already activated.
    #[arg(long)]
    pub gripper_active: bool,
    /// Stop after this many seconds instead of waiting for Ctrl-C.
    #[arg(long)]
    pub seconds: Option<f64>,
}

/// The env id and settings table to stage.
fn environment(args: &TwinArgs) -> Result<(String, toml::Table)> {
    let (model_id, mut table) = match &args.model {
        Some(path) => {
            anyhow::ensure!(
                args.config.is_none(),
                "give either --model or --config, not both"
            );
            let dir = fairgrasp_rl::model::resolve_model_dir(path)
                .with_context(|| format!("cannot find a model at {}", path.display()))?;
            let meta = fairgrasp_rl::model::ModelMeta::load(&dir)?;
            let table = fairgrasp_rl::model::env_table(&meta.env).with_context(|| {
                format!(
                    "{}: the environment settings",
                    dir.join("model.json").display()
                )
            })?;
            (Some(meta.env_id), table)
        }
        None => (
            None,
            match &args.config {
                Some(path) => read_table(path)?,
                None => toml::Table::new(),
            },
        ),
    };
    let id = match (&args.env, model_id) {
        (Some(env), Some(model)) if *env != model => {
            anyhow::bail!("--env {env} differs from the model's environment {model}")
        }
        (Some(env), _) => env.clone(),
        (None, Some(model)) => model,
        (None, None) => fairgrasp_env::ENV_ID.to_string(),
    };
    for item in &args.overrides {
        apply_override(&mut table, item).context("invalid --set")?;
    }
    fairgrasp_env::registry::validate(&id, &table)
        .with_context(|| format!("invalid settings for {id}"))?;
    Ok((id, table))
}

fn faults(args: &TwinArgs) -> Result<Vec<FaultCommand>> {
    let mut faults = if args.strict {
        fairgrasp_deploy::twin::faults::strict()
    } else {
        Vec::new()
    };
    if let Some(path) = &args.drives {
        let model = fairgrasp_deploy::sysid::DriveModel::load(path)?;
        faults.push(FaultCommand::Tracking(model.tracking()));
    }
    if args.latency_ms != 0.0 {
        faults.push(
            FaultCommand::parse("latency_ms", &args.latency_ms.to_string())
                .map_err(|e| anyhow::anyhow!("--latency-ms: {e}"))?,
        );
    }
    if args.joint_noise_deg != 0.0 {
        faults.push(
            FaultCommand::parse("joint_noise_deg", &args.joint_noise_deg.to_string())
                .map_err(|e| anyhow::anyhow!("--joint-noise-deg: {e}"))?,
        );
    }
    for item in &args.faults {
        faults.push(
            FaultCommand::parse_assignment(item).map_err(|e| anyhow::anyhow!("--fault: {e}"))?,
        );
    }
    Ok(faults)
}

fn describe(e: &EpisodeResult) -> String {
    format!(
        "episode {} (seed {}): {}, max lift {:.0} mm, {} control steps{}",
        e.number,
        e.seed,
        if e.success { "SUCCESS" } else { "failure" },
        e.max_lift * 1000.0,
        e.steps,
        if e.failed {
            ", the object left the table"
        } else {
            ""
        }
    )
}

pub fn run(args: &TwinArgs) -> Result<()> {
    if let Some(s) = args.seconds {
        anyhow::ensure!(s.is_finite() && s > 0.0, "--seconds must be positive");
    }
    let (env_id, env_config) = environment(args)?;
    let config = TwinConfig {
        env_id,
        env_config,
        bind: args.bind,
        rpc_port: args.rpc_port,
        cnde_port: args.cnde_port,
        servo_udp_port: (!args.no_servo_udp).then_some(args.servo_udp_port),
        pose_port: (!args.no_pose_feed).then_some(args.pose_port),
        pose_udp: args.pose_udp,
        camera_port: (!args.no_camera_feed).then_some(args.camera_port),
        seed: args.seed,
        start: StartState {
            enabled: !args.start_disabled,
            automatic: !args.start_manual,
            gripper_active: args.gripper_active,
        },
        faults: faults(args)?,
        log: args.log.clone(),
        ..TwinConfig::default()
    };
    if !args.bind.is_loopback() {
        eprintln!(
            "warning: serving on {} — other machines can command this twin",
            args.bind
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("cannot install the Ctrl-C handler")?;
    }
    let faults_text: Vec<String> = config.faults.iter().map(|f| f.to_string()).collect();
    let twin = Twin::spawn(config).context("cannot start the twin")?;
    println!(
        "fairgrasp twin of a FAIRINO controller, staging {}",
        twin.env_id()
    );
    println!("  XML-RPC      http://{}/RPC2", twin.rpc_addr());
    println!("  CNDE stream  {}", twin.cnde_addr());
    if let Some(addr) = twin.servo_udp_addr() {
        println!("  servo UDP    {addr} (real-time ServoJ, cmdType 1)");
    }
    match twin.pose_addr() {
        Some(addr) => println!("  object pose  {addr} (JSON lines, robot base frame)"),
        None => println!("  object pose  no TCP feed"),
    }
    if let Some(udp) = args.pose_udp {
        println!("  object pose  UDP datagrams to {udp}");
    }
    if let Some(addr) = twin.camera_addr() {
        println!("  camera       {addr} (frames: a JSON header line, then the pixels)");
    }
    if !faults_text.is_empty() {
        println!("  faults       {}", faults_text.join("; "));
    }
    println!("Ctrl-C to stop.");

    let started = Instant::now();
    let mut printed = 0;
    let mut overruns = 0;
    loop {
        let done = stop.load(Ordering::SeqCst)
            || args
                .seconds
                .is_some_and(|s| started.elapsed().as_secs_f64() >= s);
        let tally = twin.tally();
        for (i, e) in tally.results.iter().enumerate().skip(printed) {
            let successes = tally.results[..=i].iter().filter(|r| r.success).count();
            println!("{}  (tally {successes}/{})", describe(e), i + 1);
        }
        printed = tally.results.len();
        let now_overruns = twin.overruns();
        if now_overruns > overruns {
            eprintln!("warning: the physics fell behind real time ({now_overruns} times)");
            overruns = now_overruns;
        }
        if done {
            let current = twin.episode();
            println!("current {}", describe(&current));
            println!(
                "tally: {} of {} episodes succeeded (the task's rule)",
                tally.successes, tally.episodes
            );
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        twin: TwinArgs,
    }

    fn args(line: &[&str]) -> TwinArgs {
        Cli::try_parse_from(std::iter::once("twin").chain(line.iter().copied()))
            .unwrap()
            .twin
    }

    #[test]
    fn environment_and_faults_from_flags() {
        let a = args(&[
            "--set",
            "task.success_min_lift=0.04",
            "--latency-ms",
            "10",
            "--joint-noise-deg",
            "0.05",
            "--fault",
            "slow=MoveJ:500",
        ]);
        let (id, table) = environment(&a).unwrap();
        assert_eq!(id, "FaArmGrasp-v0");
        assert!(table.contains_key("task"));
        let f = faults(&a).unwrap();
        assert_eq!(f.len(), 3);
        assert_eq!(f[0], FaultCommand::LatencyMs(10.0));
        let bad = args(&["--fault", "teleport=1"]);
        assert!(faults(&bad).unwrap_err().to_string().contains("teleport"));
        let bad = args(&["--set", "task.nonsense=1"]);
        assert!(environment(&bad).is_err());
        let bad = args(&["--env", "Pendulum-v1"]);
        assert!(environment(&bad).is_ok(), "checked when the twin starts");
        let missing = args(&["--model", "/nonexistent/model"]);
        assert!(environment(&missing).is_err());
    }

    #[test]
    fn strict_turns_on_the_documented_set_and_flags_apply_after() {
        let strict = fairgrasp_deploy::twin::faults::strict();
        let a = args(&["--strict", "--fault", "tracking=off"]);
        let f = faults(&a).unwrap();
        assert_eq!(f.len(), strict.len() + 1);
        assert_eq!(&f[..strict.len()], &strict[..]);
        assert_eq!(f.last(), Some(&FaultCommand::Tracking(Default::default())));
        assert!(
            strict
                .iter()
                .any(|f| matches!(f, FaultCommand::Tracking(m) if m[0].tau_ms > 0.0))
        );
        assert!(faults(&args(&[])).unwrap().is_empty());
    }

    #[test]
    fn drives_come_from_a_sysid_file_and_a_bad_one_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sysid.toml");
        std::fs::write(
            &path,
            "env = \"FaArmGrasp-v0\"\n[[joints]]\njoint = 2\ndelay_ms = 12.0\ntau_ms = 30.0\n\
             rms_residual_deg = 0.01\nsamples = 900\n",
        )
        .unwrap();
        let p = path.to_str().unwrap();
        let f = faults(&args(&["--strict", "--drives", p])).unwrap();
        let Some(FaultCommand::Tracking(m)) = f.last() else {
            panic!("{f:?}")
        };
        assert_eq!((m[1].delay_ms, m[1].tau_ms), (12.0, 30.0));
        assert_eq!(
            m[0].tau_ms, 0.0,
            "joints not identified have no extra drive"
        );
        std::fs::write(&path, "env = \"x\"\n[[joints]]\njoint = 9\n").unwrap();
        let e = faults(&args(&["--drives", p])).unwrap_err();
        assert!(format!("{e:#}").contains("sysid.toml"), "{e:#}");
    }
}
