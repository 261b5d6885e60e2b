//! A Monte Carlo study gives bit-identical results whatever the thread count.

use kalibra_studies::w1;

#[test]
fn w1_is_bit_identical_for_1_2_and_8_threads() {
    let base = w1::Config {
        runs: 150,
        steps: 60,
        ..w1::Config::quick()
    };
    let run = |threads| {
        let mut r = w1::run(&w1::Config { threads, ..base }).unwrap();
        // The report records the thread count; everything else must match bit for bit.
        r.config.threads = 0;
        r
    };
    let one = run(1);
    let two = run(2);
    let eight = run(8);
    assert_eq!(one, two);
    assert_eq!(one, eight);
    // And the study is not trivially constant: another seed gives other numbers.
    let other = w1::run(&w1::Config {
        seed: base.seed + 1,
        threads: 2,
        ..base
    })
    .unwrap();
    assert_ne!(one.anees, other.anees);
}

/// A Monte Carlo study on `Dyn` sizes that run through faer is bit-identical for 1,
/// 2 and 8 threads too: every run's kernels run sequentially on whichever thread holds it.
#[test]
fn faer_sized_runs_are_bit_identical_for_1_2_and_8_threads() {
    use kalibra::filters::{Filter, Kf};
    use kalibra::linalg::{DMatrix, DVector, FAER_MIN_DIM};
    use kalibra::models::{LinearGaussian, LinearObservation, simulate};
    use kalibra::sim::MonteCarlo;

    let n = 2 * FAER_MIN_DIM;
    let m = n / 4;
    let wave = |i: usize, j: usize| ((i * 7 + j * 3) as f64).sin();
    let f = DMatrix::from_fn(n, n, |i, j| {
        0.02 * wave(i, j) + if i == j { 0.9 } else { 0.0 }
    });
    let spd = |k: usize| DMatrix::from_fn(k, k, |i, j| if i == j { 2.0 } else { 0.5 / k as f64 });
    let dynamics = LinearGaussian::new(f, spd(n) * 0.1).unwrap();
    let measurement = LinearObservation::new(DMatrix::from_fn(m, n, wave), spd(m)).unwrap();
    let run = |threads| {
        MonteCarlo::new(12, 7)
            .threads(threads)
            .map(|_, rng| {
                let truth = simulate(&dynamics, &measurement, DVector::zeros(n), 20, rng)?;
                let mut kf = Kf::new(&dynamics, &measurement, DVector::zeros(n), spd(n)).unwrap();
                let mut nees = Vec::new();
                for (x, z) in truth.states.iter().zip(&truth.measurements) {
                    kf.predict().unwrap();
                    let rec = kf.update(z).unwrap();
                    nees.push(rec.nees(&(x - &rec.posterior().mean)).unwrap());
                }
                Ok::<_, kalibra::models::ModelError>((nees, kf.covariance().clone()))
            })
            .unwrap()
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(8));
}
