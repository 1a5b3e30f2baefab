//! A linear layer and ReLU on plain f32 slices, forward and backward, with reused buffers: the
//! layers of the pixel policies' networks ([`crate::policies::pixel_actor`]), whose convolutions
//! ([`crate::kernels::conv`]) are linear layers over image patches.

use crate::kernels::product::product;

/// `out (rows × out_dim) = x (rows × in_dim) · weightᵀ + bias`, `weight` `out_dim × in_dim`.
pub fn linear_forward(
    (in_dim, out_dim): (usize, usize),
    x: &[f32],
    weight: &[f32],
    bias: &[f32],
    out: &mut [f32],
) {
    let rows = x.len() / in_dim;
    product(
        (rows, out_dim, in_dim),
        out,
        x,
        (in_dim, 1),
        weight,
        (1, in_dim),
    );
    add_bias(&mut out[..rows * out_dim], &bias[..out_dim]);
}

/// Adds `bias` to each row of `out` (rows of `bias.len()` values).
pub fn add_bias(out: &mut [f32], bias: &[f32]) {
    for row in out.chunks_exact_mut(bias.len()) {
        for (o, b) in row.iter_mut().zip(bias) {
            *o += b;
        }
    }
}

/// The gradients of [`linear_forward`] from its output's (`d_out`, `rows × out_dim`):
/// `d_weight = d_outᵀ · x` and `d_bias` (the column sums of `d_out`) are overwritten; with
/// `d_x`, the input's (`d_out · weight`).
pub fn linear_backward(
    (in_dim, out_dim): (usize, usize),
    x: &[f32],
    weight: &[f32],
    d_out: &[f32],
    d_weight: &mut [f32],
    d_bias: &mut [f32],
    d_x: Option<&mut [f32]>,
) {
    let rows = x.len() / in_dim;
    product(
        (out_dim, in_dim, rows),
        d_weight,
        d_out,
        (1, out_dim),
        x,
        (in_dim, 1),
    );
    bias_grad(&d_out[..rows * out_dim], &mut d_bias[..out_dim]);
    if let Some(d_x) = d_x {
        product(
            (rows, in_dim, out_dim),
            d_x,
            d_out,
            (out_dim, 1),
            weight,
            (in_dim, 1),
        );
    }
}

/// The bias's gradient (overwritten): the column sums of `d_out` (rows of `d_bias.len()`).
pub fn bias_grad(d_out: &[f32], d_bias: &mut [f32]) {
    d_bias.fill(0.0);
    for row in d_out.chunks_exact(d_bias.len()) {
        for (d, g) in d_bias.iter_mut().zip(row) {
            *d += g;
        }
    }
}

/// ReLU in place.
pub fn relu(values: &mut [f32]) {
    for v in values {
        *v = v.max(0.0);
    }
}

/// Zeroes the gradient where ReLU's output (`out`) is zero.
pub fn relu_backward(out: &[f32], grad: &mut [f32]) {
    for (g, o) in grad.iter_mut().zip(out) {
        if *o <= 0.0 {
            *g = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gradients_are_the_derivatives_of_the_output() {
        // out = x·Wᵀ + b for 2 rows, 3 → 2; loss = Σ out ⊙ g.
        let x = [1.0f32, 2.0, -1.0, 0.5, 0.0, 3.0];
        let w = [0.1f32, -0.2, 0.3, 0.4, 0.5, -0.6];
        let b = [0.01f32, -0.02];
        let mut out = [0.0; 4];
        linear_forward((3, 2), &x, &w, &b, &mut out);
        assert!((out[0] - (0.1 - 0.4 - 0.3 + 0.01)).abs() < 1e-6);
        assert!((out[3] - (0.2 - 1.8 - 0.02)).abs() < 1e-6);
        let g = [1.0f32, -1.0, 0.5, 2.0];
        let (mut dw, mut db, mut dx) = ([0.0; 6], [0.0; 2], [0.0; 6]);
        linear_backward((3, 2), &x, &w, &g, &mut dw, &mut db, Some(&mut dx));
        let loss = |x: &[f32], w: &[f32]| {
            let mut o = [0.0; 4];
            linear_forward((3, 2), x, w, &b, &mut o);
            o.iter().zip(&g).map(|(a, b)| a * b).sum::<f32>()
        };
        let eps = 1e-2;
        for i in 0..6 {
            let (mut wp, mut wm) = (w, w);
            wp[i] += eps;
            wm[i] -= eps;
            let numeric = (loss(&x, &wp) - loss(&x, &wm)) / (2.0 * eps);
            assert!((numeric - dw[i]).abs() < 1e-3, "d_weight[{i}]");
            let (mut xp, mut xm) = (x, x);
            xp[i] += eps;
            xm[i] -= eps;
            let numeric = (loss(&xp, &w) - loss(&xm, &w)) / (2.0 * eps);
            assert!((numeric - dx[i]).abs() < 1e-3, "d_x[{i}]");
        }
        assert_eq!(db, [1.5, 1.0]);
        let mut v = [-1.0f32, 2.0];
        relu(&mut v);
        let mut grad = [5.0f32, 5.0];
        relu_backward(&v, &mut grad);
        assert_eq!((v, grad), ([0.0, 2.0], [0.0, 5.0]));
    }
}
