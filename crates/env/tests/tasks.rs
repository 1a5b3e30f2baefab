//! The new tasks can be solved with their own actions, and their success rules and rewards
//! behave: a scripted pick-and-place through `step()` succeeds; sorting counts objects in bins.

use fairgrasp_env::Env;
use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::sim::rapier3d::na::Point3;
use fairgrasp_env::tasks::pick_place::{PickPlaceConfig, PickPlaceEnv};
use fairgrasp_env::tasks::sort::{SortConfig, SortEnv};

fn pick_place(mode: ActionMode) -> PickPlaceEnv {
    let mut config = PickPlaceConfig::default();
    config.control.action_mode = mode;
    config.task.max_episode_steps = 150;
    PickPlaceEnv::new(config).unwrap()
}

#[test]
fn a_scripted_pick_and_place_through_step_reaches_the_goal() {
    for mode in [ActionMode::Cartesian, ActionMode::Joint] {
        let mut env = pick_place(mode);
        let mut successes = 0;
        let episodes = 10;
        for seed in 0..episodes {
            env.reset(Some(seed)).unwrap();
            let base = env.scene().base_pose();
            let goal = base * Point3::from(env.task().goal());
            let mut policy = ScriptedGraspPolicy::with_goal(&env, Some(goal.coords));
            let mut rewards = Vec::new();
            loop {
                let step = env.step(&policy.act(&env)).unwrap();
                rewards.push(step.reward);
                if step.terminated || step.truncated {
                    if step.info.success {
                        successes += 1;
                        assert!(step.info.extras.get("object_goal_distance").unwrap() < 0.025);
                        // ≤ 0 per step until the success bonus.
                        let before = &rewards[..rewards.len() - 1];
                        assert!(before.iter().all(|r| *r <= 0.0), "{before:?}");
                    }
                    break;
                }
            }
        }
        assert!(successes >= 9, "{mode:?}: {successes}/{episodes}");
    }
}

#[test]
fn the_goal_is_observed_and_lies_in_the_area_up_to_its_height() {
    let mut env = pick_place(ActionMode::Cartesian);
    let mut heights = Vec::new();
    for seed in 0..30 {
        let (obs, _) = env.reset(Some(seed)).unwrap();
        let goal = env.task().goal();
        let n = obs.len();
        // The goal, then the object → goal vector, close the observation.
        assert_eq!(
            &obs[n - 6..n - 3],
            &[goal.x as f32, goal.y as f32, goal.z as f32]
        );
        let state = env.state().unwrap();
        let rest = state.objects[0].rest_z;
        assert!(goal.z >= rest - 1e-6 && goal.z <= rest + 0.2 + 1e-6);
        assert!((0.3..=0.7).contains(&goal.x) && (-0.2..=0.2).contains(&goal.y));
        heights.push(goal.z - rest);
    }
    assert!(heights.iter().any(|h| *h > 0.1) && heights.iter().any(|h| *h < 0.05));
}

/// The largest step-to-step drop of sorting's progress term along a scripted sort.
const DROP: f32 = 0.02;

#[test]
fn a_scripted_sort_through_step_puts_every_object_in_its_bin() {
    let mut config = SortConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    config.task.max_episode_steps = 600;
    let mut env = SortEnv::new(config.clone()).unwrap();
    // The release earns its stage when the object drifts slowly, as the script lets go.
    config.reward.release_drift = Some(0.15);
    let mut slow_release = SortEnv::new(config).unwrap();
    let mut successes = 0;
    for seed in 0..14 {
        let env = if seed < 10 {
            &mut env
        } else {
            &mut slow_release
        };
        env.reset(Some(seed)).unwrap();
        let order = env.task().order().to_vec();
        let mut sorted_seen = 0.0;
        let mut bonuses = 0.0;
        let mut progress = f32::NEG_INFINITY;
        'episode: for (k, &i) in order.iter().enumerate() {
            let mut policy = scripted_drop(env, i);
            while !policy.done() {
                let step = env.step(&policy.act(env)).unwrap();
                let sorted = step.info.extras.get("objects_sorted").unwrap();
                // The count never runs ahead of the objects dropped so far.
                assert!(sorted <= (k + 1) as f32, "{sorted} after object {i}");
                sorted_seen = f32::max(sorted_seen, sorted);
                bonuses += step.info.reward_terms.get("object_sorted").unwrap();
                // The dense term follows the script's progress: it never drops by more than
                // the sway of a carried object.
                let now = step.info.reward_terms.get("progress").unwrap();
                assert!(
                    now >= progress - DROP,
                    "seed {seed}, object {i}: {progress} → {now}"
                );
                progress = now;
                if step.info.success {
                    assert_eq!(
                        now, 0.0,
                        "seed {seed}: every object sorted is the whole progress"
                    );
                }
                if step.terminated || step.truncated {
                    successes += step.info.success as u32;
                    break 'episode;
                }
            }
        }
        // One bonus per object, paid once.
        assert_eq!(bonuses, 5.0 * sorted_seen, "seed {seed}");
    }
    assert_eq!(successes, 14);
}

/// The scripted pick of object `i`, dropped above its own slot.
fn scripted_drop(env: &SortEnv, i: usize) -> ScriptedGraspPolicy {
    let drop = env.scene().base_pose() * Point3::from(env.task().drop_point(i));
    ScriptedGraspPolicy::for_object(env, i, Some(drop.coords), true)
}

fn sort_env(configure: impl FnOnce(&mut SortConfig)) -> SortEnv {
    let mut config = SortConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    configure(&mut config);
    SortEnv::new(config).unwrap()
}

/// The gripper open, the arm still.
const WAIT: [f32; 5] = [0.0, 0.0, 0.0, 0.0, 1.0];

#[test]
fn sorting_draws_an_order_and_starts_with_up_to_its_maximum_sorted() {
    let mut env = sort_env(|c| {
        c.task.start_sorted_max = 2;
        c.task.max_episode_steps = 30;
    });
    let mut counts = [0; 3];
    let mut orders = std::collections::HashSet::new();
    for seed in 0..24 {
        env.reset(Some(seed)).unwrap();
        let task = env.task();
        let mut order = task.order().to_vec();
        orders.insert(order.clone());
        let started: Vec<usize> = (0..3).filter(|&i| task.started_sorted()[i]).collect();
        let k = started.len();
        counts[k] += 1;
        // The first k of the order, each resting in its own bin.
        order.truncate(k);
        order.sort();
        assert_eq!(started, order, "seed {seed}");
        for &i in &started {
            assert!(
                env.scene().object_in_bin(i, task.assignment()[i]),
                "seed {seed}"
            );
        }
        // The limit is the objects' share left of 30 steps; the policy is credited with none.
        let mut steps = 0;
        loop {
            let step = env.step(&WAIT).unwrap();
            steps += 1;
            let extras = &step.info.extras;
            assert_eq!(extras.get("objects_sorted"), Some(k as f32), "seed {seed}");
            assert_eq!(extras.get("fraction_sorted_by_policy"), Some(0.0));
            if step.terminated || step.truncated {
                assert!(step.truncated);
                break;
            }
        }
        assert_eq!(steps, 10 * (3 - k), "seed {seed}");
    }
    assert!(counts.iter().all(|c| *c > 0), "{counts:?}");
    assert!(orders.len() >= 4, "{orders:?}");
    // In index order, nothing sorted, when told so.
    let mut env = sort_env(|c| c.task.random_order = false);
    for seed in 0..5 {
        env.reset(Some(seed)).unwrap();
        assert_eq!(env.task().order(), &[0, 1, 2]);
        assert!(env.task().started_sorted().iter().all(|s| !s));
    }
    // Always two sorted, one to go, when the least is the most.
    let mut env = sort_env(|c| {
        c.task.start_sorted_min = 2;
        c.task.start_sorted_max = 2;
    });
    for seed in 0..5 {
        env.reset(Some(seed)).unwrap();
        let started = env.task().started_sorted().iter().filter(|s| **s).count();
        assert_eq!(started, 2, "seed {seed}");
    }
}

#[test]
fn sorting_can_start_with_the_tcp_above_the_bin_last_filled() {
    let mut env = sort_env(|c| {
        c.task.start_sorted_max = 2;
        c.task.start_above_bin = 1.0;
    });
    let mut plain = sort_env(|c| c.task.start_sorted_max = 2);
    let (mut above, mut at_home) = (0, 0);
    for seed in 0..12 {
        env.reset(Some(seed)).unwrap();
        plain.reset(Some(seed)).unwrap();
        let home = plain.scene().tcp_pose().translation.vector;
        let task = env.task();
        let k = task.started_sorted().iter().filter(|s| **s).count();
        let tcp = env.scene().tcp_pose().translation.vector;
        if k == 0 {
            assert!((tcp - home).norm() < 1e-3, "seed {seed}: {tcp:?}");
            at_home += 1;
            continue;
        }
        // Over the last sorted object's bin, inside its walls and above them.
        let last = task.order()[k - 1];
        let bin = env
            .scene()
            .bin_pose(task.assignment()[last])
            .translation
            .vector;
        assert!((tcp.x - bin.x).abs() < 0.1, "seed {seed}: {tcp:?} {bin:?}");
        assert!((tcp.y - bin.y).abs() < 0.1, "seed {seed}: {tcp:?} {bin:?}");
        assert!(tcp.z > bin.z + 0.08, "seed {seed}: {tcp:?} {bin:?}");
        // It stays there: the arm holds the pose it starts in, the sorted objects in their bins.
        for _ in 0..10 {
            env.step(&WAIT).unwrap();
        }
        let moved = (env.scene().tcp_pose().translation.vector - tcp).norm();
        assert!(moved < 0.01, "seed {seed}: moved {moved} m");
        let sorted = env.step(&WAIT).unwrap().info.extras.get("objects_sorted");
        assert_eq!(sorted, Some(k as f32), "seed {seed}");
        above += 1;
    }
    assert!(above > 0 && at_home > 0, "{above} {at_home}");
}

#[test]
fn with_return_home_each_placement_sends_the_arm_home_open() {
    for return_home in [true, false] {
        let mut env = sort_env(|c| {
            c.task.return_home = return_home;
            c.task.max_episode_steps = 600;
        });
        for seed in 0..3 {
            env.reset(Some(seed)).unwrap();
            let home = env.scene().tcp_pose().translation.vector;
            let (mut returns, mut success) = (0, false);
            'episode: for i in env.task().objects_to_sort() {
                let mut policy = scripted_drop(&env, i);
                let mut away = false;
                while !policy.done() {
                    let step = env.step(&policy.act(&env)).unwrap();
                    if step.terminated || step.truncated {
                        success = step.info.success;
                        break 'episode;
                    }
                    let tcp = env.scene().tcp_pose().translation.vector;
                    // Home as the reset left it, sagged a few mm under gravity.
                    let from_home = (tcp - home).norm();
                    if away && from_home < 5e-3 {
                        // Back at home the moment the object is let go in its bin, open.
                        assert!(!env.scene().gripper_commanded_closed(), "seed {seed}");
                        let sorted = step.info.extras.get("objects_sorted").unwrap();
                        assert!(sorted <= (returns + 1) as f32, "seed {seed}");
                        returns += 1;
                        // It holds there: the actions in flight were dropped.
                        env.step(&WAIT).unwrap();
                        let held = (env.scene().tcp_pose().translation.vector - tcp).norm();
                        assert!(held < 2e-3, "seed {seed}: drifted {held} m");
                        break;
                    }
                    away |= from_home > 0.1;
                }
            }
            assert!(success, "seed {seed}, return_home {return_home}");
            // After every object but the last, and never without the setting.
            let expected = if return_home { 2 } else { 0 };
            assert_eq!(returns, expected, "seed {seed}");
        }
    }
}

/// Plays one sorting episode: the scripted pick and place of each object left, in order.
fn scripted_sort(env: &mut SortEnv) -> bool {
    for i in env.task().objects_to_sort() {
        let mut policy = scripted_drop(env, i);
        while !policy.done() {
            let step = env.step(&policy.act(env)).unwrap();
            if step.terminated || step.truncated {
                return step.info.success;
            }
        }
    }
    false
}

#[test]
fn the_curriculum_allows_more_objects_left_as_episodes_succeed() {
    let mut env = sort_env(|c| {
        c.task.start_sorted_max = 2;
        c.task.curriculum_success = Some(0.5);
    });
    let left = |env: &SortEnv| 3 - env.task().started_sorted().iter().filter(|s| **s).count();
    // Failing episodes open nothing: one object left, always.
    for seed in 0..6 {
        env.reset(Some(seed)).unwrap();
        assert_eq!(left(&env), 1, "seed {seed}");
        while !env
            .step(&WAIT)
            .map(|s| s.terminated || s.truncated)
            .unwrap()
        {}
    }
    // Successes open two left (7 in a row reach 0.5), never three before two-left ones succeed.
    let mut seen = [0; 4];
    let mut successes = 0;
    for seed in 6..40 {
        env.reset(Some(seed)).unwrap();
        seen[left(&env)] += 1;
        if left(&env) == 1 {
            successes += scripted_sort(&mut env) as u32;
        } else {
            assert!(
                successes >= 6,
                "{successes} successes opened {}",
                left(&env)
            );
            assert_eq!(left(&env), 2);
            while !env
                .step(&WAIT)
                .map(|s| s.terminated || s.truncated)
                .unwrap()
            {}
        }
    }
    assert!(seen[2] > 0 && seen[3] == 0, "{seen:?}");
    // The count is logged with every step.
    env.reset(Some(40)).unwrap();
    let to_sort = left(&env) as f32;
    let step = env.step(&WAIT).unwrap();
    assert_eq!(step.info.extras.get("objects_to_sort"), Some(to_sort));
}

#[test]
fn an_object_off_the_table_is_skipped_and_the_last_lost_ends_the_episode() {
    use fairgrasp_env::EpisodeEvent;
    use fairgrasp_env::arm::erased::ArmWorld;
    use fairgrasp_env::sim::rapier3d::na::Isometry3;
    let mut env = sort_env(|c| c.task.num_objects = 2);
    // Beside the table, below its top: off the table at the next step.
    let away = |env: &mut SortEnv, i: usize| {
        let pose = Isometry3::translation(-2.0, 2.0 * i as f64, 0.3);
        env.scene_mut().set_object_pose(i, &pose).unwrap();
    };
    let (obs, _) = env.reset(Some(3)).unwrap();
    let order = env.task().order().to_vec();
    let active_flag = |obs: &[f32], i: usize| obs[obs.len() - 1 - 5 * (2 - i) + 4];
    assert_eq!(active_flag(&obs, order[0]), 1.0);
    away(&mut env, order[0]);
    let step = env.step(&WAIT).unwrap();
    assert!(!step.terminated && !step.truncated);
    assert_eq!(step.info.extras.get("objects_lost"), Some(1.0));
    assert_eq!(step.info.reward_terms.get("lost"), Some(0.0));
    // The other object is active now.
    assert_eq!(active_flag(&step.obs, order[0]), 0.0);
    assert_eq!(active_flag(&step.obs, order[1]), 1.0);
    away(&mut env, order[1]);
    let step = env.step(&WAIT).unwrap();
    assert!(step.terminated && !step.info.success);
    assert_eq!(step.info.events, vec![EpisodeEvent::ObjectOffTable]);
    // Both lost for the steps left: what waiting them out would have cost.
    let left = 300.0 - 2.0;
    assert_eq!(step.info.reward_terms.get("lost"), Some(-2.0 * left));
}

#[test]
fn sortings_observation_begins_with_pick_and_places_around_the_active_object() {
    let mode = ActionMode::Cartesian;
    let mut config = SortConfig::default();
    config.control.action_mode = mode;
    let mut env = SortEnv::new(config).unwrap();
    let leading = pick_place(mode).observation_space().low.len();
    let n = 3;
    // Then the active object's half extents and yaw (5), every object (5 each), the share left.
    assert_eq!(env.observation_space().low.len(), leading + 5 + 5 * n + 1);
    let (obs, _) = env.reset(Some(4)).unwrap();
    let order = env.task().order().to_vec();
    // Pick and place's goal and object→goal sit at its end: here the drop point of the first
    // object of the order.
    let goal_at = leading - 6;
    let check = |obs: &[f32], env: &SortEnv, active: usize| {
        let s = env.state().unwrap();
        let object = s.objects[active].pose.translation.vector;
        let drop = env.task().drop_point(active);
        let near =
            |a: &[f32], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (*x as f64 - y).abs() < 1e-5);
        assert!(
            near(&obs[21..24], [object.x, object.y, object.z]),
            "object {active}"
        );
        assert!(near(&obs[goal_at..goal_at + 3], [drop.x, drop.y, drop.z]));
        let to_drop = drop - object;
        assert!(near(
            &obs[goal_at + 3..leading],
            [to_drop.x, to_drop.y, to_drop.z]
        ));
        let flags = |i: usize| &obs[leading + 5 + 5 * i + 3..leading + 5 + 5 * i + 5];
        for i in 0..n {
            assert_eq!(
                flags(i)[1],
                (i == active) as u8 as f32,
                "active flag of {i}"
            );
        }
        obs[obs.len() - 1]
    };
    assert_eq!(check(&obs, &env, order[0]), 1.0);
    // Sort that object: the block moves on to the next, and a third of the objects is done.
    let mut policy = scripted_drop(&env, order[0]);
    let mut obs = obs;
    let mut steps = 0;
    while (!policy.done() || obs[obs.len() - 1] == 1.0) && steps < 150 {
        obs = env.step(&policy.act(&env)).unwrap().obs;
        steps += 1;
    }
    assert_eq!(env.task().assignment().len(), n);
    let left = check(&obs, &env, order[1]);
    assert!((left - 2.0 / 3.0).abs() < 1e-6, "{left}");
    // Without the others: the active object's blocks alone, whatever the number of objects.
    for objects in [1, 3, 5] {
        let mut alone = sort_env(|c| {
            c.task.num_objects = objects;
            c.task.observe_others = false;
        });
        let mut full = sort_env(|c| c.task.num_objects = objects);
        assert_eq!(alone.observation_space().low.len(), leading + 5);
        let (a, _) = alone.reset(Some(4)).unwrap();
        let (f, _) = full.reset(Some(4)).unwrap();
        assert_eq!(a[..], f[..leading + 5], "{objects} objects");
    }
    // Without the others but with the count: the share left follows the active object's blocks.
    let mut counted = sort_env(|c| {
        c.task.observe_others = false;
        c.task.observe_left = Some(true);
        c.task.start_sorted_min = 1;
        c.task.start_sorted_max = 1;
    });
    assert_eq!(counted.observation_space().low.len(), leading + 5 + 1);
    let (obs, _) = counted.reset(Some(4)).unwrap();
    assert!((obs[leading + 5] - 2.0 / 3.0).abs() < 1e-6, "{obs:?}");
}

#[test]
fn an_object_dropped_into_the_wrong_bin_is_not_sorted() {
    let mut config = SortConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    config.task.num_objects = 1;
    let mut env = SortEnv::new(config).unwrap();
    env.reset(Some(2)).unwrap();
    let wrong = 1 - env.task().assignment()[0];
    let mut drop = env.scene().bin_pose(wrong).translation.vector;
    drop.z += 0.11;
    let mut policy = ScriptedGraspPolicy::for_object(&env, 0, Some(drop), true);
    let mut step = env.step(&policy.act(&env)).unwrap();
    while !step.terminated && !step.truncated {
        assert_eq!(step.info.extras.get("objects_sorted").unwrap(), 0.0);
        let action = match policy.done() {
            true => WAIT.to_vec(),
            false => policy.act(&env),
        };
        step = env.step(&action).unwrap();
    }
    assert!(
        env.scene().object_in_bin(0, wrong),
        "the drop missed the bin"
    );
    // Resting in the wrong bin, it is lost: the episode ends, paying for the steps left.
    assert!(step.terminated && !step.info.success);
    assert_eq!(
        step.info.events,
        vec![fairgrasp_env::EpisodeEvent::ObjectMisplaced]
    );
    let left = 300 - step.info.elapsed_steps;
    assert_eq!(step.info.reward_terms.get("lost"), Some(-(left as f32)));
}

#[test]
fn pick_and_place_works_on_the_kinematic_arm_drive() {
    let mut config = PickPlaceConfig::default();
    config.control.action_mode = ActionMode::Cartesian;
    config.task.max_episode_steps = 150;
    config.scene.arm.drive = fairgrasp_env::sim::scene::ArmDrive::Kinematic;
    config.scene.physics.pgs_iterations = 12;
    let mut env = PickPlaceEnv::new(config).unwrap();
    let episodes = 10;
    let mut successes = 0;
    for seed in 0..episodes {
        env.reset(Some(seed)).unwrap();
        let goal = env.scene().base_pose() * Point3::from(env.task().goal());
        let mut policy = ScriptedGraspPolicy::with_goal(&env, Some(goal.coords));
        loop {
            let step = env.step(&policy.act(&env)).unwrap();
            if step.terminated || step.truncated {
                successes += usize::from(step.info.success);
                break;
            }
        }
    }
    assert!(successes >= 9, "kinematic drive: {successes}/{episodes}");
}
