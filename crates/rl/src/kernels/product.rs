//! The networks' matrix products: an AVX2 + FMA kernel of our own for the MLPs
//! ([`crate::kernels::mlp`]) on every CPU with AVX2 and FMA, and for the pixel policies' layers
//! ([`crate::kernels::dense`], [`crate::kernels::conv`]) on CPUs without AVX-512; gemm's kernels
//! elsewhere (called as candle's CPU backend calls them).
//!
//! Why by hand: on an AVX2-only CPU the NatureCNN encoder's step (eleven products, 3 GFLOP a
//! batch of 64) is where the camera policy's training spends its time, and gemm's AVX2 kernel
//! ran these shapes at 31–83 GFLOP/s against the FMA units' 87–100 (AMD EPYC, Zen 3), slowest
//! on the first layer, whose 20 MB column matrix im2col writes and both its products read back.
//! No crate multiplies through index tables. Here:
//! - a 6 × 16 tile of the result stays in twelve registers, `b` is packed into panels of 16
//!   columns, `a` into panels of 6 rows, or read in place a tile of rows at a time where the
//!   result is narrow (≤ 128 columns: the convolutions' forward passes);
//! - an operand can be read through an [`IndexTable`] (a convolution's patches, in place in
//!   the image: an implicit GEMM) and a result added through one (col2im inside the product).
//!
//! NatureCNN's step took 0.89 of gemm's AVX2 time on an AMD Zen 3 and 0.81–0.90 of its
//! AVX-512 time on a Zen 4 (`fairgrasp bench cnn`; docs/benchmarks.md, "Without AVX-512"). The
//! image layers keep gemm's AVX-512 kernel where the CPU has it: on an Intel Xeon it ran these
//! products at ~71 GFLOP/s, above the 69–70 any AVX2 kernel can reach there. The MLPs take
//! ours everywhere: on their small products gemm's AVX-512 kernel was no faster (the default
//! training 0.82–0.93 of its time with ours on the Zen 4), and one order of sums lets a seed
//! train the same PPO weights on every host.

use gemm::{Parallelism, gemm};
use std::sync::OnceLock;

/// Which kernel multiplies: `FAIRGRASP_IMAGE_KERNEL=avx2` or `=gemm` chooses (read once; the
/// CLI refuses other values through [`ProductKernel::from_env`]), else the CPU does (see the
/// module's documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProductKernel {
    /// gemm's kernel for this CPU (AVX-512 where present).
    Gemm,
    /// This module's AVX2 + FMA kernel (gemm's where the CPU lacks those).
    Avx2,
}

impl ProductKernel {
    /// The kernel this process uses (the CPU's choice where the variable is invalid).
    pub fn current() -> Self {
        static KERNEL: OnceLock<ProductKernel> = OnceLock::new();
        *KERNEL.get_or_init(|| Self::from_env().unwrap_or_else(|_| Self::choose(None)))
    }

    /// The kernel `FAIRGRASP_IMAGE_KERNEL` asks for on this CPU (unset or empty: the CPU's
    /// choice), or an error that names a value other than `avx2` or `gemm`, or `avx2` on a CPU
    /// without AVX2 and FMA.
    pub fn from_env() -> Result<Self, String> {
        let value = std::env::var("FAIRGRASP_IMAGE_KERNEL").ok();
        match value.as_deref() {
            None | Some("") => Ok(Self::choose(None)),
            Some("gemm") => Ok(Self::Gemm),
            Some("avx2") if avx2::available() => Ok(Self::Avx2),
            Some("avx2") => Err("FAIRGRASP_IMAGE_KERNEL=avx2: this CPU lacks AVX2 and FMA".into()),
            Some(other) => Err(format!(
                "FAIRGRASP_IMAGE_KERNEL={other}: expected avx2 or gemm (or unset: the CPU chooses)"
            )),
        }
    }

    /// The kernel for a `FAIRGRASP_IMAGE_KERNEL` value on this CPU: `gemm`, `avx2` where the
    /// CPU has AVX2 and FMA, else ours where the CPU has those and lacks AVX-512.
    pub fn choose(forced: Option<&str>) -> Self {
        let has_avx2 = avx2::available();
        match forced {
            Some("gemm") => Self::Gemm,
            Some("avx2") if has_avx2 => Self::Avx2,
            _ if has_avx2 && !has_avx512() => Self::Avx2,
            _ => Self::Gemm,
        }
    }

    /// The name `FAIRGRASP_IMAGE_KERNEL` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Gemm => "gemm",
            Self::Avx2 => "avx2",
        }
    }
}

/// The thread count candle's CPU backend gives `gemm` (`RAYON_NUM_THREADS`, else the physical
/// cores), read once per process. candle reads it on every call: without the variable that
/// parses /proc/cpuinfo (460 times a second in the default training when its products ran on
/// gemm, 10 % of its time in the kernel); with it (`fairgrasp` sets it) the environment, which
/// still cost that training 4.5 % of its wall time (AMD EPYC 2-vCPU host, 5 alternated pairs).
fn gemm_threads() -> usize {
    static THREADS: OnceLock<usize> = OnceLock::new();
    *THREADS.get_or_init(candle_core::utils::get_num_threads)
}

/// `dst (m × n, row-major) = lhs (m × k) · rhs (k × n)` on gemm, called as candle's CPU
/// `matmul` calls it, so that the sums run in its order.
///
/// # Safety
/// The strided operands and `dst` lie within their buffers ([`product_with`] checks them).
unsafe fn gemm_product(
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[f32],
    (rhs_rs, rhs_cs): (usize, usize),
) {
    let threads = gemm_threads();
    let parallelism = if threads > 1 {
        Parallelism::Rayon(threads)
    } else {
        Parallelism::None
    };
    // SAFETY: the caller vouches for every access of the three strided matrices.
    unsafe {
        gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            false,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            rhs_cs as isize,
            rhs_rs as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        )
    }
}

fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `dst (m × n, row-major) = lhs (m × k) · rhs (k × n)`, the operands given by their (row,
/// column) strides.
pub fn product(
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    lhs: &[f32],
    lhs_strides: (usize, usize),
    rhs: &[f32],
    rhs_strides: (usize, usize),
) {
    product_with(
        ProductKernel::current(),
        (m, n, k),
        dst,
        lhs,
        lhs_strides,
        rhs,
        rhs_strides,
    );
}

/// [`product`] with the kernel chosen by the caller. [`ProductKernel::Avx2`] falls back to
/// gemm's kernel only where the CPU lacks AVX2 or FMA: its sums run in one order on every
/// other host, so the MLPs ([`crate::kernels::mlp`]) ask for it and a seed trains the same
/// weights on an AVX-512 host and an AVX2-only one.
pub fn product_with(
    kernel: ProductKernel,
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    lhs: &[f32],
    (lrs, lcs): (usize, usize),
    rhs: &[f32],
    (rrs, rcs): (usize, usize),
) {
    assert!(dst.len() >= m * n, "product: dst too short");
    assert!(lhs.len() >= reach(lrs, lcs, m, k), "product: lhs too short");
    assert!(rhs.len() >= reach(rrs, rcs, k, n), "product: rhs too short");
    if kernel == ProductKernel::Gemm || !avx2::available() {
        // SAFETY: the asserts above keep every access in bounds.
        unsafe { gemm_product((m, n, k), dst, lhs, (lrs, lcs), rhs, (rrs, rcs)) };
        return;
    }
    let (lhs, rhs) = (
        Operand::Matrix(lhs, (lrs, lcs)),
        Operand::Matrix(rhs, (rrs, rcs)),
    );
    avx2_product((m, n, k), lhs, rhs, dst, None);
}

/// Index tables that read a matrix out of a buffer without copying it: value (i, j) lies at
/// `row_start[i] + col_offset[j]`. `col_offset` runs in stretches of `run` consecutive
/// indices, each beginning at a multiple of `run` (im2col over a channel-last image: a stretch
/// is one kernel row of a patch).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct IndexTable {
    row_start: Vec<usize>,
    col_offset: Vec<usize>,
    run: usize,
    reach: usize,
}

impl IndexTable {
    /// The table, checked: `run` at least 1 and the stretches as described.
    pub fn new(row_start: Vec<usize>, col_offset: Vec<usize>, run: usize) -> Result<Self, String> {
        if run == 0 {
            return Err("index table: run must be at least 1".into());
        }
        for (j, &offset) in col_offset.iter().enumerate() {
            let first = col_offset[j - j % run];
            if offset != first + j % run {
                return Err(format!(
                    "index table: column {j} breaks its stretch of {run} (offset {offset}, stretch starts at {first})"
                ));
            }
        }
        let max = |v: &[usize]| v.iter().copied().max();
        let reach = match (max(&row_start), max(&col_offset)) {
            (Some(r), Some(c)) => r + c + 1,
            _ => 0,
        };
        Ok(Self {
            row_start,
            col_offset,
            run,
            reach,
        })
    }

    /// Rows.
    pub fn rows(&self) -> usize {
        self.row_start.len()
    }

    /// Columns.
    pub fn cols(&self) -> usize {
        self.col_offset.len()
    }

    /// The least buffer length every index fits in.
    pub fn reach(&self) -> usize {
        self.reach
    }

    /// Value (i, j) of the matrix the table reads out of `values`.
    pub fn get(&self, values: &[f32], i: usize, j: usize) -> f32 {
        values[self.row_start[i] + self.col_offset[j]]
    }
}

/// A matrix read through an [`IndexTable`].
#[derive(Clone, Copy)]
pub struct Gathered<'a> {
    /// The buffer read.
    pub values: &'a [f32],
    /// Where each value lies in it.
    pub table: &'a IndexTable,
}

/// `dst (m × n, row-major) = lhs (gathered, m × k) · rhs (k × n, by strides)` on the AVX2
/// kernel (the caller checks [`ProductKernel::current`]).
pub fn gathered_times(
    dst: &mut [f32],
    lhs: Gathered,
    rhs: &[f32],
    rhs_strides: (usize, usize),
    n: usize,
) {
    let (m, k) = (lhs.table.rows(), lhs.table.cols());
    let rhs = Operand::Matrix(rhs, rhs_strides);
    avx2_product((m, n, k), Operand::Gathered(lhs), rhs, dst, None);
}

/// `dst (m × n, row-major) = lhs (m × k, by strides) · rhs (gathered, k × n)` on the AVX2
/// kernel.
pub fn times_gathered(
    dst: &mut [f32],
    m: usize,
    lhs: &[f32],
    lhs_strides: (usize, usize),
    rhs: Gathered,
) {
    let (k, n) = (rhs.table.rows(), rhs.table.cols());
    let lhs = Operand::Matrix(lhs, lhs_strides);
    avx2_product((m, n, k), lhs, Operand::Gathered(rhs), dst, None);
}

/// `dst[table] += lhs (m × k) · rhs (k × n)`: value (i, j) of the product added at
/// `table`'s index (i, j) of `dst` (col2im: the input's gradient from the patches'), on the
/// AVX2 kernel.
pub fn times_scatter_add(
    dst: &mut [f32],
    table: &IndexTable,
    lhs: &[f32],
    lhs_strides: (usize, usize),
    rhs: &[f32],
    rhs_strides: (usize, usize),
    k: usize,
) {
    let (m, n) = (table.rows(), table.cols());
    let (lhs, rhs) = (
        Operand::Matrix(lhs, lhs_strides),
        Operand::Matrix(rhs, rhs_strides),
    );
    avx2_product((m, n, k), lhs, rhs, dst, Some(table));
}

/// An operand of the AVX2 kernel: a matrix by its strides, or read through a table.
enum Operand<'a> {
    Matrix(&'a [f32], (usize, usize)),
    Gathered(Gathered<'a>),
}

impl Operand<'_> {
    /// Panics with `what` unless the operand holds `rows × cols` values.
    fn check(&self, rows: usize, cols: usize, what: &str) {
        match self {
            Operand::Matrix(values, (rs, cs)) => {
                assert!(
                    values.len() >= reach(*rs, *cs, rows, cols),
                    "product: {what} too short"
                )
            }
            Operand::Gathered(g) => assert!(
                g.values.len() >= g.table.reach(),
                "product: gathered {what} too short"
            ),
        }
    }
}

/// Where the AVX2 kernel's result goes: a row-major matrix (written, or added to after the
/// first block of the depth), or added through an index table.
enum Out<'a> {
    Matrix {
        ptr: *mut f32,
        rs: usize,
        cs: usize,
    },
    ScatterAdd {
        ptr: *mut f32,
        table: &'a IndexTable,
    },
}

/// `dst = lhs · rhs` (m × n, depth k) on the AVX2 kernel, or added through `scatter`, every
/// access checked first.
fn avx2_product(
    (m, n, k): (usize, usize, usize),
    lhs: Operand,
    rhs: Operand,
    dst: &mut [f32],
    scatter: Option<&IndexTable>,
) {
    assert!(
        avx2::available(),
        "product: the AVX2 kernel needs AVX2 and FMA"
    );
    lhs.check(m, k, "lhs");
    rhs.check(k, n, "rhs");
    let needed = scatter.map_or(m * n, IndexTable::reach);
    assert!(dst.len() >= needed, "product: dst too short");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if scatter.is_none() {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    let ptr = dst.as_mut_ptr();
    let out = match scatter {
        Some(table) => Out::ScatterAdd { ptr, table },
        None => Out::Matrix { ptr, rs: n, cs: 1 },
    };
    // SAFETY: AVX2 and FMA are available; the checks above keep every access in bounds.
    unsafe { avx2::run((m, n, k), &lhs, &rhs, out) };
}

/// The span a strided matrix reaches in its buffer.
fn reach(rs: usize, cs: usize, rows: usize, cols: usize) -> usize {
    if rows == 0 || cols == 0 {
        0
    } else {
        (rows - 1) * rs + (cols - 1) * cs + 1
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{Gathered, Operand, Out};
    use std::arch::x86_64::*;
    use std::cell::RefCell;

    /// Rows of a result tile.
    const MR: usize = 6;
    /// Columns of a result tile (two vectors of eight).
    const NR: usize = 16;
    /// Depth of a packed block: a panel of `b` (KC × NR, 16 KB) stays in L1 while the tiles
    /// of a block run over it.
    const KC: usize = 256;
    /// Rows of a packed block of `a` (MC × KC, 96 KB: in L2 while the panels of `b` pass).
    const MC: usize = 96;
    /// Columns of a packed block of `b` (KC × NC, 4 MB at most).
    const NC: usize = 4096;
    /// Up to this many columns, `a`'s rows are read in place (or gathered a tile at a time)
    /// rather than packed: they meet few panels of `b`, so a copy costs more than it saves.
    const NARROW: usize = 128;

    pub fn available() -> bool {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }

    /// A read-only matrix by its first value and strides.
    #[derive(Clone, Copy)]
    struct View {
        ptr: *const f32,
        rs: usize,
        cs: usize,
    }

    impl View {
        fn new(values: &[f32], rs: usize, cs: usize) -> Self {
            Self {
                ptr: values.as_ptr(),
                rs,
                cs,
            }
        }
    }

    /// An operand as the kernel reads it.
    enum Src<'a> {
        Matrix(View),
        Gathered(&'a Gathered<'a>),
    }

    impl<'a> Src<'a> {
        fn of(operand: &'a Operand<'a>) -> Self {
            match operand {
                Operand::Matrix(values, (rs, cs)) => Src::Matrix(View::new(values, *rs, *cs)),
                Operand::Gathered(g) => Src::Gathered(g),
            }
        }
    }

    #[derive(Default)]
    struct Buffers {
        a: Vec<f32>,
        b: Vec<f32>,
        /// Gathered rows: MR of `a`'s (KC each), or one of `b`'s (NC).
        rows: Vec<f32>,
    }

    thread_local! {
        static BUFFERS: RefCell<Buffers> = RefCell::new(Buffers::default());
    }

    /// `out = a · b` (m × n, depth k): `b` packed a block at a time into panels of NR
    /// columns, `a` packed into panels of MR rows or read a tile of rows at a time, tiles of
    /// MR × NR.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `a` (m × k), `b` (k × n) and `out` (m × n) lie within their
    /// buffers (gathered ones: every index the tables give), and `out` overlaps neither.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn run((m, n, k): (usize, usize, usize), a: &Operand, b: &Operand, out: Out) {
        let (a, b) = (Src::of(a), Src::of(b));
        BUFFERS.with_borrow_mut(|bufs| {
            let kmax = KC.min(k);
            let narrow =
                n <= NARROW && matches!(a, Src::Gathered(_) | Src::Matrix(View { cs: 1, .. }));
            bufs.b.resize(NC.min(n).div_ceil(NR) * NR * kmax, 0.0);
            bufs.rows.resize((MR * KC).max(NC.min(n)), 0.0);
            if !narrow {
                bufs.a.resize(MC.min(m).div_ceil(MR) * MR * kmax + 2, 0.0);
            }
            for jc in (0..n).step_by(NC) {
                let nc = NC.min(n - jc);
                for pc in (0..k).step_by(KC) {
                    let kc = KC.min(k - pc);
                    let at = |i: usize, j: usize, rows: usize, cols: usize| Spot {
                        i,
                        j: jc + j,
                        rows,
                        cols,
                        overwrite: pc == 0,
                    };
                    // SAFETY (all below): offsets within the bounds the caller vouches for.
                    unsafe {
                        pack_b(&mut bufs.b, &mut bufs.rows, kc, nc, &b, pc, jc);
                        if narrow {
                            for ic in (0..m).step_by(MR) {
                                let mr = MR.min(m - ic);
                                let rows = tile_rows(&a, &mut bufs.rows, ic, mr, pc, kc);
                                if let Src::Gathered(g) = a {
                                    for i in (ic + MR..m).take(MR) {
                                        prefetch(g, i, pc, kc);
                                    }
                                }
                                for jr in (0..nc).step_by(NR) {
                                    let panel = bufs.b.as_ptr().add(jr * kc);
                                    let spot = at(ic, jr, mr, NR.min(nc - jr));
                                    let acc = match mr {
                                        6 => micro::<6, 1>(kc, &rows, panel),
                                        5 => micro::<5, 1>(kc, &rows, panel),
                                        4 => micro::<4, 1>(kc, &rows, panel),
                                        3 => micro::<3, 1>(kc, &rows, panel),
                                        2 => micro::<2, 1>(kc, &rows, panel),
                                        _ => micro::<1, 1>(kc, &rows, panel),
                                    };
                                    store(&acc, spot, &out);
                                }
                            }
                            continue;
                        }
                        for ic in (0..m).step_by(MC) {
                            let mc = MC.min(m - ic);
                            pack_a(&mut bufs.a, &mut bufs.rows, kc, mc, &a, ic, pc);
                            for jr in (0..nc).step_by(NR) {
                                let panel_b = bufs.b.as_ptr().add(jr * kc);
                                for ir in (0..mc).step_by(MR) {
                                    let panel_a = bufs.a.as_ptr().add(ir * kc);
                                    let rows: [*const f32; MR] =
                                        std::array::from_fn(|r| panel_a.add(r));
                                    let acc = micro::<MR, MR>(kc, &rows, panel_b);
                                    let spot = at(ic + ir, jr, MR.min(mc - ir), NR.min(nc - jr));
                                    store(&acc, spot, &out);
                                }
                            }
                        }
                    }
                }
            }
        });
    }

    /// Row `i`'s values `q0..q0 + out.len()` of a gathered matrix.
    ///
    /// # Safety
    /// The table's indices lie within its values.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn gather(g: &Gathered, i: usize, q0: usize, out: &mut [f32]) {
        let t = g.table;
        let start = t.row_start[i];
        let mut q = q0;
        let end = q0 + out.len();
        let mut left_in_stretch = t.run - q0 % t.run;
        while q < end {
            let stretch = left_in_stretch.min(end - q);
            left_in_stretch = t.run;
            let from = start + t.col_offset[q];
            // SAFETY: within the values (the caller's promise); `out` is a distinct buffer.
            unsafe {
                copy(
                    g.values.as_ptr().add(from),
                    out.as_mut_ptr().add(q - q0),
                    stretch,
                )
            };
            q += stretch;
        }
    }

    /// Asks the cache for row `i`'s values `q0..q0 + len` of a gathered matrix, to be read
    /// soon: its stretches lie apart in the buffer, where the hardware's prefetcher does not
    /// follow.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn prefetch(g: &Gathered, i: usize, q0: usize, len: usize) {
        let t = g.table;
        let start = t.row_start[i];
        let mut q = q0 - q0 % t.run;
        while q < q0 + len {
            let from = start + t.col_offset[q];
            for line in (0..t.run.min(q0 + len - q)).step_by(16) {
                if let Some(v) = g.values.get(from + line) {
                    _mm_prefetch::<_MM_HINT_T0>((v as *const f32).cast());
                }
            }
            q += t.run;
        }
    }

    /// `len` values from `src` to `dst`, eight at a time: the stretches are short (24 values
    /// in NatureCNN's first layer), too short for a call to `memcpy` to pay.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn copy(src: *const f32, dst: *mut f32, len: usize) {
        let mut i = 0;
        // SAFETY: both hold len values.
        unsafe {
            while i + 8 <= len {
                _mm256_storeu_ps(dst.add(i), _mm256_loadu_ps(src.add(i)));
                i += 8;
            }
            for i in i..len {
                *dst.add(i) = *src.add(i);
            }
        }
    }

    /// Pointers to rows `ic..ic + mr` of `a` from depth `pc` on: in place, or gathered into
    /// `rows` (KC apart).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn tile_rows(
        a: &Src,
        rows: &mut [f32],
        ic: usize,
        mr: usize,
        pc: usize,
        kc: usize,
    ) -> [*const f32; MR] {
        // SAFETY: as `run`'s.
        unsafe {
            match a {
                Src::Matrix(v) => {
                    std::array::from_fn(|r| v.ptr.add((ic + r.min(mr - 1)) * v.rs + pc))
                }
                Src::Gathered(g) => {
                    for r in 0..mr {
                        gather(g, ic + r, pc, &mut rows[r * KC..r * KC + kc]);
                    }
                    std::array::from_fn(|r| rows.as_ptr().add(r.min(mr - 1) * KC))
                }
            }
        }
    }

    /// `a[ic..ic + mc][pc..pc + kc]` into panels of MR rows, each kc × MR, zero-padded.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn pack_a(
        packed: &mut [f32],
        rows: &mut [f32],
        kc: usize,
        mc: usize,
        a: &Src,
        ic: usize,
        pc: usize,
    ) {
        for ir in (0..mc).step_by(MR) {
            let mr = MR.min(mc - ir);
            let panel = &mut packed[ir * kc..(ir + MR) * kc + 2];
            // SAFETY: every read stays within a's m × k values.
            unsafe {
                let v = match a {
                    Src::Matrix(v) if v.rs == 1 && mr == MR => {
                        // Columns contiguous: a step's six values in one masked load.
                        let six = _mm256_setr_epi32(-1, -1, -1, -1, -1, -1, 0, 0);
                        let src = v.ptr.add((ic + ir) + pc * v.cs);
                        for p in 0..kc {
                            let step = _mm256_maskload_ps(src.add(p * v.cs), six);
                            _mm256_storeu_ps(panel.as_mut_ptr().add(p * MR), step);
                        }
                        continue;
                    }
                    Src::Matrix(v) if v.cs != 1 || mr < MR => {
                        let src = v.ptr.add((ic + ir) * v.rs + pc * v.cs);
                        for (p, dst) in panel.chunks_exact_mut(MR).take(kc).enumerate() {
                            for (r, d) in dst.iter_mut().enumerate() {
                                *d = if r < mr {
                                    *src.add(r * v.rs + p * v.cs)
                                } else {
                                    0.0
                                };
                            }
                        }
                        continue;
                    }
                    Src::Matrix(v) => View {
                        ptr: v.ptr.add((ic + ir) * v.rs + pc),
                        ..*v
                    },
                    Src::Gathered(g) => {
                        rows[..MR * KC].fill(0.0);
                        for r in 0..mr {
                            gather(g, ic + ir + r, pc, &mut rows[r * KC..r * KC + kc]);
                        }
                        View {
                            ptr: rows.as_ptr(),
                            rs: KC,
                            cs: 1,
                        }
                    }
                };
                // Rows contiguous: eight steps at a time, a 6 × 8 block transposed in
                // registers.
                let mut p = 0;
                while p + 8 <= kc {
                    let block: [__m256; 8] = std::array::from_fn(|r| {
                        if r < MR {
                            _mm256_loadu_ps(v.ptr.add(r * v.rs + p))
                        } else {
                            _mm256_setzero_ps()
                        }
                    });
                    let dst = panel.as_mut_ptr().add(p * MR);
                    // Each step's six values; the two after them are overwritten by the next
                    // step's, or lie in the panel's slack.
                    for (q, col) in transpose8(block).iter().enumerate() {
                        _mm256_storeu_ps(dst.add(q * MR), *col);
                    }
                    p += 8;
                }
                for p in p..kc {
                    for r in 0..MR {
                        panel[p * MR + r] = *v.ptr.add(r * v.rs + p);
                    }
                }
            }
        }
    }

    /// An 8 × 8 block transposed.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn transpose8(r: [__m256; 8]) -> [__m256; 8] {
        let t0 = _mm256_unpacklo_ps(r[0], r[1]);
        let t1 = _mm256_unpackhi_ps(r[0], r[1]);
        let t2 = _mm256_unpacklo_ps(r[2], r[3]);
        let t3 = _mm256_unpackhi_ps(r[2], r[3]);
        let t4 = _mm256_unpacklo_ps(r[4], r[5]);
        let t5 = _mm256_unpackhi_ps(r[4], r[5]);
        let t6 = _mm256_unpacklo_ps(r[6], r[7]);
        let t7 = _mm256_unpackhi_ps(r[6], r[7]);
        let u0 = _mm256_shuffle_ps::<0b01_00_01_00>(t0, t2);
        let u1 = _mm256_shuffle_ps::<0b11_10_11_10>(t0, t2);
        let u2 = _mm256_shuffle_ps::<0b01_00_01_00>(t1, t3);
        let u3 = _mm256_shuffle_ps::<0b11_10_11_10>(t1, t3);
        let u4 = _mm256_shuffle_ps::<0b01_00_01_00>(t4, t6);
        let u5 = _mm256_shuffle_ps::<0b11_10_11_10>(t4, t6);
        let u6 = _mm256_shuffle_ps::<0b01_00_01_00>(t5, t7);
        let u7 = _mm256_shuffle_ps::<0b11_10_11_10>(t5, t7);
        [
            _mm256_permute2f128_ps::<0x20>(u0, u4),
            _mm256_permute2f128_ps::<0x20>(u1, u5),
            _mm256_permute2f128_ps::<0x20>(u2, u6),
            _mm256_permute2f128_ps::<0x20>(u3, u7),
            _mm256_permute2f128_ps::<0x31>(u0, u4),
            _mm256_permute2f128_ps::<0x31>(u1, u5),
            _mm256_permute2f128_ps::<0x31>(u2, u6),
            _mm256_permute2f128_ps::<0x31>(u3, u7),
        ]
    }

    /// `b[pc..pc + kc][jc..jc + nc]` into panels of NR columns, each kc × NR, zero-padded.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn pack_b(
        packed: &mut [f32],
        row: &mut [f32],
        kc: usize,
        nc: usize,
        b: &Src,
        pc: usize,
        jc: usize,
    ) {
        // SAFETY: every read stays within b's k × n values.
        unsafe {
            match b {
                Src::Matrix(v) if v.rs == 1 && nc.is_multiple_of(NR) => {
                    // Columns contiguous (b transposed): eight steps of eight columns at a
                    // time, transposed in registers.
                    for jr in (0..nc).step_by(NR) {
                        let panel = packed.as_mut_ptr().add(jr * kc);
                        let src = v.ptr.add(pc + (jc + jr) * v.cs);
                        let mut p = 0;
                        while p + 8 <= kc {
                            for half in 0..2 {
                                let cols: [__m256; 8] = std::array::from_fn(|j| {
                                    _mm256_loadu_ps(src.add((8 * half + j) * v.cs + p))
                                });
                                for (q, step) in transpose8(cols).iter().enumerate() {
                                    _mm256_storeu_ps(panel.add((p + q) * NR + 8 * half), *step);
                                }
                            }
                            p += 8;
                        }
                        for p in p..kc {
                            for j in 0..NR {
                                *panel.add(p * NR + j) = *src.add(j * v.cs + p);
                            }
                        }
                    }
                }
                Src::Matrix(v) if v.cs != 1 => {
                    // Column by column: reads run along b's columns where b is transposed.
                    for jr in (0..nc).step_by(NR) {
                        let nr = NR.min(nc - jr);
                        let panel = &mut packed[jr * kc..(jr + NR) * kc];
                        let src = v.ptr.add(pc * v.rs + (jc + jr) * v.cs);
                        for j in 0..NR {
                            for p in 0..kc {
                                panel[p * NR + j] = if j < nr {
                                    *src.add(p * v.rs + j * v.cs)
                                } else {
                                    0.0
                                };
                            }
                        }
                    }
                }
                Src::Matrix(v) => {
                    for p in 0..kc {
                        spread(packed, kc, p, nc, v.ptr.add((pc + p) * v.rs + jc));
                    }
                }
                Src::Gathered(g) => {
                    for p in 0..kc {
                        if pc + p + 8 < g.table.rows() {
                            prefetch(g, pc + p + 8, jc, nc);
                        }
                        gather(g, pc + p, jc, &mut row[..nc]);
                        spread(packed, kc, p, nc, row.as_ptr());
                    }
                }
            }
        }
    }

    /// One row of `b` (nc contiguous values) into step `p` of each panel.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn spread(packed: &mut [f32], kc: usize, p: usize, nc: usize, src: *const f32) {
        // SAFETY: src holds nc values; the panels hold kc steps of NR.
        unsafe {
            for jr in (0..nc).step_by(NR) {
                let dst = packed.as_mut_ptr().add(jr * kc + p * NR);
                if jr + NR <= nc {
                    _mm256_storeu_ps(dst, _mm256_loadu_ps(src.add(jr)));
                    _mm256_storeu_ps(dst.add(8), _mm256_loadu_ps(src.add(jr + 8)));
                } else {
                    for j in 0..NR {
                        *dst.add(j) = if jr + j < nc { *src.add(jr + j) } else { 0.0 };
                    }
                }
            }
        }
    }

    /// A tile of the result: its first row and column, its size, and whether it overwrites
    /// (the first block of the depth) or adds.
    struct Spot {
        i: usize,
        j: usize,
        rows: usize,
        cols: usize,
        overwrite: bool,
    }

    /// One tile: `kc` steps of R rows of `a` (row r's p-th value at `a[r] + p·STEP`,
    /// broadcast) against a packed panel of `b`.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn micro<const R: usize, const STEP: usize>(
        kc: usize,
        a: &[*const f32; MR],
        b: *const f32,
    ) -> [[__m256; 2]; MR] {
        let mut c = [[_mm256_setzero_ps(); 2]; MR];
        // SAFETY: the rows and the panel hold kc steps each.
        unsafe {
            for p in 0..kc {
                let b0 = _mm256_loadu_ps(b.add(p * NR));
                let b1 = _mm256_loadu_ps(b.add(p * NR + 8));
                for r in 0..R {
                    let av = _mm256_broadcast_ss(&*a[r].add(p * STEP));
                    c[r][0] = _mm256_fmadd_ps(av, b0, c[r][0]);
                    c[r][1] = _mm256_fmadd_ps(av, b1, c[r][1]);
                }
            }
        }
        c
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn store(acc: &[[__m256; 2]; MR], at: Spot, out: &Out) {
        // SAFETY: the tile lies within the result.
        unsafe {
            let add = |d: *mut f32, v: __m256| {
                _mm256_storeu_ps(d, _mm256_add_ps(_mm256_loadu_ps(d), v));
            };
            match *out {
                Out::Matrix { ptr, rs, cs } if cs == 1 && at.cols == NR => {
                    for (r, v) in acc.iter().enumerate().take(at.rows) {
                        let row = ptr.add((at.i + r) * rs + at.j);
                        if at.overwrite {
                            _mm256_storeu_ps(row, v[0]);
                            _mm256_storeu_ps(row.add(8), v[1]);
                        } else {
                            add(row, v[0]);
                            add(row.add(8), v[1]);
                        }
                    }
                }
                Out::ScatterAdd { ptr, table }
                    if at.cols == NR && at.j % table.run + NR <= table.run =>
                {
                    // The tile's columns lie in one stretch: contiguous in the target.
                    let offset = table.col_offset[at.j];
                    for (r, v) in acc.iter().enumerate().take(at.rows) {
                        let d = ptr.add(table.row_start[at.i + r] + offset);
                        add(d, v[0]);
                        add(d.add(8), v[1]);
                    }
                }
                _ => {
                    let mut buf = [0f32; MR * NR];
                    for (r, v) in acc.iter().enumerate() {
                        _mm256_storeu_ps(buf.as_mut_ptr().add(r * NR), v[0]);
                        _mm256_storeu_ps(buf.as_mut_ptr().add(r * NR + 8), v[1]);
                    }
                    for r in 0..at.rows {
                        for j in 0..at.cols {
                            let v = buf[r * NR + j];
                            match *out {
                                Out::Matrix { ptr, rs, cs } => {
                                    let d = ptr.add((at.i + r) * rs + (at.j + j) * cs);
                                    *d = if at.overwrite { v } else { *d + v };
                                }
                                Out::ScatterAdd { ptr, table: t } => {
                                    *ptr.add(t.row_start[at.i + r] + t.col_offset[at.j + j]) += v;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod avx2 {
    use super::{Operand, Out};

    pub fn available() -> bool {
        false
    }

    /// # Safety
    /// Never called: `available()` is false.
    pub unsafe fn run(_: (usize, usize, usize), _: &Operand, _: &Operand, _: Out) {
        unreachable!("no AVX2 kernel on this architecture")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// How a reference product sums each result's terms.
    #[derive(Clone, Copy)]
    enum Sum {
        /// In f64, rounded once.
        InF64,
        /// In the AVX2 kernel's order, with scalar fused multiply-adds that every CPU rounds
        /// alike: a chain from zero over each block of 256 steps of the depth, the blocks'
        /// chains added in turn.
        InTheKernelsOrder,
    }

    /// `lhs · rhs`, row-major, each result summed as `sum` says.
    fn naive(
        sum: Sum,
        (m, n, k): (usize, usize, usize),
        lhs: &[f32],
        (lrs, lcs): (usize, usize),
        rhs: &[f32],
        (rrs, rcs): (usize, usize),
    ) -> Vec<f32> {
        let result = |i: usize, j: usize| {
            let term = |p: usize| (lhs[i * lrs + p * lcs], rhs[p * rrs + j * rcs]);
            match sum {
                Sum::InF64 => (0..k)
                    .map(|p| term(p).0 as f64 * term(p).1 as f64)
                    .sum::<f64>() as f32,
                Sum::InTheKernelsOrder => {
                    let chain = |start: usize| {
                        (start..k.min(start + 256)).fold(0.0f32, |acc, p| {
                            let (a, b) = term(p);
                            a.mul_add(b, acc)
                        })
                    };
                    (256..k)
                        .step_by(256)
                        .fold(chain(0), |total, start| total + chain(start))
                }
            }
        };
        (0..m * n).map(|q| result(q / n, q % n)).collect()
    }

    fn values(len: usize, seed: usize) -> Vec<f32> {
        (0..len)
            .map(|i| ((i * 7919 + seed * 104729) % 2001) as f32 / 1000.0 - 1.0)
            .collect()
    }

    fn assert_close(found: &[f32], expected: &[f32], k: usize, what: &str) {
        assert_eq!(found.len(), expected.len(), "{what}");
        let tolerance = 1e-5 * (k as f32).sqrt().max(1.0);
        for (i, (a, b)) in found.iter().zip(expected).enumerate() {
            assert!(
                (a - b).abs() <= tolerance * (1.0 + b.abs()),
                "{what}[{i}]: {a} vs {b}"
            );
        }
    }

    #[test]
    fn both_kernels_multiply_every_shape_and_layout() {
        // Edges of every block (tiles of 6 × 16, depth 256, 96 rows, 4096 columns, the
        // narrow bound of 128 columns) and the four layouts of the operands.
        let dims = [
            (1, 1, 1),
            (5, 7, 3),
            (6, 16, 256),
            (13, 33, 257),
            (97, 129, 40),
            (64, 128, 513),
            (200, 31, 9),
            (7, 300, 70),
            (3, 4100, 5),
        ];
        for (m, n, k) in dims {
            let lhs = values(m * k, m);
            let rhs = values(k * n, n);
            for (l_strides, r_strides) in [
                ((k, 1), (n, 1)),
                ((1, m), (n, 1)),
                ((k, 1), (1, k)),
                ((1, m), (1, k)),
            ] {
                let expected = naive(Sum::InF64, (m, n, k), &lhs, l_strides, &rhs, r_strides);
                for kernel in [ProductKernel::Gemm, ProductKernel::Avx2] {
                    let mut dst = vec![f32::NAN; m * n];
                    product_with(
                        kernel,
                        (m, n, k),
                        &mut dst,
                        &lhs,
                        l_strides,
                        &rhs,
                        r_strides,
                    );
                    let what = format!("{kernel:?} {m}×{n}×{k} {l_strides:?} {r_strides:?}");
                    assert_close(&dst, &expected, k, &what);
                }
            }
        }
    }

    /// What makes a seed train the same MLP weights on every host: the products the MLPs run
    /// sum in one order, whatever the CPU's vector width.
    #[test]
    fn the_mlps_products_sum_in_an_order_any_cpu_repeats() {
        if !avx2::available() {
            return; // gemm's kernel multiplies here: its order is its own.
        }
        // The MLPs' three products (x · Wᵀ, xᵀ · g, g · W) on a batch of 37, 11 inputs and 16
        // outputs, and shapes that cross the kernel's blocks.
        let cases = [
            ((37, 16, 11), (11, 1), (1, 11)),
            ((11, 16, 37), (1, 11), (16, 1)),
            ((37, 11, 16), (16, 1), (11, 1)),
            ((256, 64, 300), (300, 1), (1, 300)),
            ((64, 64, 600), (1, 64), (64, 1)),
            ((200, 131, 20), (20, 1), (131, 1)),
        ];
        for (dims, ls, rs) in cases {
            let (m, n, k) = dims;
            let (lhs, rhs) = (values(m * k, m + 3), values(k * n, n + 5));
            let mut dst = vec![f32::NAN; m * n];
            product_with(ProductKernel::Avx2, dims, &mut dst, &lhs, ls, &rhs, rs);
            let want = naive(Sum::InTheKernelsOrder, dims, &lhs, ls, &rhs, rs);
            let differ = dst.iter().zip(&want).filter(|(a, b)| a != b).count();
            assert_eq!(differ, 0, "{m}×{n}×{k}: {differ} results differ");
        }
    }

    #[test]
    fn an_empty_depth_gives_zeros() {
        let mut dst = vec![f32::NAN; 6];
        product_with(
            ProductKernel::Avx2,
            (2, 3, 0),
            &mut dst,
            &[],
            (0, 1),
            &[],
            (3, 1),
        );
        assert_eq!(dst, vec![0.0; 6]);
    }

    /// A table that reads a 2-row, 5-column matrix out of a 3 × 4 buffer in stretches of 2,
    /// and the matrix it reads.
    fn table_and_matrix(buffer: &[f32]) -> (IndexTable, Vec<f32>) {
        // Rows start at 0 and 4; columns at 0, 1 | 4, 5 | 8.
        let table = IndexTable::new(vec![0, 4], vec![0, 1, 4, 5, 8], 2).unwrap();
        let matrix = (0..2)
            .flat_map(|i| (0..5).map(move |j| (i, j)))
            .map(|(i, j)| table.get(buffer, i, j))
            .collect();
        (table, matrix)
    }

    #[test]
    fn gathered_operands_and_scatter_adds_match_the_matrices_they_read() {
        if !avx2::available() {
            return;
        }
        let buffer = values(16, 1);
        let (table, matrix) = table_and_matrix(&buffer);
        assert_eq!(table.reach(), 4 + 8 + 1);
        let gathered = Gathered {
            values: &buffer,
            table: &table,
        };
        // (2 × 5) · (5 × 3)
        let rhs = values(15, 2);
        let mut dst = vec![0.0; 6];
        gathered_times(&mut dst, gathered, &rhs, (3, 1), 3);
        assert_close(
            &dst,
            &naive(Sum::InF64, (2, 3, 5), &matrix, (5, 1), &rhs, (3, 1)),
            5,
            "gathered · matrix",
        );
        // (3 × 2) · (2 × 5)
        let lhs = values(6, 3);
        let mut dst = vec![0.0; 15];
        times_gathered(&mut dst, 3, &lhs, (2, 1), gathered);
        assert_close(
            &dst,
            &naive(Sum::InF64, (3, 5, 2), &lhs, (2, 1), &matrix, (5, 1)),
            2,
            "matrix · gathered",
        );
        // (2 × 4) · (4 × 5), added where the table points: overlapping indices add up.
        let (a, b) = (values(8, 4), values(20, 5));
        let mut target = values(13, 6);
        let mut expected = target.clone();
        let product = naive(Sum::InF64, (2, 5, 4), &a, (4, 1), &b, (5, 1));
        for i in 0..2 {
            for j in 0..5 {
                expected[table.row_start[i] + table.col_offset[j]] += product[i * 5 + j];
            }
        }
        times_scatter_add(&mut target, &table, &a, (4, 1), &b, (5, 1), 4);
        assert_close(&target, &expected, 4, "scatter add");
    }

    #[test]
    fn index_tables_refuse_broken_stretches() {
        assert!(
            IndexTable::new(vec![0], vec![0, 1], 0)
                .unwrap_err()
                .contains("run")
        );
        let err = IndexTable::new(vec![0], vec![0, 2, 4, 5], 2).unwrap_err();
        assert!(err.contains("column 1"), "{err}");
        assert!(IndexTable::new(vec![0, 3], vec![0, 1, 7, 8], 2).is_ok());
    }

    #[test]
    fn the_kernel_is_chosen_by_the_variable_then_the_cpu() {
        assert_eq!(ProductKernel::choose(Some("gemm")), ProductKernel::Gemm);
        let avx2 = ProductKernel::choose(Some("avx2"));
        assert_eq!(avx2 == ProductKernel::Avx2, avx2::available());
        let auto = ProductKernel::choose(None);
        assert_eq!(
            auto == ProductKernel::Avx2,
            avx2::available() && !has_avx512()
        );
        assert_eq!(ProductKernel::choose(Some("nonsense")), auto);
    }
}
