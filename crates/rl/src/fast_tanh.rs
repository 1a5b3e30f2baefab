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
        let out: Vec<f32> = values[start..end].iter().map(|&v| tanh(v)).collect();
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
