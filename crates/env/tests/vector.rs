//! VecEnv: determinism across thread counts, automatic resets, agreement with single
//! environments, errors that name the environment.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::core::{Frame, Metadata, RenderMode};
use fairgrasp_env::spaces::BoxSpace;
use fairgrasp_env::{
    Env, EnvConfig, EnvError, GraspEnv, Info, Step, VecEnv, VecNormalize, VecNormalizeConfig,
    VectorEnv,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The grasp task with domain randomisation on (so every step draws from the environment's
/// random stream) and short episodes.
fn config(max_episode_steps: u32) -> EnvConfig {
    let mut c = EnvConfig::default();
    c.task.max_episode_steps = max_episode_steps;
    c.randomization.enabled = true;
    c
}

fn grasp_envs(n: usize, config: &EnvConfig) -> Vec<GraspEnv> {
    (0..n)
        .map(|_| GraspEnv::new(config.clone()).unwrap())
        .collect()
}

/// Random actions for `n` environments, a little beyond the box so that clipping happens too.
fn actions(rng: &mut ChaCha8Rng, n: usize, space: &BoxSpace) -> Vec<f32> {
    (0..n)
        .flat_map(|_| {
            space
                .low
                .iter()
                .zip(&space.high)
                .map(|(&lo, &hi)| rng.random_range(1.2 * lo..1.2 * hi))
                .collect::<Vec<_>>()
        })
        .collect()
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

/// Everything a rollout returned, as bits.
#[derive(Debug, PartialEq)]
struct Trace {
    observations: Vec<u32>,
    rewards: Vec<u32>,
    flags: Vec<(bool, bool)>,
    terminal: Vec<(usize, usize, Vec<u32>)>,
    returns: Vec<u64>,
}

fn rollout(num_threads: usize, steps: usize) -> Trace {
    let (n, c) = (4, config(30));
    let mut venv = VecEnv::new(grasp_envs(n, &c), num_threads).unwrap();
    assert_eq!(venv.num_threads(), num_threads);
    let mut trace = Trace {
        observations: bits(venv.reset(Some(1234)).unwrap()),
        rewards: Vec::new(),
        flags: Vec::new(),
        terminal: Vec::new(),
        returns: Vec::new(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for t in 0..steps {
        let a = actions(&mut rng, n, venv.action_space());
        let step = venv.step(&a).unwrap();
        trace.observations.extend(bits(step.observations));
        trace.rewards.extend(bits(step.rewards));
        for i in 0..n {
            trace.flags.push((step.terminated[i], step.truncated[i]));
            if let Some(end) = &step.episode_ends[i] {
                trace.terminal.push((t, i, bits(&end.terminal_observation)));
                trace.returns.push(end.episode.episode_return.to_bits());
            }
        }
    }
    trace
}

#[test]
fn results_do_not_depend_on_the_number_of_threads() {
    let steps = 240;
    let one = rollout(1, steps);
    assert_eq!(
        one.terminal.len(),
        4 * steps / 30,
        "episodes ended and were reset"
    );
    assert_eq!(one, rollout(2, steps), "1 vs 2 threads");
    assert_eq!(one, rollout(3, steps), "1 vs 3 threads");
}

#[test]
fn steps_match_single_environments_stepped_by_hand() {
    let (n, seed, c) = (3, 11u64, config(7));
    let mut venv = VecEnv::new(grasp_envs(n, &c), 2).unwrap();
    let mut singles = grasp_envs(n, &c);
    let obs_dim = venv.obs_dim();
    let first = venv.reset(Some(seed)).unwrap().to_vec();
    for (i, env) in singles.iter_mut().enumerate() {
        let (obs, info) = env.reset(Some(seed + i as u64)).unwrap();
        assert_eq!(
            bits(&first[i * obs_dim..(i + 1) * obs_dim]),
            bits(&obs),
            "env {i}"
        );
        assert_eq!(venv.reset_infos()[i], info);
    }
    assert_ne!(
        first[..obs_dim],
        first[obs_dim..2 * obs_dim],
        "seed + i differ"
    );

    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut sums = vec![0.0f64; n];
    let mut ends = 0;
    for _ in 0..40 {
        let a = actions(&mut rng, n, venv.action_space());
        let act_dim = venv.act_dim();
        let step = venv.step(&a).unwrap();
        for (i, env) in singles.iter_mut().enumerate() {
            let s = env.step(&a[i * act_dim..(i + 1) * act_dim]).unwrap();
            sums[i] += s.reward as f64;
            assert_eq!(step.rewards[i].to_bits(), s.reward.to_bits(), "env {i}");
            assert_eq!(step.terminated[i], s.terminated);
            assert_eq!(step.truncated[i], s.truncated);
            assert_eq!(step.infos[i], s.info);
            if s.terminated || s.truncated {
                ends += 1;
                let end = step.episode_ends[i].as_ref().expect("episode end kept");
                assert_eq!(bits(&end.terminal_observation), bits(&s.obs));
                assert_eq!(end.episode.episode_return, sums[i]);
                assert_eq!(end.episode.length, 7);
                assert_eq!(end.episode.success, s.info.success);
                let (obs, info) = env.reset(None).unwrap();
                assert_eq!(bits(step.obs(i)), bits(&obs), "continues the stream");
                assert_eq!(end.reset_info, info);
                sums[i] = 0.0;
            } else {
                assert!(step.episode_ends[i].is_none());
                assert_eq!(bits(step.obs(i)), bits(&s.obs), "env {i}");
            }
        }
    }
    assert_eq!(ends, n * (40 / 7));
}

#[test]
fn auto_reset_keeps_the_terminal_observation_and_starts_a_fresh_episode() {
    let (n, seed) = (2, 500u64);
    let mut c = EnvConfig::default();
    c.task.max_episode_steps = 5;
    let mut venv = VecEnv::new(grasp_envs(n, &c), 1).unwrap();
    let mut twin = GraspEnv::new(c.clone()).unwrap();
    venv.reset(Some(seed)).unwrap();
    twin.reset(Some(seed + 1)).unwrap();
    let zero = vec![0.0; n * venv.act_dim()];
    let mut grip = zero.clone();
    for row in grip.chunks_mut(venv.act_dim()) {
        row[row.len() - 1] = 1.0;
        row[0] = 0.03;
    }
    for t in 1..=4u32 {
        let step = venv.step(&zero).unwrap();
        assert!(!step.truncated.iter().any(|&x| x) && !step.terminated.iter().any(|&x| x));
        assert!(step.episode_ends.iter().all(Option::is_none));
        assert!(step.infos.iter().all(|i| i.elapsed_steps == t));
        twin.step(&zero[..venv.act_dim()]).unwrap();
    }
    let last = twin.step(&zero[..venv.act_dim()]).unwrap();
    assert!(last.truncated);
    let (fresh, _) = twin.reset(None).unwrap();

    let step = venv.step(&zero).unwrap();
    assert_eq!(step.truncated, &[true, true]);
    assert_eq!(step.terminated, &[false, false]);
    for i in 0..n {
        assert!(step.done(i));
        assert_eq!(step.infos[i].elapsed_steps, 5, "the final step's info");
        let end = step.episode_ends[i].as_ref().unwrap();
        assert_eq!(end.episode.length, 5);
        assert_eq!(end.reset_info.elapsed_steps, 0);
        assert_ne!(bits(&end.terminal_observation), bits(step.obs(i)));
    }
    // Env 1: terminal observation and the next episode's first observation, as by hand.
    assert_eq!(bits(step.terminal_observation(1).unwrap()), bits(&last.obs));
    assert_eq!(bits(step.obs(1)), bits(&fresh));
    assert_eq!(step.episode(1).unwrap().episode_return, {
        // Rewards of a zero action are deterministic for this seed; recompute them.
        let mut env = GraspEnv::new(c.clone()).unwrap();
        env.reset(Some(seed + 1)).unwrap();
        (0..5)
            .map(|_| env.step(&zero[..7]).unwrap().reward as f64)
            .sum::<f64>()
    });

    // The next step belongs to the new episode.
    let step = venv.step(&grip).unwrap();
    assert!(step.infos.iter().all(|i| i.elapsed_steps == 1));
    assert!(step.episode_ends.iter().all(Option::is_none));
    assert_eq!(bits(step.obs(1)), bits(&twin.step(&grip[..7]).unwrap().obs));
}

#[test]
fn seeds_reproduce_and_none_continues_the_streams() {
    let c = config(20);
    let mut venv = VecEnv::new(grasp_envs(3, &c), 2).unwrap();
    let a = venv.reset(Some(7)).unwrap().to_vec();
    let b = venv.reset(Some(7)).unwrap().to_vec();
    assert_eq!(bits(&a), bits(&b));
    let c2 = venv.reset(None).unwrap().to_vec();
    assert_ne!(bits(&a), bits(&c2), "None continues each stream");
    let d = venv.reset(Some(8)).unwrap().to_vec();
    // Env i with seed 8 + i: env 0 now plays what env 1 played with seed 7.
    let dim = venv.obs_dim();
    assert_eq!(bits(&d[..dim]), bits(&a[dim..2 * dim]));
}

#[test]
fn bad_actions_are_errors_naming_the_env_and_change_nothing() {
    let c = config(50);
    let mut venv = VecEnv::new(grasp_envs(3, &c), 2).unwrap();
    let mut twin = VecEnv::new(grasp_envs(3, &c), 1).unwrap();
    let act_dim = venv.act_dim();
    let good = vec![0.01; 3 * act_dim];

    let e = venv.step(&good).unwrap_err();
    assert!(matches!(e, EnvError::Usage(_)), "{e}");
    assert!(e.to_string().contains("env 0 must be reset"), "{e}");

    venv.reset(Some(1)).unwrap();
    twin.reset(Some(1)).unwrap();
    let mut nan = good.clone();
    nan[2 * act_dim + 3] = f32::NAN;
    let e = venv.step(&nan).unwrap_err();
    assert!(matches!(e, EnvError::Action(_)), "{e}");
    assert!(e.to_string().contains("env 2: value 3 is NaN"), "{e}");

    let mut two = good.clone();
    two[act_dim] = f32::INFINITY;
    two[2 * act_dim] = f32::NEG_INFINITY;
    let e = venv.step(&two).unwrap_err().to_string();
    assert!(e.contains("env 1: value 0 is inf"), "{e}");
    assert!(e.contains("envs 2 failed too"), "{e}");

    let e = venv.step(&good[1..]).unwrap_err().to_string();
    assert!(
        e.contains("expected 3 envs × 7 values = 21 action values, got 20"),
        "{e}"
    );

    // None of that stepped anything: the results equal those of the untouched twin.
    for _ in 0..3 {
        let s = bits(venv.step(&good).unwrap().observations);
        assert_eq!(s, bits(twin.step(&good).unwrap().observations));
    }
    let e = venv.reset_env(3, None).unwrap_err().to_string();
    assert!(e.contains("env 3 does not exist"), "{e}");
}

#[test]
fn construction_checks_the_environments() {
    let e = VecEnv::<GraspEnv>::new(Vec::new(), 1).err().unwrap();
    assert!(e.to_string().contains("at least one"), "{e}");
    let joint = EnvConfig::default();
    let mut cartesian = EnvConfig::default();
    cartesian.control.action_mode = ActionMode::Cartesian;
    let envs = vec![
        GraspEnv::new(joint.clone()).unwrap(),
        GraspEnv::new(joint).unwrap(),
        GraspEnv::new(cartesian).unwrap(),
    ];
    let e = VecEnv::new(envs, 1).err().unwrap().to_string();
    assert!(e.contains("env 2's"), "{e}");
    let venv = VecEnv::new(grasp_envs(2, &EnvConfig::default()), 8).unwrap();
    assert_eq!(venv.num_threads(), 2, "no more threads than environments");
    assert_eq!(venv.num_envs(), 2);
    assert_eq!(venv.obs_dim(), 40);
    assert_eq!(venv.act_dim(), 7);
}

/// Counts its steps in the observation; fails or panics once, on a chosen step.
struct FlakyEnv {
    space: BoxSpace,
    t: u32,
    fail_at: Option<u32>,
    panic_at: Option<u32>,
}

impl FlakyEnv {
    fn new(fail_at: Option<u32>, panic_at: Option<u32>) -> Self {
        Self {
            space: BoxSpace::new(vec![-1.0], vec![1.0]),
            t: 0,
            fail_at,
            panic_at,
        }
    }
}

impl Env for FlakyEnv {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: "Flaky-v0",
            render_modes: vec![],
            render_fps: 1.0,
        }
    }
    fn observation_space(&self) -> &BoxSpace {
        &self.space
    }
    fn action_space(&self) -> &BoxSpace {
        &self.space
    }
    fn render_mode(&self) -> Option<RenderMode> {
        None
    }
    fn reset(&mut self, _seed: Option<u64>) -> fairgrasp_env::Result<(Vec<f32>, Info)> {
        self.t = 0;
        Ok((vec![0.0], Info::default()))
    }
    fn step(&mut self, _action: &[f32]) -> fairgrasp_env::Result<Step> {
        self.t += 1;
        if Some(self.t) == self.panic_at {
            self.panic_at = None;
            panic!("kaboom at step {}", self.t);
        }
        if Some(self.t) == self.fail_at {
            self.fail_at = None;
            return Err(EnvError::Usage(format!("boom at step {}", self.t)));
        }
        Ok(Step {
            obs: vec![self.t as f32],
            reward: 1.0,
            terminated: self.t >= 100,
            truncated: false,
            info: Info::default(),
        })
    }
    fn render(&mut self) -> fairgrasp_env::Result<Option<Frame>> {
        Ok(None)
    }
}

#[test]
fn a_failing_env_does_not_poison_the_others() {
    for threads in [1, 2] {
        let envs = vec![
            FlakyEnv::new(None, None),
            FlakyEnv::new(Some(3), None),
            FlakyEnv::new(None, Some(2)),
        ];
        let mut venv = VecEnv::new(envs, threads).unwrap();
        venv.reset(Some(0)).unwrap();
        venv.step(&[0.0; 3]).unwrap();
        // Env 2 panics: reported as an error naming it, the others step.
        let e = venv.step(&[0.0; 3]).unwrap_err().to_string();
        assert!(
            e.contains("env 2 panicked during step: kaboom at step 2"),
            "{e}"
        );
        assert_eq!(venv.observations(), &[2.0, 2.0, 1.0]);
        let e = venv.step(&[0.0; 3]).unwrap_err().to_string();
        assert!(e.contains("env 2 must be reset"), "{e}");
        venv.reset_env(2, None).unwrap();
        // Env 1 fails: the error names it, the others step.
        let e = venv.step(&[0.0; 3]).unwrap_err();
        assert!(matches!(e, EnvError::Usage(_)));
        assert!(e.to_string().contains("env 1: boom at step 3"), "{e}");
        assert_eq!(venv.observations(), &[3.0, 2.0, 1.0]);
        assert_eq!(venv.reset_env(1, Some(4)).unwrap(), &[0.0]);
        let step = venv.step(&[0.0; 3]).unwrap();
        assert_eq!(step.observations, &[4.0, 1.0, 2.0]);
        assert_eq!(step.rewards, &[1.0, 1.0, 1.0]);
    }
}

#[test]
fn vec_normalize_runs_over_grasp_envs_and_normalises_terminal_observations() {
    let c = config(6);
    let venv = VecEnv::new(grasp_envs(2, &c), 2).unwrap();
    let mut venv = VecNormalize::new(venv, VecNormalizeConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    venv.reset(Some(3)).unwrap();
    let mut seen = 0;
    for _ in 0..12 {
        let a = actions(&mut rng, 2, venv.action_space());
        let step = venv.step(&a).unwrap();
        assert!(step.observations.iter().all(|v| v.abs() <= 10.0));
        let ends: Vec<Option<Vec<f32>>> = (0..2)
            .map(|i| step.terminal_observation(i).map(<[f32]>::to_vec))
            .collect();
        for (i, end) in ends.iter().enumerate() {
            if let Some(t) = end {
                seen += 1;
                let raw = venv.original_terminal_observation(i).unwrap();
                assert_eq!(*t, venv.normalize_obs(raw).unwrap());
            }
        }
    }
    assert_eq!(seen, 4);
}
