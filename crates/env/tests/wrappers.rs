//! Wrappers (RescaleAction, RecordEpisodeStatistics) and VecNormalize, on a tiny deterministic
//! environment whose observations and rewards are known.

use fairgrasp_env::core::{Frame, Metadata, RenderMode};
use fairgrasp_env::spaces::BoxSpace;
use fairgrasp_env::{
    Env, EnvError, EpisodeStats, Info, RecordEpisodeStatistics, RescaleAction, RunningMeanStd,
    Step, VecEnv, VecNormalize, VecNormalizeConfig, VecNormalizeState, VectorEnv,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// Observations: independent Gaussians with known means and standard deviations. Reward of the
/// `t`-th step (t = 1, 2, …): `0.5 + 0.25 t + action[0]`. Episodes last `episode_len` steps and
/// end terminated with success, or truncated without.
struct TinyEnv {
    observation_space: BoxSpace,
    action_space: BoxSpace,
    means: Vec<f32>,
    stds: Vec<f32>,
    episode_len: u32,
    truncate: bool,
    rng: ChaCha8Rng,
    t: u32,
    running: bool,
    /// The last action `step` received, before clipping.
    last_action: Option<Vec<f32>>,
    steps_taken: u32,
}

impl TinyEnv {
    fn new(episode_len: u32) -> Self {
        Self::with_obs(vec![1.0, -2.0, 5.0], vec![0.5, 2.0, 0.1], episode_len)
    }

    fn with_obs(means: Vec<f32>, stds: Vec<f32>, episode_len: u32) -> Self {
        Self {
            observation_space: BoxSpace::unbounded(means.len()),
            action_space: BoxSpace::new(vec![-2.0, 1e-3, -0.05], vec![2.0, 7.77, 0.3]),
            means,
            stds,
            episode_len,
            truncate: false,
            rng: ChaCha8Rng::seed_from_u64(0),
            t: 0,
            running: false,
            last_action: None,
            steps_taken: 0,
        }
    }

    fn observe(&mut self) -> Vec<f32> {
        let (means, stds) = (self.means.clone(), self.stds.clone());
        means
            .iter()
            .zip(&stds)
            .map(|(m, s)| {
                let u1: f64 = self.rng.random::<f64>().max(1e-300);
                let u2: f64 = self.rng.random();
                let n = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
                m + s * n as f32
            })
            .collect()
    }
}

fn reward_of(t: u32, action0: f32) -> f32 {
    0.5 + 0.25 * t as f32 + action0
}

impl Env for TinyEnv {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: "Tiny-v0",
            render_modes: vec![],
            render_fps: 10.0,
        }
    }

    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }

    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }

    fn render_mode(&self) -> Option<RenderMode> {
        None
    }

    fn reset(&mut self, seed: Option<u64>) -> fairgrasp_env::Result<(Vec<f32>, Info)> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        self.t = 0;
        self.running = true;
        Ok((self.observe(), Info::default()))
    }

    fn step(&mut self, action: &[f32]) -> fairgrasp_env::Result<Step> {
        if !self.running {
            return Err(EnvError::Usage("reset first".into()));
        }
        if action.len() != self.action_space.dim() || action.iter().any(|v| !v.is_finite()) {
            return Err(EnvError::Action(format!("bad action {action:?}")));
        }
        self.last_action = Some(action.to_vec());
        self.steps_taken += 1;
        let mut clipped = action.to_vec();
        self.action_space.clip(&mut clipped);
        self.t += 1;
        let done = self.t >= self.episode_len;
        self.running = !done;
        let terminated = done && !self.truncate;
        Ok(Step {
            obs: self.observe(),
            reward: reward_of(self.t, clipped[0]),
            terminated,
            truncated: done && self.truncate,
            info: Info {
                success: terminated,
                elapsed_steps: self.t,
                ..Info::default()
            },
        })
    }

    fn render(&mut self) -> fairgrasp_env::Result<Option<Frame>> {
        Ok(None)
    }
}

// ---------------------------------------------------------------------------------------------
// RescaleAction

#[test]
fn rescale_action_maps_the_unit_box_onto_the_inner_box_exactly_and_clips() {
    let mut env = RescaleAction::new(TinyEnv::new(1000)).unwrap();
    let low = env.inner().action_space().low.clone();
    let high = env.inner().action_space().high.clone();
    assert_eq!(env.action_space().low, vec![-1.0; 3]);
    assert_eq!(env.action_space().high, vec![1.0; 3]);
    assert_eq!(env.action_space().shape, vec![3]);
    env.reset(Some(1)).unwrap();

    fn sent(env: &mut RescaleAction<TinyEnv>, a: &[f32]) -> Vec<f32> {
        env.step(a).unwrap();
        env.inner().last_action.clone().unwrap()
    }
    assert_eq!(
        sent(&mut env, &[-1.0, -1.0, -1.0]),
        low,
        "-1 must give low exactly"
    );
    assert_eq!(
        sent(&mut env, &[1.0, 1.0, 1.0]),
        high,
        "+1 must give high exactly"
    );
    let mid = sent(&mut env, &[0.0, 0.0, 0.0]);
    for i in 0..3 {
        assert!((mid[i] - (low[i] + high[i]) / 2.0).abs() < 1e-6, "{mid:?}");
    }
    let quarter = sent(&mut env, &[0.5, -0.5, 0.0]);
    assert!((quarter[0] - 1.0).abs() < 1e-6, "{quarter:?}");
    assert!(
        (quarter[1] - (1e-3 + 0.25 * (7.77 - 1e-3))).abs() < 1e-5,
        "{quarter:?}"
    );
    // Out of range: clipped to [-1, 1] first.
    assert_eq!(
        sent(&mut env, &[5.0, -7.0, 1.0 + 1e-3]),
        vec![high[0], low[1], high[2]]
    );
    assert_eq!(
        sent(&mut env, &[-1e30, 1e30, -1.5]),
        vec![low[0], high[1], low[2]]
    );

    // NaN, infinity and a wrong length are errors; the inner env is not stepped.
    let steps = env.inner().steps_taken;
    for bad in [
        vec![f32::NAN, 0.0, 0.0],
        vec![0.0, f32::INFINITY, 0.0],
        vec![0.0, 0.0],
    ] {
        let e = env.step(&bad).unwrap_err();
        assert!(matches!(e, EnvError::Action(_)), "{e}");
    }
    assert_eq!(env.inner().steps_taken, steps);

    // Inverse mapping.
    let policy = env.to_policy_action(&[2.0, 1e-3, 0.3]).unwrap();
    assert_eq!(policy, vec![1.0, -1.0, 1.0]);
    let back = env
        .to_inner_action(&env.to_policy_action(&[0.7, 3.3, 0.1]).unwrap())
        .unwrap();
    for (b, x) in back.iter().zip([0.7, 3.3, 0.1]) {
        assert!((b - x).abs() < 1e-5, "{back:?}");
    }
}

#[test]
fn rescale_action_needs_a_bounded_action_space() {
    let mut inner = TinyEnv::new(10);
    inner.action_space = BoxSpace::new(vec![-1.0, f32::NEG_INFINITY], vec![1.0, 0.0]);
    let e = RescaleAction::new(inner)
        .err()
        .expect("unbounded box must be rejected");
    assert!(e.to_string().contains("dimension 1"), "{e}");
}

#[test]
fn rescale_action_reaches_grasp_env_bounds_exactly() {
    let env = fairgrasp_env::GraspEnv::new(fairgrasp_env::EnvConfig::default()).unwrap();
    let space = env.action_space().clone();
    let env = RescaleAction::new(env).unwrap();
    let n = space.dim();
    assert_eq!(env.to_inner_action(&vec![-1.0; n]).unwrap(), space.low);
    assert_eq!(env.to_inner_action(&vec![1.0; n]).unwrap(), space.high);
}

// ---------------------------------------------------------------------------------------------
// RecordEpisodeStatistics

#[test]
fn record_episode_statistics_sums_rewards_over_each_episode() {
    let mut env = RecordEpisodeStatistics::with_buffer_length(TinyEnv::new(6), 2);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    env.reset(Some(3)).unwrap();
    assert!(env.episode().is_none());
    let mut expected = Vec::new();
    for _episode in 0..3 {
        let mut sum = 0.0f64;
        for t in 1..=6u32 {
            let a: f32 = rng.random_range(-3.0..3.0);
            let step = env.step(&[a, 1.0, 0.0]).unwrap();
            assert_eq!(step.reward, reward_of(t, a.clamp(-2.0, 2.0)));
            sum += step.reward as f64;
            if t < 6 {
                assert!(env.episode().is_none(), "no stats before the episode ends");
                assert_eq!(env.current_length(), t);
                assert!((env.current_return() - sum).abs() < 1e-12);
            }
        }
        let stats = env.episode().expect("stats at the episode's end").clone();
        assert_eq!(stats.length, 6);
        assert!(
            (stats.episode_return - sum).abs() < 1e-9,
            "{stats:?} vs {sum}"
        );
        assert!(stats.success);
        expected.push(stats);
        env.reset(None).unwrap();
        assert!(env.episode().is_none(), "reset clears the report");
    }
    assert_eq!(env.episode_count(), 3);
    let recent: Vec<EpisodeStats> = env.recent_episodes().iter().cloned().collect();
    assert_eq!(recent, expected[1..].to_vec(), "keeps the last two");

    // An episode cut short by reset is not recorded; a truncated one reports no success.
    env.step(&[0.0, 1.0, 0.0]).unwrap();
    env.reset(None).unwrap();
    assert_eq!(env.current_length(), 0);
    env.inner_mut().truncate = true;
    for _ in 0..6 {
        env.step(&[1.0, 1.0, 0.0]).unwrap();
    }
    let stats = env.episode().unwrap().clone();
    assert_eq!(env.episode_count(), 4);
    assert!(!stats.success);
    let want: f64 = (1..=6).map(|t| reward_of(t, 1.0) as f64).sum();
    assert!((stats.episode_return - want).abs() < 1e-9);

    // A failed step changes nothing.
    env.reset(None).unwrap();
    env.step(&[1.0, 1.0, 0.0]).unwrap();
    assert!(env.step(&[f32::NAN, 1.0, 0.0]).is_err());
    assert_eq!(env.current_length(), 1);
}

// ---------------------------------------------------------------------------------------------
// VecNormalize

fn tiny_venv(n: usize, episode_len: u32) -> VecEnv<TinyEnv> {
    VecEnv::new((0..n).map(|_| TinyEnv::new(episode_len)).collect(), 1).unwrap()
}

fn random_actions(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n * 3).map(|_| rng.random_range(-2.5..2.5)).collect()
}

/// Mean and population variance of column `j` of row-major `rows`, and what SB3's
/// `RunningMeanStd` holds after seeing them: the data merged with its prior (mean 0, variance 1,
/// pseudo-count 1e-4).
fn column_moments(rows: &[f64], dim: usize, j: usize) -> ((f64, f64), (f64, f64)) {
    let xs: Vec<f64> = rows.iter().skip(j).step_by(dim).copied().collect();
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n;
    let (c0, total) = (1e-4, n + 1e-4);
    let prior_mean = n * m / total;
    let prior_var = (c0 * 1.0 + n * v + m * m * c0 * n / total) / total;
    ((m, v), (prior_mean, prior_var))
}

#[test]
fn vec_normalize_learns_the_observation_and_return_statistics() {
    let (n, gamma) = (8, 0.9);
    let config = VecNormalizeConfig {
        gamma,
        ..VecNormalizeConfig::default()
    };
    let mut venv = VecNormalize::new(tiny_venv(n, 25), config).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut all_obs: Vec<f64> = Vec::new();
    let mut all_returns: Vec<f64> = Vec::new();
    let mut returns = vec![0.0f64; n];
    let mut episode_sums = vec![0.0f64; n];

    let first = venv.reset(Some(100)).unwrap().to_vec();
    all_obs.extend(venv.original_observations().iter().map(|&x| x as f64));
    assert_eq!(
        first,
        venv.normalize_obs(venv.original_observations()).unwrap()
    );
    let mut ends = 0;
    for _ in 0..1500 {
        let actions = random_actions(&mut rng, n);
        let step = venv.step(&actions).unwrap();
        let (obs, rewards) = (step.observations.to_vec(), step.rewards.to_vec());
        let dones: Vec<bool> = (0..n).map(|i| step.done(i)).collect();
        let normalised_terminal: Vec<Option<Vec<f32>>> = (0..n)
            .map(|i| step.terminal_observation(i).map(<[f32]>::to_vec))
            .collect();
        let episodes: Vec<Option<EpisodeStats>> =
            (0..n).map(|i| step.episode(i).cloned()).collect();

        all_obs.extend(venv.original_observations().iter().map(|&x| x as f64));
        for i in 0..n {
            returns[i] = returns[i] * gamma + venv.original_rewards()[i] as f64;
            episode_sums[i] += venv.original_rewards()[i] as f64;
        }
        all_returns.extend(&returns);
        let state = venv.state();
        // What the step returned is the normalisation by the statistics after the update.
        assert_eq!(
            obs,
            state.normalize_obs(venv.original_observations()).unwrap()
        );
        let scale = (state.ret_rms.var()[0] + 1e-8).sqrt();
        for i in 0..n {
            let want = (venv.original_rewards()[i] as f64 / scale).clamp(-10.0, 10.0) as f32;
            assert_eq!(rewards[i], want);
            if dones[i] {
                ends += 1;
                returns[i] = 0.0;
                let raw = venv.original_terminal_observation(i).unwrap().to_vec();
                assert_eq!(
                    normalised_terminal[i].as_deref(),
                    Some(state.normalize_obs(&raw).unwrap().as_slice()),
                    "terminal observations are normalised"
                );
                assert_ne!(raw, normalised_terminal[i].clone().unwrap());
                // Episode statistics stay in raw reward units.
                assert_eq!(
                    episodes[i].as_ref().unwrap().episode_return,
                    episode_sums[i]
                );
                assert_eq!(episodes[i].as_ref().unwrap().length, 25);
                episode_sums[i] = 0.0;
            } else {
                assert!(normalised_terminal[i].is_none());
            }
        }
    }
    assert_eq!(ends, n * 1500 / 25);

    // The running statistics equal the moments of everything seen, merged with SB3's prior, and
    // match the generating distribution.
    let obs_rms = venv.obs_rms();
    assert!((obs_rms.count() - (1e-4 + (n * 1501) as f64)).abs() < 1e-6);
    let (means, stds) = ([1.0, -2.0, 5.0], [0.5f64, 2.0, 0.1]);
    for j in 0..3 {
        let (_, (m, v)) = column_moments(&all_obs, 3, j);
        assert!((obs_rms.mean()[j] - m).abs() < 1e-9 * stds[j], "mean {j}");
        assert!((obs_rms.var()[j] / v - 1.0).abs() < 1e-9, "var {j}");
        let sem = stds[j] / ((n * 1501) as f64).sqrt();
        assert!(
            (obs_rms.mean()[j] - means[j]).abs() < 5.0 * sem,
            "mean {j}: {} vs {}",
            obs_rms.mean()[j],
            means[j]
        );
        assert!(
            (obs_rms.var()[j] / (stds[j] * stds[j]) - 1.0).abs() < 0.05,
            "var {j}: {} vs {}",
            obs_rms.var()[j],
            stds[j] * stds[j]
        );
    }
    let (_, (rm, rv)) = column_moments(&all_returns, 1, 0);
    let ret_rms = venv.ret_rms();
    assert!((ret_rms.mean()[0] - rm).abs() < 1e-9 * rv.sqrt());
    assert!((ret_rms.var()[0] / rv - 1.0).abs() < 1e-9);
    assert!((ret_rms.count() - (1e-4 + (n * 1500) as f64)).abs() < 1e-6);

    // Single observations; bad lengths are errors.
    let single = venv.normalize_obs(&[1.0, -2.0, 5.0]).unwrap();
    assert!(single.iter().all(|v| v.abs() < 0.05), "{single:?}");
    let far = venv.normalize_obs(&[1e6, -1e6, 5.0]).unwrap();
    assert_eq!(&far[..2], &[10.0, -10.0], "clip_obs = 10");
    assert!(venv.normalize_obs(&[1.0, 2.0]).is_err());
    assert!(venv.normalize_obs(&[]).is_err());
}

#[test]
fn vec_normalize_clips_and_can_be_switched_off() {
    let config = VecNormalizeConfig {
        clip_obs: 0.5,
        clip_reward: 0.25,
        ..VecNormalizeConfig::default()
    };
    let mut venv = VecNormalize::new(tiny_venv(4, 10), config).unwrap();
    venv.reset(Some(1)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let (mut obs_hit, mut rew_hit) = (false, false);
    for _ in 0..200 {
        let step = venv.step(&random_actions(&mut rng, 4)).unwrap();
        assert!(step.observations.iter().all(|v| v.abs() <= 0.5));
        assert!(step.rewards.iter().all(|v| v.abs() <= 0.25));
        obs_hit |= step.observations.iter().any(|v| v.abs() == 0.5);
        rew_hit |= step.rewards.iter().any(|v| v.abs() == 0.25);
    }
    assert!(obs_hit && rew_hit, "the bounds are reached");

    let off = VecNormalizeConfig {
        norm_obs: false,
        norm_reward: false,
        ..VecNormalizeConfig::default()
    };
    let mut plain = VecNormalize::new(tiny_venv(2, 10), off).unwrap();
    let mut raw = tiny_venv(2, 10);
    assert_eq!(plain.reset(Some(4)).unwrap(), raw.reset(Some(4)).unwrap());
    for _ in 0..30 {
        let a = random_actions(&mut rng, 2);
        let s1 = plain.step(&a).unwrap();
        let (o1, r1) = (s1.observations.to_vec(), s1.rewards.to_vec());
        let s2 = raw.step(&a).unwrap();
        assert_eq!(o1, s2.observations);
        assert_eq!(r1, s2.rewards);
    }
    let bad = VecNormalizeConfig {
        gamma: 1.5,
        ..VecNormalizeConfig::default()
    };
    let e = VecNormalize::new(tiny_venv(1, 5), bad).err().unwrap();
    assert!(e.to_string().contains("gamma"), "{e}");
}

#[test]
fn vec_normalize_statistics_are_frozen_when_not_training() {
    let mut venv = VecNormalize::new(tiny_venv(4, 7), VecNormalizeConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    venv.reset(Some(0)).unwrap();
    for _ in 0..50 {
        venv.step(&random_actions(&mut rng, 4)).unwrap();
    }
    venv.set_training(false);
    assert!(!venv.training());
    let frozen = venv.state().clone();
    venv.reset(None).unwrap();
    for _ in 0..50 {
        let step = venv.step(&random_actions(&mut rng, 4)).unwrap();
        let obs = step.observations.to_vec();
        assert_eq!(
            obs,
            frozen.normalize_obs(venv.original_observations()).unwrap()
        );
    }
    assert_eq!(*venv.state(), frozen, "no statistic may change");

    venv.set_training(true);
    venv.step(&random_actions(&mut rng, 4)).unwrap();
    assert_ne!(venv.obs_rms(), &frozen.obs_rms, "training resumes");
    assert_ne!(venv.ret_rms(), &frozen.ret_rms);
}

fn trained(n: usize, steps: usize) -> VecNormalize<VecEnv<TinyEnv>> {
    let mut venv = VecNormalize::new(tiny_venv(n, 9), VecNormalizeConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    venv.reset(Some(21)).unwrap();
    for _ in 0..steps {
        venv.step(&random_actions(&mut rng, n)).unwrap();
    }
    venv
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn vec_normalize_save_load_round_trip_is_exact_and_atomic() {
    let venv = trained(3, 120);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vec_normalize.json");
    venv.save(&path).unwrap();
    assert_eq!(
        dir_entries(dir.path()),
        vec!["vec_normalize.json"],
        "no temp files"
    );
    // Overwriting goes through the same rename.
    venv.save(&path).unwrap();
    assert_eq!(dir_entries(dir.path()), vec!["vec_normalize.json"]);

    let loaded = VecNormalize::load(&path, tiny_venv(3, 9)).unwrap();
    let (a, b) = (venv.state(), loaded.state());
    assert_eq!(a, b);
    for (x, y) in [(&a.obs_rms, &b.obs_rms), (&a.ret_rms, &b.ret_rms)] {
        for (u, v) in x
            .mean()
            .iter()
            .chain(x.var())
            .zip(y.mean().iter().chain(y.var()))
        {
            assert_eq!(u.to_bits(), v.to_bits());
        }
        assert_eq!(x.count().to_bits(), y.count().to_bits());
    }
    assert!(loaded.training(), "loads in training mode, as SB3 does");
    let probe = [0.3, -1.7, 5.02];
    assert_eq!(
        venv.normalize_obs(&probe).unwrap(),
        loaded.normalize_obs(&probe).unwrap()
    );
    assert_eq!(venv.normalize_reward(1.25), loaded.normalize_reward(1.25));
    // The state alone loads too (deployment), and the file names its format.
    let state = VecNormalizeState::load(&path).unwrap();
    assert_eq!(&state, a);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("\"format\": \"fairgrasp.vec_normalize\""),
        "{text}"
    );

    // Saving where no directory can be made (under a file) fails, names the file and leaves
    // nothing behind; a missing directory is made, as for every saved file.
    let blocked = path.join("no/dir/stats.json");
    match venv.save(&blocked).unwrap_err() {
        EnvError::File { path, problem } => {
            assert!(
                path.ends_with("vec_normalize.json/no/dir/stats.json"),
                "{path}"
            );
            assert!(problem.contains("cannot write"), "{problem}");
        }
        e => panic!("unexpected {e:?}"),
    }
    assert_eq!(dir_entries(dir.path()), vec!["vec_normalize.json"]);
    venv.save(&dir.path().join("new/dir/stats.json")).unwrap();
    assert!(VecNormalizeState::load(&dir.path().join("new/dir/stats.json")).is_ok());
}

fn load_error(path: &Path, obs_dim: usize) -> (String, String) {
    let means = vec![0.0; obs_dim];
    let stds = vec![1.0; obs_dim];
    let venv = VecEnv::new(vec![TinyEnv::with_obs(means, stds, 5)], 1).unwrap();
    match VecNormalize::load(path, venv)
        .err()
        .expect("load must fail")
    {
        EnvError::File { path, problem } => (path, problem),
        e => panic!("expected a file error, got {e:?}"),
    }
}

#[test]
fn loading_a_corrupt_or_mismatched_file_is_a_clear_error() {
    let venv = trained(2, 20);
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.json");
    venv.save(&good).unwrap();
    let text = std::fs::read_to_string(&good).unwrap();
    let write = |name: &str, content: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, content).unwrap();
        p
    };

    // Wrong dimension: statistics for 3 values, environment with 4.
    let (path, problem) = load_error(&good, 4);
    assert!(path.ends_with("good.json"), "{path}");
    assert!(
        problem.contains("observations of 3 values, the environment's have 4"),
        "{problem}"
    );

    // Not JSON at all, and a file cut in half.
    let p = write("garbage.json", "{ this is not json");
    let (path, problem) = load_error(&p, 3);
    assert!(path.ends_with("garbage.json"), "{path}");
    assert!(
        problem.contains("not a valid VecNormalize statistics file"),
        "{problem}"
    );
    assert!(problem.contains("line 1"), "says where: {problem}");
    let p = write("truncated.json", &text[..text.len() / 2]);
    let (_, problem) = load_error(&p, 3);
    assert!(
        problem.contains("not a valid VecNormalize statistics file"),
        "{problem}"
    );

    // Valid JSON, wrong content.
    let p = write(
        "other.json",
        &text.replace("fairgrasp.vec_normalize", "something.else"),
    );
    let (_, problem) = load_error(&p, 3);
    assert!(problem.contains("format is `something.else`"), "{problem}");
    let p = write(
        "version.json",
        &text.replace("\"version\": 1", "\"version\": 7"),
    );
    let (_, problem) = load_error(&p, 3);
    assert!(problem.contains("version 7 is not supported"), "{problem}");
    let mut bad_var = VecNormalizeState::load(&good).unwrap();
    bad_var.obs_rms = RunningMeanStd::from_parts(vec![0.0; 3], vec![1.0, 2.0, 3.0], 5.0).unwrap();
    let json = bad_var.to_json().replacen("\"2.0\"", "\"-2.0\"", 1);
    let p = write("negvar.json", &json);
    let (_, problem) = load_error(&p, 3);
    assert!(problem.contains("obs_rms: var[1]"), "{problem}");
    let p = write("extra.json", &text.replacen('{', "{\"surprise\": 1, ", 1));
    let (_, problem) = load_error(&p, 3);
    assert!(problem.contains("surprise"), "{problem}");

    // A missing file.
    let (path, problem) = load_error(&dir.path().join("absent.json"), 3);
    assert!(path.ends_with("absent.json"));
    assert!(problem.contains("cannot read"), "{problem}");
}
