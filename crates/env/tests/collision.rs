//! `control.collision_force_limit`: a robot link pressing on something harder than the limit
//! ends the episode as a cobot's collision detection would; a grasp stays within it.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::core::EpisodeEvent;
use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};

mod common;
use common::scripted_successes;

fn env(limit: Option<f32>) -> GraspEnv {
    env_with(|c| c.control.collision_force_limit = limit)
}

fn env_with(mutate: impl FnOnce(&mut GraspConfig)) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    mutate(&mut config);
    GraspEnv::new(config).expect("env builds")
}

/// Closed fingers over the cube's centre, then straight down onto its top: the events and the
/// largest `contact_force` seen before the episode ended.
fn press_down(env: &mut GraspEnv, seed: u64) -> (Vec<EpisodeEvent>, f32, bool) {
    let (events, forces, terminated) = press_steps(env, seed);
    (
        events,
        forces.iter().fold(0.0, |m, s| m.max(s.0)),
        terminated,
    )
}

/// [`press_down`] with each step's (`contact_force`, `press` reward term).
fn press_steps(env: &mut GraspEnv, seed: u64) -> (Vec<EpisodeEvent>, Vec<(f32, f32)>, bool) {
    env.reset(Some(seed)).unwrap();
    let (mut events, mut forces) = (Vec::new(), Vec::new());
    for step in 0..100 {
        let to_object = env.state().unwrap().tcp_to_object(0);
        let above = step < 30;
        let dz = if above { 0.0 } else { -0.02 };
        let action = [
            (to_object.x as f32).clamp(-0.02, 0.02),
            (to_object.y as f32).clamp(-0.02, 0.02),
            dz,
            0.0,
            -1.0,
        ];
        let s = env.step(&action).unwrap();
        events.extend(s.info.events.iter().copied());
        forces.push((
            // Neither where the env watches no force and prices no press.
            s.info.extras.get("contact_force").unwrap_or(0.0),
            s.info.reward_terms.get("press").unwrap_or(0.0),
        ));
        if s.terminated || s.truncated {
            return (events, forces, s.terminated);
        }
    }
    (events, forces, false)
}

#[test]
fn pressing_the_closed_fingers_onto_the_cube_stops_the_episode() {
    let mut watched = env(Some(150.0));
    let (events, peak, terminated) = press_down(&mut watched, 3);
    assert!(terminated, "the press ended the episode");
    assert!(events.contains(&EpisodeEvent::Collision), "{events:?}");
    assert!(
        peak > 150.0,
        "the force that stopped it is reported ({peak} N)"
    );

    // Unwatched, the same press goes on (the arm drives on into the cube and the table).
    let mut unwatched = env(None);
    let (events, _, _) = press_down(&mut unwatched, 3);
    assert!(!events.contains(&EpisodeEvent::Collision));
}

#[test]
fn a_scripted_grasp_stays_within_the_limit() {
    let mut watched = env(Some(150.0));
    let successes = scripted_successes(&mut watched, 100..120);
    assert!(successes >= 19, "{successes} of 20 scripted grasps");
}

#[test]
fn the_limit_must_be_positive() {
    let mut config = GraspConfig::default();
    config.control.collision_force_limit = Some(-1.0);
    let error = GraspEnv::new(config).err().expect("refused").to_string();
    assert!(error.contains("control.collision_force_limit"), "{error}");
}

#[test]
fn pressing_costs_in_proportion_to_the_force_and_a_grasp_next_to_nothing() {
    let mut env = env_with(|c| {
        c.control.collision_penalty = 2.0;
        c.control.collision_penalty_force = 150.0;
        // The fingertips clear the table at the lowest TCP target (`configs/ppo_deploy.toml`).
        c.control.workspace_min[2] = 0.025;
    });
    let (events, steps, _) = press_steps(&mut env, 3);
    // The penalty alone stops nothing.
    assert!(!events.contains(&EpisodeEvent::Collision), "{events:?}");
    for &(force, press) in &steps {
        let expected = -2.0 * (force / 150.0).min(4.0);
        assert!((press - expected).abs() < 1e-5, "{force} N cost {press}");
    }
    let hardest = steps.iter().fold(0.0f32, |m, s| m.min(s.1));
    assert!(hardest < -2.0, "the press reached past 150 N: {hardest}");

    // A scripted grasp costs a small part of that: the arm pushes the squeezed cube down
    // into the table while it closes (40-50 N for a third of a second), then lifts it.
    let mut total = 0.0;
    let mut n = 0;
    for seed in 100..104 {
        env.reset(Some(seed)).unwrap();
        let mut policy = ScriptedGraspPolicy::new(&env);
        loop {
            let s = env.step(&policy.act(&env)).unwrap();
            total += s.info.reward_terms.get("press").unwrap();
            n += 1;
            if s.terminated || s.truncated {
                break;
            }
        }
    }
    let grasp = total / n as f32;
    assert!(grasp > 0.05 * hardest, "a grasp cost {grasp} per step");

    // Off (the default), there is no such term.
    let mut free = self::env(None);
    free.reset(Some(3)).unwrap();
    let s = free.step(&[0.0, 0.0, -0.02, 0.0, -1.0]).unwrap();
    assert!(s.info.reward_terms.get("press").is_none());
}

#[test]
fn the_penalty_must_be_finite_and_non_negative() {
    for bad in [-1.0, f32::NAN] {
        let mut config = GraspConfig::default();
        config.control.collision_penalty = bad;
        let error = GraspEnv::new(config).err().expect("refused").to_string();
        assert!(error.contains("control.collision_penalty"), "{error}");
    }
}
