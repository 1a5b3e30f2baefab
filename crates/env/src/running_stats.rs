//! Running mean and variance of vectors, merged batch by batch.
//!
//! [`RunningMeanStd`] mirrors Stable-Baselines3's `RunningMeanStd`
//! (`stable_baselines3/common/running_mean_std.py`): float64 statistics that start at mean 0,
//! variance 1 and a pseudo-count of `1e-4`, updated with the batch moments by the parallel
//! algorithm of Chan, Golub & LeVeque (the batched form of Welford's update). It is what
//! [`crate::wrappers::VecNormalize`] uses for observations and discounted returns.

use serde::{Deserialize, Serialize};

/// SB3's default pseudo-count of a fresh [`RunningMeanStd`] (its `epsilon` argument): it makes the
/// first update dominate the initial mean 0 and variance 1 without dividing by zero.
pub const DEFAULT_COUNT_EPSILON: f64 = 1e-4;

/// Running per-component mean and (population) variance of `dim`-vectors.
///
/// Serialised with every number written as the shortest decimal string that reads back to the
/// same `f64` (see *Exact round trips* below), so saving and loading is bit-exact; plain JSON
/// numbers are accepted on input.
///
/// # Exact round trips
///
/// `serde_json` parses numbers by a fast method that can be off by one unit in the last place
/// unless its `float_roundtrip` feature is on; writing the values as strings and parsing them
/// with Rust's correctly rounded `str::parse::<f64>` avoids that.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunningMeanStd {
    #[serde(with = "exact_f64::vec")]
    mean: Vec<f64>,
    #[serde(with = "exact_f64::vec")]
    var: Vec<f64>,
    #[serde(with = "exact_f64::scalar")]
    count: f64,
}

impl RunningMeanStd {
    /// Mean 0, variance 1, count [`DEFAULT_COUNT_EPSILON`] (SB3's defaults).
    pub fn new(dim: usize) -> Self {
        Self::with_count_epsilon(dim, DEFAULT_COUNT_EPSILON)
    }

    /// Mean 0, variance 1 and the pseudo-count `count_epsilon`.
    pub fn with_count_epsilon(dim: usize, count_epsilon: f64) -> Self {
        Self {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: count_epsilon,
        }
    }

    /// Statistics from their parts; checked with [`Self::validate`].
    pub fn from_parts(mean: Vec<f64>, var: Vec<f64>, count: f64) -> Result<Self, String> {
        let stats = Self { mean, var, count };
        stats.validate()?;
        Ok(stats)
    }

    /// Number of components.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Mean of each component.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Population variance of each component.
    pub fn var(&self) -> &[f64] {
        &self.var
    }

    /// Number of vectors seen, plus the initial pseudo-count.
    pub fn count(&self) -> f64 {
        self.count
    }

    /// Whether the statistics are usable: as many variances as means, every value finite,
    /// variances non-negative, count positive. Says which value is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.mean.len() != self.var.len() {
            return Err(format!(
                "{} means but {} variances",
                self.mean.len(),
                self.var.len()
            ));
        }
        if let Some(i) = self.mean.iter().position(|m| !m.is_finite()) {
            return Err(format!("mean[{i}] is {}", self.mean[i]));
        }
        if let Some(i) = self.var.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(format!(
                "var[{i}] is {}; variances must be finite and non-negative",
                self.var[i]
            ));
        }
        if !(self.count.is_finite() && self.count > 0.0) {
            return Err(format!(
                "count is {}; it must be finite and positive",
                self.count
            ));
        }
        Ok(())
    }

    /// Normalises whole rows of `x` into `out` (same length): `clip((x − mean) / sqrt(var +
    /// epsilon), ±clip)`, SB3 VecNormalize's rule.
    pub fn normalize_into(&self, x: &[f32], epsilon: f64, clip: f64, out: &mut [f32]) {
        let dim = self.dim().max(1);
        for (row_in, row_out) in x.chunks_exact(dim).zip(out.chunks_exact_mut(dim)) {
            let stats = self.mean.iter().zip(&self.var);
            for ((o, &x), (&m, &v)) in row_out.iter_mut().zip(row_in).zip(stats) {
                *o = ((x as f64 - m) / (v + epsilon).sqrt()).clamp(-clip, clip) as f32;
            }
        }
    }

    /// Adds a batch of vectors stored row-major (`rows × dim` values), like SB3's
    /// `update(arr)`: the batch mean and population variance (two-pass) are merged in with
    /// [`Self::update_from_moments`]. An empty batch changes nothing.
    ///
    /// # Panics
    /// When `batch.len()` is not a multiple of [`Self::dim`] (a programming error).
    pub fn update<T: Copy + Into<f64>>(&mut self, batch: &[T]) {
        let dim = self.dim();
        if dim == 0 || batch.is_empty() {
            return;
        }
        assert!(
            batch.len().is_multiple_of(dim),
            "RunningMeanStd::update: {} values is not a whole number of {dim}-vectors",
            batch.len()
        );
        let rows = batch.len() / dim;
        let n = rows as f64;
        let mut batch_mean = vec![0.0f64; dim];
        for row in batch.chunks_exact(dim) {
            for (m, &x) in batch_mean.iter_mut().zip(row) {
                *m += x.into();
            }
        }
        for m in &mut batch_mean {
            *m /= n;
        }
        let mut batch_var = vec![0.0f64; dim];
        for row in batch.chunks_exact(dim) {
            for ((v, &x), m) in batch_var.iter_mut().zip(row).zip(&batch_mean) {
                let d = x.into() - m;
                *v += d * d;
            }
        }
        for v in &mut batch_var {
            *v /= n;
        }
        self.update_from_moments(&batch_mean, &batch_var, n);
    }

    /// Merges in a batch given by its mean, population variance and size (SB3's
    /// `update_from_moments`; Chan et al.'s parallel variance formula).
    ///
    /// # Panics
    /// When the moment vectors do not have [`Self::dim`] components.
    pub fn update_from_moments(&mut self, batch_mean: &[f64], batch_var: &[f64], batch_count: f64) {
        assert!(
            batch_mean.len() == self.dim() && batch_var.len() == self.dim(),
            "RunningMeanStd::update_from_moments: moments of {} and {} components for {}-vectors",
            batch_mean.len(),
            batch_var.len(),
            self.dim()
        );
        if batch_count <= 0.0 {
            return;
        }
        let total = self.count + batch_count;
        for ((mean, var), (&b_mean, &b_var)) in self
            .mean
            .iter_mut()
            .zip(&mut self.var)
            .zip(batch_mean.iter().zip(batch_var))
        {
            let delta = b_mean - *mean;
            let m_a = *var * self.count;
            let m_b = b_var * batch_count;
            let m2 = m_a + m_b + delta * delta * self.count * batch_count / total;
            *mean += delta * batch_count / total;
            *var = m2 / total;
        }
        self.count = total;
    }

    /// Merges another set of statistics of the same dimension into this one.
    ///
    /// # Panics
    /// When the dimensions differ.
    pub fn merge(&mut self, other: &RunningMeanStd) {
        self.update_from_moments(&other.mean, &other.var, other.count);
    }
}

/// Serde helpers that write `f64` values as shortest round-trip decimal strings and read strings
/// or numbers back.
mod exact_f64 {
    use serde::de::{self, Deserialize, Deserializer, Visitor};
    use serde::ser::{Serialize, Serializer};
    use std::fmt;

    struct Exact(f64);

    impl Serialize for Exact {
        fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
            // `Debug` gives the shortest digits that parse back to the same value, switching to
            // an exponent for very large and very small magnitudes.
            serializer.collect_str(&format_args!("{:?}", self.0))
        }
    }

    impl<'de> Deserialize<'de> for Exact {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            struct ExactVisitor;
            impl Visitor<'_> for ExactVisitor {
                type Value = Exact;
                fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                    f.write_str("a number or a string holding a number")
                }
                fn visit_f64<E: de::Error>(self, v: f64) -> Result<Exact, E> {
                    Ok(Exact(v))
                }
                fn visit_i64<E: de::Error>(self, v: i64) -> Result<Exact, E> {
                    Ok(Exact(v as f64))
                }
                fn visit_u64<E: de::Error>(self, v: u64) -> Result<Exact, E> {
                    Ok(Exact(v as f64))
                }
                fn visit_str<E: de::Error>(self, v: &str) -> Result<Exact, E> {
                    v.trim()
                        .parse::<f64>()
                        .map(Exact)
                        .map_err(|_| E::custom(format!("`{v}` is not a number")))
                }
            }
            deserializer.deserialize_any(ExactVisitor)
        }
    }

    pub mod scalar {
        use super::*;

        pub fn serialize<S: Serializer>(v: &f64, serializer: S) -> Result<S::Ok, S::Error> {
            Exact(*v).serialize(serializer)
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
            Exact::deserialize(deserializer).map(|e| e.0)
        }
    }

    pub mod vec {
        use super::*;

        pub fn serialize<S: Serializer>(v: &[f64], serializer: S) -> Result<S::Ok, S::Error> {
            serializer.collect_seq(v.iter().map(|&x| Exact(x)))
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(
            deserializer: D,
        ) -> Result<Vec<f64>, D::Error> {
            Vec::<Exact>::deserialize(deserializer).map(|v| v.into_iter().map(|e| e.0).collect())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batched_updates_equal_one_pass_over_all_data() {
        let data: Vec<f32> = (0..300)
            .map(|i| ((i * 37) % 101) as f32 * 0.25 - 7.0)
            .collect();
        let mut batched = RunningMeanStd::with_count_epsilon(3, f64::MIN_POSITIVE);
        for chunk in data.chunks(3 * 7) {
            batched.update(chunk);
        }
        let mut whole = RunningMeanStd::with_count_epsilon(3, f64::MIN_POSITIVE);
        whole.update(&data);
        for j in 0..3 {
            let xs: Vec<f64> = data.iter().skip(j).step_by(3).map(|&x| x as f64).collect();
            let m = xs.iter().sum::<f64>() / xs.len() as f64;
            let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / xs.len() as f64;
            assert!((batched.mean()[j] - m).abs() < 1e-9, "{j}");
            assert!((batched.var()[j] - v).abs() < 1e-9, "{j}");
            assert!((whole.mean()[j] - m).abs() < 1e-12, "{j}");
            assert!((whole.var()[j] - v).abs() < 1e-9, "{j}");
        }
        assert!((batched.count() - 100.0).abs() < 1e-9);
    }

    #[test]
    fn json_round_trip_is_bit_exact() {
        let mut s = RunningMeanStd::new(4);
        s.update(&[0.1f32, 1e-7, -3.3, 12345.678, 0.2, 2e-7, -3.1, 12000.5]);
        s.update(&[1.0f64 / 3.0, 2.0f64.sqrt(), 1e-300, 1e300]);
        let text = serde_json::to_string(&s).unwrap();
        let back: RunningMeanStd = serde_json::from_str(&text).unwrap();
        for (a, b) in s
            .mean()
            .iter()
            .chain(s.var())
            .zip(back.mean().iter().chain(back.var()))
        {
            assert_eq!(a.to_bits(), b.to_bits(), "{text}");
        }
        assert_eq!(s.count().to_bits(), back.count().to_bits());
        let plain: RunningMeanStd =
            serde_json::from_str(r#"{"mean": [0.5, 1], "var": ["2.25", 4], "count": 3}"#).unwrap();
        assert_eq!(plain.mean(), &[0.5, 1.0]);
        assert_eq!(plain.var(), &[2.25, 4.0]);
    }

    #[test]
    fn validate_names_the_bad_value() {
        let e = RunningMeanStd::from_parts(vec![0.0, 1.0], vec![1.0, -1.0], 2.0).unwrap_err();
        assert!(e.contains("var[1]"), "{e}");
        let e = RunningMeanStd::from_parts(vec![0.0], vec![1.0, 1.0], 2.0).unwrap_err();
        assert!(e.contains("1 means but 2 variances"), "{e}");
        let e = RunningMeanStd::from_parts(vec![0.0], vec![1.0], 0.0).unwrap_err();
        assert!(e.contains("count"), "{e}");
    }
}
