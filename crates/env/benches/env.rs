//! Environment throughput with random actions: one env on one thread, and the vectorised env on
//! 1 and 2 threads. `cargo bench -p fairgrasp-env --bench env`; the same loops as plain figures:
//! `fairgrasp bench env`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fairgrasp_env::{Env, EnvConfig, GraspEnv, VecEnv, VectorEnv};
use rand::SeedableRng;
use std::hint::black_box;

const NUM_ENVS: usize = 8;

fn env_steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("env");
    let config = EnvConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);

    let mut env = GraspEnv::new(config.clone()).expect("env");
    env.reset(Some(0)).expect("reset");
    let space = env.action_space().clone();
    group.throughput(Throughput::Elements(1));
    group.bench_function("single_env_step", |b| {
        b.iter(|| {
            let step = env.step(&space.sample(&mut rng)).expect("step");
            if step.terminated || step.truncated {
                env.reset(None).expect("reset");
            }
            black_box(step.reward)
        })
    });

    group.throughput(Throughput::Elements(NUM_ENVS as u64));
    for threads in [1, 2] {
        let envs = (0..NUM_ENVS)
            .map(|_| GraspEnv::new(config.clone()).expect("env"))
            .collect();
        let mut venv = VecEnv::new(envs, threads).expect("vec env");
        venv.reset(Some(0)).expect("reset");
        let mut actions = Vec::new();
        group.bench_function(format!("vec_env_{NUM_ENVS}_envs_{threads}_threads"), |b| {
            b.iter(|| {
                actions.clear();
                for _ in 0..NUM_ENVS {
                    actions.extend(space.sample(&mut rng));
                }
                black_box(venv.step(&actions).expect("step").rewards[0])
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = env_steps
}
criterion_main!(benches);
