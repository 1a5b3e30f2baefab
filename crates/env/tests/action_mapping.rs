//! Cartesian actions at the edge of the arm's reach: a yaw the wrist cannot reach does not
//! freeze the arm; a position it cannot reach keeps the targets.

use fairgrasp_env::arm::control::top_down_pose;
use fairgrasp_env::arm::{
    ActionMapper, ActionMode, ArmState, Command, ControlConfig, MappingEvent,
};
use fairgrasp_env::sim::kinematics::SerialChain;
use fairgrasp_env::sim::rapier3d::na::Vector3;
use fairgrasp_env::sim::scene::{Scene, SceneConfig};

/// The mapper, a state and a command with the arm at `q_deg`, the TCP target where it is.
fn at(q_deg: [f32; 6]) -> (ActionMapper, ArmState, Command, SerialChain) {
    let scene = Scene::new(SceneConfig::default()).unwrap();
    let chain = SerialChain::new(&scene.robot().model, "tcp").unwrap();
    let config = ControlConfig {
        action_mode: ActionMode::Cartesian,
        ..ControlConfig::default()
    };
    let mapper = ActionMapper::new(config, chain.clone(), scene.arm_limits()).unwrap();
    let q: Vec<f32> = q_deg.iter().map(|d| d.to_radians()).collect();
    let tcp = mapper.forward(&q);
    let command = Command {
        arm_target: q,
        tcp_target: top_down_pose(tcp.translation.vector, tcp.rotation.euler_angles().2),
        gripper_open: true,
    };
    (mapper, ArmState::from_scene(&scene), command, chain)
}

fn tcp(chain: &SerialChain, q: &[f32]) -> fairgrasp_env::sim::rapier3d::na::Isometry3<f64> {
    chain.forward(&q.iter().map(|&v| v as f64).collect::<Vec<_>>())
}

#[test]
fn a_yaw_beyond_the_wrist_limits_the_yaw_and_still_moves_the_arm() {
    // The last joint 0.5° from its -175° limit, the TCP low over the table: a move along -y at
    // a fixed yaw needs that joint past its limit (a trained policy met this in MuJoCo and,
    // with the targets kept, stood still for 60 steps).
    let (mapper, state, mut command, chain) = at([-8.5, -109.5, -127.3, -33.7, 90.0, -174.5]);
    let before = command.tcp_target;
    let limits = mapper_limits();
    for step in 0..5 {
        let event = mapper.apply(&state, &[0.0, -0.02, 0.0, 0.0, 1.0], &mut command);
        assert_eq!(event, Some(MappingEvent::YawLimited), "step {step}");
        let reached = tcp(&chain, &command.arm_target);
        let gap = reached.translation.vector - command.tcp_target.translation.vector;
        assert!(
            gap.norm() < 1e-3,
            "step {step}: the joints reach the position within {gap:?}"
        );
        let tool_axis = reached.rotation * Vector3::z();
        assert!(
            tool_axis.z < -0.9999,
            "step {step}: the tool still points down ({tool_axis:?})"
        );
        let target_axis = command.tcp_target.rotation * Vector3::z();
        assert!(target_axis.z < -0.9999, "the target stays top-down");
        for (q, (lo, hi)) in command.arm_target.iter().zip(&limits) {
            assert!((*lo..=*hi).contains(q), "joint {q} within [{lo}, {hi}]");
        }
    }
    let moved = command.tcp_target.translation.vector - before.translation.vector;
    assert!(
        (moved - Vector3::new(0.0, -0.1, 0.0)).norm() < 1e-6,
        "moved {moved:?}"
    );
}

#[test]
fn a_reachable_pose_is_solved_in_full_and_an_unreachable_position_keeps_the_targets() {
    let (mapper, state, mut command, chain) = at([11.8, -90.2, -101.4, -78.8, 90.0, -78.2]);
    assert_eq!(
        mapper.apply(&state, &[0.01, 0.01, -0.02, 0.05, 1.0], &mut command),
        None
    );
    let reached = tcp(&chain, &command.arm_target);
    let error = (reached.rotation * command.tcp_target.rotation.inverse()).angle();
    assert!(error < 1e-3, "the yaw is reached too ({error} rad off)");

    // In towards the base at table height until the folded elbow reaches its limit (the
    // workspace box allows x down to 15 cm): that step keeps the targets.
    for step in 0..40 {
        let before = command.clone();
        match mapper.apply(&state, &[-0.02, 0.0, -0.02, 0.0, 1.0], &mut command) {
            Some(MappingEvent::IkFailed) => {
                assert_eq!(command.arm_target, before.arm_target, "step {step}");
                assert_eq!(command.tcp_target, before.tcp_target, "step {step}");
                return;
            }
            _ => assert_ne!(command.arm_target, before.arm_target, "step {step} moved"),
        }
    }
    panic!("40 steps of 2 cm towards the base stayed within reach");
}

fn mapper_limits() -> Vec<(f32, f32)> {
    Scene::new(SceneConfig::default()).unwrap().arm_limits()
}
