//! Physics throughput of the full grasp scene (FR5 + gripper + table + cube) on one thread.
//!
//! `cargo bench -p fairgrasp-sim --bench physics`. The same loops, as plain figures:
//! `fairgrasp bench physics`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fairgrasp_sim::pick::{PickScript, grasp_and_lift};
use fairgrasp_sim::scene::{Scene, SceneConfig};
use std::hint::black_box;

const STEPS: u64 = 240;

fn physics_steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("scene");
    group.throughput(Throughput::Elements(STEPS));

    let mut scene = Scene::new(SceneConfig::default()).expect("scene");
    scene.reset(0).expect("reset");
    let idle = scene.snapshot();
    group.bench_function("physics_steps_cube_on_table", |b| {
        b.iter(|| {
            scene.restore(&idle);
            for _ in 0..STEPS {
                scene.step_physics().expect("step");
            }
            black_box(scene.object_state(0))
        })
    });

    scene.reset(0).expect("reset");
    grasp_and_lift(&mut scene, 0, &PickScript::default(), &mut |s| {
        s.step_control()
    })
    .expect("grasp");
    let held = scene.snapshot();
    group.bench_function("physics_steps_cube_grasped", |b| {
        b.iter(|| {
            scene.restore(&held);
            for _ in 0..STEPS {
                scene.step_physics().expect("step");
            }
            black_box(scene.object_state(0))
        })
    });
    group.finish();

    let mut group = c.benchmark_group("reset");
    group.throughput(Throughput::Elements(1));
    let mut seed = 0;
    group.bench_function("random_placement_and_settle", |b| {
        b.iter(|| {
            seed += 1;
            black_box(scene.reset(seed).expect("reset"))
        })
    });
    group.bench_function("snapshot_restore", |b| {
        b.iter(|| scene.restore(black_box(&idle)))
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = physics_steps
}
criterion_main!(benches);
