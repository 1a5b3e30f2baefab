//! Two layer ops as single candle ops, for the networks' hot path: the bias add of a linear
//! layer and ReLU. Each computes exactly what candle's ops computed (same f32 operations in the
//! same order, so training is unchanged bit for bit), with less work around it:
//! - bias add: candle's `broadcast_add` backward sums the gradient over the batch with a
//!   divide and a modulo per element (`sum_keepdim(0)`, 10.6 % of a SAC gradient step in
//!   perf); here it is a row-by-row sum the compiler vectorises;
//! - ReLU: candle's backward builds a mask with a comparison op and a dtype conversion, then
//!   multiplies (three ops, 7.5 % of a step); here it is one pass.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};

/// The contiguous f32 values of a storage.
fn values<'a>(storage: &'a CpuStorage, layout: &Layout, op: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(v) = storage else {
        candle_core::bail!("{op} takes f32 tensors");
    };
    let Some((start, end)) = layout.contiguous_offsets() else {
        candle_core::bail!("{op} takes contiguous tensors");
    };
    Ok(&v[start..end])
}

/// `x + bias` for `x` of shape `batch × n` and `bias` of shape `n` (a linear layer's bias).
pub fn add_bias(x: &Tensor, bias: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&bias.contiguous()?, AddBias)
}

struct AddBias;

impl CustomOp2 for AddBias {
    fn name(&self) -> &'static str {
        "add-bias"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (x, bias) = (values(s1, l1, "add_bias")?, values(s2, l2, "add_bias")?);
        let (_, n) = l1.shape().dims2()?;
        if l2.shape().dims() != [n] {
            candle_core::bail!(
                "add_bias: bias of shape {:?} for rows of {n}",
                l2.shape().dims()
            );
        }
        let mut out = Vec::with_capacity(x.len());
        for row in x.chunks_exact(n) {
            out.extend(row.iter().zip(bias).map(|(a, b)| a + b));
        }
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }

    fn bwd(
        &self,
        _x: &Tensor,
        bias: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        let (_, n) = grad.dims2()?;
        // Column sums, rows in order (the order candle's reduction adds them in).
        let mut sums = vec![0.0f32; n];
        crate::kernels::storage::with_f32_slice(&grad, |g| {
            for row in g.chunks_exact(n) {
                for (s, g) in sums.iter_mut().zip(row) {
                    *s += g;
                }
            }
        })?;
        let bias_grad = Tensor::from_vec(sums, n, bias.device())?;
        Ok((Some(grad), Some(bias_grad)))
    }
}

/// `max(x, 0)`, with the gradient passed where `x ≥ 0` (candle's convention).
pub fn relu(x: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op1(Relu)
}

struct Relu;

impl CustomOp1 for Relu {
    fn name(&self) -> &'static str {
        "relu"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = values(storage, layout, "relu")?;
        let out = x.iter().map(|v| v.max(0.0)).collect();
        Ok((CpuStorage::F32(out), layout.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let out: Vec<f32> = crate::kernels::storage::with_f32_slice(arg, |x| {
            crate::kernels::storage::with_f32_slice(grad, |g| {
                x.iter()
                    .zip(g)
                    .map(|(&x, &g)| g * if x >= 0.0 { 1.0 } else { 0.0 })
                    .collect()
            })
        })??;
        Ok(Some(Tensor::from_vec(out, arg.shape(), arg.device())?))
    }
}

/// Polyak averaging in place, `target ← (1 − τ) target + τ online`, as candle's
/// `target * (1 − τ) + online * τ` computed it (without the three temporary tensors).
pub fn polyak_update(target: &candle_core::Var, online: &Tensor, tau: f64) -> Result<()> {
    let online = online.contiguous()?;
    let (storage, layout) = online.storage_and_layout();
    let candle_core::Storage::Cpu(cpu) = &*storage else {
        candle_core::bail!("polyak_update runs on the CPU");
    };
    let op = Polyak {
        online: values(cpu, layout, "polyak_update")?,
        keep: (1.0 - tau) as f32,
        take: tau as f32,
    };
    target.as_tensor().inplace_op1(&op)
}

struct Polyak<'a> {
    online: &'a [f32],
    keep: f32,
    take: f32,
}

impl candle_core::InplaceOp1 for Polyak<'_> {
    fn name(&self) -> &'static str {
        "polyak"
    }

    fn cpu_fwd(&self, storage: &mut CpuStorage, layout: &Layout) -> Result<()> {
        let CpuStorage::F32(v) = storage else {
            candle_core::bail!("polyak_update takes f32 variables");
        };
        let Some((start, end)) = layout.contiguous_offsets() else {
            candle_core::bail!("polyak_update takes contiguous variables");
        };
        let target = &mut v[start..end];
        if target.len() != self.online.len() {
            candle_core::bail!(
                "polyak_update: {} values for {}",
                self.online.len(),
                target.len()
            );
        }
        // `x * c + 0.0` is candle's affine op (kept: it turns −0 into +0).
        for (t, &o) in target.iter_mut().zip(self.online) {
            *t = (*t * self.keep + 0.0) + (o * self.take + 0.0);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn bits(t: &Tensor) -> Vec<u32> {
        let v: Vec<f32> = t.flatten_all().unwrap().to_vec1().unwrap();
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn values_and_gradients_match_candles_ops_bit_for_bit() {
        let dev = Device::Cpu;
        let xs: Vec<f32> = (0..96)
            .map(|i| ((i * 37 % 41) as f32 - 20.0) / 7.3)
            .collect();
        let x = Var::from_vec(xs, (12, 8), &dev).unwrap();
        let b = Var::from_vec((0..8).map(|i| i as f32 / 3.0 - 1.0).collect(), 8, &dev).unwrap();
        let w = Tensor::from_vec(
            (0..96).map(|i| (i % 7) as f32 - 2.5).collect(),
            (12, 8),
            &dev,
        )
        .unwrap();
        let ours = relu(&add_bias(x.as_tensor(), b.as_tensor()).unwrap()).unwrap();
        let theirs = x
            .as_tensor()
            .broadcast_add(b.as_tensor())
            .unwrap()
            .relu()
            .unwrap();
        assert_eq!(bits(&ours), bits(&theirs));
        // Zero crossings included: some pre-activations are exactly 0.
        let g_ours = (ours * &w).unwrap().sum_all().unwrap().backward().unwrap();
        let g_theirs = (theirs * &w)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        for v in [&x, &b] {
            assert_eq!(bits(g_ours.get(v).unwrap()), bits(g_theirs.get(v).unwrap()));
        }
        assert!(
            add_bias(
                x.as_tensor(),
                &Tensor::zeros(7, candle_core::DType::F32, &dev).unwrap()
            )
            .is_err()
        );
    }
}
