//! `fairgrasp sysid`: identify the arm's drives (delay and lag per joint, the gripper's close
//! time) through the safety layer, and write the file the twin and training read. Dry run by
//! default.

use crate::deploy_cmd::{RobotArgs, interrupt_flag, load_safety};
use anyhow::{Context, Result, bail};
use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::fairino::error_code_meaning;
use fairgrasp_deploy::fairino::xmlrpc::Value;
use fairgrasp_deploy::runner::ModelIo;
use fairgrasp_deploy::safety::{SafetyFilter, Watchdog};
use fairgrasp_deploy::sysid::{ArmSim, ExcitationPlan, RecordOptions, identify, record};
use fairgrasp_env::GraspConfig;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct SysidArgs {
    #[command(flatten)]
    pub robot: RobotArgs,
    /// Move the arm (without it: print the plan and check it against the safety layer).
    #[arg(long)]
    pub live: bool,
    /// Joints to identify, one after another, e.g. `--joints 1,2,3`.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 2, 3, 4, 5, 6])]
    pub joints: Vec<usize>,
    /// Where to write the identified model. An existing file is never replaced: the run
    /// refuses before moving anything.
    #[arg(long, default_value = "sysid.toml")]
    pub out: PathBuf,
    /// How far each joint moves either way from the present pose (deg, at most 5).
    #[arg(long, default_value_t = 3.0)]
    pub amplitude_deg: f64,
    /// Calibration file (`fairgrasp calibrate`): soft limits, and the mapping to the
    /// simulator's joints. A real controller needs one for --live.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// TOML file with a [safety] table (limits, caps, workspace box, deadline).
    #[arg(long)]
    pub safety: Option<PathBuf>,
    /// Speed scale of the safety caps in force (1: the safety file's caps). The excitation
    /// itself stays under 20 deg/s and 250 deg/s², and under half the caps.
    #[arg(long, default_value_t = 1.0)]
    pub speed_scale: f64,
    /// The arm task whose simulated arm the drives are fitted against (default: the twin's
    /// when talking to one, else FaArmGrasp-v0).
    #[arg(long = "env")]
    pub env: Option<String>,
    /// MoveGripper speed for timing the gripper's close (%).
    #[arg(long, default_value_t = 50)]
    pub gripper_speed: u8,
    /// Leave the gripper alone.
    #[arg(long)]
    pub no_gripper: bool,
    #[arg(long, default_value_t = 1)]
    pub gripper_index: u8,
}

pub fn run(args: &SysidArgs) -> Result<()> {
    if args.out.exists() {
        bail!(
            "{} exists already; it is kept: give another --out, or move it away",
            args.out.display()
        );
    }
    let io = ModelIo::for_config(GraspConfig::default())?;
    let mut client = args.robot.connect()?;
    let twin_env = match client.call_raw("TwinInfo", &[]) {
        Ok(Value::Array(items))
            if items.get(1).and_then(Value::as_str) == Some(fairgrasp_deploy::twin::TWIN_NAME) =>
        {
            items.get(2).and_then(Value::as_str).map(str::to_string)
        }
        _ => None,
    };
    let calibration = match (&args.calib, &twin_env) {
        (Some(path), _) => Calibration::load(path)?,
        (None, Some(_)) => Calibration::identity(&io.limits_rad),
        (None, None) if !args.live => {
            eprintln!("warning: no --calib; the dry run maps joints one to one");
            Calibration::identity(&io.limits_rad)
        }
        (None, None) => bail!(
            "a real controller needs a calibration file: run `fairgrasp calibrate --robot {}` \
             and pass --calib",
            args.robot.robot
        ),
    };
    let mut safety = load_safety(args.safety.as_deref())?;
    safety.speed_scale = args.speed_scale;
    safety.validate().context("--speed-scale")?;
    let mut filter = SafetyFilter::new(
        &safety,
        &calibration.soft_limits(),
        io.nominal.table_z * 1000.0,
        io.arm_kinematics(&calibration),
    )?;
    let watchdog = Watchdog::new(
        Duration::from_secs_f64(safety.state_deadline_ms / 1000.0),
        error_code_meaning,
    );
    let (speed, acc, _) = filter.caps();
    let plan = ExcitationPlan::new(&args.joints, args.amplitude_deg, speed, acc)?;
    let env_id = (args.env.clone())
        .or(twin_env.clone())
        .unwrap_or_else(|| fairgrasp_env::ENV_ID.to_string());
    println!(
        "{} on {} ({}); fitting against the simulated arm of {env_id}",
        if args.live { "LIVE" } else { "dry run" },
        args.robot.robot,
        if twin_env.is_some() {
            "fairgrasp twin"
        } else {
            "controller"
        },
    );
    let interrupt = interrupt_flag()?;
    let options = RecordOptions {
        live: args.live,
        gripper_speed_percent: (!args.no_gripper).then_some(args.gripper_speed),
        gripper_index: args.gripper_index,
    };
    let Some(recording) = record(
        &mut client,
        &mut filter,
        &watchdog,
        &plan,
        &options,
        &interrupt,
    )?
    else {
        return Ok(());
    };
    println!(
        "recorded {} set points and {} states; fitting",
        recording.commands.len(),
        recording.states.len()
    );
    let in_sim = recording.map_joints(|q| {
        let v = calibration.to_sim_deg(q);
        std::array::from_fn(|i| v[i])
    });
    let started = Instant::now();
    let model = identify(&in_sim, &ArmSim::new(&env_id))?;
    for j in &model.joints {
        println!(
            "  joint {}: delay {:.1} ms, lag {:.1} ms (residual {:.4} deg RMS over {} readings)",
            j.joint, j.delay_ms, j.tau_ms, j.rms_residual_deg, j.samples
        );
    }
    if let Some(g) = &model.gripper {
        println!(
            "  gripper: closed in {:.2} s at {} % to {:.0} %{}",
            g.close_time_s,
            g.speed_percent,
            g.final_position_percent,
            if g.stalled { " (stalled)" } else { "" }
        );
    }
    println!("fitted in {:.1} s", started.elapsed().as_secs_f64());
    model.save_new(&args.out)?;
    println!(
        "wrote {}; rehearse on the twin with: fairgrasp twin --drives {}",
        args.out.display(),
        args.out.display()
    );
    Ok(())
}
