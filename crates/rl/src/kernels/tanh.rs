//! tanh as a candle op that vectorises. Candle's CPU `tanh` calls libm's `tanhf` once per value:
//! a perf profile of the default `fairgrasp train` spent 17 % of its time there (`__expm1f` 11 %,
//! `__tanhf` 6 %), more than any part of the physics. This op evaluates a rational minimax
//! approximation instead, branch-free, which the compiler turns into SIMD code; its coefficients
//! are the published ones of Eigen's `ptanh_float` (error within a few ulp on [-7.9, 7.9], where
//! tanh is clamped: beyond it tanh differs from ±1 by less than 3e-7).

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor};

const CLAMP: f32 = 7.905_311;
const ALPHA: [f32; 7] = [
    4.893_524_6e-3,
    6.372_619_3e-4,
    1.485_722_4e-5,
    5.122_297e-8,
    -8.604_672e-11,
    2.000_188e-13,
    -2.760_768_5e-16,
];
const BETA: [f32; 4] = [4.893_525e-3, 2.268_434_6e-3, 1.185_347e-4, 1.198_258_4e-6];

/// tanh of one value (NaN stays NaN).
#[inline]
pub fn tanh(x: f32) -> f32 {
    let x = x.clamp(-CLAMP, CLAMP);
    let x2 = x * x;
    let mut p = ALPHA[6];
    for a in ALPHA[..6].iter().rev() {
        p = p * x2 + a;
    }
    let mut q = BETA[3];
    for b in BETA[..3].iter().rev() {
        q = q * x2 + b;
    }
    x * p / q
}

/// [`tanh`] of every value, in place. Compiled a second time for AVX and chosen at run time
/// where the CPU has it: the same operations 8 lanes wide instead of SSE's 4 (the division
/// dominates), so the same results. The hidden layers' tanh was 15 % of a written-out PPO
/// update on SSE; with AVX the `ppo_timing` example takes 600-630 ms of CPU for 6 iterations
/// instead of 650-680.
pub fn tanh_in_place(values: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX.
        return unsafe { tanh_in_place_avx(values) };
    }
    values.iter_mut().for_each(|v| *v = tanh(*v));
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn tanh_in_place_avx(values: &mut [f32]) {
    values.iter_mut().for_each(|v| *v = tanh(*v));
}

/// `x.tanh()`, with gradients (1 − tanh²), through [`tanh`] on f32 CPU tensors.
pub fn tanh_tensor(x: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op1(FastTanh)
}

struct FastTanh;

impl CustomOp1 for FastTanh {
    fn name(&self) -> &'static str {
        "fast-tanh"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let CpuStorage::F32(values) = storage else {
            return Err(candle_core::Error::Msg(
                "fast tanh takes f32 tensors".into(),
            ));
        };
        let Some((start, end)) = layout.contiguous_offsets() else {
            return Err(candle_core::Error::Msg(
                "fast tanh takes contiguous tensors (tanh_tensor makes them so)".into(),
            ));
        };
        let mut out = values[start..end].to_vec();
        tanh_in_place(&mut out);
        Ok((CpuStorage::F32(out), layout.shape().clone()))
    }

    fn bwd(&self, _arg: &Tensor, res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let slope = res.sqr()?.affine(-1.0, 1.0)?;
        Ok(Some(grad_res.mul(&slope)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn matches_libm_tanh_everywhere() {
        let mut worst = 0.0f64;
        let mut x = -12.0f32;
        while x <= 12.0 {
            let err = (tanh(x) as f64 - (x as f64).tanh()).abs();
            worst = worst.max(err);
            x += 1e-3;
        }
        assert!(worst < 4e-7, "worst absolute error {worst}");
        assert_eq!(tanh(0.0), 0.0);
        assert!(tanh(f32::NAN).is_nan());
        assert_eq!(tanh(1e30), tanh(CLAMP));
        assert_eq!(tanh(-3.0), -tanh(3.0));
        // The slice version (AVX where the CPU has it) gives the same bits.
        let xs: Vec<f32> = (0..1001).map(|i| (i as f32 - 500.0) / 37.0).collect();
        let mut ys = xs.clone();
        tanh_in_place(&mut ys);
        for (x, y) in xs.iter().zip(&ys) {
            assert_eq!(tanh(*x).to_bits(), y.to_bits(), "tanh({x})");
        }
    }

    #[test]
    fn gradients_match_candles_tanh() {
        let device = Device::Cpu;
        let values: Vec<f32> = (0..64).map(|i| (i as f32 - 32.0) / 7.0).collect();
        let x = Var::from_vec(values, (8, 8), &device).unwrap();
        let ours = tanh_tensor(x.as_tensor()).unwrap();
        let reference = x.as_tensor().tanh().unwrap();
        let diff = (&ours - &reference)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap();
        assert!(diff.to_scalar::<f32>().unwrap() < 4e-7);
        let g_ours = ours.sum_all().unwrap().backward().unwrap();
        let g_ref = reference.sum_all().unwrap().backward().unwrap();
        let (a, b) = (g_ours.get(&x).unwrap(), g_ref.get(&x).unwrap());
        let diff = (a - b).unwrap().abs().unwrap().max_all().unwrap();
        assert!(diff.to_scalar::<f32>().unwrap() < 1e-6);
        // A transposed (strided) input gives the transposed result.
        let t = tanh_tensor(&x.as_tensor().t().unwrap()).unwrap();
        let diff = (t.t().unwrap() - &ours)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap();
        assert_eq!(diff.to_scalar::<f32>().unwrap(), 0.0);
    }
}
