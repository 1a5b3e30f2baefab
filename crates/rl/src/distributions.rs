//! Action distributions (SB3's `common/distributions.py`): the Gaussian of PPO and the
//! tanh-squashed Gaussian of SAC, each written once for rollouts, losses and inference.
//!
//! Sampling is reparameterised and takes its standard normal noise as an argument, so the
//! caller keeps the random stream (and with it a seeded run's reproducibility): see
//! [`standard_normal_tensor`].

use candle_core::{D, Device, Result, Tensor};
use fairgrasp_env::random::standard_normal;
use rand::Rng;

/// ½ ln 2π.
pub(crate) const HALF_LN_2PI: f64 = 0.918_938_533_204_672_8;

/// One action dimension's term of [`DiagGaussian::log_prob`], `z² · (−½) − log σ − ½ ln 2π`
/// for `z = (a − μ)·e^{−log σ}`, with candle's f32 arithmetic (`x · c` is `x · c + 0`): for the
/// code that computes log-probabilities without tensors and must agree with it bit for bit.
pub fn log_prob_term(z: f32, log_std: f32) -> f32 {
    ((z * z * -0.5 + 0.0) - log_std) * 1.0 + (-HALF_LN_2PI) as f32
}

/// `rows × cols` standard normal draws from `rng`, row by row (the order PPO and SAC have
/// always drawn in, so seeded runs keep their noise).
pub fn standard_normal_tensor(rng: &mut impl Rng, rows: usize, cols: usize) -> Result<Tensor> {
    let values: Vec<f32> = (0..rows * cols).map(|_| standard_normal(rng)).collect();
    Tensor::from_vec(values, (rows, cols), &Device::Cpu)
}

/// A Gaussian with diagonal covariance over `batch × act_dim` actions. The log standard
/// deviation is either state-dependent (`batch × act_dim`, like the mean) or state-independent
/// (`act_dim`, one learnt vector broadcast over the batch, as in PPO).
#[derive(Clone, Debug)]
pub struct DiagGaussian {
    mean: Tensor,
    log_std: Tensor,
}

impl DiagGaussian {
    /// Errors unless `mean` is `batch × act_dim` and `log_std` is `act_dim` or `batch × act_dim`.
    pub fn new(mean: Tensor, log_std: Tensor) -> Result<Self> {
        let (_, act_dim) = mean.dims2()?;
        let fits = match log_std.dims() {
            [n] => *n == act_dim,
            dims => dims == mean.dims(),
        };
        if !fits {
            return Err(candle_core::Error::Msg(format!(
                "a Gaussian with mean {:?} cannot have log std {:?}",
                mean.dims(),
                log_std.dims()
            )));
        }
        Ok(Self { mean, log_std })
    }

    /// The means, `batch × act_dim`.
    pub fn mean(&self) -> &Tensor {
        &self.mean
    }

    /// The log standard deviations, `act_dim` or `batch × act_dim`.
    pub fn log_std(&self) -> &Tensor {
        &self.log_std
    }

    /// `log N(a; μ, σ²)` summed over the action dimensions: one value per row.
    pub fn log_prob(&self, actions: &Tensor) -> Result<Tensor> {
        let z = actions
            .sub(&self.mean)?
            .broadcast_mul(&self.log_std.neg()?.exp()?)?;
        ((z.sqr()? * -0.5)?.broadcast_sub(&self.log_std)? - HALF_LN_2PI)?.sum(D::Minus1)
    }

    /// Entropy `Σ (log σ + ½ ln 2πe)`: one value per row.
    pub fn entropy(&self) -> Result<Tensor> {
        (self.log_std.broadcast_as(self.mean.shape())? + (0.5 + HALF_LN_2PI))?.sum(D::Minus1)
    }

    /// `μ + σ ε` for standard normal noise `eps` (`batch × act_dim`); gradients reach μ and σ.
    pub fn sample(&self, eps: &Tensor) -> Result<Tensor> {
        self.mean.add(&eps.broadcast_mul(&self.log_std.exp()?)?)
    }

    /// The most likely action: the mean.
    pub fn mode(&self) -> Tensor {
        self.mean.clone()
    }
}

/// SAC's policy distribution: `a = tanh(u)`, `u ~ N(μ, σ²)` diagonal, so actions lie in
/// `(-1, 1)`.
#[derive(Clone, Debug)]
pub struct SquashedDiagGaussian {
    gaussian: DiagGaussian,
}

impl SquashedDiagGaussian {
    /// `mean` and `log_std` of the Gaussian before the tanh (see [`DiagGaussian::new`]).
    pub fn new(mean: Tensor, log_std: Tensor) -> Result<Self> {
        Ok(Self {
            gaussian: DiagGaussian::new(mean, log_std)?,
        })
    }

    /// Actions `tanh(μ + σ ε)` for standard normal noise `eps`, and their log-probabilities
    /// `Σ [log N(u; μ, σ²) − log(1 − tanh(u)² + 1e-6)]` (the change of variables through tanh;
    /// the 1e-6 keeps the logarithm finite where tanh saturates). Reparameterised: gradients
    /// reach μ and σ. The log-probabilities are one value per row.
    pub fn sample(&self, eps: &Tensor) -> Result<(Tensor, Tensor)> {
        let u = self.gaussian.sample(eps)?;
        let actions = u.tanh()?;
        // (u − μ)/σ = ε, so log N(u; μ, σ²) = −½ ε² − log σ − ½ ln 2π without a division.
        let gaussian = (eps.sqr()? * -0.5)?.broadcast_sub(&self.gaussian.log_std)?;
        let jacobian = actions.sqr()?.affine(-1.0, 1.0 + 1e-6)?.log()?;
        let log_probs =
            ((gaussian - jacobian)?.sum(D::Minus1)? - HALF_LN_2PI * eps.dim(D::Minus1)? as f64)?;
        Ok((actions, log_probs))
    }

    /// The deterministic action `tanh(μ)`.
    pub fn mode(&self) -> Result<Tensor> {
        self.gaussian.mean.tanh()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    const MEAN: [f32; 3] = [0.3, -1.2, 0.8];
    const LOG_STD: [f32; 3] = [-0.5, 0.4, -1.0];
    const EPS: [f32; 3] = [0.7, -0.2, 1.5];

    fn row(v: [f32; 3]) -> Tensor {
        Tensor::new(&[v], &Device::Cpu).unwrap()
    }

    fn normal_density(x: f64, mean: f64, std: f64) -> f64 {
        (-0.5 * ((x - mean) / std).powi(2)).exp() / (std * (2.0 * std::f64::consts::PI).sqrt())
    }

    fn values(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1().unwrap()
    }

    #[test]
    fn gaussian_log_prob_matches_the_density_for_both_log_std_shapes() {
        let actions = [0.1f32, 0.5, -0.3];
        let want: f64 = (0..3)
            .map(|k| {
                let std = (LOG_STD[k] as f64).exp();
                normal_density(actions[k] as f64, MEAN[k] as f64, std).ln()
            })
            .sum();
        let per_row = DiagGaussian::new(row(MEAN), row(LOG_STD)).unwrap();
        let shared =
            DiagGaussian::new(row(MEAN), Tensor::new(&LOG_STD, &Device::Cpu).unwrap()).unwrap();
        for dist in [per_row, shared] {
            let got = values(&dist.log_prob(&row(actions)).unwrap());
            assert_eq!(got.len(), 1);
            assert!((got[0] as f64 - want).abs() < 1e-5, "{got:?} vs {want}");
        }
    }

    #[test]
    fn gaussian_entropy_is_the_closed_form_per_row() {
        // H = ½ Σ ln(2πe σ²), for each of two rows sharing one log std.
        let mean = Tensor::new(&[MEAN, [0.0; 3]], &Device::Cpu).unwrap();
        let log_std = Tensor::new(&LOG_STD, &Device::Cpu).unwrap();
        let dist = DiagGaussian::new(mean, log_std).unwrap();
        let want: f64 = LOG_STD
            .iter()
            .map(|&l| {
                let var = (2.0 * l as f64).exp();
                0.5 * (2.0 * std::f64::consts::PI * std::f64::consts::E * var).ln()
            })
            .sum();
        let got = values(&dist.entropy().unwrap());
        assert_eq!(got.len(), 2);
        for h in got {
            assert!((h as f64 - want).abs() < 1e-5, "{h} vs {want}");
        }
    }

    #[test]
    fn gaussian_sample_and_mode() {
        let dist = DiagGaussian::new(row(MEAN), row(LOG_STD)).unwrap();
        assert_eq!(values(&dist.mode()), MEAN);
        let sample = values(&dist.sample(&row(EPS)).unwrap());
        for k in 0..3 {
            let want = MEAN[k] + LOG_STD[k].exp() * EPS[k];
            assert!((sample[k] - want).abs() < 1e-6, "{sample:?}");
        }
        // Zero noise gives the mode.
        assert_eq!(values(&dist.sample(&row([0.0; 3])).unwrap()), MEAN);
    }

    #[test]
    fn mismatched_shapes_are_refused() {
        let err = DiagGaussian::new(row(MEAN), Tensor::new(&[0.0f32; 2], &Device::Cpu).unwrap())
            .unwrap_err();
        assert!(err.to_string().contains("log std [2]"), "{err}");
        assert!(
            DiagGaussian::new(Tensor::new(&MEAN, &Device::Cpu).unwrap(), row(LOG_STD)).is_err()
        );
    }

    #[test]
    fn squashed_log_prob_matches_a_numeric_density() {
        let dist = SquashedDiagGaussian::new(row(MEAN), row(LOG_STD)).unwrap();
        let (actions, log_probs) = dist.sample(&row(EPS)).unwrap();
        let actions = values(&actions);
        let log_prob = values(&log_probs);
        assert_eq!(log_prob.len(), 1);
        // The density of a = tanh(u), u ~ N(μ, σ²): p(u) / |da/du|, with the derivative taken by
        // central differences.
        let mut want = 0.0f64;
        for k in 0..3 {
            let (m, s) = (MEAN[k] as f64, (LOG_STD[k] as f64).exp());
            let u = m + s * EPS[k] as f64;
            assert!((actions[k] as f64 - u.tanh()).abs() < 1e-6);
            let h = 1e-5;
            let slope = ((u + h).tanh() - (u - h).tanh()) / (2.0 * h);
            want += (normal_density(u, m, s) / slope).ln();
        }
        assert!(
            (log_prob[0] as f64 - want).abs() < 1e-4,
            "log π {}, numerically {want}",
            log_prob[0]
        );
    }

    #[test]
    fn squashed_mode_is_tanh_of_the_mean() {
        let dist = SquashedDiagGaussian::new(row(MEAN), row(LOG_STD)).unwrap();
        let mode = values(&dist.mode().unwrap());
        for k in 0..3 {
            assert!((mode[k] - MEAN[k].tanh()).abs() < 1e-6, "{mode:?}");
        }
    }

    #[test]
    fn noise_is_drawn_row_by_row_from_the_stream() {
        let mut a = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut b = a.clone();
        let t = standard_normal_tensor(&mut a, 2, 3).unwrap();
        assert_eq!(t.dims(), [2, 3]);
        let want: Vec<f32> = (0..6).map(|_| standard_normal(&mut b)).collect();
        assert_eq!(values(&t), want);
    }
}
