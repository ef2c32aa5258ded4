//! The noise part of the step's linearisation: the gain `G = √Δ F` of paper Eq. 10 and its
//! derivatives with respect to the state and controls.

use super::{DiscreteDynamics, Dynamics, Linearization, NoiseKind, seed};
use crate::scalar::{MAX_NU, MAX_NW, MAX_NX, Scalar};
use num_dual::{Dual, DualNum};

impl DiscreteDynamics {
    /// The noise part of the linearisation: `c_i`, `Cx_i`, `Cu_i`, and whether the noise
    /// depends on the state or controls at all.
    pub(super) fn noise_linearization(&self, x: &[f64], u: &[f64], lin: &mut Linearization) {
        let (nx, nu, nw) = (self.nx(), self.nu(), self.nw());
        if nw == 0 || lin.c.ncols() == 0 {
            lin.noise = NoiseKind::None;
            return;
        }
        // Scratch sized for the plant: `noise_jacobian` writes every entry read back, so the
        // buffers only need to be large enough; clearing the largest plant's (6.5 kB) at
        // every knot of every linearisation would cost the delayed single joint (whose plant
        // needs 20 entries) a pass over memory it never reads.
        let fits = |g: usize, dx: usize, du: usize| {
            nx * nw <= g && nx * nx * nw <= dx && nu * nx * nw <= du
        };
        if fits(4, 8, 8) {
            self.noise_linearization_in::<4, 8, 8>(x, u, lin)
        } else if fits(16, 64, 64) {
            self.noise_linearization_in::<16, 64, 64>(x, u, lin)
        } else {
            self.noise_linearization_in::<{ MAX_NX * MAX_NW }, { MAX_NX * MAX_NX * MAX_NW }, { MAX_NU * MAX_NX * MAX_NW }>(x, u, lin)
        }
    }

    /// [`DiscreteDynamics::noise_linearization`] with scratch of `G`, `DX`, `DU` entries for
    /// `g`, `∂g/∂x` and `∂g/∂u`.
    fn noise_linearization_in<const G: usize, const DX: usize, const DU: usize>(
        &self,
        x: &[f64],
        u: &[f64],
        lin: &mut Linearization,
    ) {
        let (nx, nu, nw) = (self.nx(), self.nu(), self.nw());
        let mut g = [0.0; G];
        let mut dgx = [0.0; DX];
        let mut dgu = [0.0; DU];
        self.noise_jacobian(x, u, &mut g, &mut dgx, &mut dgu);
        let block = nx * nw;
        let mut dependent = false;
        for ch in 0..nw {
            for r in 0..nx {
                lin.c[(r, ch)] = g[ch * nx + r];
            }
            for j in 0..nx {
                for r in 0..nx {
                    let v = dgx[j * block + ch * nx + r];
                    dependent |= v != 0.0;
                    lin.cx[ch][(r, j)] = v;
                }
            }
            for j in 0..nu {
                for r in 0..nx {
                    let v = dgu[j * block + ch * nx + r];
                    dependent |= v != 0.0;
                    lin.cu[ch][(r, j)] = v;
                }
            }
        }
        lin.noise = if dependent {
            NoiseKind::Dependent
        } else {
            NoiseKind::Additive
        };
    }

    /// The noise gain `G = √Δ F` (layout of [`crate::model::ArmModel::diffusion`]) and its derivatives
    /// `dgx[j]`, `dgu[j]` with respect to `x_j` and `u_j`, in any scalar type.
    pub(crate) fn noise_jacobian<S: Scalar + DualNum<Primitive = f64>>(
        &self,
        x: &[S],
        u: &[S],
        g: &mut [S],
        dgx: &mut [S],
        dgu: &mut [S],
    ) {
        let (nx, nu, nw) = (self.nx(), self.nu(), self.nw());
        let block = nx * nw;
        let s = self.dt.sqrt();
        let mut xd = [Dual::from_re(<S as Scalar>::zero()); MAX_NX];
        let mut ud = [Dual::from_re(<S as Scalar>::zero()); MAX_NU];
        for (d, v) in xd.iter_mut().zip(x) {
            *d = Dual::from_re(*v);
        }
        for (d, v) in ud.iter_mut().zip(u) {
            *d = Dual::from_re(*v);
        }
        let mut big_f = [Dual::from_re(<S as Scalar>::zero()); MAX_NX * MAX_NW];
        for j in 0..nx + nu {
            seed(&mut xd, &mut ud, nx, j, <S as Scalar>::one());
            self.model.diffusion(&xd[..nx], &ud[..nu], &mut big_f);
            seed(&mut xd, &mut ud, nx, j, <S as Scalar>::zero());
            if j == 0 {
                for (dst, v) in g.iter_mut().zip(&big_f[..block]) {
                    *dst = v.re * s;
                }
            }
            let dst = if j < nx {
                &mut dgx[j * block..(j + 1) * block]
            } else {
                &mut dgu[(j - nx) * block..(j - nx + 1) * block]
            };
            for (d, v) in dst.iter_mut().zip(&big_f[..block]) {
                *d = v.eps * s;
            }
        }
    }
}
