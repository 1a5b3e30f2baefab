//! The safety filter against a million random policy outputs (NaN, ±inf and 1e30 among them)
//! from random starting states of the FR5: no set point ever leaves the soft limits, the FR5's
//! published limits, the speed and acceleration caps, the workspace box, or lets any part of
//! the arm (link origins, flange, fingertips) near the table or out of the cell; and no MoveJ
//! path it passes does either.
//!
//! The set points are judged with forward kinematics of this file's own, from the FR5's
//! published joint chain and the gripper's drawing, not with the filter's.

use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::safety::{Fault, SafetyConfig, SafetyFilter};
use fairgrasp_env::arm::ArmState;
use fairgrasp_env::sim::envelope::Envelope;
use fairgrasp_env::sim::kinematics::SerialChain;
use fairgrasp_env::sim::rapier3d::na::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use fairgrasp_env::{GraspConfig, GraspEnv};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct Arm {
    home_deg: [f64; 6],
    table_z_mm: f64,
    calibration: Calibration,
    chain: SerialChain,
    envelope: Envelope,
}

fn fr5() -> Arm {
    let env = GraspEnv::new(GraspConfig::default()).unwrap();
    let scene = env.scene();
    let calibration = Calibration::identity(&scene.arm_limits());
    let state = ArmState::from_scene(scene);
    Arm {
        home_deg: calibration.to_robot(&state.q),
        table_z_mm: state.table_z * 1000.0,
        chain: SerialChain::new(&scene.robot().model, "tcp").unwrap(),
        envelope: Envelope::new(&scene.robot().model, "tcp").unwrap(),
        calibration,
    }
}

fn filter(arm: &Arm, config: &SafetyConfig) -> SafetyFilter {
    let fk = fairgrasp_deploy::kinematics::ArmKinematics::new(
        arm.envelope.clone(),
        arm.calibration.clone(),
    );
    SafetyFilter::new(config, &arm.calibration.soft_limits(), arm.table_z_mm, fk).unwrap()
}

/// The FR5's published joint limits (rad): j1 to j6.
const PUBLISHED_LIMITS: [(f64, f64); 6] = [
    (-3.0543, 3.0543),
    (-4.6251, 1.4835),
    (-2.8274, 2.8274),
    (-4.6251, 1.4835),
    (-3.0543, 3.0543),
    (-3.0543, 3.0543),
];

/// The FR5's published chain (origin xyz in m, rpy in rad; every joint turns about its z),
/// with its figures as published (1.5708, not π/2).
#[allow(clippy::approx_constant)]
const CHAIN: [([f64; 3], [f64; 3]); 6] = [
    ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([0.0, 0.0, 0.152], [1.5708, 0.0, 0.0]),
    ([-0.425, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([-0.39501, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([0.0, 0.0, 0.1021], [1.5708, 0.0, 0.0]),
    ([0.0, 0.0, 0.102], [-1.5708, 0.0, 0.0]),
];

/// Points of the arm at joint angles (robot deg, identity calibration), mm in the base frame:
/// the elbow, the three wrist joints, the flange, and the corners of the fingertips (fingers
/// open and closed: 20 mm wide, their ends 120 mm out from the flange, from 0 to 55 mm either
/// side of the middle), each with its name.
fn own_points(q_deg: &[f64; 6]) -> Vec<(&'static str, [f64; 3])> {
    let names = [
        "shoulder",
        "elbow",
        "wrist 1",
        "wrist 2",
        "wrist 3",
        "wrist 3 (j6)",
    ];
    let mut pose = Isometry3::identity();
    let mut out = Vec::new();
    for (i, (xyz, rpy)) in CHAIN.iter().enumerate() {
        pose *= Isometry3::from_parts(
            Translation3::new(xyz[0], xyz[1], xyz[2]),
            UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        );
        pose *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), q_deg[i].to_radians());
        if i >= 2 {
            out.push((names[i], pose * Point3::origin()));
        }
    }
    let flange = pose * Translation3::new(0.0, 0.0, 0.1);
    out.push(("flange", flange * Point3::origin()));
    for x in [-0.01, 0.01] {
        for y in [-0.055, -0.045, -0.01, 0.0, 0.01, 0.045, 0.055] {
            out.push(("fingertip", flange * Point3::new(x, y, 0.12)));
        }
    }
    out.into_iter()
        .map(|(n, p)| (n, [p.x * 1000.0, p.y * 1000.0, p.z * 1000.0]))
        .collect()
}

/// Panics unless every point of `q` is above the floor and inside the cell.
fn assert_whole_arm_clear(f: &SafetyFilter, q: &[f64; 6]) {
    let (floor, cell_min, cell_max) = f.arm_bounds();
    for (name, p) in own_points(q) {
        assert!(
            p[2] >= floor - 1e-6,
            "{name} at z {:.2} mm, below the floor {floor:.2} mm (q {q:?})",
            p[2]
        );
        for k in 0..3 {
            assert!(
                p[k] >= cell_min[k] - 1e-6 && p[k] <= cell_max[k] + 1e-6,
                "{name} at {p:?} outside the cell"
            );
        }
    }
}

#[test]
fn the_test_s_own_kinematics_agree_with_the_model_s_tcp() {
    let arm = fr5();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..100 {
        let q_deg: [f64; 6] = std::array::from_fn(|i| {
            let (lo, hi) = PUBLISHED_LIMITS[i];
            rng.random_range(lo..hi).to_degrees()
        });
        let q: Vec<f64> = q_deg.iter().map(|d| d.to_radians()).collect();
        let tcp = arm.chain.forward(&q).translation.vector * 1000.0;
        // The TCP lies 100 mm out from the flange, between the fingertips' ends (120 mm).
        let points = own_points(&q_deg);
        let flange = points.iter().find(|(n, _)| *n == "flange").unwrap().1;
        let tip = points.iter().find(|(n, _)| *n == "fingertip").unwrap().1;
        let d_flange = (0..3)
            .map(|k| (tcp[k] - flange[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!((d_flange - 100.0).abs() < 0.01, "{d_flange}");
        let d_tip = (0..3)
            .map(|k| (tcp[k] - tip[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let want = (20.0f64.powi(2) + 10.0f64.powi(2) + 55.0f64.powi(2)).sqrt();
        assert!((d_tip - want).abs() < 0.01, "{d_tip} vs {want}");
    }
}

/// A wild value: what a broken policy might emit.
fn wild(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..6) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        3 => 1e30,
        4 => -1e30,
        _ => rng.random_range(-1e6..1e6),
    }
}

#[test]
fn a_million_random_outputs_never_leave_the_limits_caps_or_box() {
    let arm = fr5();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut sent, mut faults, mut non_finite) = (0u64, 0u64, 0u64);
    let mut workspace_faults = 0u64;
    let mut moves_passed = 0u64;
    let mut total = 0u64;
    while total < 1_000_000 {
        // A random episode: speed scale, margins and a starting state.
        let config = SafetyConfig {
            speed_scale: rng.random_range(0.05..=1.0),
            joint_margin_deg: rng.random_range(0.0..10.0),
            max_joint_acc_deg_s2: rng.random_range(100.0..=1440.0),
            ..SafetyConfig::default()
        };
        let mut f = filter(&arm, &config);
        let (lower, upper) = f.joint_limits();
        let (speed, acc, dt) = f.caps();
        // The scale only ever lowers the caps the checks below hold the set points to.
        assert!(speed <= config.max_joint_speed_deg_s && acc <= config.max_joint_acc_deg_s2);
        let (box_min, box_max) = f.workspace();
        let mut start = arm.home_deg;
        for v in &mut start {
            *v += rng.random_range(-25.0..25.0);
        }
        if f.start(&start).is_err() {
            continue;
        }
        // One episode in twenty, a MoveJ from the start to a random pose: when the filter
        // passes its path, every point of the path keeps the limits, the box and the clearance.
        if rng.random_bool(0.05) {
            let to: [f64; 6] = std::array::from_fn(|i| start[i] + rng.random_range(-40.0..40.0));
            if f.check_path(&start, &to).is_ok() {
                moves_passed += 1;
                assert_move_j_path_clear(&f, &start, &to);
            }
        }
        let (mut last, mut velocity) = (start, [0.0; 6]);
        for _ in 0..1000 {
            total += 1;
            let mut target = [0.0; 6];
            let kind = rng.random_range(0..10);
            for (i, t) in target.iter_mut().enumerate() {
                *t = match kind {
                    // A broken policy.
                    0 => {
                        if rng.random_bool(0.3) {
                            wild(&mut rng)
                        } else {
                            last[i]
                        }
                    }
                    // Anywhere, limits or not.
                    1..=3 => rng.random_range(-400.0..400.0),
                    // A policy's small steps.
                    _ => last[i] + rng.random_range(-5.0..5.0),
                };
            }
            let finite = target.iter().all(|v| v.is_finite());
            match f.next(&target) {
                Ok(q) => {
                    assert!(finite, "a non-finite target produced a set point");
                    sent += 1;
                    let tcp = f
                        .tcp_in_box(&q)
                        .expect("set point with its TCP out of the box");
                    for k in 0..3 {
                        assert!(tcp[k] >= box_min[k] - 1e-6 && tcp[k] <= box_max[k] + 1e-6);
                    }
                    assert_whole_arm_clear(&f, &q);
                    for i in 0..6 {
                        let (lo, hi) = PUBLISHED_LIMITS[i];
                        let (lo, hi) = (lo.to_degrees(), hi.to_degrees());
                        let (c_lo, c_hi) = arm.calibration.soft_limits()[i];
                        let margin = config.joint_margin_deg;
                        assert!(
                            q[i] >= lo - 1e-3 && q[i] <= hi + 1e-3,
                            "joint {i} at {} deg",
                            q[i]
                        );
                        assert!(q[i] >= c_lo + margin - 1e-9 && q[i] <= c_hi - margin + 1e-9);
                    }
                    for i in 0..6 {
                        assert!(
                            q[i] >= lower[i] - 1e-9 && q[i] <= upper[i] + 1e-9,
                            "joint {i} at {} outside [{}, {}]",
                            q[i],
                            lower[i],
                            upper[i]
                        );
                        let v = (q[i] - last[i]) / dt;
                        assert!(
                            v.abs() <= speed * (1.0 + 1e-9) + 1e-9,
                            "speed {v} > {speed}"
                        );
                        let a = (v - velocity[i]) / dt;
                        assert!(
                            a.abs() <= acc * (1.0 + 1e-6) + 1e-6,
                            "acceleration {a} > {acc}"
                        );
                        velocity[i] = v;
                    }
                    last = q;
                }
                Err(fault) => {
                    faults += 1;
                    match fault {
                        Fault::NonFiniteOutput { .. } => {
                            assert!(!finite, "a finite target was called non-finite");
                            non_finite += 1;
                        }
                        Fault::WorkspaceExit { .. } => workspace_faults += 1,
                        other => panic!("unexpected fault {other}"),
                    }
                    break;
                }
            }
        }
    }
    println!(
        "{total} outputs: {sent} set points, {faults} stops ({non_finite} non-finite, \
         {workspace_faults} workspace); {moves_passed} MoveJ paths passed and held"
    );
    // The filter must not buy safety by refusing everything: most outputs become set points.
    assert!(
        sent as f64 > 0.9 * total as f64,
        "only {sent} of {total} outputs were sent"
    );
    assert!(non_finite > 0);
    assert!(moves_passed >= 10, "only {moves_passed} MoveJ paths passed");
}

/// Every point of the straight joint-space line from `from` to `to` (each joint in step, as
/// MoveJ moves), sampled every 0.1 deg of the largest joint's turn, inside the soft limits,
/// the TCP in its box and every point of the arm above the floor and in the cell — judged
/// with this file's kinematics. The filter checks points no part moves 1 mm between; the
/// floor here gives that millimetre.
fn assert_move_j_path_clear(f: &SafetyFilter, from: &[f64; 6], to: &[f64; 6]) {
    let (lower, upper) = f.joint_limits();
    let (box_min, box_max) = f.workspace();
    let (floor, cell_min, cell_max) = f.arm_bounds();
    let widest = (0..6).map(|i| (to[i] - from[i]).abs()).fold(0.0, f64::max);
    let n = (widest / 0.1).ceil().max(1.0) as usize;
    for k in 0..=n {
        let s = k as f64 / n as f64;
        let q: [f64; 6] = std::array::from_fn(|i| from[i] + (to[i] - from[i]) * s);
        for i in 0..6 {
            assert!(
                q[i] >= lower[i] - 1e-9 && q[i] <= upper[i] + 1e-9,
                "joint {i}"
            );
        }
        let tcp = f.tcp_in_box(&q);
        assert!(tcp.is_some(), "TCP out of {box_min:?}–{box_max:?} at {q:?}");
        for (name, p) in own_points(&q) {
            assert!(
                p[2] >= floor - 1.0,
                "{name} at z {:.2} mm on the way to {to:?}",
                p[2]
            );
            for k in 0..3 {
                assert!(
                    p[k] >= cell_min[k] - 1.0 && p[k] <= cell_max[k] + 1.0,
                    "{name}"
                );
            }
        }
    }
}

#[test]
fn reachable_targets_are_reached_exactly_and_within_the_caps() {
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 0.5,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    let mut target = arm.home_deg;
    target[0] += 20.0;
    target[2] -= 10.0;
    let (speed, _, dt) = f.caps();
    // 20 deg at 90 deg/s takes ~0.22 s plus ramps: well within 200 periods (1.6 s).
    let mut q = arm.home_deg;
    for _ in 0..200 {
        q = f.next(&target).unwrap();
    }
    for i in 0..6 {
        assert!(
            (q[i] - target[i]).abs() < 1e-9,
            "joint {i}: {} vs {}",
            q[i],
            target[i]
        );
    }
    // It did not get there at once.
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    let first = f.next(&target).unwrap();
    assert!((first[0] - arm.home_deg[0]).abs() <= speed * dt + 1e-9);
    assert!(first[0] > arm.home_deg[0]);
}

#[test]
fn a_target_beyond_the_soft_limit_stops_at_the_margin() {
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 1.0,
        joint_margin_deg: 5.0,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    let (_, upper) = f.joint_limits();
    let mut target = arm.home_deg;
    target[5] = 1e30;
    let mut q = arm.home_deg;
    for _ in 0..2000 {
        q = f.next(&target).unwrap();
    }
    assert!((q[5] - upper[5]).abs() < 1e-6, "{} vs {}", q[5], upper[5]);
    assert!(upper[5] <= arm.calibration.joints[5].max_deg - 5.0 + 1e-9);
}

#[test]
fn the_tcp_never_goes_below_the_table_plus_margin() {
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 1.0,
        table_margin_mm: 30.0,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    // Drive the shoulder and elbow down hard, towards the table.
    let mut target = arm.home_deg;
    target[1] -= 60.0;
    target[2] += 60.0;
    let floor = f.workspace().0[2];
    assert!((floor - (arm.table_z_mm + 30.0)).abs() < 1e-9);
    let mut lowest = f64::INFINITY;
    for _ in 0..1000 {
        match f.next(&target) {
            Ok(q) => lowest = lowest.min(f.tcp_in_box(&q).unwrap()[2]),
            Err(Fault::WorkspaceExit { .. }) => break,
            Err(other) => panic!("{other}"),
        }
    }
    assert!(lowest >= floor - 1e-6, "{lowest} < {floor}");
}

#[test]
fn starting_outside_the_limits_or_with_nan_is_refused() {
    let arm = fr5();
    let mut f = filter(&arm, &SafetyConfig::default());
    let mut bad = arm.home_deg;
    bad[0] = 1000.0;
    assert!(matches!(f.start(&bad), Err(Fault::UnsafeStart(_))));
    bad[0] = f64::NAN;
    assert!(matches!(f.start(&bad), Err(Fault::UnsafeStart(_))));
    // Not started: nothing is sent.
    assert!(f.next(&arm.home_deg).is_err());
}

#[test]
fn joints_move_in_step_along_the_straight_line_to_the_target() {
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 0.25,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    let mut target = arm.home_deg;
    let delta = [12.0, -6.0, 9.0, 3.0, -1.0, 20.0];
    for i in 0..6 {
        target[i] += delta[i];
    }
    for _ in 0..400 {
        let q = f.next(&target).unwrap();
        // The share of the way covered is the same for every joint.
        let share: Vec<f64> = (0..6)
            .map(|i| (q[i] - arm.home_deg[i]) / delta[i])
            .collect();
        for s in &share {
            assert!((s - share[0]).abs() < 1e-9, "{share:?}");
        }
    }
    let q = f.next(&target).unwrap();
    assert!((0..6).all(|i| (q[i] - target[i]).abs() < 1e-9));
}

/// A policy's targets: top-down TCP poses inside the training box of `configs/ppo_deploy.toml`
/// (x 0.15–0.85 m, y ±0.35 m, z 25–120 mm, the fingers near the table), a new one every few
/// servo periods as a policy acts, reached by inverse kinematics from the present set point.
/// Checking only where braking ends, the path between set points dipped to the floor (table +
/// 10 mm) and the filter stopped the arm within three episodes.
#[test]
fn a_policy_s_targets_near_the_floor_are_braked_for_never_stopped_at() {
    use fairgrasp_env::arm::control::top_down_pose;
    use fairgrasp_env::sim::rapier3d::na::Vector3;
    let arm = fr5();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut sent = 0u64;
    for episode in 0..60 {
        let config = SafetyConfig {
            speed_scale: [0.25, 0.5, 1.0][episode % 3],
            ..SafetyConfig::default()
        };
        let mut f = filter(&arm, &config);
        f.start(&arm.home_deg).unwrap();
        let mut last = arm.home_deg;
        let mut target = arm.home_deg;
        for tick in 0..1500 {
            if tick % 5 == 0 {
                let tcp = Vector3::new(
                    rng.random_range(0.15..=0.85),
                    rng.random_range(-0.35..=0.35),
                    rng.random_range(0.025..=0.12),
                );
                let pose = top_down_pose(tcp, rng.random_range(-1.5..1.5));
                let seed: Vec<f64> = last.iter().map(|d| d.to_radians()).collect();
                if let Ok(q) = arm.chain.inverse(&pose, &seed, 1e-4) {
                    let q: Vec<f32> = q.iter().map(|&v| v as f32).collect();
                    target = arm.calibration.to_robot(&q);
                }
            }
            match f.next(&target) {
                Ok(q) => {
                    sent += 1;
                    last = q;
                }
                Err(fault) => panic!("episode {episode}, tick {tick}: {fault}"),
            }
        }
    }
    assert_eq!(sent, 60 * 1500);
}

/// Fingers pointing down over the table and a target with the TCP 12 mm up: above the TCP's
/// 10 mm margin, with the fingertips 8 mm into the table. The filter holds the fingertips
/// above the table's clearance.
#[test]
fn the_fingertips_never_reach_the_table() {
    use fairgrasp_env::arm::control::top_down_pose;
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 1.0,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    f.start(&arm.home_deg).unwrap();
    let pose = top_down_pose(Vector3::new(0.45, 0.0, 0.012), 0.0);
    let seed: Vec<f64> = arm.home_deg.iter().map(|d| d.to_radians()).collect();
    let q = arm.chain.inverse(&pose, &seed, 1e-5).unwrap();
    let target = arm
        .calibration
        .to_robot(&q.iter().map(|&v| v as f32).collect::<Vec<_>>());
    let (floor, _, _) = f.arm_bounds();
    let mut lowest_tip = f64::INFINITY;
    for _ in 0..1000 {
        match f.next(&target) {
            Ok(q) => {
                assert_whole_arm_clear(&f, &q);
                let tips = own_points(&q)
                    .into_iter()
                    .filter(|(n, _)| *n == "fingertip");
                lowest_tip = tips.fold(lowest_tip, |low, (_, p)| low.min(p[2]));
            }
            Err(Fault::WorkspaceExit { .. }) => break,
            Err(other) => panic!("{other}"),
        }
    }
    // It went down as far as the fingertips allow, not stopping short.
    assert!(
        lowest_tip >= floor - 1e-6 && lowest_tip < floor + 3.0,
        "lowest fingertip {lowest_tip:.2} mm, floor {floor:.2} mm"
    );
}

/// A pose with the TCP inside its box all the way from home, and the forearm and wrist below
/// the table's top at the end (found by a seeded search over the FR5's joint range).
fn tcp_safe_pose_with_a_link_under_the_table(arm: &Arm, f: &SafetyFilter) -> [f64; 6] {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    loop {
        let q: [f64; 6] = std::array::from_fn(|i| {
            let (lo, hi) = PUBLISHED_LIMITS[i];
            0.9 * rng.random_range(lo..hi).to_degrees()
        });
        let links_low = own_points(&q)
            .iter()
            .filter(|(n, _)| *n != "fingertip" && *n != "flange")
            .any(|(_, p)| p[2] < -20.0);
        let tcp_safe = (0..=200).all(|k| {
            let s = k as f64 / 200.0;
            let p: [f64; 6] =
                std::array::from_fn(|i| arm.home_deg[i] + (q[i] - arm.home_deg[i]) * s);
            f.tcp_in_box(&p).is_some()
        });
        if links_low && tcp_safe {
            return q;
        }
    }
}

#[test]
fn no_link_reaches_the_table_though_the_tcp_stays_in_its_box() {
    let arm = fr5();
    let config = SafetyConfig {
        speed_scale: 1.0,
        ..SafetyConfig::default()
    };
    let mut f = filter(&arm, &config);
    let target = tcp_safe_pose_with_a_link_under_the_table(&arm, &f);
    // Starting there is refused, naming the part.
    match f.start(&target) {
        Err(Fault::UnsafeStart(m)) => assert!(m.contains("_link") || m.contains("finger"), "{m}"),
        other => panic!("{other:?}"),
    }
    // Driven there from home, the arm is braked before any part reaches the table.
    f.start(&arm.home_deg).unwrap();
    let mut last = arm.home_deg;
    for _ in 0..2000 {
        match f.next(&target) {
            Ok(q) => {
                assert_whole_arm_clear(&f, &q);
                last = q;
            }
            Err(Fault::WorkspaceExit { part, .. }) => {
                assert!(part != "TCP", "the TCP never leaves its box on this path");
                break;
            }
            Err(other) => panic!("{other}"),
        }
    }
    assert!(
        last != target,
        "it reached the pose with a link under the table"
    );
}

#[test]
fn a_move_j_path_through_the_table_is_refused_before_it_starts() {
    let arm = fr5();
    let f = filter(&arm, &SafetyConfig::default());
    let bad = tcp_safe_pose_with_a_link_under_the_table(&arm, &f);
    // Only the end point, or only the TCP, would pass: the path is checked with every part.
    assert!(f.tcp_in_box(&bad).is_some());
    let e = f.check_path(&arm.home_deg, &bad).unwrap_err().to_string();
    assert!(e.contains("of the way"), "{e}");
    // A small move near home passes, and so does staying put.
    let mut near = arm.home_deg;
    near[0] += 5.0;
    near[3] -= 5.0;
    f.check_path(&arm.home_deg, &near).unwrap();
    f.check_path(&arm.home_deg, &arm.home_deg).unwrap();
    // Past a soft limit on the way is refused, naming the joint.
    let (_, upper) = f.joint_limits();
    let mut beyond = arm.home_deg;
    beyond[5] = upper[5] + 1.0;
    let e = f
        .check_path(&arm.home_deg, &beyond)
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint 6"), "{e}");
}
