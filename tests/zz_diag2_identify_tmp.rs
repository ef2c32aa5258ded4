#[allow(dead_code)]
#[path = "/tmp/diagcrate/identify_v1.rs"]
mod identify;
use identify::*;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
#[test]
fn diag2() {
    let mut rej = 0;
    let mut ks = vec![];
    for seed in 1000..1150u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let qd: Vec<f64> = (0..20000).map(|_| rng.random_range(-2.0..2.0)).collect();
        let eta: Vec<f64> = (0..20000).map(|_| rng.sample(StandardNormal)).collect();
        let e: Vec<f64> = qd
            .iter()
            .zip(&eta)
            .map(|(&v, n)| (0.15 + 0.37 * v) * n)
            .collect();
        let f = fit_noise_ml(&qd, &e).unwrap();
        let et: Vec<f64> = qd
            .iter()
            .zip(&e)
            .map(|(v, x)| x / (f.a + f.b * v))
            .collect();
        let jb = jarque_bera(&et).unwrap();
        let jt = jarque_bera(&eta).unwrap();
        if jb.p_value < 0.05 {
            rej += 1;
            ks.push((
                seed,
                jb.kurtosis,
                jt.kurtosis,
                jb.p_value,
                jt.p_value,
                f.a,
                f.b,
            ));
        }
    }
    println!("rej {rej}/150");
    for k in ks {
        println!("{k:?}");
    }
}
