//! 2-D convolutions over channel-last (NHWC) images, forward and backward, as im2col and one
//! matrix product each: the image encoders of pixel policies.
//!
//! Layout: an image batch is `batch × height × width × channels` (what the cameras give, so
//! the `u8` images go into the first layer without a float copy of their own); a filter bank is
//! `filters × kernel × kernel × channels`, so that one row of the column matrix (the patch under
//! one output pixel) meets one filter row, and the output comes out channel-last again.
//!
//! Why by hand: candle's CPU backward of `conv2d` computes the input's gradient with a direct
//! `conv_transpose2d` loop even for the first layer, whose input is data; on NatureCNN's shapes
//! the written-out pass is the measured figure in docs/benchmarks.md ("CNN step").

use crate::kernels::dense::{linear_backward, linear_forward};

/// One convolution layer's geometry (valid padding, square kernel and stride).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvShape {
    /// Input rows.
    pub height: usize,
    /// Input columns.
    pub width: usize,
    /// Input channels.
    pub channels: usize,
    /// Output channels.
    pub filters: usize,
    /// Kernel side (pixels).
    pub kernel: usize,
    /// Stride (pixels).
    pub stride: usize,
}

impl ConvShape {
    /// Output rows (the input must be at least a kernel high).
    pub fn out_height(&self) -> usize {
        (self.height - self.kernel) / self.stride + 1
    }

    /// Output columns.
    pub fn out_width(&self) -> usize {
        (self.width - self.kernel) / self.stride + 1
    }

    /// Values of one patch (a row of the column matrix, a filter).
    pub fn patch(&self) -> usize {
        self.kernel * self.kernel * self.channels
    }

    /// Output pixels of one image.
    pub fn out_pixels(&self) -> usize {
        self.out_height() * self.out_width()
    }

    /// Values of one input image.
    pub fn in_len(&self) -> usize {
        self.height * self.width * self.channels
    }

    /// Values of one output image.
    pub fn out_len(&self) -> usize {
        self.out_pixels() * self.filters
    }

    /// Values of the filter bank.
    pub fn weight_len(&self) -> usize {
        self.filters * self.patch()
    }
}

/// Writes the column matrix of `batch` images (`batch · out_pixels × patch`, one row per
/// output pixel), converting each input value with `value` (`u8` pixels scale to [0, 1]).
pub fn im2col<T: Copy>(
    shape: &ConvShape,
    input: &[T],
    batch: usize,
    value: impl Fn(T) -> f32,
    cols: &mut Vec<f32>,
) {
    let (oh, ow) = (shape.out_height(), shape.out_width());
    let (k, s, c) = (shape.kernel, shape.stride, shape.channels);
    let row_len = shape.width * c;
    let span = k * c;
    assert!(
        input.len() >= batch * shape.in_len(),
        "im2col input too short"
    );
    cols.clear();
    cols.reserve(batch * oh * ow * shape.patch());
    for image in input.chunks_exact(shape.in_len()).take(batch) {
        for oy in 0..oh {
            for ox in 0..ow {
                let corner = oy * s * row_len + ox * s * c;
                for ky in 0..k {
                    let start = corner + ky * row_len;
                    cols.extend(image[start..start + span].iter().map(|&v| value(v)));
                }
            }
        }
    }
}

/// Adds each row of the column matrix's gradient back onto the input pixels it was read from
/// (`d_input`, `batch × in_len`, overwritten).
pub fn col2im(shape: &ConvShape, d_cols: &[f32], batch: usize, d_input: &mut [f32]) {
    let (oh, ow) = (shape.out_height(), shape.out_width());
    let (k, s, c) = (shape.kernel, shape.stride, shape.channels);
    let row_len = shape.width * c;
    let span = k * c;
    let patch = shape.patch();
    d_input[..batch * shape.in_len()].fill(0.0);
    let images = d_input.chunks_exact_mut(shape.in_len()).take(batch);
    for (image, d_image_cols) in images.zip(d_cols.chunks_exact(oh * ow * patch)) {
        for (p, row) in d_image_cols.chunks_exact(patch).enumerate() {
            let (oy, ox) = (p / ow, p % ow);
            let corner = oy * s * row_len + ox * s * c;
            for (ky, part) in row.chunks_exact(span).enumerate() {
                let start = corner + ky * row_len;
                for (d, g) in image[start..start + span].iter_mut().zip(part) {
                    *d += g;
                }
            }
        }
    }
}

/// `out (rows × filters) = cols · weightᵀ + bias`: the layer's output, channel-last.
pub fn forward(shape: &ConvShape, cols: &[f32], weight: &[f32], bias: &[f32], out: &mut [f32]) {
    linear_forward((shape.patch(), shape.filters), cols, weight, bias, out);
}

/// The layer's gradients from its output's (`d_out`, `rows × filters`): `d_weight = d_outᵀ ·
/// cols`, `d_bias` the column sums of `d_out`, and with `d_cols` the column matrix's
/// (`d_out · weight`), which [`col2im`] turns into the input's.
pub fn backward(
    shape: &ConvShape,
    cols: &[f32],
    weight: &[f32],
    d_out: &[f32],
    d_weight: &mut [f32],
    d_bias: &mut [f32],
    d_cols: Option<&mut [f32]>,
) {
    let dims = (shape.patch(), shape.filters);
    linear_backward(dims, cols, weight, d_out, d_weight, d_bias, d_cols);
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor, Var};

    /// candle's NCHW convolution and its autograd as the reference.
    #[test]
    fn forward_and_backward_match_candles_convolution() {
        let dev = Device::Cpu;
        let shape = ConvShape {
            height: 11,
            width: 9,
            channels: 3,
            filters: 4,
            kernel: 3,
            stride: 2,
        };
        let batch = 2;
        let input: Vec<f32> = (0..batch * shape.in_len())
            .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
            .collect();
        let weight: Vec<f32> = (0..shape.weight_len())
            .map(|i| ((i * 13 % 29) as f32 / 14.0) - 1.0)
            .collect();
        let bias = [0.1f32, -0.2, 0.3, 0.0];
        let d_out: Vec<f32> = (0..batch * shape.out_len())
            .map(|i| ((i * 7 % 17) as f32 / 8.0) - 1.0)
            .collect();

        let mut cols = Vec::new();
        im2col(&shape, &input, batch, |v| v, &mut cols);
        let mut out = vec![0.0; batch * shape.out_len()];
        forward(&shape, &cols, &weight, &bias, &mut out);
        let (mut dw, mut db) = (vec![0.0; shape.weight_len()], vec![0.0; 4]);
        let mut d_cols = vec![0.0; cols.len()];
        backward(
            &shape,
            &cols,
            &weight,
            &d_out,
            &mut dw,
            &mut db,
            Some(&mut d_cols),
        );
        let mut d_input = vec![0.0; input.len()];
        col2im(&shape, &d_cols, batch, &mut d_input);

        let (h, w, c, f, k) = (shape.height, shape.width, 3, 4, 3);
        let (oh, ow) = (shape.out_height(), shape.out_width());
        // Channel-last values as a channel-first variable.
        let nchw = |values: &[f32], dims: (usize, usize, usize, usize)| {
            let t = Tensor::from_vec(values.to_vec(), dims, &dev).unwrap();
            Var::from_tensor(&t.permute((0, 3, 1, 2)).unwrap().contiguous().unwrap()).unwrap()
        };
        let x = nchw(&input, (batch, h, w, c));
        let kernel = nchw(&weight, (f, k, k, c));
        let b = Var::from_tensor(&Tensor::new(&bias, &dev).unwrap()).unwrap();
        let y = x
            .as_tensor()
            .conv2d(kernel.as_tensor(), 0, 2, 1, 1)
            .unwrap()
            .broadcast_add(&b.as_tensor().reshape((1, f, 1, 1)).unwrap())
            .unwrap();
        let g = Tensor::from_vec(d_out.clone(), (batch, oh, ow, f), &dev)
            .unwrap()
            .permute((0, 3, 1, 2))
            .unwrap();
        let grads = (y.clone() * g)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let nhwc = |t: &Tensor| -> Vec<f32> {
            t.permute((0, 2, 3, 1))
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        let close = |a: &[f32], b: &[f32], what: &str| {
            assert_eq!(a.len(), b.len(), "{what}");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-4 * (1.0 + y.abs()),
                    "{what}[{i}]: {x} vs {y}"
                );
            }
        };
        close(&out, &nhwc(&y), "output");
        close(
            &dw,
            &nhwc(grads.get(kernel.as_tensor()).unwrap()),
            "d_weight",
        );
        close(
            &db,
            &grads.get(b.as_tensor()).unwrap().to_vec1::<f32>().unwrap(),
            "d_bias",
        );
        close(
            &d_input,
            &nhwc(grads.get(x.as_tensor()).unwrap()),
            "d_input",
        );
    }

    #[test]
    fn u8_pixels_enter_as_values_in_zero_to_one() {
        let shape = ConvShape {
            height: 2,
            width: 2,
            channels: 1,
            filters: 1,
            kernel: 2,
            stride: 1,
        };
        let mut cols = Vec::new();
        im2col(
            &shape,
            &[0u8, 51, 102, 255],
            1,
            |v| v as f32 / 255.0,
            &mut cols,
        );
        assert_eq!(cols, vec![0.0, 0.2, 0.4, 1.0]);
    }
}
