//! `fairgrasp calibrate` and `fairgrasp jog-test`: the operator's steps before a policy runs.

use crate::deploy_cmd::{RobotArgs, load_safety};
use anyhow::{Context, Result, bail};
use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::commissioning::{
    CalibrationReadings, JogOptions, calibration_from_readings, jog_test,
};
use fairgrasp_deploy::fairino::error_code_meaning;
use fairgrasp_deploy::robot::RobotLink;
use fairgrasp_deploy::runner::ModelIo;
use fairgrasp_deploy::safety::{SafetyFilter, Watchdog};
use fairgrasp_env::GraspConfig;
use fairgrasp_rl::Policy;
use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The robot's kinematics and home pose: a model's, or the default grasp scene's.
fn model_io(model: Option<&PathBuf>) -> Result<ModelIo> {
    Ok(match model {
        Some(path) => {
            let policy = Policy::load(path)
                .with_context(|| format!("cannot load model {}", path.display()))?;
            ModelIo::for_policy(&policy)?
        }
        None => ModelIo::for_config(GraspConfig::default())?,
    })
}

fn line(prompt: &str) -> Result<String> {
    print!("{prompt} ");
    std::io::stdout().flush()?;
    let mut answer = String::new();
    if std::io::stdin().lock().read_line(&mut answer)? == 0 {
        bail!("no answer (end of input)");
    }
    Ok(answer.trim().to_lowercase())
}

#[derive(clap::Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    pub robot: RobotArgs,
    /// The model whose robot description to map (default: the bundled FR5).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Where to write the calibration (atomically).
    #[arg(long, default_value = "calibration.toml")]
    pub out: PathBuf,
    /// A label stored in the file (model, serial number).
    #[arg(long, default_value = "FR5")]
    pub label: String,
}

pub fn calibrate(args: &CalibrateArgs) -> Result<()> {
    let io = model_io(args.model.as_ref())?;
    let client = args.robot.connect()?;
    let home_sim_deg: [f64; 6] = std::array::from_fn(|i| (io.nominal.q[i] as f64).to_degrees());
    let read = || -> Result<[f64; 6]> {
        let s = client.state()?;
        anyhow::ensure!(
            s.received_at.elapsed() < Duration::from_millis(200),
            "the controller's state is stale"
        );
        Ok(s.state.joints_deg)
    };
    println!(
        "Step 1 of 2. With the teach pendant, move the arm to the simulator's home pose:\n  {}\n\
         (degrees, joints 1 to 6; if your robot's conventions match the simulator's, the \
         pendant shows the same values).",
        fmt6(&home_sim_deg)
    );
    line("Press Enter when the arm is there.")?;
    let at_home = read()?;
    println!("  read {}", fmt6(&at_home));
    println!(
        "Step 2 of 2. Jog every joint about +10 deg in the simulator's positive direction \
         (right-hand rule about the joint's axis; docs/deployment.md shows each one)."
    );
    line("Press Enter when all six have moved.")?;
    let after_jog = read()?;
    println!("  read {}", fmt6(&after_jog));
    let calibration = calibration_from_readings(
        &CalibrationReadings {
            home_sim_deg,
            at_home,
            after_jog,
        },
        &io.limits_rad,
        &args.label,
    )?;
    calibration.save(&args.out)?;
    for (i, j) in calibration.joints.iter().enumerate() {
        println!(
            "  joint {}: sign {:+}, offset {:+.2} deg, soft limits [{:.1}, {:.1}] deg",
            i + 1,
            j.sign,
            j.offset_deg,
            j.min_deg,
            j.max_deg
        );
    }
    println!(
        "wrote {}; next: fairgrasp jog-test --robot {} --calib {}",
        args.out.display(),
        args.robot.robot,
        args.out.display()
    );
    Ok(())
}

fn fmt6(v: &[f64; 6]) -> String {
    v.iter()
        .map(|x| format!("{x:.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[derive(clap::Args)]
pub struct JogArgs {
    #[command(flatten)]
    pub robot: RobotArgs,
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Calibration file (default: joints map one to one).
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// TOML file with a [safety] table (soft-limit margin, workspace box).
    #[arg(long)]
    pub safety: Option<PathBuf>,
    /// Jog size (deg, at most 10).
    #[arg(long, default_value_t = 5.0)]
    pub degrees: f64,
    /// MoveJ speed (% of the maximum, at most 30).
    #[arg(long, default_value_t = 10.0)]
    pub speed_percent: f64,
    /// Joints to test, e.g. `--joints 1,2,3`.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 2, 3, 4, 5, 6])]
    pub joints: Vec<usize>,
    /// Move the arm (without it: print the moves).
    #[arg(long)]
    pub live: bool,
    /// Answer yes for the operator (a twin rehearsal; never at a real robot).
    #[arg(long)]
    pub yes: bool,
}

pub fn jog(args: &JogArgs) -> Result<()> {
    let io = model_io(args.model.as_ref())?;
    let calibration = match &args.calib {
        Some(p) => Calibration::load(p)?,
        None => {
            eprintln!("warning: no --calib: joints map one to one");
            Calibration::identity(&io.limits_rad)
        }
    };
    let safety = load_safety(args.safety.as_deref())?;
    let fk = io.arm_kinematics(&calibration);
    let filter = SafetyFilter::new(
        &safety,
        &calibration.soft_limits(),
        io.nominal.table_z * 1000.0,
        fk,
    )?;
    let watchdog = Watchdog::new(
        Duration::from_secs_f64(safety.state_deadline_ms / 1000.0),
        error_code_meaning,
    );
    let mut client = args.robot.connect()?;
    let yes = args.yes;
    let mut ask = |q: &str| -> fairgrasp_deploy::Result<bool> {
        if yes {
            println!("{q} y (--yes)");
            return Ok(true);
        }
        loop {
            match line(q)
                .map_err(|e| fairgrasp_deploy::DeployError::Other(e.to_string()))?
                .as_str()
            {
                "y" | "yes" => return Ok(true),
                "n" | "no" => return Ok(false),
                _ => println!("answer y or n"),
            }
        }
    };
    let started = Instant::now();
    let outcomes = jog_test(
        &mut client as &mut dyn RobotLink,
        &calibration,
        &filter,
        &watchdog,
        &JogOptions {
            degrees: args.degrees,
            speed_percent: args.speed_percent,
            joints: args.joints.clone(),
            live: args.live,
        },
        &mut ask,
    )?;
    let mut wrong = Vec::new();
    for o in &outcomes {
        let moved_ok = !args.live || (o.measured_deg - o.jog_deg).abs() < 0.5;
        println!(
            "joint {}: commanded {:+.2} deg, measured {:+.2} deg{}",
            o.joint,
            o.jog_deg,
            o.measured_deg,
            match o.confirmed {
                Some(true) => ", direction confirmed",
                Some(false) => ", direction WRONG",
                None => "",
            }
        );
        if o.confirmed == Some(false) || !moved_ok {
            wrong.push(o.joint);
        }
    }
    println!("jog test took {:.1} s", started.elapsed().as_secs_f64());
    if !wrong.is_empty() {
        bail!(
            "joints {wrong:?} did not move as expected: flip their sign (or fix their offset) \
             in the calibration file, or re-run fairgrasp calibrate"
        );
    }
    Ok(())
}
