//! The bundled FR5 model against the forward-kinematics check figures of the FR5 reference sheet.

use fairgrasp_sim::assets;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::scene::{Scene, SceneConfig};
use rapier3d::na::{Isometry3, Point3};

use fairgrasp_sim::rapier3d;

/// (joint vector, flange position in the base frame) from the reference sheet.
const CHECKS: [([f64; 6], [f64; 3]); 2] = [
    ([0.0; 6], [-0.8200, -0.2021, 0.0500]),
    ([0.3, -1.2, 1.0, -0.5, 0.7, 0.2], [-0.5741, -0.3644, 0.5901]),
];

fn assert_close_mm(actual: [f64; 3], expected: [f64; 3], tolerance_m: f64, what: &str) {
    let err = ((actual[0] - expected[0]).powi(2)
        + (actual[1] - expected[1]).powi(2)
        + (actual[2] - expected[2]).powi(2))
    .sqrt();
    assert!(
        err < tolerance_m,
        "{what}: flange at {actual:?}, expected {expected:?} (error {:.2} mm)",
        err * 1000.0
    );
}

#[test]
fn model_flange_matches_reference_figures() {
    let model = assets::fr5().unwrap();
    let chain = SerialChain::new(&model, "tool0").unwrap();
    assert_eq!(chain.joint_names, ["j1", "j2", "j3", "j4", "j5", "j6"]);
    for (q, expected) in CHECKS {
        let p = chain.forward(&q).translation.vector;
        assert_close_mm(
            [p.x, p.y, p.z],
            expected,
            1e-3,
            &format!("model FK at {q:?}"),
        );
    }
}

/// Standard DH parameters (d, a, alpha) published for the FR5.
fn dh_flange(q: &[f64; 6]) -> [f64; 3] {
    let d = [0.152, 0.0, 0.0, 0.102, 0.102, 0.100];
    let a = [0.0, -0.425, -0.395, 0.0, 0.0, 0.0];
    let alpha = [
        std::f64::consts::FRAC_PI_2,
        0.0,
        0.0,
        std::f64::consts::FRAC_PI_2,
        -std::f64::consts::FRAC_PI_2,
        0.0,
    ];
    let mut t = rapier3d::na::Matrix4::<f64>::identity();
    for i in 0..6 {
        let (ct, st) = (q[i].cos(), q[i].sin());
        let (ca, sa) = (alpha[i].cos(), alpha[i].sin());
        let step = rapier3d::na::Matrix4::new(
            ct,
            -st * ca,
            st * sa,
            a[i] * ct,
            st,
            ct * ca,
            -ct * sa,
            a[i] * st,
            0.0,
            sa,
            ca,
            d[i],
            0.0,
            0.0,
            0.0,
            1.0,
        );
        t *= step;
    }
    [t[(0, 3)], t[(1, 3)], t[(2, 3)]]
}

#[test]
fn model_agrees_with_dh_table_at_many_joint_vectors() {
    let model = assets::fr5().unwrap();
    let chain = SerialChain::new(&model, "tool0").unwrap();
    let mut state = 12345u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 33) as f64 / (1u64 << 31) as f64) * 2.0 - 1.0
    };
    for _ in 0..50 {
        let q = [
            next() * 3.0,
            next() * 3.0,
            next() * 2.8,
            next() * 3.0,
            next() * 3.0,
            next() * 3.0,
        ];
        let p = chain.forward(&q).translation.vector;
        // The URDF uses the measured 0.39501 m and 0.1021 m, the DH table rounds them.
        assert_close_mm(
            [p.x, p.y, p.z],
            dh_flange(&q),
            1.5e-3,
            &format!("DH at {q:?}"),
        );
    }
}

#[test]
fn simulated_flange_matches_reference_figures() {
    let mut scene = Scene::new(SceneConfig::default()).unwrap();
    let base: Isometry3<f64> = scene.base_pose();
    for (q, expected) in CHECKS {
        let q32: Vec<f32> = q.iter().map(|&v| v as f32).collect();
        scene.set_arm_positions(&q32).unwrap();
        let flange = scene.flange_pose();
        let local = base.inverse_transform_point(&Point3::from(flange.translation.vector));
        assert_close_mm(
            [local.x, local.y, local.z],
            expected,
            1e-3,
            &format!("simulated flange at {q:?}"),
        );
    }
}
