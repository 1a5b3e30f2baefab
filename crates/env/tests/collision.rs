//! `control.collision_force_limit`: a robot link pressing on something harder than the limit
//! ends the episode as a cobot's collision detection would; a grasp stays within it.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::core::EpisodeEvent;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};

mod common;
use common::scripted_successes;

fn env(limit: Option<f32>) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    config.control.collision_force_limit = limit;
    GraspEnv::new(config).expect("env builds")
}

/// Closed fingers over the cube's centre, then straight down onto its top: the events and the
/// largest `contact_force` seen before the episode ended.
fn press_down(env: &mut GraspEnv, seed: u64) -> (Vec<EpisodeEvent>, f32, bool) {
    env.reset(Some(seed)).unwrap();
    let (mut events, mut peak) = (Vec::new(), 0.0f32);
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
        peak = peak.max(s.info.extras.value("contact_force"));
        if s.terminated || s.truncated {
            return (events, peak, s.terminated);
        }
    }
    (events, peak, false)
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
