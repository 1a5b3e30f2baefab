//! Random draws the layers share.
//!
//! Standard normals by Box–Muller, written here rather than taken from `rand_distr` (whose
//! ziggurat gives other values from the same stream): every seeded episode, noise draw and
//! initial weight depends on these exact draws, and the pinned weights in
//! `crates/rl/tests/train.rs` hold them to it.

use rand::Rng;

/// A draw from N(0, 1), two uniforms per draw.
pub fn standard_normal(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.random::<f32>().max(1e-12);
    let u2: f32 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
}

/// [`standard_normal`] in `f64`, for the twin's sensor and timing noise.
pub fn standard_normal_f64(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A draw uniform in `[range[0], range[1])`.
pub fn uniform(rng: &mut impl Rng, range: [f32; 2]) -> f32 {
    range[0] + (range[1] - range[0]) * rng.random::<f32>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn draws_have_zero_mean_and_unit_spread() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 200_000;
        let a: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng) as f64).collect();
        let b: Vec<f64> = (0..n).map(|_| standard_normal_f64(&mut rng)).collect();
        for draws in [a, b] {
            let mean = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
            assert!(
                mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
                "{mean} {var}"
            );
            let beyond = draws.iter().filter(|x| x.abs() > 1.96).count() as f64 / n as f64;
            assert!((beyond - 0.05).abs() < 0.003, "{beyond}");
        }
    }
}
