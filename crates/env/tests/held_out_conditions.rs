//! The settings that fix one held-out condition (for `fairgrasp robustness`): randomisation
//! ranges pinned at the nominal values, a fixed action latency and joint calibration errors.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};
use rand::SeedableRng;

/// Index of the joint angles, the TCP position and the object position in the `rich`
/// observation (docs/tasks.md).
const JOINTS: std::ops::Range<usize> = 0..6;
const TCP: std::ops::Range<usize> = 12..15;
const OBJECT: std::ops::Range<usize> = 21..24;

/// Randomisation on with every range pinned at the scene's nominal value and no noise.
fn pinned(mutate: impl FnOnce(&mut GraspConfig)) -> GraspEnv {
    let mut c = GraspConfig::default();
    let r = &mut c.randomization;
    r.enabled = true;
    r.object_mass = [0.1; 2];
    r.object_friction = [0.8; 2];
    r.object_scale = [1.0; 2];
    r.joint_damping_scale = Some([1.0; 2]);
    r.actuator_gain_scale = [1.0; 2];
    r.max_latency_steps = 0;
    r.initial_joint_jitter = 0.0;
    r.observation_noise = fairgrasp_env::arm::ObservationNoise {
        joint_position: 0.0,
        joint_velocity: 0.0,
        ee_position: 0.0,
        ee_orientation: 0.0,
        ee_velocity: 0.0,
        object_position: 0.0,
        object_orientation: 0.0,
        gripper_opening: 0.0,
    };
    mutate(&mut c);
    GraspEnv::new(c).expect("env builds")
}

#[test]
fn pinned_ranges_give_the_nominal_physical_parameters() {
    let mut env = pinned(|_| {});
    let mut plain = GraspEnv::new(GraspConfig::default()).unwrap();
    plain.reset(Some(3)).unwrap();
    for seed in [3, 4] {
        let (_, info) = env.reset(Some(seed)).unwrap();
        let p = &info.extras;
        // The FR5's URDF damping, joint by joint.
        let urdf = [0.5, 0.5, 0.5, 0.1, 0.1, 0.1];
        for (j, d) in urdf.iter().enumerate() {
            assert_eq!(p.get(&format!("param/joint_damping_{j}")), Some(*d));
        }
        assert_eq!(p.get("param/gain_scale"), Some(1.0));
        assert_eq!(p.get("param/latency_steps"), Some(0.0));
        assert_eq!(p.get("param/joint_offset_0"), None);
        assert_eq!(env.scene().object_config(0), plain.scene().object_config(0));
        assert!(env.joint_offset().is_empty());
    }
}

/// Observations of one episode from `seed` under `actions`.
fn trajectory(env: &mut GraspEnv, seed: u64, actions: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let (obs, _) = env.reset(Some(seed)).unwrap();
    let mut out = vec![obs];
    for a in actions {
        out.push(env.step(a).unwrap().obs);
    }
    out
}

#[test]
fn a_fixed_latency_delays_every_action_by_exactly_that_many_steps() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut late = pinned(|c| {
        c.randomization.min_latency_steps = 2;
        c.randomization.max_latency_steps = 2;
    });
    let mut prompt = pinned(|_| {});
    let actions: Vec<Vec<f32>> = (0..12)
        .map(|_| late.action_space().sample(&mut rng))
        .collect();
    let mut no_op = vec![0.0; actions[0].len()];
    *no_op.last_mut().unwrap() = 1.0;
    let delayed: Vec<Vec<f32>> = [no_op.clone(), no_op]
        .into_iter()
        .chain(actions[..10].iter().cloned())
        .collect();
    let (_, info) = late.reset(Some(8)).unwrap();
    assert_eq!(info.extras.get("param/latency_steps"), Some(2.0));
    assert_eq!(
        trajectory(&mut late, 8, &actions),
        trajectory(&mut prompt, 8, &delayed)
    );
    // And a latency of 2 is not a latency of 1.
    let mut one = pinned(|c| {
        c.randomization.min_latency_steps = 1;
        c.randomization.max_latency_steps = 1;
    });
    assert_ne!(
        trajectory(&mut one, 8, &actions),
        trajectory(&mut prompt, 8, &delayed)
    );
}

#[test]
fn latency_is_drawn_between_its_bounds() {
    let mut env = pinned(|c| {
        c.randomization.min_latency_steps = 1;
        c.randomization.max_latency_steps = 3;
    });
    let mut seen = std::collections::BTreeSet::new();
    for seed in 0..30 {
        let (_, info) = env.reset(Some(seed)).unwrap();
        seen.insert(info.extras.get("param/latency_steps").unwrap() as u32);
    }
    assert_eq!(seen.into_iter().collect::<Vec<_>>(), vec![1, 2, 3]);
    let mut c = GraspConfig::default();
    c.randomization.min_latency_steps = 3;
    let err = GraspEnv::new(c).err().unwrap().to_string();
    assert!(err.contains("randomization.min_latency_steps"), "{err}");
}

#[test]
fn joint_offsets_shift_the_reported_joints_and_tcp_but_not_the_object() {
    for mode in [ActionMode::Joint, ActionMode::Cartesian] {
        let offset = 1f32.to_radians();
        let mut env = pinned(|c| {
            c.randomization.joint_offset = offset;
            c.control.action_mode = mode;
        });
        let mut exact = pinned(|c| c.control.action_mode = mode);
        let (obs, info) = env.reset(Some(11)).unwrap();
        let (exact_obs, _) = exact.reset(Some(11)).unwrap();
        let e = env.joint_offset().to_vec();
        assert_eq!(e.len(), 6);
        assert!(e.iter().all(|v| v.abs() <= offset) && e.iter().any(|v| v.abs() > 0.1 * offset));
        for (j, v) in e.iter().enumerate() {
            assert_eq!(
                info.extras.get(&format!("param/joint_offset_{j}")),
                Some(*v)
            );
        }
        // The same episode (offsets are drawn after the placement) seen through the offsets.
        let truth = env.state().unwrap().clone();
        assert_eq!(&truth, exact.state().unwrap());
        let reported: Vec<f32> = truth.q.iter().zip(&e).map(|(q, e)| q + e).collect();
        assert_eq!(&obs[JOINTS], reported.as_slice());
        assert_eq!(&exact_obs[JOINTS], truth.q.as_slice());
        let fk = env.mapper().forward(&reported).translation.vector;
        let fk = [fk.x as f32, fk.y as f32, fk.z as f32];
        assert_eq!(&obs[TCP], fk.as_slice());
        let shown_shift = (0..3)
            .map(|k| (obs[TCP][k] - exact_obs[TCP][k]).powi(2))
            .sum::<f32>()
            .sqrt();
        // A degree on a ~0.5 m lever moves the reported TCP by millimetres.
        assert!(shown_shift > 1e-4 && shown_shift < 0.05, "{shown_shift}");
        assert_eq!(&obs[OBJECT], &exact_obs[OBJECT]);
        // The model agrees with the simulator where there is no offset.
        let fk_true = env.mapper().forward(&truth.q).translation.vector;
        assert!((fk_true - truth.tcp.translation.vector).norm() < 1e-4);

        // The controller servoes the reported joints: holding still does to the reported pose
        // what it does to the true pose without offsets (without the correction, the real arm
        // would move by the offsets). In joint mode the real arm follows the very same path.
        let mut hold = vec![0.0; env.action_space().dim()];
        *hold.last_mut().unwrap() = 1.0;
        for _ in 0..10 {
            let step = env.step(&hold).unwrap();
            exact.step(&hold).unwrap();
            let now = env.state().unwrap();
            let shown: Vec<f32> = now.q.iter().zip(&e).map(|(q, e)| q + e).collect();
            assert_eq!(&step.obs[JOINTS], shown.as_slice());
            let o = now.objects[0].pose.translation.vector;
            assert_eq!(&step.obs[OBJECT], &[o.x as f32, o.y as f32, o.z as f32]);
        }
        let shown_move =
            env.reported_state().unwrap().tcp.translation.vector - fk_reported_start(&obs);
        let exact_move =
            exact.state().unwrap().tcp.translation.vector - truth.tcp.translation.vector;
        let gap = (shown_move - exact_move).norm();
        assert!(
            gap < 5e-4,
            "{mode:?}: held, the reported TCP moved {shown_move:?}, the exact arm {exact_move:?}"
        );
        if mode == ActionMode::Joint {
            let (q, q_exact) = (&env.state().unwrap().q, &exact.state().unwrap().q);
            for (a, b) in q.iter().zip(q_exact) {
                assert!((a - b).abs() < 1e-5, "{q:?} vs {q_exact:?}");
            }
        }
    }
}

/// The TCP position shown in a `rich` observation.
fn fk_reported_start(obs: &[f32]) -> fairgrasp_env::sim::rapier3d::na::Vector3<f64> {
    fairgrasp_env::sim::rapier3d::na::Vector3::new(
        obs[TCP][0] as f64,
        obs[TCP][1] as f64,
        obs[TCP][2] as f64,
    )
}

#[test]
fn joint_offsets_are_off_without_randomisation_and_bounded() {
    let mut c = GraspConfig::default();
    c.randomization.joint_offset = 0.01;
    let mut env = GraspEnv::new(c).unwrap();
    env.reset(Some(1)).unwrap();
    assert!(env.joint_offset().is_empty());
    assert_eq!(env.reported_state(), env.state());
    let mut c = GraspConfig::default();
    c.randomization.joint_offset = 0.5;
    let err = GraspEnv::new(c).err().unwrap().to_string();
    assert!(err.contains("randomization.joint_offset"), "{err}");
}
