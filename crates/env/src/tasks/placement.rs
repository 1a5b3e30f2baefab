//! Placing objects at the start of an episode: uniform in an area of the table, uniform yaw,
//! reachable from above and clear of the arm, the bins and the objects already placed.

use crate::error::{EnvError, Result};
use fairgrasp_sim::rapier3d::na::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use fairgrasp_sim::scene::Scene;
use rand::Rng;

/// A rectangle on the table, in the arm base frame, and a yaw range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Area {
    /// Centre x, y (m).
    pub center: [f32; 2],
    /// Extent along x and y (m).
    pub size: [f32; 2],
    /// Yaw drawn from [-yaw_range, yaw_range] (rad).
    pub yaw_range: f32,
}

impl Area {
    /// The scene's own placement area (`scene.placement`).
    pub fn of_scene(scene: &Scene) -> Self {
        let p = &scene.config().placement;
        Self {
            center: p.center,
            size: p.size,
            yaw_range: p.yaw_range,
        }
    }

    /// A uniform point of the area (base frame x, y).
    pub fn sample_xy(&self, rng: &mut impl Rng) -> [f64; 2] {
        [0, 1].map(|k| (self.center[k] + (rng.random::<f32>() - 0.5) * self.size[k]) as f64)
    }
}

/// Draws a pose for object `i` resting upright in `area` (world frame), retrying until it is
/// reachable from above and free; sets it. Objects placed later see it as an obstacle.
pub fn place_object(
    scene: &mut Scene,
    i: usize,
    area: &Area,
    rng: &mut impl Rng,
) -> Result<Isometry3<f64>> {
    let base = scene.base_pose();
    let base_yaw = base.rotation.euler_angles().2;
    for _ in 0..100 {
        let [x, y] = area.sample_xy(rng);
        let yaw = ((rng.random::<f32>() * 2.0 - 1.0) * area.yaw_range) as f64;
        let world = base * Point3::new(x, y, 0.0);
        let position = Vector3::new(world.x, world.y, scene.object_rest_height(i) + 0.001);
        let pose = Isometry3::from_parts(
            Translation3::from(position),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw + base_yaw),
        );
        if scene.reachable_from_above(&pose) && scene.pose_is_free(i, &pose) {
            scene.set_object_pose(i, &pose);
            return Ok(pose);
        }
    }
    Err(EnvError::config(
        "scene.placement",
        format!(
            "no reachable, collision-free place for object {i} (`{}`) in 100 draws; enlarge the area or use fewer or smaller objects",
            scene.object_name(i)
        ),
    ))
}

/// Parks every object, places objects `0..n` one after another in `area`, then settles.
pub fn place_all(scene: &mut Scene, area: &Area, rng: &mut impl Rng) -> Result<()> {
    scene.park_objects();
    for i in 0..scene.num_objects() {
        place_object(scene, i, area, rng)?;
    }
    scene.settle()?;
    Ok(())
}
