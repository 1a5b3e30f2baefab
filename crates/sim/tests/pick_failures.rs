//! A failed scripted pick says why: each reason forced by a scene or rule that causes it.

use fairgrasp_sim::pick::{
    FailureKind, PickFailure, PickOutcome, PickPhase, PickScript, SuccessRule,
    evaluate_scripted_pick, run_scripted_pick,
};
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, Vector3};
use fairgrasp_sim::scene::{Scene, SceneConfig};

fn scene() -> Scene {
    Scene::new(SceneConfig::default()).expect("default scene builds")
}

/// Resets with `seed`, lets `prepare` change the scene, then runs the default script.
fn pick(
    scene: &mut Scene,
    seed: u64,
    script: &PickScript,
    rule: SuccessRule,
    prepare: impl FnOnce(&mut Scene),
) -> PickOutcome {
    scene.reset(seed).unwrap();
    prepare(scene);
    let outcome = run_scripted_pick(scene, 0, script, rule).unwrap();
    assert_eq!(
        outcome.success,
        outcome.failure.is_none(),
        "success and failure disagree: {outcome:?}"
    );
    outcome
}

/// Changes the cube's mass and friction, keeping its shape.
fn set_mass_friction(scene: &mut Scene, mass: f32, friction: f32) {
    let shape = scene.object_config(0).shape.clone();
    scene.set_object_params(0, &shape, mass, friction).unwrap();
}

fn move_object(scene: &mut Scene, to: Vector3<f64>) {
    let rotation = scene.object_state(0).pose.rotation;
    scene
        .set_object_pose(0, &Isometry3::from_parts(Translation3::from(to), rotation))
        .unwrap();
}

#[test]
fn the_default_pick_has_no_failure() {
    let outcome = pick(
        &mut scene(),
        0,
        &PickScript::default(),
        SuccessRule::default(),
        |_| {},
    );
    assert!(outcome.success, "{outcome:?}");
}

#[test]
fn an_object_far_outside_the_workspace_is_unreachable_before_the_approach() {
    let outcome = pick(
        &mut scene(),
        0,
        &PickScript::default(),
        SuccessRule::default(),
        |scene| {
            // On the table's far corner, 1.1 m from the base: beyond the FR5's 0.92 m reach.
            let z = scene.object_rest_height(0);
            move_object(scene, Vector3::new(1.0, 0.5, z));
        },
    );
    assert_eq!(
        outcome.failure,
        Some(PickFailure::Unreachable {
            phase: PickPhase::Approach
        })
    );
    assert_eq!(
        outcome.steps, 0,
        "no step before the pre-grasp pose is solved"
    );
    assert_eq!(
        outcome.failure.unwrap().to_string(),
        "pre-grasp pose unreachable (IK found no solution)"
    );
}

#[test]
fn a_lift_beyond_reach_is_unreachable_during_the_lift() {
    let script = PickScript {
        lift_height: 1.5,
        ..PickScript::default()
    };
    let outcome = pick(&mut scene(), 0, &script, SuccessRule::default(), |_| {});
    assert_eq!(
        outcome.failure,
        Some(PickFailure::Unreachable {
            phase: PickPhase::Lift
        })
    );
    assert!(outcome.steps > 0);
    assert_eq!(
        outcome.failure.unwrap().to_string(),
        "lift pose unreachable (IK found no solution)"
    );
}

#[test]
fn fingers_closing_where_the_object_no_longer_is_miss_it() {
    // The script aims at where the cube is at the start, 30 cm up in the air; by the time the
    // fingers get there it has fallen onto the table.
    let outcome = pick(
        &mut scene(),
        0,
        &PickScript::default(),
        SuccessRule::default(),
        |scene| {
            let up = scene.object_state(0).pose.translation.vector + Vector3::new(0.0, 0.0, 0.3);
            move_object(scene, up);
        },
    );
    assert_eq!(outcome.failure, Some(PickFailure::FingersMissed));
    assert!(outcome.final_lift.abs() < 0.01, "{outcome:?}");
}

#[test]
fn a_heavy_or_slippery_object_slips_out_during_the_lift() {
    let heavy = pick(
        &mut scene(),
        0,
        &PickScript::default(),
        SuccessRule::default(),
        // 45 N of weight: held while still, it slides out once the lift accelerates it.
        |scene| set_mass_friction(scene, 4.6, 0.8),
    );
    let mut config = SceneConfig::default();
    config.gripper.pad_friction = 0.01;
    let slippery = pick(
        &mut Scene::new(config).unwrap(),
        0,
        &PickScript::default(),
        SuccessRule::default(),
        |scene| set_mass_friction(scene, 0.1, 0.0),
    );
    // The heavy cube rises a little before it slips; the slippery one never leaves the table.
    for (what, outcome, lifted) in [
        ("heavy", heavy, 0.005..0.05),
        ("slippery", slippery, 0.0..0.005),
    ] {
        let Some(PickFailure::ObjectSlipped { lift }) = outcome.failure else {
            panic!("{what}: {outcome:?}");
        };
        assert!(lifted.contains(&lift), "{what}: lifted {lift} m");
        assert!(outcome.final_lift < 0.005, "{what}: {outcome:?}");
        let message = outcome.failure.unwrap().to_string();
        assert!(
            message.contains("slipped") && message.contains(&format!("{:.1} cm", lift * 100.0)),
            "{what}: {message}"
        );
    }
}

#[test]
fn a_held_object_farther_from_the_tcp_than_allowed_is_off_centre() {
    let rule = SuccessRule {
        max_offset: 0.0,
        ..SuccessRule::default()
    };
    let outcome = pick(&mut scene(), 0, &PickScript::default(), rule, |_| {});
    let Some(PickFailure::HeldOffCentre { offset, max_offset }) = outcome.failure else {
        panic!("{outcome:?}");
    };
    assert_eq!(max_offset, 0.0);
    assert!(offset > 0.0 && offset < 0.02, "offset {offset}");
    assert!(outcome.final_lift > 0.1);
}

#[test]
fn a_hold_longer_than_the_script_times_out() {
    let rule = SuccessRule {
        hold_steps: 10_000,
        ..SuccessRule::default()
    };
    let outcome = pick(&mut scene(), 0, &PickScript::default(), rule, |_| {});
    let Some(PickFailure::TimedOut {
        longest_run,
        hold_steps,
    }) = outcome.failure
    else {
        panic!("{outcome:?}");
    };
    assert_eq!(hold_steps, 10_000);
    // The rule held from early in the lift to the end of the script.
    assert!(
        longest_run > 30 && longest_run < outcome.steps,
        "{longest_run}"
    );
    assert!(
        outcome
            .failure
            .unwrap()
            .to_string()
            .starts_with("timed out before the hold ended")
    );
}

#[test]
fn the_report_counts_failures_by_reason() {
    let mut config = SceneConfig::default();
    config.objects[0].mass = 4.6;
    let mut scene = Scene::new(config).unwrap();
    let mut seen = Vec::new();
    let report = evaluate_scripted_pick(
        &mut scene,
        3,
        7,
        &PickScript::default(),
        SuccessRule::default(),
        |seed, _| seen.push(seed),
    )
    .unwrap();
    assert_eq!(seen, [7, 8, 9]);
    assert_eq!(report.successes, 0);
    let seeds: Vec<u64> = report.failures.iter().map(|(seed, _)| *seed).collect();
    assert_eq!(seeds, [7, 8, 9]);
    assert_eq!(report.failure_counts(), [(FailureKind::ObjectSlipped, 3)]);
}
