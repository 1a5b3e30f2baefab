//! `FaArmSort-v0`: put each object into the bin of its colour.
//!
//! `num_objects` objects of different kinds (1–5, 3 by default) lie on the table beside
//! `num_bins` bins (2–3) with real walls. Each episode gives every object a bin (the bin's
//! colour in the scene) and the objects an order (random by default). The *active* object is
//! the first in that order neither placed in its bin nor lost (off the table, or resting in
//! another bin: skipped), and the observation (pick and place's, with the active object's drop
//! point as its goal) and the staged reward centre on it. Success: every object rests in its
//! bin. For training, episodes can start with some objects already sorted
//! (`start_sorted_min`…`start_sorted_max`, or a curriculum over the objects left), their time
//! limit shortened to the share of objects left, and the TCP above the bin last filled
//! (`start_above_bin`).

use crate::arm::observation::{rich_observation, shape_observation};
use crate::arm::{
    ArmEnv, ArmEnvConfig, ArmState, Evaluation, NoiseGroup, ObsWriter, RewardSettings, Task,
    TaskFlags, TaskSettings,
};
use crate::config::{check_at_least_one, check_non_negative};
use crate::core::{EpisodeEvent, NamedValues, RenderMode};
use crate::error::{EnvError, Result};
use fairgrasp_sim::rapier3d::na::{Point3, Vector3};
use fairgrasp_sim::scene::{BinConfig, ObjectConfig, ObjectShape, Scene, SceneConfig};
use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// The Gymnasium id of the sorting task.
pub const ENV_ID: &str = "FaArmSort-v0";

/// Slot offsets inside a bin, in units of `slot_spacing`.
const SLOTS: [[f64; 2]; 5] = [
    [-1.0, -1.0],
    [1.0, 1.0],
    [-1.0, 1.0],
    [1.0, -1.0],
    [0.0, 0.0],
];

/// The objects' spin damping (1/s; [`ObjectConfig::angular_damping`]): a cylinder knocked
/// over, or dropped on its side into a bin, comes to rest instead of rolling off the table or
/// wall to wall in the bin (at 1/s it still rolled at 7–9 cm/s when the episode ended).
const SPIN_DAMPING: f32 = 5.0;

/// How far inside its bin's walls a released object's centre must be to count as dropped into
/// it (m): less than the smallest object's half width, so one lying against a wall counts.
const WALL_MARGIN: f64 = 0.015;

/// Height above its bin's floor an object that starts sorted is dropped from (m): it settles
/// before the episode begins.
const START_GAP: f64 = 0.002;

/// How far from its drop point, along x and y, a TCP that starts above a bin may be (m): where
/// a policy lets go varies.
const START_ABOVE_JITTER: f64 = 0.03;

/// The weight of each episode in the curriculum's recent success rate (an exponential
/// average: about the last 10 episodes).
const CURRICULUM_RATE: f32 = 0.1;

/// Bin colours, in bin order: red, blue, green (linear RGB).
const BIN_COLORS: [[f32; 3]; 3] = [[0.8, 0.15, 0.15], [0.15, 0.3, 0.85], [0.15, 0.7, 0.2]];

/// The objects' shapes, in order: a cube, a long box, a flat box, a cylinder, a short
/// cylinder.
fn object_shape(k: usize) -> ObjectShape {
    match k % 5 {
        0 => ObjectShape::Box {
            size: [0.045, 0.045, 0.045],
        },
        1 => ObjectShape::Box {
            size: [0.04, 0.04, 0.06],
        },
        2 => ObjectShape::Box {
            size: [0.05, 0.04, 0.035],
        },
        3 => ObjectShape::Cylinder {
            radius: 0.022,
            height: 0.05,
        },
        _ => ObjectShape::Cylinder {
            radius: 0.025,
            height: 0.04,
        },
    }
}

/// The `[task]` section of the sorting task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SortSettings {
    /// 1–5 objects.
    pub num_objects: usize,
    /// 2–3 bins.
    pub num_bins: usize,
    /// Control steps before the episode is truncated.
    pub max_episode_steps: u32,
    /// Centre of the area the objects are placed in (arm base frame x, y; m).
    pub object_area_center: [f32; 2],
    /// Extent of that area along x and y (m).
    pub object_area_size: [f32; 2],
    /// Least gap between objects at the start (m): room for the open fingers beside a
    /// neighbour. Unset: 4 cm for up to 3 objects, 2 cm for more (5 objects do not fit the
    /// 20 × 20 cm area 4 cm apart).
    pub object_clearance: Option<f32>,
    /// Bin centres (arm base frame x, y, m), the first `num_bins` used.
    pub bin_centers: Vec<[f32; 2]>,
    /// Inner size of every bin (m).
    pub bin_inner_size: [f32; 2],
    /// An object counts as resting when slower than this (m/s).
    pub max_object_speed: f32,
    /// Each episode starts with a uniform draw of 0 to this many objects (at most
    /// `num_objects` − 1) already resting in their bins, the first in the order: start states
    /// across the task for training. `max_episode_steps` is for nothing sorted; an episode
    /// with `k` of `n` sorted gets its `(n − k)/n` share.
    pub start_sorted_max: usize,
    /// The least number of objects an episode starts with sorted (at most
    /// `start_sorted_max`): with both at `num_objects` − 1, every episode is one object's pick
    /// and place among the others.
    pub start_sorted_min: usize,
    /// A curriculum over the objects left to sort, for training with start states: each env
    /// first starts its episodes with the fewest objects left (`num_objects` −
    /// `start_sorted_max`), and allows one more each time its recent success rate (about the
    /// last 10 episodes) with the most it allows reaches this. `None`: every count from the
    /// start.
    pub curriculum_success: Option<f32>,
    /// The share of the episodes starting with objects sorted in which the TCP starts above
    /// the bin the last of them went into, as it would be just after dropping it (else at
    /// home): the reach from a bin to the next object, which otherwise follows only a
    /// successful placement.
    pub start_above_bin: f32,
    /// Sort the objects in a random order each episode (else in index order).
    pub random_order: bool,
    /// After each object placed, with objects left, the arm returns to its home pose with the
    /// gripper open (a scripted move between picks, as a cell's MoveJ home): every pick starts
    /// where the first did.
    pub return_home: bool,
    /// Observe every object (its position from the TCP, placed and active flags) and the
    /// share left after the active object's blocks. Without them the observation is the same
    /// whatever the number of objects and how many are placed, so a policy that learnt to sort
    /// the last object sorts the first alike; a scripted sorter, which sees only the active
    /// object, sorts 100 of 100.
    pub observe_others: bool,
    /// Observe the share of objects still to place last (unset: with the others). The reward's
    /// level per step is minus the objects left, so a value function that cannot see the count
    /// mistakes it for noise once episodes start with different counts (explained variance
    /// fell from 0.72 to 0.56 as the curriculum opened two objects left, seed 42).
    pub observe_left: Option<bool>,
    /// How [`crate::Env::render`] renders; `None`: it returns nothing.
    pub render_mode: Option<RenderMode>,
}

impl Default for SortSettings {
    fn default() -> Self {
        Self {
            num_objects: 3,
            num_bins: 2,
            max_episode_steps: 300,
            object_area_center: [0.45, 0.0],
            object_area_size: [0.2, 0.2],
            object_clearance: None,
            bin_centers: vec![[0.45, -0.27], [0.45, 0.27], [0.7, 0.0]],
            // Room for every object side by side: 3 objects of up to 6 cm.
            bin_inner_size: [0.2, 0.2],
            max_object_speed: 0.05,
            start_sorted_max: 0,
            start_sorted_min: 0,
            curriculum_success: None,
            start_above_bin: 0.0,
            random_order: true,
            return_home: false,
            observe_others: true,
            observe_left: None,
            render_mode: None,
        }
    }
}

impl SortSettings {
    /// The gap kept between objects at the start (m).
    pub fn object_clearance(&self) -> f32 {
        self.object_clearance
            .unwrap_or(if self.num_objects <= 3 { 0.04 } else { 0.02 })
    }
}

impl TaskSettings for SortSettings {
    type Task = Sort;

    fn max_episode_steps(&self) -> u32 {
        self.max_episode_steps
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.render_mode
    }

    fn validate(&self) -> Result<()> {
        if !(1..=5).contains(&self.num_objects) {
            return Err(EnvError::config("task.num_objects", "must be in 1..=5"));
        }
        if !(2..=3).contains(&self.num_bins) {
            return Err(EnvError::config("task.num_bins", "must be 2 or 3"));
        }
        if self.bin_centers.len() < self.num_bins {
            return Err(EnvError::config(
                "task.bin_centers",
                format!(
                    "lists {} centres for {} bins",
                    self.bin_centers.len(),
                    self.num_bins
                ),
            ));
        }
        check_at_least_one("task.max_episode_steps", self.max_episode_steps)?;
        if !self.bin_inner_size.iter().all(|v| (0.1..=0.4).contains(v)) {
            return Err(EnvError::config(
                "task.bin_inner_size",
                "each side must be in [0.1, 0.4] m",
            ));
        }
        if let Some(gap) = self.object_clearance
            && !(gap.is_finite() && (0.0..=0.2).contains(&gap))
        {
            return Err(EnvError::config(
                "task.object_clearance",
                "must be in [0, 0.2] m",
            ));
        }
        if self.start_sorted_max >= self.num_objects {
            return Err(EnvError::config(
                "task.start_sorted_max",
                format!(
                    "must be below task.num_objects ({}): an episode needs an object to sort",
                    self.num_objects
                ),
            ));
        }
        if self.start_sorted_min > self.start_sorted_max {
            return Err(EnvError::config(
                "task.start_sorted_min",
                format!(
                    "must be at most task.start_sorted_max ({})",
                    self.start_sorted_max
                ),
            ));
        }
        if let Some(bar) = self.curriculum_success
            && !(0.0..=1.0).contains(&bar)
        {
            return Err(EnvError::config(
                "task.curriculum_success",
                "must be a success rate in [0, 1]",
            ));
        }
        if !(0.0..=1.0).contains(&self.start_above_bin) {
            return Err(EnvError::config(
                "task.start_above_bin",
                "must be a share in [0, 1]",
            ));
        }
        check_non_negative("task.max_object_speed", self.max_object_speed)
    }
}

/// The `[reward]` section of the sorting task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SortReward {
    /// Paid once for each object the first time it rests in its bin.
    pub object_sorted: f32,
    /// Paid on success (every object sorted).
    pub success: f32,
    /// The fastest an object let go over its bin may drift sideways and still earn the
    /// release's stage (m/s; unset: any): one thrown from a moving gripper flies over the far
    /// wall, out of reach.
    pub release_drift: Option<f32>,
}

impl Default for SortReward {
    fn default() -> Self {
        Self {
            object_sorted: 5.0,
            success: 10.0,
            release_drift: None,
        }
    }
}

impl RewardSettings for SortReward {
    fn validate(&self) -> Result<()> {
        check_non_negative("reward.object_sorted", self.object_sorted)?;
        if let Some(v) = self.release_drift {
            check_non_negative("reward.release_drift", v)?;
        }
        check_non_negative("reward.success", self.success)
    }
}

/// The sorting task's whole configuration.
pub type SortConfig = ArmEnvConfig<SortSettings, SortReward>;
/// The sorting environment.
pub type SortEnv = ArmEnv<Sort>;

/// The sorting task.
pub struct Sort {
    settings: SortSettings,
    reward: SortReward,
    /// Each object's bin this episode.
    assignment: Vec<usize>,
    /// Bin floor centres (arm base frame).
    bins: Vec<Vector3<f64>>,
    /// Height above a bin's floor from which objects are dropped in (m).
    drop_height: f64,
    /// Lift above its resting height at which an object clears the bin walls (m).
    clear_lift: f64,
    /// Distance of a slot's centre from the bin's centre along x and y (m).
    slot_spacing: f64,
    /// The order the objects are sorted in this episode.
    order: Vec<usize>,
    /// Objects that started the episode in their bins.
    started_sorted: Vec<bool>,
    /// Objects already paid for.
    paid: Vec<bool>,
    /// Objects in their bin and let go at the last evaluation, moving or not: the task moves
    /// on to the next object (an object settling in its bin flickers in and out of `sorted`).
    placed: Vec<bool>,
    /// Objects resting in their bin at the last evaluation.
    sorted: Vec<bool>,
    /// Objects off the table, or let go in a bin not their own, at the last evaluation: the
    /// task goes on without them.
    lost: Vec<bool>,
    /// The curriculum's state in this env.
    curriculum: Curriculum,
    /// An object was placed at the last evaluation with objects left: the arm is to go home
    /// (`return_home`).
    return_due: bool,
}

/// How far an env's curriculum over the objects left has gone.
#[derive(Clone, Debug)]
struct Curriculum {
    /// The most objects left an episode may start with.
    allowed_left: usize,
    /// Recent success rate of the episodes that started with `allowed_left` objects left.
    recent_success: f32,
    /// Objects left at the start of the episode being played; `None` before the first.
    episode_left: Option<usize>,
}

impl Curriculum {
    /// Counts the episode just played (`success`); opens one more object left when the
    /// recent success rate at the most allowed reaches `bar`, up to `most_left`.
    fn record(&mut self, success: bool, bar: f32, most_left: usize) {
        if self.episode_left != Some(self.allowed_left) {
            return;
        }
        let outcome = if success { 1.0 } else { 0.0 };
        self.recent_success += CURRICULUM_RATE * (outcome - self.recent_success);
        if self.recent_success >= bar && self.allowed_left < most_left {
            self.allowed_left += 1;
            self.recent_success = 0.0;
        }
    }
}

impl Sort {
    /// The first object in the order neither placed in its bin nor lost.
    fn active(&self) -> Option<usize> {
        (self.order.iter().copied()).find(|&i| !self.placed[i] && !self.lost[i])
    }

    /// The centre of object `i`'s own slot in its bin, on the bin floor (arm base frame):
    /// objects sharing a bin lie side by side, in their order, instead of stacking.
    fn slot_point(&self, i: usize) -> Vector3<f64> {
        let bin = self.assignment[i];
        let rank = self.order.iter().position(|&k| k == i).unwrap_or(i);
        let slot = (self.order[..rank].iter())
            .filter(|&&k| self.assignment[k] == bin)
            .count();
        let [dx, dy] = SLOTS[slot % SLOTS.len()].map(|v| v * self.slot_spacing);
        self.bins[bin] + Vector3::new(dx, dy, 0.0)
    }

    /// Where object `i` should be dropped from (arm base frame): above its own slot.
    pub fn drop_point(&self, i: usize) -> Vector3<f64> {
        self.slot_point(i) + Vector3::new(0.0, 0.0, self.drop_height)
    }

    /// The order the objects are sorted in this episode.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// The objects the policy has to sort this episode, in their order: those that did not
    /// start sorted.
    pub fn objects_to_sort(&self) -> Vec<usize> {
        let to_sort = |i: &usize| !self.started_sorted[*i];
        self.order.iter().copied().filter(to_sort).collect()
    }

    /// Objects that started this episode resting in their bins.
    pub fn started_sorted(&self) -> &[bool] {
        &self.started_sorted
    }

    /// Moves the first `k` objects of the order into their slots, upright as they stood, and
    /// lets the scene settle.
    fn start_sorted(&mut self, scene: &mut Scene, k: usize) -> Result<()> {
        let base = scene.base_pose();
        for &i in &self.order[..k] {
            let mut pose = scene.object_state(i).pose;
            let slot = base * Point3::from(self.slot_point(i));
            let rest = slot.z + scene.object_half_height(i) + START_GAP;
            pose.translation.vector = Vector3::new(slot.x, slot.y, rest);
            scene.set_object_pose(i, &pose)?;
            self.started_sorted[i] = true;
        }
        if k > 0 {
            scene.settle()?;
        }
        Ok(())
    }

    /// Moves the arm, its gripper open, so that the TCP is above object `i`'s drop point (within
    /// [`START_ABOVE_JITTER`] along x and y), pointing down as at home. Stays at home where no
    /// joint vector reaches there.
    fn start_above_bin(&self, scene: &mut Scene, i: usize, rng: &mut ChaCha8Rng) -> Result<()> {
        let mut jitter = || rng.random_range(-START_ABOVE_JITTER..=START_ABOVE_JITTER);
        let offset = Vector3::new(jitter(), jitter(), 0.0);
        let mut target = scene.tcp_pose();
        target.translation.vector =
            (scene.base_pose() * Point3::from(self.drop_point(i) + offset)).coords;
        if let Ok(q) = scene.solve_ik(&target, &scene.arm_positions()) {
            scene.set_arm_positions(&q)?;
            scene.set_arm_targets(&q)?;
        }
        Ok(())
    }

    /// Whether object `i`'s centre lies over the inside of its own bin (any height), at least
    /// [`WALL_MARGIN`] from the walls: an object balanced on a wall top has its centre over the
    /// wall, one lying against it inside.
    fn over_own_bin(&self, i: usize, s: &ArmState) -> bool {
        let bin = self.bins[self.assignment[i]];
        let at = s.objects[i].pose.translation.vector;
        let [ix, iy] = self
            .settings
            .bin_inner_size
            .map(|v| v as f64 / 2.0 - WALL_MARGIN);
        (at.x - bin.x).abs() <= ix && (at.y - bin.y).abs() <= iy
    }

    /// The active object's stage in [0, 1]: reach (up to 1/4), grasp (1/4), lift over the
    /// walls (1/4) and carry to the drop point (1/4, earned only as high as the lift: no
    /// dragging through a wall); 1 once let go over its bin clear of the walls, drifting
    /// sideways no faster than `reward.release_drift` where set.
    fn stage(&self, i: usize, s: &ArmState) -> f32 {
        if !s.grasped(i) {
            let drift = || s.objects[i].linvel.xy().norm();
            let slow = self
                .reward
                .release_drift
                .is_none_or(|v| drift() <= v as f64);
            if self.over_own_bin(i, s) && slow {
                return 1.0;
            }
            let reach = 1.0 - (4.0 * s.tcp_to_object(i).norm() as f32).tanh();
            return reach / 4.0;
        }
        let lift = (s.lift(i) / self.clear_lift).clamp(0.0, 1.0) as f32;
        let to_drop = (self.drop_point(i) - s.objects[i].pose.translation.vector).norm();
        let carry = 1.0 - (4.0 * to_drop as f32).tanh();
        (1.0 + lift + lift * carry) / 4.0
    }

    /// Each object's bin this episode.
    pub fn assignment(&self) -> &[usize] {
        &self.assignment
    }
}

/// Sorting's flags for one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SortFlags {
    /// Objects resting in their own bins.
    pub objects_sorted: usize,
    /// Objects in the scene.
    pub objects: usize,
    /// Objects that started the episode sorted.
    pub started_sorted: usize,
    /// Objects resting in their own bins that did not start there: the policy's work.
    pub sorted_by_policy: usize,
    /// Objects off the table or in a bin not their own.
    pub objects_lost: usize,
    /// The fingers are closed on the active object.
    pub grasped: bool,
}

impl TaskFlags for SortFlags {
    fn named(&self) -> NamedValues {
        let to_sort = (self.objects - self.started_sorted).max(1);
        NamedValues::new()
            .with("objects_sorted", self.objects_sorted as f32)
            .with(
                "fraction_sorted",
                self.objects_sorted as f32 / self.objects as f32,
            )
            .with(
                "fraction_sorted_by_policy",
                self.sorted_by_policy as f32 / to_sort as f32,
            )
            .with(
                "objects_to_sort",
                (self.objects - self.started_sorted) as f32,
            )
            .with("objects_lost", self.objects_lost as f32)
            .with("grasped", self.grasped as u8 as f32)
    }
}

impl Task for Sort {
    type Settings = SortSettings;
    type Reward = SortReward;
    type Flags = SortFlags;
    const ID: &'static str = ENV_ID;

    fn configure_scene(config: &SortConfig, scene: &mut SceneConfig) -> Result<()> {
        let t = &config.task;
        scene.placement.center = t.object_area_center;
        scene.placement.size = t.object_area_size;
        scene.placement.clearance = t.object_clearance();
        scene.objects = (0..t.num_objects)
            .map(|k| ObjectConfig {
                name: format!("object{k}"),
                shape: object_shape(k),
                mass: 0.08,
                friction: 0.8,
                color: [0.6, 0.6, 0.6],
                angular_damping: SPIN_DAMPING,
            })
            .collect();
        scene.bins = (0..t.num_bins)
            .map(|j| BinConfig {
                name: format!("bin{j}"),
                center: t.bin_centers[j],
                inner_size: t.bin_inner_size,
                color: BIN_COLORS[j],
                ..BinConfig::default()
            })
            .collect();
        Ok(())
    }

    fn new(config: &SortConfig, scene: &Scene) -> Result<Self> {
        let base = scene.base_pose();
        let bins = (0..scene.bins().len())
            .map(|j| (base.inverse() * scene.bin_pose(j)).translation.vector)
            .collect();
        let wall = scene.bins().first().map(|b| b.wall_height).unwrap_or(0.05) as f64;
        let n = config.task.num_objects;
        Ok(Self {
            settings: config.task.clone(),
            reward: config.reward.clone(),
            assignment: vec![0; n],
            bins,
            drop_height: wall + 0.06,
            clear_lift: wall + 0.02,
            slot_spacing: (config.task.bin_inner_size[0].min(config.task.bin_inner_size[1]) / 4.0)
                as f64,
            order: (0..n).collect(),
            started_sorted: vec![false; n],
            paid: vec![false; n],
            placed: vec![false; n],
            sorted: vec![false; n],
            lost: vec![false; n],
            curriculum: Curriculum {
                allowed_left: n - config.task.start_sorted_max,
                recent_success: 0.0,
                episode_left: None,
            },
            return_due: false,
        })
    }

    fn initialize_episode(&mut self, scene: &mut Scene, rng: &mut ChaCha8Rng) -> Result<()> {
        scene.place_objects_at_random(rng)?;
        for a in &mut self.assignment {
            *a = rng.random_range(0..self.settings.num_bins);
        }
        self.order = (0..self.assignment.len()).collect();
        if self.settings.random_order {
            self.order.shuffle(rng);
        }
        self.started_sorted.fill(false);
        let (n, max) = (self.order.len(), self.settings.start_sorted_max);
        let mut min = self.settings.start_sorted_min;
        if let Some(bar) = self.settings.curriculum_success {
            let success = self.sorted.iter().all(|s| *s);
            self.curriculum.record(success, bar, n - min);
            min = min.max(n - self.curriculum.allowed_left);
        }
        let k = rng.random_range(min..=max);
        self.curriculum.episode_left = Some(n - k);
        self.start_sorted(scene, k)?;
        // Drawn only when asked for, so that other configurations draw as before.
        if k > 0
            && self.settings.start_above_bin > 0.0
            && rng.random::<f32>() < self.settings.start_above_bin
        {
            self.start_above_bin(scene, self.order[k - 1], rng)?;
        }
        // Objects that start sorted are paid for and placed already.
        self.paid.clone_from(&self.started_sorted);
        self.placed.clone_from(&self.started_sorted);
        self.sorted.clone_from(&self.started_sorted);
        self.lost.fill(false);
        self.return_due = false;
        Ok(())
    }

    fn episode_steps(&self, max_episode_steps: u32) -> u32 {
        let n = self.order.len() as u32;
        let left = self.started_sorted.iter().filter(|s| !**s).count() as u32;
        (max_episode_steps * left).div_ceil(n).max(1)
    }

    fn observe(&self, s: &ArmState, previous_action: &[f32], out: &mut ObsWriter) {
        use NoiseGroup::*;
        let active = self.active().unwrap_or(0);
        let object = &s.objects[active];
        // Pick and place's layout, its goal being the active object's drop point.
        let drop = self.drop_point(active);
        rich_observation(s, active, previous_action, out);
        out.push3(None, &drop);
        out.push3(ObjectPosition, &(drop - object.pose.translation.vector));
        // What sorting needs beyond it: the active object's size and how its sides lie, ...
        shape_observation(s, active, out);
        // ... every object from the TCP (the ones in the way), placed or not, which is active ...
        if self.settings.observe_others {
            let tcp = s.tcp.translation.vector;
            for (i, o) in s.objects.iter().enumerate() {
                out.push3(ObjectPosition, &(o.pose.translation.vector - tcp));
                out.push1(None, self.placed[i] as u8 as f32);
                out.push1(None, (i == active) as u8 as f32);
            }
        }
        // ... and the share of objects still to place.
        let observe_left = (self.settings.observe_left).unwrap_or(self.settings.observe_others);
        if !observe_left {
            return;
        }
        let left = self.placed.iter().filter(|p| !**p).count();
        out.push1(None, left as f32 / self.placed.len() as f32);
    }

    fn evaluate(&mut self, scene: &Scene, s: &ArmState) -> Evaluation<SortFlags> {
        let n = self.sorted.len();
        let placed_before = self.placed.iter().filter(|p| **p).count();
        let mut off_table = false;
        for i in 0..n {
            let resting = s.objects[i].linvel.norm() < self.settings.max_object_speed as f64;
            let released = !s.grasped(i);
            self.placed[i] = scene.object_in_bin(i, self.assignment[i]) && released;
            self.sorted[i] = self.placed[i] && resting;
            let off = scene.object_off_table(i);
            let misplaced = released
                && resting
                && (0..self.bins.len())
                    .any(|j| j != self.assignment[i] && scene.object_in_bin(i, j));
            self.lost[i] = off || misplaced;
            off_table |= off;
        }
        let count = self.sorted.iter().filter(|s| **s).count();
        let lost = self.lost.iter().filter(|l| **l).count();
        let active = self.active();
        let placed = self.placed.iter().filter(|p| **p).count();
        self.return_due = self.settings.return_home && placed > placed_before && active.is_some();
        // Nothing left to do but objects lost: the episode ends without success.
        let failure = (active.is_none() && lost > 0).then_some(if off_table {
            EpisodeEvent::ObjectOffTable
        } else {
            EpisodeEvent::ObjectMisplaced
        });
        let by_policy = (0..n)
            .filter(|&i| self.sorted[i] && !self.started_sorted[i])
            .count();
        Evaluation {
            success: count == n,
            failure,
            flags: SortFlags {
                objects_sorted: count,
                objects: n,
                started_sorted: self.started_sorted.iter().filter(|s| **s).count(),
                sorted_by_policy: by_policy,
                objects_lost: lost,
                grasped: active.is_some_and(|i| s.grasped(i)),
            },
        }
    }

    fn reward(&mut self, e: &Evaluation<SortFlags>, s: &ArmState, steps_left: u32) -> NamedValues {
        let n = self.sorted.len() as f32;
        let mut newly = 0;
        for (paid, sorted) in self.paid.iter_mut().zip(&self.sorted) {
            if *sorted && !*paid {
                *paid = true;
                newly += 1;
            }
        }
        // Every object placed: their count is the whole progress.
        let stage = self.active().map_or(0.0, |i| self.stage(i, s));
        let placed = self.placed.iter().filter(|p| **p).count() as f32;
        let mut terms = NamedValues::new();
        // In [-n, 0] per step: each object placed is worth a whole stage, so carrying the
        // active object pays as much as the pick-and-place task's carry does.
        terms.set("progress", placed + stage - n);
        terms.set("object_sorted", newly as f32 * self.reward.object_sorted);
        // Ending early with objects lost costs what the steps left would have (−1 a step for
        // each): losing one is never a way out.
        let lost = match e.failure {
            Some(_) => -(e.flags.objects_lost as f32) * steps_left as f32,
            None => 0.0,
        };
        terms.set("lost", lost);
        terms.set("success", if e.success { self.reward.success } else { 0.0 });
        terms
    }

    fn return_home(&mut self) -> bool {
        std::mem::take(&mut self.return_due)
    }

    fn describe(&self, _s: &ArmState) -> String {
        format!(
            "bins {:?}, order {:?}, placed {:?}, sorted {:?}, lost {:?}, active {:?}",
            self.assignment,
            self.order,
            self.placed,
            self.sorted,
            self.lost,
            self.active()
        )
    }
}
