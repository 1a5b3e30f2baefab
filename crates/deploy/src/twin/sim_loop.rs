//! The twin's physics thread: the world stepped in real time at its physics rate (sleeping
//! until each step's deadline), the controller's set points in, its measurements out.

use super::Shared;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Falling further behind than this (s) drops the lost time instead of racing to catch up.
const MAX_LAG: f64 = 0.25;

pub(super) fn run(shared: Arc<Shared>) {
    let dt = shared.world.lock().expect("world lock").dt();
    let mut deadline = shared.now();
    while !shared.shutdown.load(Ordering::SeqCst) {
        let now = shared.now();
        if now < deadline {
            std::thread::sleep(Duration::from_secs_f64(deadline - now));
            continue;
        }
        if now - deadline > MAX_LAG {
            shared.overruns.fetch_add(1, Ordering::Relaxed);
            deadline = now;
        }
        step(&shared, deadline);
        deadline += dt;
    }
    // Wake every waiting call so it sees the shutdown.
    shared.ticked.notify_all();
}

/// One physics step at twin time `t`.
fn step(shared: &Shared, t: f64) {
    let mut world = shared.world.lock().expect("world lock");
    let setpoint = shared
        .controller
        .lock()
        .expect("controller lock")
        .setpoint(t);
    if let Err(e) = world.step(&setpoint) {
        // The physics blew up (it should not): start the episode again rather than stream
        // NaN; the episode is judged as it stood.
        tracing::error!("twin physics: {e}; restarting the episode");
        let seed = world.episode().seed;
        if let Err(e) = world.start_episode(seed) {
            tracing::error!("twin physics: cannot restart: {e}");
        }
    }
    let measured = world.measure();
    let object = world.object_pose();
    // Still holding the world, so a reset cannot slip between the step and what it publishes.
    let state = {
        let mut controller = shared.controller.lock().expect("controller lock");
        controller.observe(t, measured);
        controller.state()
    };
    shared.record_state(t, state, object);
    drop(world);
    shared.ticked.notify_all();
}
