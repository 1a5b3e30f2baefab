//! The environment contract, mirroring Gymnasium's `Env`: `reset(seed) -> (obs, info)`,
//! `step(action) -> (obs, reward, terminated, truncated, info)`, Box spaces, render modes.

use crate::error::Result as EnvResult;
use crate::spaces::{BoxSpace, ImageSpace};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// How an environment renders (Gymnasium's `render_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderMode {
    /// A text description of the current state, returned by [`Env::render`].
    Ansi,
    /// An RGB image from the `[render]` camera ([`Frame::Rgb`]).
    RgbArray,
    /// A depth image from the `[render]` camera ([`Frame::Depth`]).
    DepthArray,
    /// A segmentation image from the `[render]` camera ([`Frame::Segmentation`]).
    SegmentationArray,
}

/// What [`Env::render`] returns.
#[derive(Clone, Debug, PartialEq)]
pub enum Frame {
    /// The text of [`RenderMode::Ansi`].
    Text(String),
    /// `height × width × 3` bytes of sRGB, rows top to bottom.
    Rgb {
        /// Image width (pixels).
        width: u32,
        /// Image height (pixels).
        height: u32,
        /// The pixels, row-major.
        data: Vec<u8>,
    },
    /// `height × width` distances along the camera's optical axis (m); the camera's `far` where
    /// nothing is in view.
    Depth {
        /// Image width (pixels).
        width: u32,
        /// Image height (pixels).
        height: u32,
        /// The depths, row-major, top row first.
        data: Vec<f32>,
    },
    /// `height × width` ids of what each pixel shows: 0 background, 1 table, 2 + j bin j,
    /// 32 + i object i, 64 + l robot link l (docs/rendering.md).
    Segmentation {
        /// Image width (pixels).
        width: u32,
        /// Image height (pixels).
        height: u32,
        /// The ids, row-major, top row first.
        data: Vec<u16>,
    },
}

/// Why an episode ended early, beside success and the time limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EpisodeEvent {
    /// The object left the table (terminates, with a penalty).
    ObjectOffTable,
    /// An object came to rest in a bin not its own (sorting; the task moves on without it).
    ObjectMisplaced,
    /// The physics produced NaN or infinity; the episode was cut and the last finite
    /// observation returned.
    NonFiniteState,
    /// Cartesian mode: inverse kinematics found no joint vector for the commanded pose; the
    /// previous target was kept (the episode goes on).
    IkFailed,
    /// A robot link pressed on something harder than `control.collision_force_limit` allows,
    /// as a cobot's collision detection would stop it (terminates, with the failure penalty).
    Collision,
}

/// Named scalars in insertion order: a task's own values in [`Info::extras`] and the reward's
/// terms in [`Info::reward_terms`]. The core never interprets the names, so a new task adds
/// values without touching it; TensorBoard, the CSV log and Python see them by name. Serialises
/// as a map (`{"grasped": 1.0, "lift": 0.02}`).
///
/// Names are `&'static str` when a task sets them (no allocation per step) and owned strings
/// when read back from a file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NamedValues(Vec<(Cow<'static, str>, f32)>);

impl NamedValues {
    /// No values.
    pub fn new() -> Self {
        Self(Vec::new())
    }

    /// Sets `name` to `value`, keeping its position if it is already there.
    pub fn set(&mut self, name: impl Into<Cow<'static, str>>, value: f32) {
        let name = name.into();
        match self.0.iter_mut().find(|(n, _)| *n == name) {
            Some(entry) => entry.1 = value,
            None => self.0.push((name, value)),
        }
    }

    /// Builder form of [`Self::set`].
    pub fn with(mut self, name: impl Into<Cow<'static, str>>, value: f32) -> Self {
        self.set(name, value);
        self
    }

    /// The value of `name`, if set.
    pub fn get(&self, name: &str) -> Option<f32> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }

    /// The names and values, in insertion order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = (&str, f32)> {
        self.0.iter().map(|(n, v)| (n.as_ref(), *v))
    }

    /// The names, in insertion order.
    pub fn names(&self) -> impl ExactSizeIterator<Item = &str> {
        self.0.iter().map(|(n, _)| n.as_ref())
    }

    /// Number of names.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether no name is set.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Sum of the values (a reward's terms sum to the reward).
    pub fn total(&self) -> f32 {
        self.0.iter().map(|(_, v)| v).sum()
    }

    /// Keeps, for every name, the larger of the present and the new value (new names join).
    pub fn merge_max(&mut self, other: &NamedValues) {
        for (name, value) in &other.0 {
            match self.0.iter_mut().find(|(n, _)| n == name) {
                Some(entry) => entry.1 = entry.1.max(*value),
                None => self.0.push((name.clone(), *value)),
            }
        }
    }

    /// Removes every name.
    pub fn clear(&mut self) {
        self.0.clear();
    }
}

impl Serialize for NamedValues {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (name, value) in &self.0 {
            map.serialize_entry(name.as_ref(), value)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for NamedValues {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = NamedValues;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a map of names to numbers")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<NamedValues, A::Error> {
                let mut out = NamedValues::new();
                while let Some((name, value)) = map.next_entry::<String, f32>()? {
                    out.set(name, value);
                }
                Ok(out)
            }
        }
        deserializer.deserialize_map(Visitor)
    }
}

/// What `reset` and `step` report besides the observation (Gymnasium's `info` dict): what
/// every environment has, and the task's own values by name.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// The task's success rule holds (SB3 reads this as `is_success`).
    pub success: bool,
    /// Control steps since reset.
    pub elapsed_steps: u32,
    /// Anything unusual this step.
    pub events: Vec<EpisodeEvent>,
    /// The task's own values (ManiSkill's `evaluate()` flags: `grasped`, `lift`, …; at reset,
    /// the episode's randomised parameters as `param/…`).
    pub extras: NamedValues,
    /// The reward split into its terms by name; they sum to the reward.
    pub reward_terms: NamedValues,
    /// What only the simulator knows, for a critic (asymmetric actor-critic, Pinto et al.
    /// 2018) or a distillation's teacher, never for the policy: [`Env::privileged_dim`] values,
    /// none when the environment offers no privileged state.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub privileged: Vec<f32>,
}

/// The result of [`Env::step`].
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The observation after the action.
    pub obs: Vec<f32>,
    /// The reward for the transition.
    pub reward: f32,
    /// The episode reached a terminal state of the task (success, object off the table).
    pub terminated: bool,
    /// The episode was cut for a reason outside the task (time limit, non-finite physics).
    pub truncated: bool,
    /// Everything else the step reports.
    pub info: Info,
}

/// Metadata of an environment, like Gymnasium's `metadata` dict.
#[derive(Clone, Debug, PartialEq)]
pub struct Metadata {
    /// The registry id, e.g. `FaArmGrasp-v0`.
    pub id: &'static str,
    /// The render modes the environment supports.
    pub render_modes: Vec<RenderMode>,
    /// Control steps per second.
    pub render_fps: f32,
}

/// A reinforcement-learning environment with continuous (Box) observation and action spaces.
pub trait Env: Send {
    /// Id, render modes and frame rate.
    fn metadata(&self) -> Metadata;
    /// The space every observation lies in.
    fn observation_space(&self) -> &BoxSpace;
    /// The actions [`Env::step`] takes (others are clipped into it).
    fn action_space(&self) -> &BoxSpace;
    /// The render mode chosen when the environment was made; `None` when it does not render.
    fn render_mode(&self) -> Option<RenderMode>;

    /// Starts an episode. `Some(seed)` re-seeds the environment's random stream (the same seed
    /// gives the same episode); `None` continues the stream.
    fn reset(&mut self, seed: Option<u64>) -> EnvResult<(Vec<f32>, Info)>;

    /// Applies one action for one control period. Actions outside the action space are clipped
    /// to it; NaN, infinite or wrong-length actions are errors and change nothing.
    fn step(&mut self, action: &[f32]) -> EnvResult<Step>;

    /// Renders in the environment's render mode; `None` when it has none.
    fn render(&mut self) -> EnvResult<Option<Frame>>;

    /// Values of [`Info::privileged`] at every reset and step; 0 when the environment offers
    /// no privileged state.
    fn privileged_dim(&self) -> usize {
        0
    }

    /// The camera images each observation carries besides the state vector (a Gymnasium `Dict`
    /// observation: the state under `state`, each image under its view's name); `None` when
    /// the environment observes no images.
    fn image_space(&self) -> Option<&ImageSpace> {
        None
    }

    /// The images of the observation [`Env::reset`] or [`Env::step`] returned last:
    /// [`ImageSpace::len`] bytes, the views in order. `None` without an image space or before
    /// the first reset.
    fn image(&self) -> Option<&[u8]> {
        None
    }

    /// Releases resources. The environment must not be used afterwards.
    fn close(&mut self) {}
}

/// A boxed environment is an environment: what [`crate::registry::make`] returns (and any
/// other boxed env, such as [`crate::arm::ArmTaskEnv`]) nests in wrappers and vector
/// environments like a concrete one.
impl<E: Env + ?Sized> Env for Box<E> {
    fn metadata(&self) -> Metadata {
        (**self).metadata()
    }

    fn observation_space(&self) -> &BoxSpace {
        (**self).observation_space()
    }

    fn action_space(&self) -> &BoxSpace {
        (**self).action_space()
    }

    fn render_mode(&self) -> Option<RenderMode> {
        (**self).render_mode()
    }

    fn reset(&mut self, seed: Option<u64>) -> EnvResult<(Vec<f32>, Info)> {
        (**self).reset(seed)
    }

    fn step(&mut self, action: &[f32]) -> EnvResult<Step> {
        (**self).step(action)
    }

    fn render(&mut self) -> EnvResult<Option<Frame>> {
        (**self).render()
    }

    fn privileged_dim(&self) -> usize {
        (**self).privileged_dim()
    }

    fn image_space(&self) -> Option<&ImageSpace> {
        (**self).image_space()
    }

    fn image(&self) -> Option<&[u8]> {
        (**self).image()
    }

    fn close(&mut self) {
        (**self).close()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_values_keep_order_replace_by_name_and_round_trip_as_a_map() {
        let mut v = NamedValues::new().with("reach", 0.25).with("grasp", 0.0);
        v.set("reach", 0.5);
        v.set(String::from("lift"), 0.1);
        assert_eq!(v.names().collect::<Vec<_>>(), ["reach", "grasp", "lift"]);
        assert_eq!(v.get("reach"), Some(0.5));
        assert_eq!(v.get("missing"), None);
        assert!((v.total() - 0.6).abs() < 1e-6);
        let json = serde_json::to_string(&v).unwrap();
        assert_eq!(json, r#"{"reach":0.5,"grasp":0.0,"lift":0.1}"#);
        let back: NamedValues = serde_json::from_str(&json).unwrap();
        assert_eq!(back, v);
        let mut m = NamedValues::new().with("lift", 0.3).with("grasped", 0.0);
        m.merge_max(&v);
        assert_eq!(m.get("lift"), Some(0.3));
        assert_eq!(m.get("reach"), Some(0.5));
    }
}
