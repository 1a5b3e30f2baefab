//! The fit of one joint's extra drive dynamics: a pure delay and a first-order lag that, put in
//! front of the simulated arm, make its response match the recorded joint.
//!
//! Both the drive model and the simulated arm (a PD joint moving a few degrees about a pose)
//! are linear and time-invariant, so their order may be swapped: the recorded set points are
//! replayed through the simulator once, and each candidate (delay, lag) filters that response
//! instead of being replayed through the simulator again. A candidate then costs a pass over
//! a few thousand samples, and the search (a grid, then a pattern search) takes milliseconds.

use crate::error::{DeployError, Result};

/// Searched delays (ms): at most this.
pub const MAX_DELAY_MS: f64 = 100.0;
/// Searched lag time constants (ms): at most this.
pub const MAX_TAU_MS: f64 = 300.0;
/// The search stops once its step is this fine (ms).
const FINEST_STEP_MS: f64 = 0.01;
/// Fewest recorded samples a fit accepts.
pub const MIN_SAMPLES: usize = 50;

/// A signal sampled every `dt` seconds from `t0`.
#[derive(Clone, Debug, PartialEq)]
pub struct Uniform {
    /// Time of the first sample (s).
    pub t0: f64,
    /// Time between samples (s).
    pub dt: f64,
    /// The signal at `t0`, `t0 + dt`, …
    pub values: Vec<f64>,
}

impl Uniform {
    /// The value at `t`, linear between samples, held beyond the ends.
    pub fn at(&self, t: f64) -> f64 {
        let n = self.values.len();
        if n == 0 {
            return 0.0;
        }
        let x = (t - self.t0) / self.dt;
        if x <= 0.0 {
            return self.values[0];
        }
        let i = x.floor() as usize;
        if i + 1 >= n {
            return self.values[n - 1];
        }
        let s = x - i as f64;
        self.values[i] + (self.values[i + 1] - self.values[i]) * s
    }

    /// Time of the last sample (s); `t0` when there is none or one.
    pub fn end(&self) -> f64 {
        self.t0 + self.dt * self.values.len().saturating_sub(1) as f64
    }
}

/// `input` through a pure delay of `delay` s and a first-order lag of time constant `tau` s,
/// starting at rest at the first sample. The lag is integrated exactly for an input linear
/// between samples, as the twin's drives integrate it.
pub fn delay_and_lag(input: &Uniform, delay: f64, tau: f64) -> Uniform {
    let dt = input.dt;
    let mut out = Vec::with_capacity(input.values.len());
    let first = input.values.first().copied().unwrap_or(0.0);
    let mut y = first;
    let mut u0 = first;
    let decay = if tau > 0.0 { (-dt / tau).exp() } else { 0.0 };
    for k in 0..input.values.len() {
        let u1 = input.at(input.t0 + k as f64 * dt - delay);
        if k > 0 {
            y = if tau > 0.0 {
                let slope = (u1 - u0) / dt;
                u1 - slope * tau + (y - u0 + slope * tau) * decay
            } else {
                u1
            };
        }
        out.push(y);
        u0 = u1;
    }
    Uniform {
        t0: input.t0,
        dt,
        values: out,
    }
}

/// Recorded samples of one joint: times (s, the simulated response's clock) and angles (deg).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    /// Sample times (s).
    pub t: Vec<f64>,
    /// Joint angle at each time (deg).
    pub q: Vec<f64>,
}

/// One joint's fitted drive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointFit {
    /// Pure delay (ms), within [0, [`MAX_DELAY_MS`]].
    pub delay_ms: f64,
    /// First-order lag time constant (ms), within [0, [`MAX_TAU_MS`]].
    pub tau_ms: f64,
    /// RMS of what the model leaves unexplained (deg), a constant offset removed.
    pub rms_deg: f64,
    /// The constant offset between the recording and the model (deg): a sag or a calibration
    /// offset the fit is not about.
    pub offset_deg: f64,
}

/// RMS residual and offset of `recorded` against `model`.
pub fn residual(model: &Uniform, recorded: &Samples) -> (f64, f64) {
    let n = recorded.t.len() as f64;
    let r: Vec<f64> = (recorded.t.iter().zip(&recorded.q))
        .map(|(&t, &q)| q - model.at(t))
        .collect();
    let offset = r.iter().sum::<f64>() / n;
    let rms = (r.iter().map(|v| (v - offset).powi(2)).sum::<f64>() / n).sqrt();
    (rms, offset)
}

/// The delay and lag (clamped to `[0, MAX_…]`) that best explain `recorded` as `simulated`
/// through them: a grid over both, then a pattern search from the best point of it.
pub fn fit_joint(simulated: &Uniform, recorded: &Samples) -> Result<JointFit> {
    check(simulated, recorded)?;
    let cost = |d_ms: f64, tau_ms: f64| {
        residual(
            &delay_and_lag(simulated, d_ms / 1e3, tau_ms / 1e3),
            recorded,
        )
        .0
    };
    let (mut best, mut best_cost) = ((0.0, 0.0), f64::INFINITY);
    let (grid_d, grid_tau) = (4.0, 10.0);
    let mut d = 0.0;
    while d <= MAX_DELAY_MS {
        let mut tau = 0.0;
        while tau <= MAX_TAU_MS {
            let c = cost(d, tau);
            if c < best_cost {
                (best, best_cost) = ((d, tau), c);
            }
            tau += grid_tau;
        }
        d += grid_d;
    }
    // Pattern search: try the eight neighbours at the step, move to the best, halve the step
    // when none is better.
    let (mut step_d, mut step_tau) = (grid_d / 2.0, grid_tau / 2.0);
    while step_d > FINEST_STEP_MS || step_tau > FINEST_STEP_MS {
        let mut moved = false;
        for (sd, st) in [
            (1.0, 0.0),
            (-1.0, 0.0),
            (0.0, 1.0),
            (0.0, -1.0),
            (1.0, 1.0),
            (1.0, -1.0),
            (-1.0, 1.0),
            (-1.0, -1.0),
        ] {
            let d = (best.0 + sd * step_d).clamp(0.0, MAX_DELAY_MS);
            let tau = (best.1 + st * step_tau).clamp(0.0, MAX_TAU_MS);
            let c = cost(d, tau);
            if c < best_cost {
                (best, best_cost, moved) = ((d, tau), c, true);
            }
        }
        if !moved {
            step_d /= 2.0;
            step_tau /= 2.0;
        }
    }
    let model = delay_and_lag(simulated, best.0 / 1e3, best.1 / 1e3);
    let (rms_deg, offset_deg) = residual(&model, recorded);
    Ok(JointFit {
        delay_ms: best.0,
        tau_ms: best.1,
        rms_deg,
        offset_deg,
    })
}

fn check(simulated: &Uniform, recorded: &Samples) -> Result<()> {
    let bad = |m: String| Err(DeployError::config("system identification", m));
    if !(simulated.dt.is_finite() && simulated.dt > 0.0) {
        return bad(format!(
            "the simulated step {} s is not positive",
            simulated.dt
        ));
    }
    if simulated.values.len() < 2 || simulated.values.iter().any(|v| !v.is_finite()) {
        return bad("the simulated response is empty or not finite".into());
    }
    if recorded.t.len() != recorded.q.len() {
        return bad(format!(
            "{} times for {} joint readings",
            recorded.t.len(),
            recorded.q.len()
        ));
    }
    if recorded.t.len() < MIN_SAMPLES {
        return bad(format!(
            "{} joint readings; at least {MIN_SAMPLES} are needed (did the state stream run?)",
            recorded.t.len()
        ));
    }
    if let Some(i) =
        (0..recorded.t.len()).find(|&i| !(recorded.t[i].is_finite() && recorded.q[i].is_finite()))
    {
        return bad(format!("reading {i} is not finite"));
    }
    let (lo, hi) = recorded
        .q
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if hi - lo < 0.05 {
        return bad(format!(
            "the joint moved only {:.3} deg during its excitation: too little to fit (was the \
             arm enabled, the right joint excited?)",
            hi - lo
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A stand-in for the simulated arm's response: steps smoothed over 0.1 s, then a chirp.
    fn excitation(dt: f64) -> Uniform {
        let n = (6.0 / dt) as usize;
        let values = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                if t < 2.0 {
                    let s = ((t % 1.0) / 0.1).min(1.0);
                    let smooth = s * s * (3.0 - 2.0 * s);
                    if t < 1.0 {
                        2.0 * smooth
                    } else {
                        2.0 - 2.0 * smooth
                    }
                } else {
                    let tc = t - 2.0;
                    let f = 0.5 + 3.5 * tc / 4.0;
                    (2.0 * std::f64::consts::PI * (0.5 * tc + 3.5 * tc * tc / 8.0)).sin()
                        * (1.0 / f).min(1.0)
                }
            })
            .collect();
        Uniform {
            t0: 10.0,
            dt,
            values,
        }
    }

    /// Readings every 8 ms, jittered in time as a stream is, with encoder noise.
    fn readings(truth: &Uniform, noise_deg: f64, seed: u64) -> Samples {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = Samples::default();
        let mut t = truth.t0;
        while t < truth.end() {
            let jitter = fairgrasp_env::random::standard_normal_f64(&mut rng) * 0.0003;
            s.t.push(t + jitter);
            s.q.push(
                truth.at(t + jitter)
                    + noise_deg * fairgrasp_env::random::standard_normal_f64(&mut rng)
                    + 0.2,
            );
            t += 0.008;
        }
        s
    }

    #[test]
    fn a_known_delay_and_lag_are_recovered_with_noise() {
        let sim = excitation(1.0 / 240.0);
        for (d, tau) in [(12.0, 30.0), (5.0, 60.0), (25.0, 8.0), (0.0, 0.0)] {
            let truth = delay_and_lag(&sim, d / 1e3, tau / 1e3);
            let fit = fit_joint(&sim, &readings(&truth, 0.002, 7)).unwrap();
            assert!(
                (fit.delay_ms - d).abs() < 0.05 * d.max(10.0)
                    && (fit.tau_ms - tau).abs() < 0.05 * tau.max(10.0),
                "injected {d} ms / {tau} ms, fitted {fit:?}"
            );
            assert!((fit.offset_deg - 0.2).abs() < 0.01, "{fit:?}");
            assert!(fit.rms_deg < 0.01, "{fit:?}");
        }
    }

    #[test]
    fn the_delay_is_not_traded_for_lag() {
        // Same total (delay + lag) either way: the fit must tell them apart.
        let sim = excitation(1.0 / 240.0);
        let a = delay_and_lag(&sim, 0.030, 0.010);
        let b = delay_and_lag(&sim, 0.010, 0.030);
        let fa = fit_joint(&sim, &readings(&a, 0.002, 1)).unwrap();
        let fb = fit_joint(&sim, &readings(&b, 0.002, 1)).unwrap();
        assert!(
            (fa.delay_ms - 30.0).abs() < 1.5 && (fa.tau_ms - 10.0).abs() < 1.0,
            "{fa:?}"
        );
        assert!(
            (fb.delay_ms - 10.0).abs() < 1.0 && (fb.tau_ms - 30.0).abs() < 1.5,
            "{fb:?}"
        );
    }

    #[test]
    fn bad_input_is_named() {
        let sim = excitation(0.01);
        let still = Samples {
            t: (0..100).map(|k| 10.0 + k as f64 * 0.01).collect(),
            q: vec![1.0; 100],
        };
        let e = fit_joint(&sim, &still).unwrap_err().to_string();
        assert!(e.contains("moved only"), "{e}");
        let few = Samples {
            t: vec![10.0, 10.1],
            q: vec![0.0, 1.0],
        };
        assert!(
            fit_joint(&sim, &few)
                .unwrap_err()
                .to_string()
                .contains("at least")
        );
        let mut nan = readings(&sim, 0.0, 2);
        nan.q[7] = f64::NAN;
        assert!(
            fit_joint(&sim, &nan)
                .unwrap_err()
                .to_string()
                .contains("reading 7")
        );
        let empty = Uniform {
            t0: 0.0,
            dt: 0.01,
            values: vec![],
        };
        assert!(fit_joint(&empty, &readings(&sim, 0.0, 3)).is_err());
        let zero_dt = Uniform {
            dt: 0.0,
            ..sim.clone()
        };
        assert!(fit_joint(&zero_dt, &readings(&sim, 0.0, 3)).is_err());
    }

    #[test]
    fn the_filter_matches_the_twins_drives() {
        // The twin's drives on one joint, fed the same samples, give the same output.
        use crate::twin::faults::JointTracking;
        use crate::twin::motion::Drives;
        let sim = excitation(1.0 / 240.0);
        let mut model = [JointTracking::default(); 6];
        model[0] = JointTracking {
            delay_ms: 12.0,
            tau_ms: 30.0,
        };
        let mut drives = Drives::new([sim.values[0]; 6], sim.t0);
        let ours = delay_and_lag(&sim, 0.012, 0.030);
        for (k, &v) in sim.values.iter().enumerate() {
            let t = sim.t0 + k as f64 * sim.dt;
            let out = drives.follow(&model, t, [v; 6], t);
            assert!(
                (out[0] - ours.values[k]).abs() < 1e-9,
                "sample {k}: {} vs {}",
                out[0],
                ours.values[k]
            );
        }
    }
}
