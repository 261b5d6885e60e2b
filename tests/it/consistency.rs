//! Statistical tests: a correctly tuned Kalman filter is consistent (its ANEES falls inside the
//! chi-square band) and a mistuned one is caught.
//!
//! # False-alarm rate
//! One study: `RUNS` independent runs of `STEPS` steps; at the last step the sum of the runs'
//! NEES is exactly chi-square with `RUNS * 4` degrees of freedom for a consistent filter, so the
//! ANEES falls outside its two-sided 95% band with probability 5%. The test runs `STUDIES`
//! independent studies (disjoint ChaCha streams of one seed) and requires at least
//! `MIN_INSIDE` of them inside: for a consistent filter the count is Binomial(40, 0.95) and
//! P(count <= 33) = 0.34%, the test's false-alarm rate over seeds. The seed is fixed, so the
//! outcome is reproducible; it was not chosen to pass.

use kalibra::filters::{Filter, Kf};
use kalibra::linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra::metrics::{ChiSquareBand, StepMean, nees};
use kalibra::models::{
    Kinematic, LinearGaussian, LinearObservation, Simulator, sample_with_factor,
};
use kalibra::sim::MonteCarlo;
use kalibra_studies::StudyError;

const RUNS: usize = 100;
const STEPS: usize = 30;
const STUDIES: usize = 40;
const MIN_INSIDE: usize = 34;

fn models(r: f64) -> (LinearGaussian<U4>, LinearObservation<U4, U2>) {
    let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
    (
        cv.dynamics(U4).unwrap(),
        cv.position_measurement(U4, U2, Matrix2::identity() * r)
            .unwrap(),
    )
}

/// Final-step ANEES of one study whose filter uses `r_filter` while the truth uses R = 100.
fn final_anees(study: usize, r_filter: f64) -> f64 {
    let (f, h_true) = models(100.0);
    let (_, h_filter) = models(r_filter);
    let m0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0));
    let l0 = p0.map(f64::sqrt);
    // Disjoint streams: study s uses streams s * RUNS .. (s + 1) * RUNS of seed 7.
    let mc = MonteCarlo::new(RUNS * STUDIES, 7);
    let acc = MonteCarlo::new(RUNS, 0)
        .accumulate(
            || StepMean::new(1),
            |run, _, acc| {
                let mut rng = mc.rng(study * RUNS + run);
                let x0 = m0 + sample_with_factor(&l0, &mut rng);
                let mut truth = Simulator::new(&f, &h_true, x0, 0)?;
                let mut kf = Kf::new(&f, &h_filter, m0, p0)?;
                for k in 0..STEPS {
                    let (x, z) = truth.step(&mut rng)?;
                    if k > 0 {
                        kf.predict()?;
                    }
                    let rec = kf.update(&z)?;
                    if k == STEPS - 1 {
                        acc.push(
                            0,
                            nees(&(x - rec.posterior().mean), &rec.posterior().cov)? / 4.0,
                        )?;
                    }
                }
                Ok::<(), StudyError>(())
            },
        )
        .unwrap();
    acc.mean(0).expect("every run pushed step 0")
}

#[test]
fn anees_of_a_correctly_tuned_kf_is_inside_its_95_percent_band() {
    let band = ChiSquareBand::for_normalized_mean(4.0, RUNS, 0.95).unwrap();
    let values: Vec<f64> = (0..STUDIES).map(|s| final_anees(s, 100.0)).collect();
    let inside = values.iter().filter(|v| band.contains(**v)).count();
    assert!(
        inside >= MIN_INSIDE,
        "{inside}/{STUDIES} inside [{:.3}, {:.3}]: {values:?}",
        band.lower,
        band.upper
    );
}

#[test]
fn an_overconfident_kf_is_caught() {
    // The filter believes R is 4 times smaller than it is: its covariance is too small and
    // its ANEES far above the band in essentially every study.
    let band = ChiSquareBand::for_normalized_mean(4.0, RUNS, 0.95).unwrap();
    let above = (0..10)
        .filter(|&s| final_anees(s, 25.0) > band.upper)
        .count();
    assert_eq!(above, 10);
}
