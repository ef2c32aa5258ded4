//! Whole-matrix operations on contiguous storage as plain slice operations.
//!
//! nalgebra's `fill` and `copy_from` go element by element through a strided iterator, which
//! does not vectorise: in profiles of the 42-state delayed problem, clearing the cost's and the
//! linearisation's matrices at every knot took a fifth of an ILQG iteration. On owned
//! (contiguous) storage the same operations are one `memset` or `memcpy`, with the same result.

use nalgebra::{Dim, IsContiguous, Matrix, RawStorage, RawStorageMut};

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
