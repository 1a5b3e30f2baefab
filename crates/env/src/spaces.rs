//! Gymnasium's `Box` space (a product of intervals, float32) and the camera images beside it.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// A box `[low, high]` of f32 values with a shape (flattened row-major).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoxSpace {
    /// Lower bound of each value (may be −∞).
    pub low: Vec<f32>,
    /// Upper bound of each value (may be +∞).
    pub high: Vec<f32>,
    /// The shape the flattened values take: `[dim]` for a box from [`BoxSpace::new`].
    pub shape: Vec<usize>,
}

impl BoxSpace {
    /// A one-dimensional box; `low` and `high` must have the same length.
    pub fn new(low: Vec<f32>, high: Vec<f32>) -> Self {
        assert_eq!(low.len(), high.len(), "box bounds of different lengths");
        let shape = vec![low.len()];
        Self { low, high, shape }
    }

    /// An unbounded box of `n` values.
    pub fn unbounded(n: usize) -> Self {
        Self::new(vec![f32::NEG_INFINITY; n], vec![f32::INFINITY; n])
    }

    /// Number of values.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// The element type, as Gymnasium names it.
    pub fn dtype(&self) -> &'static str {
        "float32"
    }

    /// Whether every bound is finite.
    pub fn is_bounded(&self) -> bool {
        self.low.iter().chain(&self.high).all(|v| v.is_finite())
    }

    /// Whether `x` has the right length, is finite and lies in the box.
    pub fn contains(&self, x: &[f32]) -> bool {
        x.len() == self.dim()
            && x.iter()
                .zip(self.low.iter().zip(&self.high))
                .all(|(v, (lo, hi))| v.is_finite() && *v >= *lo && *v <= *hi)
    }

    /// Clips `x` into the box in place.
    pub fn clip(&self, x: &mut [f32]) {
        for (v, (lo, hi)) in x.iter_mut().zip(self.low.iter().zip(&self.high)) {
            *v = v.clamp(*lo, *hi);
        }
    }

    /// A uniform sample (bounded boxes) or a standard normal one (unbounded dimensions).
    pub fn sample(&self, rng: &mut impl Rng) -> Vec<f32> {
        self.low
            .iter()
            .zip(&self.high)
            .map(|(&lo, &hi)| {
                if lo.is_finite() && hi.is_finite() {
                    lo + (hi - lo) * rng.random::<f32>()
                } else {
                    // Clamped into whichever side is bounded.
                    crate::random::standard_normal(rng).clamp(lo, hi)
                }
            })
            .collect()
    }
}

/// One camera's image in an observation: `height × width × channels` bytes, row-major, top row
/// first (Gymnasium's `Box(0, 255, (height, width, channels), uint8)`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImageView {
    /// The observation key (`scene_rgb`, `wrist_depth`, …).
    pub name: String,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Bytes per pixel: 3 (RGB), 1 (depth) or 4 (RGB and depth).
    pub channels: u32,
}

impl ImageView {
    /// Bytes of one image.
    pub fn len(&self) -> usize {
        self.height as usize * self.width as usize * self.channels as usize
    }

    /// Whether the image has no pixels (never, for a checked camera).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The camera images an environment observes besides its state vector: the `u8` entries of a
/// Gymnasium `Dict` observation. An environment's images are one buffer of
/// [`ImageSpace::len`] bytes, the views one after another.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImageSpace {
    /// The images, in buffer order.
    pub views: Vec<ImageView>,
}

impl ImageSpace {
    /// Bytes of all the images.
    pub fn len(&self) -> usize {
        self.views.iter().map(ImageView::len).sum()
    }

    /// Whether there are no images.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The views in words: `scene_rgb 64×64×3, wrist_depth 64×64×1`.
    pub fn describe(&self) -> String {
        let views: Vec<String> = (self.views.iter())
            .map(|v| format!("{} {}×{}×{}", v.name, v.height, v.width, v.channels))
            .collect();
        views.join(", ")
    }

    /// Where view `i` lies in the buffer.
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        let start: usize = self.views[..i].iter().map(ImageView::len).sum();
        start..start + self.views[i].len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn samples_lie_in_the_box_and_clip_projects_onto_it() {
        let space = BoxSpace::new(vec![-1.0, 0.0, -0.05], vec![1.0, 2.0, 0.05]);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..1000 {
            assert!(space.contains(&space.sample(&mut rng)));
        }
        let mut x = vec![5.0, -3.0, 0.01];
        space.clip(&mut x);
        assert_eq!(x, vec![1.0, 0.0, 0.01]);
        assert!(!space.contains(&[0.0, 0.0]));
        assert!(!space.contains(&[f32::NAN, 0.0, 0.0]));
        assert!(BoxSpace::unbounded(3).contains(&[1e30, -1e30, 0.0]));
        assert!(!BoxSpace::unbounded(3).is_bounded());
    }

    #[test]
    fn image_views_lie_one_after_another_in_the_buffer() {
        let view = |name: &str, channels| ImageView {
            name: name.into(),
            height: 4,
            width: 5,
            channels,
        };
        let space = ImageSpace {
            views: vec![view("scene_rgb", 3), view("wrist_depth", 1)],
        };
        assert_eq!(space.len(), 80);
        assert_eq!(space.range(0), 0..60);
        assert_eq!(space.range(1), 60..80);
        assert!(ImageSpace::default().is_empty());
    }
}
