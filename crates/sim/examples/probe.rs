use fairgrasp_sim::pick::*;
use fairgrasp_sim::rapier3d::na::Point3;
use fairgrasp_sim::scene::{Scene, SceneConfig};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut config = SceneConfig::default();
    config.physics.solver_iterations = args[1].parse().unwrap();
    config.physics.pgs_iterations = args[2].parse().unwrap();
    config.gripper.force_limit = args[3].parse().unwrap();
    let motion: f32 = args[4].parse().unwrap();
    config.physics.contact_frequency = args[5].parse().unwrap();
    config.gripper.pad_friction = args[6].parse().unwrap();
    let mut scene = Scene::new(config).unwrap();
    scene.reset(8).unwrap();
    grasp_and_lift(&mut scene, &PickScript::default(), &mut |s| {
        s.step_control()
    })
    .unwrap();
    let relative = |scene: &Scene| {
        let tcp = scene.tcp_pose();
        tcp.inverse_transform_point(&Point3::from(scene.object_state().pose.translation.vector))
            .coords
    };
    let start = relative(&scene);
    let hold = scene.arm_targets();
    let steps = (30.0 / scene.control_period()).ceil() as usize;
    for i in 0..steps {
        let t = i as f32 * scene.control_period();
        let mut q = hold.clone();
        q[0] += motion * 0.4 * (0.5 * t).sin();
        q[5] += motion * 0.5 * (0.7 * t).sin();
        scene.set_arm_targets(&q).unwrap();
        scene.step_control().unwrap();
        if i % 150 == 0 {
            let d = relative(&scene) - start;
            let q = scene.robot().joint_positions(scene.world_multibody_joints()); let rel = scene.tcp_pose().rotation.inverse() * scene.object_state().pose.rotation; println!("t={t:.1} drift {:.4} {:.4} {:.4} fingers {:.4} {:.4} rel rot {:?}", d.x, d.y, d.z, q[6], q[7], rel.euler_angles());
        }
    }
}
