//! Whole-matrix operations on contiguous storage as plain slice operations.
//!
//! nalgebra's `fill` and `copy_from` go element by element through a strided iterator, which
//! does not vectorise: in profiles of the 42-state delayed problem, clearing the cost's and the
//! linearisation's matrices at every knot took a fifth of an ILQG iteration. On owned
//! (contiguous) storage the same operations are one `memset` or `memcpy`, with the same result.

use nalgebra::{DMatrix, Dim, IsContiguous, Matrix, RawStorage, RawStorageMut};

/// `m = 0`.
pub fn zero<R: Dim, C: Dim, S: RawStorageMut<f64, R, C> + IsContiguous>(
    m: &mut Matrix<f64, R, C, S>,
) {
    m.as_mut_slice().fill(0.0);
}

/// `dst = src` for matrices of one shape.
pub fn copy<R, C, S1, S2>(src: &Matrix<f64, R, C, S1>, dst: &mut Matrix<f64, R, C, S2>)
where
    R: Dim,
    C: Dim,
    S1: RawStorage<f64, R, C> + IsContiguous,
    S2: RawStorageMut<f64, R, C> + IsContiguous,
{
    debug_assert_eq!(src.shape(), dst.shape());
    dst.as_mut_slice().copy_from_slice(src.as_slice());
}

/// `dst = srcᵀ` on column-major storage.
pub fn transpose<R, C, S1, S2>(src: &Matrix<f64, R, C, S1>, dst: &mut Matrix<f64, C, R, S2>)
where
    R: Dim,
    C: Dim,
    S1: RawStorage<f64, R, C> + IsContiguous,
    S2: RawStorageMut<f64, C, R> + IsContiguous,
{
    let (r, c) = src.shape();
    debug_assert_eq!(dst.shape(), (c, r));
    let (sd, dd) = (src.as_slice(), dst.as_mut_slice());
    for j in 0..c {
        for (i, &v) in sd[j * r..(j + 1) * r].iter().enumerate() {
            dd[i * c + j] = v;
        }
    }
}

/// Lanes of [`TransposedProduct`]: output columns computed side by side.
const LANES: usize = 4;

/// `c = aᵀ b` or `c += aᵀ b` for dynamically sized matrices, with the bits of nalgebra's
/// `c.gemm_tr(1.0, a, b, β)` (β = 0 or 1), faster.
///
/// Why: nalgebra computes each entry as a dot product of two columns on its own (eight partial
/// sums over blocks of eight rows, then the rest), one call per entry; for the SOOC backward
/// pass's `Aᵀ (V A)` on the VSA arm's 44 moment states that was 13 % of a plan. Here
/// [`LANES`] entries of a row of `c` are computed side by side, each with exactly nalgebra's
/// partial sums in nalgebra's order (the lanes are independent entries, not parts of one sum),
/// so the compiler vectorises across entries and no rounding changes. `b` is read from a copy
/// in blocks of [`LANES`] columns kept in the workspace (no allocation once sized).
#[derive(Debug, Clone, Default)]
pub struct TransposedProduct {
    /// `b` in blocks of [`LANES`] columns, each block row by row:
    /// `blocks[(jb · rows + r) · LANES + l] = b[(r, jb · LANES + l)]`, padded with 0.
    blocks: Vec<f64>,
}

impl TransposedProduct {
    /// A workspace for `b` of up to `rows × cols` entries (it grows if a larger `b` comes).
    pub fn new(rows: usize, cols: usize) -> Self {
        TransposedProduct {
            blocks: vec![0.0; rows * cols.div_ceil(LANES) * LANES],
        }
    }

    /// `c = aᵀ b` (`accumulate` false) or `c += aᵀ b` (true).
    pub fn apply(
        &mut self,
        c: &mut DMatrix<f64>,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        accumulate: bool,
    ) {
        let (r, p) = a.shape();
        let q = b.ncols();
        assert_eq!(b.nrows(), r, "aᵀ b: a and b differ in rows");
        assert_eq!(c.shape(), (p, q), "aᵀ b: c has the wrong shape");
        if r == 0 {
            // Empty sums (no blocks to cut the rows into): nalgebra's own answer.
            c.gemm_tr(1.0, a, b, if accumulate { 1.0 } else { 0.0 });
            return;
        }
        let len = r * q.div_ceil(LANES) * LANES;
        if self.blocks.len() < len {
            self.blocks.resize(len, 0.0);
        }
        let bs = b.as_slice();
        for (jb, block) in self.blocks[..len].chunks_exact_mut(r * LANES).enumerate() {
            for (row, lanes) in block.chunks_exact_mut(LANES).enumerate() {
                for (l, v) in lanes.iter_mut().enumerate() {
                    let j = jb * LANES + l;
                    *v = if j < q { bs[j * r + row] } else { 0.0 };
                }
            }
        }
        let blocks = &self.blocks[..len];
        #[cfg(target_arch = "x86_64")]
        if crate::core::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            unsafe { product_avx2(c, a, blocks, accumulate) };
            return;
        }
        product(c, a, blocks, accumulate);
    }
}

/// [`product`] compiled for AVX2 (see [`crate::core::wide`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn product_avx2(c: &mut DMatrix<f64>, a: &DMatrix<f64>, blocks: &[f64], accumulate: bool) {
    product(c, a, blocks, accumulate);
}

/// The kernel of [`TransposedProduct::apply`]: entry `(i, j)` is nalgebra's `dotx` of column `i`
/// of `a` and column `j` of `b` (partial sums 0–7 over whole blocks of eight rows, then
/// `0 + (s0 + s4) + (s1 + s5) + (s2 + s6) + (s3 + s7)`, then the remaining rows one by one),
/// added to `c` as nalgebra's `gemv` adds it (`1·dot + 1·c`).
#[inline(always)]
fn product(c: &mut DMatrix<f64>, a: &DMatrix<f64>, blocks: &[f64], accumulate: bool) {
    let (r, p) = a.shape();
    let q = c.ncols();
    let whole = r / 8 * 8;
    let a = a.as_slice();
    let c = c.as_mut_slice();
    for (jb, block) in blocks.chunks_exact(r * LANES).enumerate() {
        let (head, tail) = block.split_at(whole * LANES);
        let j0 = jb * LANES;
        for (i, col) in a.chunks_exact(r).enumerate() {
            let (col_head, col_tail) = col.split_at(whole);
            let mut res = [0.0f64; LANES];
            if whole > 0 {
                let mut s = [[0.0f64; LANES]; 8];
                for (x8, b8) in col_head.chunks_exact(8).zip(head.chunks_exact(8 * LANES)) {
                    for (t, st) in s.iter_mut().enumerate() {
                        for l in 0..LANES {
                            st[l] += x8[t] * b8[t * LANES + l];
                        }
                    }
                }
                for l in 0..LANES {
                    res[l] += s[0][l] + s[4][l];
                    res[l] += s[1][l] + s[5][l];
                    res[l] += s[2][l] + s[6][l];
                    res[l] += s[3][l] + s[7][l];
                }
            }
            // With no whole block nalgebra adds eight zero partial sums to 0: +0, as here.
            for (&x, lanes) in col_tail.iter().zip(tail.chunks_exact(LANES)) {
                for l in 0..LANES {
                    res[l] += x * lanes[l];
                }
            }
            for (l, &v) in res.iter().enumerate().take(q - j0) {
                let e = &mut c[(j0 + l) * p + i];
                *e = if accumulate { v + *e } else { v };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix of awkward values (no two alike, mixed signs and magnitudes) from a seed.
    fn awkward(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        DMatrix::from_fn(rows, cols, |_, _| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (state >> 11) as f64 / (1u64 << 53) as f64;
            (u - 0.4) * 10f64.powi(((state >> 7) % 7) as i32 - 3)
        })
    }

    /// Every shape the solvers use and the edges of the kernel's blocks: fewer than eight rows,
    /// whole blocks with and without a rest, columns not a multiple of the lanes. Bit for bit
    /// nalgebra's `gemm_tr` with β = 0 and β = 1, on both instruction sets.
    #[test]
    fn the_product_has_nalgebras_bits() {
        let shapes = [
            (1, 1, 1),
            (4, 4, 4),
            (4, 14, 14),
            (14, 14, 14),
            (14, 4, 14),
            (14, 4, 4),
            (8, 3, 5),
            (16, 7, 9),
            (44, 44, 44),
            (44, 4, 44),
            (44, 4, 4),
            (4, 44, 44),
            (23, 6, 2),
            (0, 3, 2),
        ];
        let wide_before = crate::core::wide::enabled();
        for wide in [false, true] {
            crate::core::wide::set_enabled(wide);
            let mut ws = TransposedProduct::new(2, 2);
            for (k, &(r, p, q)) in shapes.iter().enumerate() {
                let a = awkward(r, p, 3 * k as u64);
                let b = awkward(r, q, 3 * k as u64 + 1);
                let c0 = awkward(p, q, 3 * k as u64 + 2);
                for accumulate in [false, true] {
                    let mut want = c0.clone();
                    want.gemm_tr(1.0, &a, &b, if accumulate { 1.0 } else { 0.0 });
                    let mut got = c0.clone();
                    ws.apply(&mut got, &a, &b, accumulate);
                    for (g, w) in got.iter().zip(want.iter()) {
                        assert_eq!(
                            g.to_bits(),
                            w.to_bits(),
                            "{r}x{p}ᵀ · {r}x{q}, accumulate {accumulate}, wide {wide}: {g} vs {w}"
                        );
                    }
                }
            }
        }
        crate::core::wide::set_enabled(wide_before);
    }
}
