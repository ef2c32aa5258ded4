//! Seeded randomness shared by every simulation of the stochastic plant: the offline Monte Carlo,
//! the lockstep pair and the live board draw the same noise for the same `(seed, trial)`.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};

/// The random stream of one trial: SplitMix64 of the seed and the trial index, so results do not
/// depend on how many threads run the trials or in which order.
pub fn trial_rng(seed: u64, trial: u64) -> Xoshiro256PlusPlus {
    let mut z = seed ^ trial.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    Xoshiro256PlusPlus::seed_from_u64(z ^ (z >> 31))
}

/// The noise increment of one Euler–Maruyama step (paper Eq. 10): `next += √Δ F(x, u) ε`,
/// `ε ~ N(0, I)`, with `gain = √Δ F` stored column-major (`nx × nw`, channel `i` in
/// `gain[i nx .. (i + 1) nx]`). One standard normal is drawn per channel, in channel order.
///
/// Allocates nothing: the board calls it at every tick.
pub fn add_diffusion<R: rand::Rng + ?Sized>(
    next: &mut [f64],
    gain: &[f64],
    nx: usize,
    nw: usize,
    rng: &mut R,
) {
    for ch in 0..nw {
        let e: f64 = StandardNormal.sample(rng);
        let column = &gain[ch * nx..(ch + 1) * nx];
        for (n, g) in next[..nx].iter_mut().zip(column) {
            *n += g * e;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Same numbers as drawing every ε first and adding `G ε` with a matrix-vector product.
    #[test]
    fn diffusion_equals_the_matrix_product() {
        let (nx, nw) = (4, 3);
        let g = DMatrix::from_fn(nx, nw, |r, c| 0.1 * (r as f64 + 1.0) - 0.07 * c as f64);
        let mut a = DVector::from_fn(nx, |r, _| r as f64 * 0.3);
        let mut b = a.clone();
        add_diffusion(a.as_mut_slice(), g.as_slice(), nx, nw, &mut trial_rng(7, 3));
        let mut rng = trial_rng(7, 3);
        let eps = DVector::from_fn(nw, |_, _| StandardNormal.sample(&mut rng));
        b.gemv(1.0, &g, &eps, 1.0);
        assert_eq!(a, b);
    }

    #[test]
    fn trials_have_distinct_streams() {
        let x: f64 = StandardNormal.sample(&mut trial_rng(1, 0));
        let y: f64 = StandardNormal.sample(&mut trial_rng(1, 1));
        assert_ne!(x, y);
    }
}
