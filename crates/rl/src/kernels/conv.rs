//! 2-D convolutions over channel-last (NHWC) images, forward and backward, as matrix products
//! over the column matrix (one row per output pixel: the patch under it): the image encoders
//! of pixel policies.
//!
//! Layout: an image batch is `batch × height × width × channels` (what the cameras give); a
//! filter bank is `filters × kernel × kernel × channels`, so that one row of the column matrix
//! meets one filter row, and the output comes out channel-last again.
//!
//! Two ways, by the product kernel ([`ProductKernel`]): gemm's writes the column matrix out
//! (im2col) and multiplies it; the AVX2 kernel reads the patches in place through an index
//! table (an implicit GEMM) and adds the input's gradient straight into the image (col2im in
//! the product), so that NatureCNN's first layer never writes its 20 MB column matrix.
//!
//! Why by hand: candle's CPU backward of `conv2d` computes the input's gradient with a direct
//! `conv_transpose2d` loop even for the first layer, whose input is data; on NatureCNN's shapes
//! the written-out pass is the measured figure in docs/benchmarks.md ("CNN step").

use crate::kernels::dense::{add_bias, bias_grad, linear_backward, linear_forward};
use crate::kernels::product::{
    Gathered, IndexTable, ProductKernel, gathered_times, times_gathered, times_scatter_add,
};

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

/// A layer's buffers, kept between its forward and backward passes and from batch to batch:
/// the column matrix (gemm's way) or the table that reads the patches in place (the AVX2
/// kernel's).
#[derive(Default)]
pub struct ConvScratch {
    cols: Vec<f32>,
    d_cols: Vec<f32>,
    table: Option<(ConvShape, usize, IndexTable)>,
}

impl ConvScratch {
    /// The patch table of `batch` images of `shape`, made once.
    fn table(&mut self, shape: &ConvShape, batch: usize) -> &IndexTable {
        if !matches!(&self.table, Some((s, b, _)) if s == shape && *b == batch) {
            self.table = Some((*shape, batch, patch_table(shape, batch)));
        }
        &self.table.as_ref().expect("made above").2
    }
}

/// The column matrix of `batch` images as an index table into the images: row `r` (image `b`,
/// output pixel `(y, x)`) starts at the patch's corner, column `(ky, kx, c)` lies `ky` input
/// rows and `kx · channels + c` values on; each kernel row is one stretch.
pub fn patch_table(shape: &ConvShape, batch: usize) -> IndexTable {
    let (oh, ow) = (shape.out_height(), shape.out_width());
    let (k, s, c) = (shape.kernel, shape.stride, shape.channels);
    let row_len = shape.width * c;
    let mut row_start = Vec::with_capacity(batch * oh * ow);
    for b in 0..batch {
        for y in 0..oh {
            for x in 0..ow {
                row_start.push(b * shape.in_len() + y * s * row_len + x * s * c);
            }
        }
    }
    let span = k * c;
    let col_offset = (0..shape.patch())
        .map(|q| (q / span) * row_len + q % span)
        .collect();
    IndexTable::new(row_start, col_offset, span).expect("a patch's kernel rows are stretches")
}

/// The layer on `kernel`'s products: `out (batch · out_pixels × filters) = patches(input) ·
/// weightᵀ + bias`, channel-last.
#[allow(clippy::too_many_arguments)]
pub fn layer_forward(
    kernel: ProductKernel,
    shape: &ConvShape,
    input: &[f32],
    batch: usize,
    weight: &[f32],
    bias: &[f32],
    out: &mut [f32],
    scratch: &mut ConvScratch,
) {
    let (patch, filters) = (shape.patch(), shape.filters);
    let out = &mut out[..batch * shape.out_len()];
    if kernel == ProductKernel::Avx2 {
        let table = scratch.table(shape, batch);
        let patches = Gathered {
            values: &input[..batch * shape.in_len()],
            table,
        };
        gathered_times(out, patches, weight, (1, patch), filters);
        add_bias(out, &bias[..filters]);
    } else {
        im2col(shape, input, batch, |v| v, &mut scratch.cols);
        forward(shape, &scratch.cols, weight, bias, out);
    }
}

/// The layer's gradients from its output's (`d_out`): `d_weight` and `d_bias` overwritten,
/// and with `d_input` the input's (overwritten). `input` and `scratch` are the forward pass's.
#[allow(clippy::too_many_arguments)]
pub fn layer_backward(
    kernel: ProductKernel,
    shape: &ConvShape,
    input: &[f32],
    batch: usize,
    weight: &[f32],
    d_out: &[f32],
    d_weight: &mut [f32],
    d_bias: &mut [f32],
    d_input: Option<&mut [f32]>,
    scratch: &mut ConvScratch,
) {
    let (patch, filters) = (shape.patch(), shape.filters);
    let d_out = &d_out[..batch * shape.out_len()];
    if kernel == ProductKernel::Avx2 {
        let table = scratch.table(shape, batch);
        let patches = Gathered {
            values: &input[..batch * shape.in_len()],
            table,
        };
        times_gathered(d_weight, filters, d_out, (1, filters), patches);
        bias_grad(d_out, &mut d_bias[..filters]);
        if let Some(d_input) = d_input {
            let d_input = &mut d_input[..batch * shape.in_len()];
            d_input.fill(0.0);
            times_scatter_add(
                d_input,
                table,
                d_out,
                (filters, 1),
                weight,
                (patch, 1),
                filters,
            );
        }
    } else {
        match d_input {
            None => backward(shape, &scratch.cols, weight, d_out, d_weight, d_bias, None),
            Some(d_input) => {
                scratch.d_cols.resize(scratch.cols.len(), 0.0);
                let d_cols = Some(&mut scratch.d_cols[..]);
                backward(
                    shape,
                    &scratch.cols,
                    weight,
                    d_out,
                    d_weight,
                    d_bias,
                    d_cols,
                );
                col2im(shape, &scratch.d_cols, batch, d_input);
            }
        }
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

    /// candle's NCHW convolution and its autograd as the reference, for both product kernels:
    /// a small odd layer, and one whose kernel rows are 32 values (the AVX2 kernel's
    /// 16-column tiles then lie in one stretch) with filters that fill no tile.
    #[test]
    fn forward_and_backward_match_candles_convolution() {
        let small = ConvShape {
            height: 11,
            width: 9,
            channels: 3,
            filters: 4,
            kernel: 3,
            stride: 2,
        };
        let wide = ConvShape {
            height: 10,
            width: 12,
            channels: 16,
            filters: 20,
            kernel: 2,
            stride: 2,
        };
        for shape in [small, wide] {
            for kernel in [ProductKernel::Gemm, ProductKernel::Avx2] {
                matches_candle(kernel, shape);
            }
        }
    }

    fn matches_candle(kernel: ProductKernel, shape: ConvShape) {
        let dev = Device::Cpu;
        let batch = 2;
        let input: Vec<f32> = (0..batch * shape.in_len())
            .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
            .collect();
        let weight: Vec<f32> = (0..shape.weight_len())
            .map(|i| ((i * 13 % 29) as f32 / 14.0) - 1.0)
            .collect();
        let bias: Vec<f32> = (0..shape.filters).map(|i| 0.1 * i as f32 - 0.2).collect();
        let d_out: Vec<f32> = (0..batch * shape.out_len())
            .map(|i| ((i * 7 % 17) as f32 / 8.0) - 1.0)
            .collect();

        let mut scratch = ConvScratch::default();
        let mut out = vec![0.0; batch * shape.out_len()];
        layer_forward(
            kernel,
            &shape,
            &input,
            batch,
            &weight,
            &bias,
            &mut out,
            &mut scratch,
        );
        let (mut dw, mut db) = (vec![0.0; shape.weight_len()], vec![0.0; shape.filters]);
        let mut d_input = vec![f32::NAN; input.len()];
        layer_backward(
            kernel,
            &shape,
            &input,
            batch,
            &weight,
            &d_out,
            &mut dw,
            &mut db,
            Some(&mut d_input),
            &mut scratch,
        );

        let (h, w, c, f, k) = (
            shape.height,
            shape.width,
            shape.channels,
            shape.filters,
            shape.kernel,
        );
        let (oh, ow) = (shape.out_height(), shape.out_width());
        // Channel-last values as a channel-first variable.
        let nchw = |values: &[f32], dims: (usize, usize, usize, usize)| {
            let t = Tensor::from_vec(values.to_vec(), dims, &dev).unwrap();
            Var::from_tensor(&t.permute((0, 3, 1, 2)).unwrap().contiguous().unwrap()).unwrap()
        };
        let x = nchw(&input, (batch, h, w, c));
        let kernel_var = nchw(&weight, (f, k, k, c));
        let b = Var::from_tensor(&Tensor::new(bias.as_slice(), &dev).unwrap()).unwrap();
        let y = x
            .as_tensor()
            .conv2d(kernel_var.as_tensor(), 0, shape.stride, 1, 1)
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
                    "{kernel:?} {shape:?} {what}[{i}]: {x} vs {y}"
                );
            }
        };
        close(&out, &nhwc(&y), "output");
        close(
            &dw,
            &nhwc(grads.get(kernel_var.as_tensor()).unwrap()),
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
