//! The `fairgrasp` binary as a user runs it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fairgrasp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args(args)
        .env_remove("ROS_PACKAGE_PATH")
        .env_remove("FAIRGRASP_PACKAGE_PATH")
        .output()
        .expect("run fairgrasp")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn text(output: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn inspect_prints_joint_table_chain_and_flange_pose_of_the_bundled_fr5() {
    let urdf = repo().join("assets/robots/fr5/urdf/fr5.urdf");
    let out = fairgrasp(&["inspect", urdf.to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    for expected in [
        "robot 'fr5'",
        "j1",
        "revolute",
        "base_link",
        "shoulder_link",
        "-4.6251",
        "150.0000",
        "3.2000",
        "chain: base_link -> shoulder_link -> upperarm_link -> forearm_link -> wrist1_link -> wrist2_link -> wrist3_link -> tool0",
        "xyz = (-0.8200, -0.2021, 0.0500)",
    ] {
        assert!(
            stdout.contains(expected),
            "missing {expected:?} in:\n{stdout}"
        );
    }
}

#[test]
fn an_unknown_image_kernel_is_refused_by_name() {
    let urdf = repo().join("assets/robots/fr5/urdf/fr5.urdf");
    let out = Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args(["inspect", urdf.to_str().unwrap()])
        .env("FAIRGRASP_IMAGE_KERNEL", "avx9")
        .output()
        .expect("run fairgrasp");
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("FAIRGRASP_IMAGE_KERNEL=avx9") && stderr.contains("expected avx2 or gemm"),
        "{stderr}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args(["inspect", urdf.to_str().unwrap()])
        .env("FAIRGRASP_IMAGE_KERNEL", "gemm")
        .output()
        .expect("run fairgrasp");
    assert!(out.status.success(), "{}", text(&out).1);
}

#[test]
fn a_reader_that_stops_early_ends_an_output_command_without_a_panic() {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args(["bench", "cnn", "--batch", "1", "--seconds", "0.2"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run fairgrasp");
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    // The reader is gone; the next lines are written into a closed pipe.
    assert!(first.starts_with("CPU: "), "{first}");
    let out = child.wait_with_output().expect("wait for fairgrasp");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
}

#[test]
fn inspect_resolves_package_meshes_from_a_flag() {
    let data = repo().join("crates/sim/tests/data/mesh_robot");
    let urdf = data.join("mesh_robot_description/urdf/arm.urdf");
    let out = fairgrasp(&[
        "inspect",
        urdf.to_str().unwrap(),
        "--package-path",
        data.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains("package://mesh_robot_description/meshes/base.stl"),
        "{stdout}"
    );
    assert!(stdout.contains("triangles"), "{stdout}");
    assert!(stdout.contains("chain: "), "{stdout}");
}

#[test]
fn inspect_reports_a_broken_urdf_without_panicking() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.urdf");
    std::fs::write(
        &bad,
        r#"<robot name="r"><link name="a"/><link name="b"/>
           <joint name="j" type="hinge"><parent link="a"/><child link="b"/></joint></robot>"#,
    )
    .unwrap();
    let out = fairgrasp(&["inspect", bad.to_str().unwrap()]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("joint 'j'") && stderr.contains("hinge"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");

    let xacro = dir.path().join("arm.urdf.xacro");
    std::fs::write(
        &xacro,
        "<robot name=\"r\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n\
         <xacro:include filename=\"arm_macros.xacro\"/>\n</robot>",
    )
    .unwrap();
    let (_, stderr) = text(&fairgrasp(&["inspect", xacro.to_str().unwrap()]));
    assert!(
        stderr.contains("line 2")
            && stderr.contains("<xacro:include>")
            && stderr.contains("expand it"),
        "{stderr}"
    );

    let (_, stderr) = text(&fairgrasp(&["inspect", "/no/such/robot.urdf"]));
    assert!(stderr.contains("/no/such/robot.urdf"), "{stderr}");
}

#[test]
fn scripted_pick_demo_reports_success_rate_and_drift() {
    let out = fairgrasp(&["demo", "scripted-pick", "--episodes", "3", "--seed", "40"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("success: 3/3"), "{stdout}");
    assert!(stdout.contains("drift"), "{stdout}");
}

#[test]
fn scripted_pick_demo_breaks_failures_down_by_reason() {
    let dir = tempfile::tempdir().unwrap();
    let heavy = dir.path().join("heavy.toml");
    // 45 N of cube: held while still, it slides out once the lift accelerates it.
    std::fs::write(
        &heavy,
        "[[objects]]\nname = \"cube\"\nshape = { kind = \"box\", size = [0.05, 0.05, 0.05] }\nmass = 4.6\n",
    )
    .unwrap();
    let out = fairgrasp(&[
        "demo",
        "scripted-pick",
        "--episodes",
        "2",
        "--verbose",
        "--config",
        heavy.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("success: 0/2"), "{stdout}");
    assert!(
        stdout.contains("FAILED (the object slipped out of the fingers"),
        "{stdout}"
    );
    assert!(
        stdout.contains("failures by reason:\n      2  object slipped out of the fingers\n"),
        "{stdout}"
    );
}

#[test]
fn config_errors_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("[physics]\nsubsteps = 0\n", "physics.substeps"),
        (
            "[[objects]]\nname = \"cube\"\nshape = { kind = \"sphere\", radius = 0.02 }\nmass = -0.1\n",
            "objects[0].mass",
        ),
        ("[gripper]\nforce_limt = 10.0\n", "force_limt"),
        ("[tabel]\nheight = 0.7\n", "tabel"),
        ("[physics]\ndt = \"fast\"\n", "dt"),
    ];
    for (i, (toml, key)) in cases.iter().enumerate() {
        let path = dir.path().join(format!("c{i}.toml"));
        std::fs::write(&path, toml).unwrap();
        let out = fairgrasp(&[
            "demo",
            "scripted-pick",
            "--episodes",
            "1",
            "--config",
            path.to_str().unwrap(),
        ]);
        let (_, stderr) = text(&out);
        assert!(!out.status.success(), "{toml} accepted");
        assert!(stderr.contains(key), "{toml}: {stderr}");
    }
    let (_, stderr) = text(&fairgrasp(&["demo", "scripted-pick", "--physics-hz=-5"]));
    assert!(stderr.contains("--physics-hz"), "{stderr}");
}

/// A training configuration small enough for a test: 2 envs, 256 steps per PPO iteration.
const TINY_TRAIN_TOML: &str = "total_timesteps = 200000\nn_envs = 2\nthreads = 1\n\
    checkpoint_freq = 512\n[eval]\nfreq = 1024\nepisodes = 1\n\
    [ppo]\nn_steps = 128\nbatch_size = 128\nn_epochs = 1\n\
    [env.task]\nmax_episode_steps = 20\n[env.reward]\nkind = \"staged\"\n";

/// `fairgrasp train --quiet` on [`TINY_TRAIN_TOML`] into `dir/run`, in the background, returned
/// once the run has written its checkpoint at `step` (with the config and run paths).
fn tiny_training_past_checkpoint(
    dir: &Path,
    step: u64,
    output: fn() -> std::process::Stdio,
) -> (std::process::Child, PathBuf, PathBuf) {
    let config = dir.join("tiny.toml");
    std::fs::write(&config, TINY_TRAIN_TOML).unwrap();
    let run = dir.join("run");
    let mut child = Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args(["train", "--quiet", "--config"])
        .arg(&config)
        .arg("--run-dir")
        .arg(&run)
        .stdout(output())
        .stderr(output())
        .spawn()
        .unwrap();
    let checkpoint = run.join(format!("checkpoints/step_{step}/trainer_state.json"));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(300);
    while !checkpoint.exists() {
        assert!(child.try_wait().unwrap().is_none(), "training exited early");
        assert!(std::time::Instant::now() < deadline, "no checkpoint");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    (child, config, run)
}

#[test]
fn ctrl_c_stops_training_with_its_final_model_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    // After the first checkpoint, one SIGINT: the run ends after that iteration, far short of
    // its 200,000 steps, and writes what a finished run writes.
    let (child, _, run) =
        tiny_training_past_checkpoint(dir.path(), 512, std::process::Stdio::piped);
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("stopped early by Ctrl-C"), "{stdout}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["stopped"], true);
    let steps = summary["num_timesteps"].as_u64().unwrap();
    assert!((512..200_000).contains(&steps), "{steps} steps");
    assert!(run.join("final/model.json").is_file());
}

#[test]
fn training_killed_with_sigkill_resumes_from_its_last_checkpoint_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    // After the second checkpoint, kill -9 in the middle of training.
    let (mut child, config, run) =
        tiny_training_past_checkpoint(dir.path(), 1024, std::process::Stdio::null);
    let (config_arg, run_arg) = (config.to_str().unwrap(), run.to_str().unwrap());
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(!run.join("final").exists());

    // Starting a new run over it is refused; resuming continues it to the (new) end.
    let out = fairgrasp(&["train", "--config", config_arg, "--run-dir", run_arg]);
    let (_, stderr) = text(&out);
    assert!(
        !out.status.success() && stderr.contains("--resume"),
        "{stderr}"
    );
    let out = fairgrasp(&[
        "train",
        "--resume",
        run_arg,
        "--total-timesteps",
        "3072",
        "--quiet",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("resumed from step"), "{stdout}");
    assert!(stdout.contains("trained 3072 steps"), "{stdout}");
    assert!(run.join("final/model.json").is_file());
    assert!(
        run.join("checkpoints/step_3072/trainer_state.json")
            .is_file()
    );

    let out = fairgrasp(&["eval", "--model", run_arg, "--episodes", "3", "--json"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    for key in [
        "\"success_rate\"",
        "\"mean_return\"",
        "\"mean_length\"",
        "\"episodes\": 3",
    ] {
        assert!(stdout.contains(key), "{key} missing: {stdout}");
    }
    // A corrupt model is an error that names the file.
    std::fs::write(run.join("best/model.safetensors"), b"garbage").unwrap();
    let out = fairgrasp(&["eval", "--model", run_arg, "--episodes", "1"]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(stderr.contains("model.safetensors"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn env_commands_take_any_registered_id() {
    let (stdout, stderr) = text(&fairgrasp(&["env", "list"]));
    for id in [
        "FaArmGrasp-v0",
        "FaArmPickPlace-v0",
        "FaArmSort-v0",
        "Pendulum-v1",
        "PointReach-v0",
    ] {
        assert!(stdout.contains(id), "{id} not listed: {stdout}{stderr}");
    }
    let out = fairgrasp(&[
        "env",
        "config",
        "--env",
        "FaArmSort-v0",
        "--set",
        "task.num_objects=4",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("num_objects = 4"), "{stdout}");
    assert!(
        stdout.contains("[control]") && stdout.contains("[shapes]"),
        "{stdout}"
    );

    let out = fairgrasp(&[
        "env",
        "random",
        "--env",
        "FaArmPickPlace-v0",
        "--steps",
        "50",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("FaArmPickPlace-v0"), "{stdout}");

    // Unknown ids and keys name themselves and the ids there are.
    let (_, stderr) = text(&fairgrasp(&["env", "config", "--env", "FaArmJuggle-v9"]));
    assert!(
        stderr.contains("FaArmJuggle-v9") && stderr.contains("FaArmSort-v0"),
        "{stderr}"
    );
    let (_, stderr) = text(&fairgrasp(&[
        "train",
        "--env",
        "FaArmSort-v0",
        "--set",
        "env.task.num_bins=7",
    ]));
    assert!(stderr.contains("num_bins"), "{stderr}");
}

#[test]
fn export_writes_onnx_and_safetensors_beside_the_model_and_says_how_to_check_them() {
    use fairgrasp_rl::AlgoConfig;
    use fairgrasp_rl::algorithm::Algorithm;
    use fairgrasp_rl::model::{FORMAT_VERSION, ModelMeta, save_model};
    use fairgrasp_rl::ppo::{Ppo, PpoConfig};
    let config = PpoConfig {
        net_arch: vec![8],
        ..PpoConfig::default()
    };
    let ppo = Ppo::new(config.clone(), 3, 1, 1, 0).unwrap();
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: AlgoConfig::Ppo(config),
        obs_dim: 3,
        act_dim: 1,
        env_id: "Pendulum-v1".into(),
        env: serde_json::json!({}),
        normalization: None,
        num_timesteps: 0,
        train_seed: 0,
        n_envs: 1,
        privileged_dim: 0,
        pixel_actor: None,
    };
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    save_model(&model, &ppo.weights().unwrap(), &meta).unwrap();
    let model_arg = model.to_str().unwrap();
    for (format, file, hint) in [
        ("onnx", "policy.onnx", "onnxruntime"),
        ("safetensors", "policy.safetensors", "safe_open"),
    ] {
        let out = fairgrasp(&["export", "--model", model_arg, "--format", format]);
        let (stdout, stderr) = text(&out);
        assert!(out.status.success(), "{stderr}");
        let path = model.join(file);
        assert!(path.is_file(), "{stdout}");
        assert!(
            stdout.contains(&format!("wrote {}", path.display())) && stdout.contains(hint),
            "{stdout}"
        );
    }
    let out = fairgrasp(&["export", "--model", model_arg, "--format", "pytorch"]);
    assert!(!out.status.success());
    assert!(text(&out).1.contains("pytorch"), "{}", text(&out).1);
    let missing = dir.path().join("nothing-here");
    let out = fairgrasp(&[
        "export",
        "--model",
        missing.to_str().unwrap(),
        "--format",
        "onnx",
    ]);
    assert!(!out.status.success());
    assert!(text(&out).1.contains("nothing-here"), "{}", text(&out).1);
}

#[test]
fn plot_reports_a_bad_run_directory_or_format_and_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no_such_run");
    let out = tmp.path().join("curves.png");
    let result = fairgrasp(&[
        "plot",
        missing.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&result);
    assert!(!result.status.success());
    assert!(
        stderr.contains(&format!("{}: no such run directory", missing.display())),
        "{stderr}"
    );
    let result = fairgrasp(&["plot", missing.to_str().unwrap(), "--out", "curves.pdf"]);
    let (_, stderr) = text(&result);
    assert!(!result.status.success());
    assert!(stderr.contains("must end in .png or .svg"), "{stderr}");
    assert!(!out.exists());
}

#[test]
fn env_render_writes_png_images_and_bench_render_prints_frame_rates() {
    let dir = tempfile::tempdir().unwrap();
    let (rgb, depth) = (dir.path().join("scene.png"), dir.path().join("depth.png"));
    let out = fairgrasp(&[
        "env",
        "render",
        "--env",
        "FaArmSort-v0",
        "--out",
        rgb.to_str().unwrap(),
        "--depth",
        depth.to_str().unwrap(),
        "--set",
        "render.width=64",
        "--set",
        "render.height=48",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("64×48"), "{stdout}");
    for path in [&rgb, &depth] {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        // IHDR: width and height, big-endian, after the signature and chunk header.
        assert_eq!(&bytes[16..24], &[0, 0, 0, 64, 0, 0, 0, 48]);
    }
    let (_, stderr) = text(&fairgrasp(&[
        "env",
        "render",
        "--set",
        "render.fov_deg=200",
    ]));
    assert!(stderr.contains("render.fov_deg"), "{stderr}");

    let out = fairgrasp(&["bench", "render", "--seconds", "0.05", "--json"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert!(v["fps_84x84"].as_f64().unwrap() > v["fps_640x480"].as_f64().unwrap());
}

/// The frames of a GIF as RGBA, with its size.
fn gif_frames(path: &std::path::Path) -> (u16, u16, Vec<Vec<u8>>) {
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::RGBA);
    let mut decoder = options
        .read_info(std::fs::File::open(path).unwrap())
        .unwrap();
    let (w, h) = (decoder.width(), decoder.height());
    let mut frames = Vec::new();
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!((frame.width, frame.height), (w, h), "full frames only");
        frames.push(frame.buffer.to_vec());
    }
    (w, h, frames)
}

/// Pixels of the success caption's green in the top-left corner.
fn green_caption_pixels(rgba: &[u8], w: usize) -> usize {
    (0..60)
        .flat_map(|y| (0..w / 2).map(move |x| (y * w + x) * 4))
        .filter(|&i| {
            let (r, g, b) = (rgba[i] as i32, rgba[i + 1] as i32, rgba[i + 2] as i32);
            g > r + 25 && g > b + 25
        })
        .count()
}

#[test]
fn record_writes_a_gif_of_a_policy_s_episodes_with_the_outcome_shown() {
    let dir = tempfile::tempdir().unwrap();
    // Random actions, a 5-step episode: a frame before each step, then the final state held
    // for 15 frames.
    let random = dir.path().join("random.gif");
    let out = fairgrasp(&[
        "record",
        "--episodes",
        "1",
        "--out",
        random.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "48",
        "--set",
        "task.max_episode_steps=5",
    ]);
    assert!(out.status.success(), "{}", text(&out).1);
    let (w, h, frames) = gif_frames(&random);
    assert_eq!((w, h), (64, 48));
    assert_eq!(frames.len(), 5 + 15);
    assert_ne!(frames[0], frames[5], "the arm moved");

    // The servo-trained grasp policy of the deployment tests: it lifts the cube, and the
    // last frames say so in green; the first does not.
    let model =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/tests/data/deploy_ppo");
    let trained = dir.path().join("trained.gif");
    let out = fairgrasp(&[
        "record",
        "--model",
        model.to_str().unwrap(),
        "--episodes",
        "1",
        "--out",
        trained.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("1 successful"), "{stdout}");
    let (w, _, frames) = gif_frames(&trained);
    let last = frames.last().unwrap();
    assert!(green_caption_pixels(last, w as usize) > 20);
    assert_eq!(green_caption_pixels(&frames[0], w as usize), 0);

    // MP4 goes through ffmpeg: written where it is installed, refused by name where not.
    let mp4 = dir.path().join("x.mp4");
    let out = fairgrasp(&[
        "record",
        "--episodes",
        "1",
        "--out",
        mp4.to_str().unwrap(),
        "--set",
        "task.max_episode_steps=5",
    ]);
    if Command::new("ffmpeg").arg("-version").output().is_ok() {
        assert!(out.status.success(), "{}", text(&out).1);
        let bytes = std::fs::read(&mp4).unwrap();
        assert_eq!(&bytes[4..8], b"ftyp", "an MP4 starts with its ftyp box");
    } else {
        assert!(!out.status.success());
        assert!(
            text(&out).1.contains("MP4 needs ffmpeg"),
            "{}",
            text(&out).1
        );
        assert!(!mp4.exists());
    }
    let out = fairgrasp(&[
        "record",
        "--out",
        dir.path().join("x.avi").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out).1.contains("must end in .gif or .mp4"),
        "{}",
        text(&out).1
    );
}

#[test]
fn bench_sac_prints_gradient_steps_at_the_default_sizes() {
    let out = fairgrasp(&[
        "bench",
        "sac",
        "--seconds",
        "0.01",
        "--transitions",
        "300",
        "--set",
        "sac.batch_size=32",
        "--json",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert!(v["gradient_steps_per_s"].as_f64().unwrap() > 0.0, "{v}");
    assert_eq!(v["batch_size"], 32);
    assert_eq!(v["net_arch"], serde_json::json!([128, 128]));
    // The grasp task's rich observation and Cartesian actions (configs/sac_grasp.toml).
    assert_eq!(
        (v["obs_dim"].as_u64(), v["act_dim"].as_u64()),
        (Some(38), Some(5))
    );
    let (_, stderr) = text(&fairgrasp(&["bench", "sac", "--set", "sac.batch_size=0"]));
    assert!(stderr.contains("sac.batch_size"), "{stderr}");
}

#[test]
fn a_live_deploy_refuses_a_fixed_object_pose_unless_told_the_object_is_static() {
    let model = repo().join("crates/deploy/tests/data/deploy_ppo");
    let args = [
        "deploy",
        "--robot",
        "127.0.0.1",
        "--model",
        model.to_str().unwrap(),
        "--live",
        "--object-pose",
        "0.45,0.0,0.025",
    ];
    let out = fairgrasp(&args);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("--object-pose with --live") && stderr.contains("--static-object"),
        "{stderr}"
    );
    // The flag needs a fixed pose to apply to.
    let out = fairgrasp(&[
        "deploy",
        "--robot",
        "127.0.0.1",
        "--model",
        "m",
        "--static-object",
    ]);
    let (_, stderr) = text(&out);
    assert!(
        !out.status.success() && stderr.contains("--object-pose"),
        "{stderr}"
    );
}

#[test]
fn a_deploy_killed_with_sigkill_while_the_controller_hangs_leaves_its_log_complete() {
    use fairgrasp_deploy::twin::{Twin, TwinConfig};
    use std::time::{Duration, Instant};
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Deadlines a shared host cannot race: the run must still be going when it is killed.
    let safety = dir.path().join("safety.toml");
    std::fs::write(
        &safety,
        "[safety]\nstate_deadline_ms = 500.0\npose_deadline_ms = 1000.0\n",
    )
    .unwrap();
    // An earlier run's log stays as it was; this one goes beside it.
    let earlier = dir.path().join("run.jsonl");
    std::fs::write(&earlier, "{\"t\":0.0,\"earlier\":true}\n").unwrap();
    let log = dir.path().join("run.2.jsonl");
    let model = repo().join("crates/rl/tests/data/format1/ppo");
    let (rpc, cnde) = (twin.rpc_addr().port(), twin.cnde_addr().port());
    let pose = twin.pose_addr().unwrap().to_string();
    let (stdout, stderr) = (dir.path().join("stdout"), dir.path().join("stderr"));
    let child = Command::new(env!("CARGO_BIN_EXE_fairgrasp"))
        .args([
            "deploy",
            "--robot",
            "127.0.0.1",
            "--rpc-port",
            &rpc.to_string(),
        ])
        .args(["--cnde-port", &cnde.to_string(), "--pose-tcp", &pose])
        .args([
            "--model",
            model.to_str().unwrap(),
            "--live",
            "--episodes",
            "50",
        ])
        .args(["--log", earlier.to_str().unwrap()])
        .args(["--safety", safety.to_str().unwrap()])
        // A late reply must hold the loop, as a hung controller would, not fault it.
        .args(["--call-timeout-ms", "30000"])
        .stdin(std::process::Stdio::null())
        .stdout(std::fs::File::create(&stdout).unwrap())
        .stderr(std::fs::File::create(&stderr).unwrap())
        .spawn()
        .unwrap();
    let mut child = KillOnDrop(Some(child));
    let output = || {
        let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
        format!("stdout:\n{}\nstderr:\n{}", read(&stdout), read(&stderr))
    };
    let servo_calls = || {
        let calls = twin.calls();
        calls.iter().filter(|c| c.method == "ServoJ").count()
    };
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut wait = |what: &str, done: &mut dyn FnMut() -> bool| {
        while !done() {
            assert!(child.running(), "exited; {}", output());
            assert!(Instant::now() < deadline, "{what}; {}", output());
            std::thread::sleep(Duration::from_millis(2));
        }
        Instant::now()
    };
    // The log's clock starts as its file is created.
    let created = wait("no log", &mut || log.exists());
    wait("the log never reached 1.5 s of servoing", &mut || {
        last_t(&complete_json_lines(&log)).is_some_and(|t| t >= 1.5) && servo_calls() > 0
    });
    // The controller takes 20 s to answer the next ServoJ: the loop waits for it, logging
    // nothing more, and is killed there. Everything it logged before must be in the file.
    twin.inject_text("slow", "ServoJ:20000:1").unwrap();
    let held = wait("the slow ServoJ never came", &mut || {
        twin.faults().slow.is_none()
    });
    let answered = servo_calls();
    std::thread::sleep(Duration::from_millis(200));
    child.kill();
    assert_eq!(
        std::fs::read_to_string(&earlier).unwrap(),
        "{\"t\":0.0,\"earlier\":true}\n"
    );
    assert!(
        output().contains(&format!("log: {}", log.display())),
        "{}",
        output()
    );

    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        text.ends_with('\n'),
        "a line cut short: {:?}",
        &text[text.len().saturating_sub(200)..]
    );
    let lines = complete_json_lines(&log);
    let logged = lines
        .iter()
        .filter(|l| l["sent"]["call"] == "ServoJ")
        .count();
    assert_eq!(
        logged, answered,
        "ServoJ calls logged / answered by the twin"
    );
    // The loop ran until the slow ServoJ reached the twin, seen here at `held`: its last
    // event came one servo period before that, give or take a loaded host.
    let last = last_t(&lines).unwrap();
    let held_at = held.duration_since(created).as_secs_f64();
    assert!(
        last >= held_at - 1.0,
        "the log ends at t = {last:.3} s, the loop was held from t >= {held_at:.3} s"
    );
}

/// The complete lines of a JSON-lines file (a line cut by a kill is left out), parsed.
fn complete_json_lines(path: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let complete = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
    complete
        .lines()
        .map(|line| {
            serde_json::from_str(line).unwrap_or_else(|e| panic!("{e} in log line {line:?}"))
        })
        .collect()
}

/// The `t` of a log's last line.
fn last_t(lines: &[serde_json::Value]) -> Option<f64> {
    lines.last().and_then(|l| l["t"].as_f64())
}

/// A child process killed (SIGKILL) when dropped, so a failing test leaves none behind.
struct KillOnDrop(Option<std::process::Child>);

impl KillOnDrop {
    fn running(&mut self) -> bool {
        self.0
            .as_mut()
            .is_some_and(|c| c.try_wait().unwrap().is_none())
    }

    fn kill(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        self.kill();
    }
}

#[test]
fn training_through_identified_drives_keeps_them_in_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let sysid = dir.path().join("sysid.toml");
    std::fs::write(
        &sysid,
        "env = \"FaArmGrasp-v0\"\n[[joints]]\njoint = 1\ndelay_ms = 8.1\ntau_ms = 15.2\n\
         rms_residual_deg = 0.01\nsamples = 500\n[[joints]]\njoint = 3\ndelay_ms = 7.5\n\
         tau_ms = 14.0\nrms_residual_deg = 0.01\nsamples = 500\n",
    )
    .unwrap();
    let config = dir.path().join("tiny.toml");
    let servo = format!("{TINY_TRAIN_TOML}[env.control.servo]\nenabled = true\n");
    std::fs::write(&config, servo).unwrap();
    let run = dir.path().join("run");
    let train = |extra: &[&str]| {
        let mut args = vec!["train", "--quiet", "--total-timesteps", "256", "--config"];
        args.push(config.to_str().unwrap());
        args.extend_from_slice(extra);
        fairgrasp(&args)
    };
    let out = train(&[
        "--drives",
        sysid.to_str().unwrap(),
        "--run-dir",
        run.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("final/model.json")).unwrap())
            .unwrap();
    let drives = &model["env"]["control"]["drives"];
    assert_eq!(drives["enabled"], true, "{model}");
    assert_eq!(
        drives["delay_ms"],
        serde_json::json!([8.1, 0.0, 7.5, 0.0, 0.0, 0.0])
    );
    assert_eq!(
        drives["tau_ms"],
        serde_json::json!([15.2, 0.0, 14.0, 0.0, 0.0, 0.0])
    );
    // A file fitted against another env's arm, or not a sysid file, is refused by name.
    let other = dir.path().join("other.toml");
    let text_other = std::fs::read_to_string(&sysid)
        .unwrap()
        .replace("FaArmGrasp-v0", "FaArmPickPlace-v0");
    std::fs::write(&other, text_other).unwrap();
    let (_, stderr) = text(&train(&["--drives", other.to_str().unwrap()]));
    assert!(stderr.contains("FaArmPickPlace-v0"), "{stderr}");
    let (_, stderr) = text(&train(&["--drives", config.to_str().unwrap()]));
    assert!(stderr.contains("tiny.toml"), "{stderr}");
}

#[test]
fn the_camera_config_trains_a_teacher_then_distils_and_evaluates_a_student() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("cam");
    let config = repo().join("configs/distill_grasp.toml");
    let out = fairgrasp(&[
        "train",
        "--config",
        config.to_str().unwrap(),
        "--run-dir",
        run.to_str().unwrap(),
        "--quiet",
        "--set",
        "total_timesteps=4096",
        "--set",
        "eval.freq=2048",
        "--set",
        "eval.episodes=2",
        "--set",
        "distill.rounds=2",
        "--set",
        "distill.steps_per_round=3",
        "--set",
        "distill.n_envs=2",
        "--set",
        "distill.batch_size=4",
        "--set",
        "distill.eval_episodes=2",
        "--set",
        "distill.env.camera.width=24",
        "--set",
        "distill.env.camera.height=24",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("round  1: β 0.67,     12 states"),
        "{stdout}"
    );
    assert!(
        stdout.contains("/2 held-out episodes succeeded"),
        "{stdout}"
    );
    let student = run.join("student");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(student.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(
        (summary["episodes"].as_u64(), summary["samples"].as_u64()),
        (Some(2), Some(12))
    );
    // The student is a model: evaluated on its own camera env, exported with image inputs.
    let out = fairgrasp(&[
        "eval",
        "--model",
        student.to_str().unwrap(),
        "--episodes",
        "2",
        "--json",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let eval: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(eval["episodes"].as_u64(), Some(2), "{stdout}");
    let onnx = dir.path().join("student.onnx");
    let out = fairgrasp(&[
        "export",
        "--model",
        student.to_str().unwrap(),
        "--format",
        "onnx",
        "--out",
        onnx.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let bytes = std::fs::read(&onnx).unwrap();
    for name in [&b"scene_rgb"[..], b"wrist_rgb"] {
        assert!(
            bytes.windows(name.len()).any(|w| w == name),
            "the config's two cameras are named inputs"
        );
    }

    // A bad [distill] key is named before anything trains.
    let out = fairgrasp(&[
        "train",
        "--config",
        config.to_str().unwrap(),
        "--run-dir",
        dir.path().join("bad").to_str().unwrap(),
        "--set",
        "distill.env.camera.width=8",
    ]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(stderr.contains("distill.env.camera.width"), "{stderr}");
}
