//! `fairgrasp`: the command-line face of the project. Thin: every command parses its arguments,
//! calls the library crates and prints.

mod bench;
mod bench_cnn;
mod bench_learning;
mod bench_sac;
mod camera_check_cmd;
mod commission_cmd;
mod demo;
mod deploy_cmd;
mod distill_cmd;
mod env_cmd;
mod eval_cmd;
mod eval_deployment;
mod export_cmd;
mod host;
mod inspect;
mod plot_cmd;
mod record_cmd;
mod robustness_cmd;
mod scene_args;
mod sysid_cmd;
mod train_cmd;
mod twin_cmd;
mod view;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "fairgrasp",
    version,
    about = "Teach a FAIRINO arm to grasp: simulation, learning, deployment"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print a robot description's joints, chain and flange pose (like PyBullet's getJointInfo).
    Inspect(inspect::InspectArgs),
    /// Run a demonstration in simulation.
    #[command(subcommand)]
    Demo(demo::DemoCommand),
    /// Train a grasp policy (PPO, SAC or TD3) with evaluation, checkpoints, resume and TensorBoard logs.
    Train(train_cmd::TrainArgs),
    /// Evaluate a saved model on held-out episodes (success rate, mean return and length).
    Eval(eval_cmd::EvalArgs),
    /// Teach a camera policy from a trained state policy (teacher–student distillation, DAgger)
    /// and evaluate it alone on held-out episodes.
    Distill(distill_cmd::DistillArgs),
    /// Plot runs' learning curves (success rate and return against env steps and wall time)
    /// from their progress.csv into one PNG or SVG.
    Plot(plot_cmd::PlotArgs),
    /// Record episodes of a saved model (or random actions) as an animated GIF, with an
    /// overlay of the step, return and success.
    Record(record_cmd::RecordArgs),
    /// Export a saved model as ONNX (raw observation → action) or standalone safetensors.
    Export(export_cmd::ExportArgs),
    /// Evaluate a saved model over a grid of held-out conditions (mass, friction, latency,
    /// observation noise, joint offsets).
    Robustness(robustness_cmd::RobustnessArgs),
    /// Check, exercise and measure the grasp environment (FaArmGrasp-v0).
    #[command(subcommand)]
    Env(env_cmd::EnvCommand),
    /// Run a trained policy on a FAIRINO controller or its digital twin (dry run unless --live).
    Deploy(deploy_cmd::DeployArgs),
    /// Write a calibration file (joint signs, offsets, soft limits) from readings of the robot.
    Calibrate(commission_cmd::CalibrateArgs),
    /// Move each joint a few degrees and back, the operator confirming each direction.
    JogTest(commission_cmd::JogArgs),
    /// Read a camera feed as the deployment would and report each camera's frames, rate and
    /// age: check a camera policy's feed before deploying it.
    CameraCheck(camera_check_cmd::CameraCheckArgs),
    /// Identify the arm's drives (delay and lag per joint, the gripper's close time) with small,
    /// slow moves through the safety layer; write the file the twin reads (dry run unless --live).
    Sysid(sysid_cmd::SysidArgs),
    /// Measure simulator throughput.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Serve a digital twin of the FAIRINO controller (XML-RPC 20003, CNDE 20005), backed by the simulator.
    Twin(twin_cmd::TwinArgs),
    /// Serve a page on loopback that shows the scene live: play, step, reset, policy, random or
    /// manual (joint sliders) mode, the last step's reward terms, an orbit camera.
    View(view::ViewArgs),
}

#[cfg(unix)]
fn end_on_broken_pipe() {
    // SAFETY: called before this process starts any thread; SIG_DFL is a valid disposition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn end_on_broken_pipe() {}

fn main() -> std::process::ExitCode {
    // candle sizes its matrix-multiply parallelism from RAYON_NUM_THREADS. Our networks are
    // small: on one thread a SAC gradient step is ~2.5x faster than on two, and a PPO run a few
    // percent faster (the environments keep their own thread pool). A user's setting wins.
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        // SAFETY: nothing else runs yet; no other thread can read the environment concurrently.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", "1") };
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    // Commands that only print end quietly when their reader stops early (`fairgrasp bench cnn |
    // head`), as Unix tools do, instead of panicking in `println!` (Rust ignores SIGPIPE).
    // Commands that serve or drive keep ignoring it: a closed socket is an error they handle.
    if matches!(
        cli.command,
        Command::Inspect(_) | Command::Bench(_) | Command::Eval(_) | Command::Plot(_)
    ) {
        end_on_broken_pipe();
    }
    if let Err(e) = fairgrasp_rl::kernels::product::ProductKernel::from_env() {
        eprintln!("error: {e}");
        return std::process::ExitCode::FAILURE;
    }
    let result = match cli.command {
        Command::Inspect(args) => inspect::run(&args),
        Command::Demo(command) => demo::run(command),
        Command::Train(args) => train_cmd::run(&args),
        Command::Distill(args) => distill_cmd::run(&args),
        Command::Eval(args) => eval_cmd::run(&args),
        Command::Plot(args) => plot_cmd::run(&args),
        Command::Record(args) => record_cmd::run(&args),
        Command::Export(args) => export_cmd::run(&args),
        Command::Robustness(args) => robustness_cmd::run(&args),
        Command::Env(command) => env_cmd::run(command),
        Command::Bench(command) => bench::run(command),
        Command::Deploy(args) => deploy_cmd::run(&args),
        Command::Calibrate(args) => commission_cmd::calibrate(&args),
        Command::JogTest(args) => commission_cmd::jog(&args),
        Command::Sysid(args) => sysid_cmd::run(&args),
        Command::CameraCheck(args) => camera_check_cmd::run(&args),
        Command::Twin(args) => twin_cmd::run(&args),
        Command::View(args) => view::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
