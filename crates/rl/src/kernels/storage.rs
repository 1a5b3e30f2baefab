//! Reading a tensor's values in place, without a copy.

use candle_core::Tensor;

/// The values of a contiguous f32 tensor, read in place.
pub fn with_f32_slice<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    let candle_core::Storage::Cpu(cpu) = &*storage else {
        candle_core::bail!("f32 CPU tensors only");
    };
    let data = cpu.as_slice::<f32>()?;
    let (start, end) = layout
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::Msg("non-contiguous tensor".into()))?;
    Ok(f(&data[start..end]))
}
