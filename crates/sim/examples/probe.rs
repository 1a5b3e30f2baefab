use fairgrasp_sim::pick::*;
use fairgrasp_sim::scene::{Scene, SceneConfig};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut config = SceneConfig::default();
    if args.len() > 1 { config.physics.dt = 1.0 / args[1].parse::<f32>().unwrap(); config.physics.substeps = (config.physics.substeps as f32 * config.physics.dt.recip() / 240.0) as u32; }
    let mut scene = Scene::new(config).unwrap();
    let t = std::time::Instant::now();
    let report = evaluate_scripted_pick(&mut scene, 20, 0, &PickScript::default(), SuccessRule::default(), |seed, o| {
        println!("seed {seed} success {} drift {:.4} lift {:.3}", o.success, o.hold_drift, o.final_lift);
    }).unwrap();
    println!("{}/{} max drift {:.4} mean {:.4} failures {:?} in {:?}", report.successes, report.episodes, report.max_drift, report.mean_drift, report.failures, t.elapsed());
}
