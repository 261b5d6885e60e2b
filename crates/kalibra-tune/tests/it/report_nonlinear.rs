//! The report of maximum likelihood through the EKF and the UKF
//! (`NoiseReport::estimate_nonlinear`): a profile likelihood per free parameter whose interval
//! holds the estimate and agrees with the observed information's, and the problem's own filter
//! judged on the data with the estimate and with the starting guess.

use kalibra_filters::SigmaSet;
use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_models::{LinearGaussian, LinearObservation};
use kalibra_tune::{
    CovarianceForm, LikelihoodFilter, MaximumLikelihood, MethodKind, NoiseReport,
    NonlinearNoiseProblem, Parametrisation, ReportOptions, Run, Start,
};
use rand::RngExt;
use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
use rand_distr::StandardNormal;

type Walk = NonlinearNoiseProblem<Dyn, Dyn, LinearGaussian<Dyn>, LinearObservation<Dyn, Dyn>>;

/// A scalar random walk `x_k = x_{k-1} + w`, `z_k = x_k + v` with `q = 0.5`, `r = 2` (300
/// steps), as truth and measurements.
fn walk_log(seed: u64) -> (Run, Run) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = 0.0f64;
    (0..300)
        .map(|_| {
            let w: f64 = rng.sample(StandardNormal);
            let e: f64 = rng.sample(StandardNormal);
            x += 0.5f64.sqrt() * w;
            (
                Some(DVector::from_element(1, x)),
                Some(DVector::from_element(1, x + 2f64.sqrt() * e)),
            )
        })
        .unzip()
}

/// The walk as a model for the EKF or the UKF; the starting guess `q = 0.05`, `r = 1` is ten
/// times too small in `q`.
fn walk(filter: LikelihoodFilter, zs: Run) -> Walk {
    let one = |v: f64| DMatrix::from_element(1, 1, v);
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(0.05)),
        CovarianceForm::scaled(one(1.0)),
    )
    .unwrap();
    NonlinearNoiseProblem::new(
        LinearGaussian::new(one(1.0), one(1.0)).unwrap(),
        LinearObservation::new(one(1.0), one(1.0)).unwrap(),
        filter,
        DVector::zeros(1),
        one(1.0),
        Start::PredictFirst,
        noise,
        vec![zs],
    )
    .unwrap()
}

/// Through the EKF: every parameter has a profile with the estimate at its peak; its
/// likelihood-ratio interval holds the estimate and each end lies within 20% of the width of
/// the observed information's 95% interval from that interval's end. Both intervals are
/// exact to first order in `1 / sqrt(N)` and differ by the log-likelihood's skewness, which
/// on 300 measurements moves the ends by a few per cent of the width (the 20% leaves room for
/// the profile's linear interpolation between grid points half a standard error apart). The
/// filter with the estimate and with the starting guess both have ANIS with its band,
/// whiteness, and with the truth ANEES and RMSE; the estimate's RMSE is smaller.
#[test]
fn ekf_report_has_profiles_and_consistency() {
    let (truth, zs) = walk_log(11);
    let problem = walk(LikelihoodFilter::Ekf, zs);
    let truth = [truth];
    let report = NoiseReport::estimate_nonlinear(
        &problem,
        &MaximumLikelihood::new(),
        ReportOptions::new(),
        Some(&truth),
    )
    .unwrap();
    assert_eq!(report.method, MethodKind::Ml);
    assert!(report.converged);
    let ll = report.log_likelihood.unwrap();
    assert!(ll > report.start_log_likelihood.unwrap());
    assert_eq!(report.parameters.len(), 2);
    for p in &report.parameters {
        let profile = p.profile.as_ref().unwrap_or_else(|| panic!("{}", p.name));
        let best = profile
            .points
            .iter()
            .filter_map(|pt| pt.log_likelihood)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!((best - ll).abs() < 1e-6, "{}: {best} vs {ll}", p.name);
        let [Some(lo), Some(hi)] = profile.interval else {
            panic!("{}: {:?}", p.name, profile.interval)
        };
        assert!(
            lo < p.value && p.value < hi,
            "{}: {lo} {} {hi}",
            p.name,
            p.value
        );
        let [wlo, whi] = p.ci95.unwrap();
        let width = whi - wlo;
        assert!(
            (lo - wlo).abs() < 0.2 * width && (hi - whi).abs() < 0.2 * width,
            "{}: profile [{lo}, {hi}], information [{wlo}, {whi}]",
            p.name
        );
    }
    for check in [&report.consistency.estimate, &report.consistency.start] {
        let check = check.as_ref().unwrap();
        assert!(check.anis.is_some() && check.whiteness.is_some());
        assert!(check.anees.is_some() && check.rmse.is_some());
    }
    let rmse = |c: &Option<kalibra_tune::FilterCheck>| c.as_ref().unwrap().rmse.unwrap();
    assert!(rmse(&report.consistency.estimate) < rmse(&report.consistency.start));
    assert!(report.warnings.iter().any(|w| w.contains("EKF's Gaussian")));
}

/// Through the UKF with the profiles turned off: no profile is computed, the consistency of
/// both filters is still there, and the estimate is the EKF's (the same linear model).
#[test]
fn ukf_report_without_profiles() {
    let (_, zs) = walk_log(12);
    let options = ReportOptions::new().profile(false);
    let ml = MaximumLikelihood::new();
    let ukf = walk(LikelihoodFilter::Ukf(SigmaSet::recommended(1)), zs.clone());
    let report = NoiseReport::estimate_nonlinear(&ukf, &ml, options, None).unwrap();
    assert!(report.parameters.iter().all(|p| p.profile.is_none()));
    let estimate = report.consistency.estimate.as_ref().unwrap();
    assert!(estimate.anis.is_some() && estimate.anees.is_none());
    assert!(report.consistency.start.as_ref().unwrap().anis.is_some());
    let ekf = walk(LikelihoodFilter::Ekf, zs);
    let other = NoiseReport::estimate_nonlinear(&ekf, &ml, options, None).unwrap();
    for (a, b) in report.parameters.iter().zip(&other.parameters) {
        assert!(
            (a.value - b.value).abs() < 1e-4 * b.value,
            "{} {}",
            a.value,
            b.value
        );
    }
}
