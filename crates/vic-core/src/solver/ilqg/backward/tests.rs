//! The knot of the backward pass on the stack against the one by the nonzero patterns.

use super::*;

/// Entries of every kind the products meet: ordinary values, exact zeros of both signs
/// (whose sums depend on the order and the starting zero) and values far apart in scale.
fn entries(seed: &mut u64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (*seed >> 11) as f64 / (1u64 << 53) as f64;
            match *seed >> 60 {
                0 => 0.0,
                1 => -0.0,
                2 => (u - 0.5) * 1e12,
                3 => (u - 0.5) * 1e-9,
                _ => u - 0.5,
            }
        })
        .collect()
}

fn matrix(r: usize, c: usize, seed: &mut u64) -> DMatrix<f64> {
    DMatrix::from_vec(r, c, entries(seed, r * c))
}

/// One knot's inputs: the next knot's value, the linearisation, the cost's expansion, the
/// nominal control, the previous feedforward step, the limits and μ.
#[derive(Clone)]
struct Case {
    s_mat: DMatrix<f64>,
    s_vec: DVector<f64>,
    lin: Linearization,
    d: CostDerivatives,
    running: f64,
    stochastic: bool,
    mu: f64,
    bounds: Bounds,
    u: DVector<f64>,
    l: DVector<f64>,
}

impl Case {
    fn new(nx: usize, nu: usize, seed: &mut u64) -> Self {
        let nw = 1 + (*seed >> 33) as usize % 3;
        let mut lin = Linearization::new(nx, nu, nw);
        lin.noise = [NoiseKind::None, NoiseKind::Additive, NoiseKind::Dependent]
            [(*seed >> 40) as usize % 3];
        lin.a = matrix(nx, nx, seed);
        lin.b = matrix(nx, nu, seed);
        lin.c = matrix(nx, nw, seed);
        for (cx, cu) in lin.cx.iter_mut().zip(&mut lin.cu) {
            *cx = matrix(nx, nx, seed);
            *cu = matrix(nx, nu, seed);
        }
        let mut d = CostDerivatives::new(nx, nu);
        d.lx = DVector::from_vec(entries(seed, nx));
        d.lu = DVector::from_vec(entries(seed, nu));
        d.lxx = matrix(nx, nx, seed);
        d.lux = matrix(nu, nx, seed);
        // A control Hessian that dominates half the time, so that the policy and the
        // value update are reached as well as the failure of the factorisation.
        d.luu = matrix(nu, nu, seed);
        if (*seed >> 50) & 1 == 0 {
            let big = DMatrix::identity(nu, nu) * 1e30;
            d.luu += &big;
        }
        let s = matrix(nx, nx, seed);
        let u = DVector::from_vec(entries(seed, nu));
        let half = DVector::from_vec(entries(seed, nu)).abs();
        let bounds = if (*seed >> 51) & 1 == 0 {
            Bounds::unbounded(nu)
        } else {
            Bounds {
                lower: (&u - &half).iter().copied().collect(),
                upper: (&u + &half).iter().copied().collect(),
            }
        };
        Case {
            // Symmetric as every `S_k` the value update makes, but a terminal Hessian need
            // not be: then the sparse pass reads the rows of `S` from its transpose.
            s_mat: if (*seed >> 54).is_multiple_of(4) {
                s
            } else {
                &s + s.transpose()
            },
            s_vec: DVector::from_vec(entries(seed, nx)),
            lin,
            d,
            running: entries(seed, 1)[0],
            stochastic: (*seed >> 52) & 1 == 0,
            mu: if (*seed >> 53) & 1 == 0 {
                0.0
            } else {
                entries(seed, 1)[0].abs()
            },
            bounds,
            u,
            l: DVector::from_vec(entries(seed, nu)),
        }
    }

    /// The knot by the nonzero patterns and nalgebra: `(Q_0, l, L, s, S, lᵀQ_u, lᵀQ_uu l)`
    /// as bits, or `None` when the policy fails.
    fn dynamic(&self) -> Option<Vec<u64>> {
        self.dynamic_within(0..self.lin.b.nrows())
    }

    /// [`Case::dynamic`] taking the columns of `l_xx` outside `hessian` as zero unread.
    fn dynamic_within(&self, hessian: std::ops::Range<usize>) -> Option<Vec<u64>> {
        let (nx, nu) = (self.lin.b.nrows(), self.lin.b.ncols());
        let mut bw = Backward::new(nx, nu);
        bw.s_vec.copy_from(&self.s_vec);
        let mut sp = SparseLinearization::new(nx, nu, self.lin.c.ncols());
        sp.assign(&self.lin, None);
        let s_next = self.s_mat.clone();
        let s_rows = s_next.transpose();
        let next = Next {
            s: &s_next,
            rows: if symmetric(&s_next) { &s_next } else { &s_rows },
        };
        let knot = KnotInputs {
            lin: &self.lin,
            d: &self.d,
            sp: &sp,
            hessian: &hessian,
        };
        let q0 = bw.q_function(next, knot, self.running, self.stochastic);
        bw.regularize(&sp.b, &self.lin, self.mu);
        let (mut l, mut gain) = (self.l.clone(), DMatrix::from_element(nu, nx, 7.0));
        policy::<MAX_QP>(
            bw.quu_reg.as_slice(),
            bw.qu.as_slice(),
            bw.qux_reg.as_slice(),
            &self.bounds,
            self.u.as_slice(),
            l.as_mut_slice(),
            gain.as_mut_slice(),
        )
        .then(|| {
            // Over a dirty matrix: the update writes every entry of S.
            let mut s_mat = DMatrix::from_element(nx, nx, f64::NAN);
            let (lqu, lquul) =
                bw.value_update((next, knot, self.stochastic), &l, &gain, &mut s_mat);
            let parts = [&[q0][..], l.as_slice(), gain.as_slice()];
            let rest = [bw.s_vec.as_slice(), s_mat.as_slice(), &[lqu, lquul]];
            parts
                .iter()
                .chain(&rest)
                .flat_map(|p| p.iter().map(|x| x.to_bits()))
                .collect()
        })
    }

    /// [`Case::fixed`] compiled for AVX2, as the backward pass runs it where the CPU has it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn fixed_avx2<const NX: usize, const NU: usize>(&self) -> Option<Vec<u64>> {
        self.fixed::<NX, NU>()
    }

    /// The knot on the stack for the CPU `wide` says, if it has AVX2 (else portably).
    fn fixed_on<const NX: usize, const NU: usize>(&self, wide: bool) -> Option<Vec<u64>> {
        #[cfg(target_arch = "x86_64")]
        if wide && crate::wide::available() {
            // SAFETY: the CPU reported AVX2.
            return unsafe { self.fixed_avx2::<NX, NU>() };
        }
        let _ = wide;
        self.fixed::<NX, NU>()
    }

    /// The same knot on the stack ([`super::super::knot`]).
    #[inline(always)]
    fn fixed<const NX: usize, const NU: usize>(&self) -> Option<Vec<u64>> {
        let mut v = Value::<NX> {
            s_mat: [[0.0; NX]; NX],
            s_vec: [0.0; NX],
        };
        v.s_mat
            .as_flattened_mut()
            .copy_from_slice(self.s_mat.as_slice());
        v.s_vec.copy_from_slice(self.s_vec.as_slice());
        let mut knot = Knot::<NX, NU>::EMPTY;
        let q0 = knot.expand(
            &v,
            (&self.lin, &self.d),
            self.running,
            self.stochastic,
            self.mu,
        );
        let (mut l, mut gain) = (self.l.clone(), DMatrix::from_element(NU, NX, 7.0));
        let (ls, gs) = (l.as_mut_slice(), gain.as_mut_slice());
        knot.policy(&self.bounds, self.u.as_slice(), ls, gs)
            .then(|| {
                let (lqu, lquul) = knot.value_update(ls, gs, &mut v);
                let parts = [&[q0][..], ls, gs, &v.s_vec, v.s_mat.as_flattened()];
                parts
                    .iter()
                    .chain(&[&[lqu, lquul][..]])
                    .flat_map(|p| p.iter().map(|x| x.to_bits()))
                    .collect()
            })
    }
}

/// The stack path ([`super::super::knot`]) against the dynamic path by nonzero patterns, on
/// random knots with exact zeros of both signs and values far apart in scale, with and
/// without noise of each kind, μ and limits: the same numbers to the bit, so the choice of
/// path cannot change a plan. The stack path both portable and compiled for AVX2 (where the
/// CPU has it: [`crate::wide`]).
#[test]
fn the_fixed_knot_matches_the_dynamic_one_bit_for_bit() {
    let mut seed = 7;
    for (nx, nu) in [(2, 1), (2, 2), (4, 2), (4, 4), (8, 4)] {
        let mut solved = 0;
        for _ in 0..400 {
            let case = Case::new(nx, nu, &mut seed);
            let dynamic = case.dynamic();
            for wide in [false, true] {
                let fixed = match (nx, nu) {
                    (2, 1) => case.fixed_on::<2, 1>(wide),
                    (2, 2) => case.fixed_on::<2, 2>(wide),
                    (4, 2) => case.fixed_on::<4, 2>(wide),
                    (4, 4) => case.fixed_on::<4, 4>(wide),
                    _ => case.fixed_on::<8, 4>(wide),
                };
                assert_eq!(fixed.is_some(), dynamic.is_some(), "{nx}x{nu}, wide {wide}");
                if let (Some(f), Some(d)) = (fixed, &dynamic) {
                    assert_eq!(&f, d, "{nx}x{nu}, wide {wide}");
                    solved += usize::from(wide);
                }
            }
        }
        // The comparison reached the value update often enough to mean something.
        assert!(
            solved >= 100,
            "{nx}x{nu}: only {solved} of 400 knots solved"
        );
    }
}

/// A cost Hessian that is zero outside its support (`Cost::hessian_support`, the delayed
/// plant's cost) gives the same knot to the bit whether its zero columns are read or taken as
/// zero, on the 42-state size and on the small ones; junk in those columns is not read.
#[test]
fn a_cost_hessian_taken_by_its_support_gives_the_same_knot() {
    let mut seed = 11;
    let mut solved = 0;
    for trial in 0..120 {
        let (nx, nu) = [(42, 2), (4, 2), (9, 3)][trial % 3];
        let mut case = Case::new(nx, nu, &mut seed);
        let h = 1 + trial % (nx - 1);
        for j in 0..nx {
            for i in 0..nx {
                if i >= h || j >= h {
                    case.d.lxx[(i, j)] = 0.0;
                }
            }
        }
        let whole = case.dynamic();
        let mut junk = case.clone();
        junk.d.lxx.columns_mut(h, nx - h).fill(f64::NAN);
        let within = junk.dynamic_within(0..h);
        assert_eq!(whole, within, "{nx}x{nu}, support 0..{h}");
        solved += usize::from(whole.is_some());
    }
    assert!(solved >= 30, "only {solved} of 120 knots solved");
}

/// `mul_nonzeros` gives `gemv`'s bits wherever the product is not zero, for noise columns
/// that are zero outside a plant block (the delayed plant's), dense, or zero altogether,
/// with exact zeros of both signs and values far apart in scale in `S`.
#[test]
fn the_product_over_the_nonzeros_is_gemv_to_the_bit() {
    let mut seed = 7;
    for trial in 0..200 {
        let n = [2, 4, 42][trial % 3];
        let s = matrix(n, n, &mut seed);
        let mut c = DVector::from_vec(entries(&mut seed, n));
        match trial % 4 {
            0 => c.rows_mut(2.min(n), n - 2.min(n)).fill(0.0),
            1 => c.fill(0.0),
            _ => {}
        }
        let mut want = DVector::zeros(n);
        want.gemv(1.0, &s, &c, 0.0);
        let mut got = DVector::from_element(n, f64::NAN);
        mul_nonzeros(&s, c.as_slice(), &mut got);
        for (g, w) in got.iter().zip(want.iter()) {
            if *w == 0.0 {
                assert_eq!(*g, 0.0, "trial {trial}");
            } else {
                assert_eq!(g.to_bits(), w.to_bits(), "trial {trial}: {g} vs {w}");
            }
        }
    }
}
