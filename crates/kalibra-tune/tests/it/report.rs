//! The report of every method, its profile likelihood and its consistency check, and the bad
//! inputs: each a typed error or a clear message, never a panic or a silent estimate.

use crate::common::{System, one};
use kalibra_tune::{
    Als, CovarianceForm, DMatrix, DVector, Em, LikelihoodError, MaximumLikelihood, Method,
    MethodKind, NoiseError, NoiseProblem, NoiseReport, ParameterSweep, Parametrisation,
    ReportError, ReportOptions, Run, Start, log_likelihood,
};

/// A scalar random walk seen in noise.
fn walk(q: f64, r: f64) -> System {
    System {
        f: one(1.0),
        g: one(1.0),
        qw: one(q),
        h: one(1.0),
        r: one(r),
        x0: DVector::zeros(1),
    }
}

fn scaled_problem(runs: Vec<Run>) -> NoiseProblem {
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(1.0)),
        CovarianceForm::scaled(one(1.0)),
    )
    .unwrap();
    NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(0.0),
        Start::PredictFirst,
        noise,
        runs,
    )
    .unwrap()
}

fn ml() -> Method {
    Method::MaximumLikelihood(MaximumLikelihood::new())
}

/// Every method fills the same fields; the likelihood methods agree, and their profiles
/// peak at the estimate and cross the threshold near the interval's ends.
#[test]
fn every_method_reports_in_one_schema() {
    let (zs, xs) = walk(0.5, 1.0).simulate(300, 5);
    let problem = scaled_problem(vec![zs]);
    let truth = vec![xs];
    let ml = NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), Some(&truth)).unwrap();
    assert_eq!(ml.method, MethodKind::Ml);
    assert!(ml.converged && ml.iterations > 0, "{:?}", ml.warnings);
    assert!(ml.warnings.is_empty(), "{:?}", ml.warnings);
    let names: Vec<&str> = ml.parameters.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["q", "r"]);
    assert_eq!(ml.q, vec![vec![ml.parameters[0].value]]);
    assert_eq!(ml.r, vec![vec![ml.parameters[1].value]]);
    let id = ml.identifiability.as_ref().unwrap();
    assert_eq!((id.rank, id.parameters), (2, 2));
    assert!(id.unidentifiable.is_empty() && id.condition.is_some());
    let (ll, start_ll) = (ml.log_likelihood.unwrap(), ml.start_log_likelihood.unwrap());
    assert!(ll >= start_ll);
    for p in &ml.parameters {
        let [lo, hi] = p.ci95.unwrap();
        assert!(lo < p.value && p.value < hi, "{p:?}");
        let prof = p.profile.as_ref().unwrap();
        assert_eq!(prof.points.len(), kalibra_tune::PROFILE_POINTS);
        // The profile's maximum is the estimate, up to the optimisers' tolerance.
        let best = prof
            .points
            .iter()
            .filter_map(|q| q.log_likelihood)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            best - ll < 1e-4,
            "{}: profile {best} above ln L {ll}",
            p.name
        );
        assert!(prof.points.first().unwrap().value < lo && hi < prof.points.last().unwrap().value);
        // The likelihood-ratio interval is close to the Wald one on the log scale.
        let [Some(llo), Some(lhi)] = prof.interval else {
            panic!(
                "{}: the profile does not cross its threshold: {prof:?}",
                p.name
            )
        };
        for (a, b) in [(llo, lo), (lhi, hi)] {
            assert!(
                (a.ln() - b.ln()).abs() < 0.25,
                "{}: LR {a} vs Wald {b}",
                p.name
            );
        }
    }
    // Consistency: the tuned filter is consistent on its own data; with the truth, ANEES
    // and RMSE are there.
    let check = ml.consistency.estimate.as_ref().unwrap();
    let anis = check.anis.as_ref().unwrap();
    assert!(anis.band.unwrap().contains(anis.value), "{anis:?}");
    assert!(check.whiteness.as_ref().unwrap().white);
    assert!(check.anees.is_some() && check.rmse.unwrap() > 0.0);
    assert_eq!(check.rmse_per_component.len(), 1);
    assert!(ml.consistency.start.is_some());
    let json = serde_json::to_value(&ml).unwrap();
    for key in [
        "method",
        "log_likelihood",
        "q",
        "qw",
        "r",
        "parameters",
        "converged",
        "iterations",
        "identifiability",
        "warnings",
        "consistency",
    ] {
        assert!(json.get(key).is_some(), "report.json lacks {key}");
    }
    assert_eq!(json["method"], "ml");
    let words = ml.summary();
    assert!(
        words.starts_with("Maximum likelihood recommends q = ")
            && words.contains("95% interval")
            && words.contains("the starting guess's 0."),
        "{words}"
    );
    assert!(json["parameters"][0]["ci95"].is_array());

    let em = NoiseReport::estimate(
        &problem,
        &Method::Em(Em::new()),
        ReportOptions::new().profile(false),
        None,
    )
    .unwrap();
    assert_eq!(em.method, MethodKind::Em);
    assert!(em.converged);
    assert!((em.log_likelihood.unwrap() - ll).abs() < 1e-3);
    for (a, b) in em.parameters.iter().zip(&ml.parameters) {
        assert!((a.value - b.value).abs() < 0.02 * b.value, "{a:?} vs {b:?}");
        assert!(a.ci95.is_some() && a.profile.is_none());
    }
    assert!(em.consistency.estimate.as_ref().unwrap().anees.is_none());

    let als = NoiseReport::estimate(
        &problem,
        &Method::Als(Als::new()),
        ReportOptions::new(),
        None,
    )
    .unwrap();
    assert_eq!(als.method, MethodKind::Als);
    assert!(als.parameters.iter().all(|p| p.ci95.is_none()));
    assert_eq!(
        als.identifiability.as_ref().unwrap().source,
        "least-squares matrix"
    );

    let j = NoiseReport::estimate(
        &problem,
        &Method::J1J2(ParameterSweep::new()),
        ReportOptions::new(),
        None,
    )
    .unwrap();
    assert_eq!(j.method, MethodKind::J1j2);
    assert_eq!(j.j1j2.as_ref().unwrap().len(), 2);
    assert!(j.warnings.iter().any(|w| w.contains("not found jointly")));
    assert!(j.identifiability.is_none());
    assert!(
        j.parameters
            .iter()
            .all(|p| p.ci95.is_none() && p.at_bound.is_none())
    );
    assert!(j.log_likelihood.unwrap() <= ll + 1e-6);
}

/// More parameters than innovations can identify are refused with the reason.
#[test]
fn an_unidentifiable_parametrisation_is_refused_with_the_reason() {
    // n = 2, m = 1: at most 2 + 1 = 3; a full Qw (3) and a scaled R (1) ask for 4.
    let err = Parametrisation::new(
        None,
        CovarianceForm::full(DMatrix::identity(2, 2)),
        CovarianceForm::scaled(one(1.0)),
    )
    .unwrap_err();
    assert!(matches!(
        err,
        NoiseError::TooManyParameters {
            free: 4,
            limit: 3,
            ..
        }
    ));
    assert!(err.to_string().contains("n m + m (m + 1) / 2 = 3"), "{err}");
    // Fewer scalar measurements than parameters.
    let problem = scaled_problem(vec![vec![Some(DVector::from_element(1, 0.3)), None]]);
    let err = NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), None).unwrap_err();
    assert!(
        matches!(
            err,
            ReportError::TooFewMeasurements {
                measurements: 1,
                parameters: 2
            }
        ),
        "{err}"
    );
}

/// An optimiser stopped early says so: converged is false and a warning tells why.
#[test]
fn non_convergence_is_a_warning() {
    let (zs, _) = walk(0.5, 1.0).simulate(100, 11);
    let problem = scaled_problem(vec![zs]);
    let ml = Method::MaximumLikelihood(MaximumLikelihood::new().max_iterations(1));
    let report = NoiseReport::estimate(&problem, &ml, ReportOptions::new(), None).unwrap();
    assert!(!report.converged);
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("did not converge") && w.contains("iteration limit")),
        "{:?}",
        report.warnings
    );
    // Exactly 2 iterations count as converged for EM, but its point is not the maximum the
    // intervals are centred on: none are given, and the warning says how far off it is.
    let exact = Method::Em(Em::new().exact_iterations(2));
    let report = NoiseReport::estimate(&problem, &exact, ReportOptions::new(), None).unwrap();
    assert!(report.converged && report.parameters.iter().all(|p| p.ci95.is_none()));
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("standard errors from the likelihood's maximum")),
        "{:?}",
        report.warnings
    );
    let em = Method::Em(Em::new().max_iterations(2));
    let report = NoiseReport::estimate(&problem, &em, ReportOptions::new(), None).unwrap();
    assert!(!report.converged && report.iterations == 2);
    assert!(report.parameters.iter().all(|p| p.ci95.is_none()));
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("EM did not converge")),
        "{:?}",
        report.warnings
    );
}

/// A walk without process noise: q runs to 0, the warning names it, and the identifiability
/// says what the data show (q cannot be told from 0; r is identified), not a combination
/// "mostly r".
#[test]
fn a_parameter_at_its_bound_is_named_and_not_misread() {
    let (zs, _) = walk(0.0, 1.0).simulate(200, 3);
    let problem = scaled_problem(vec![zs]);
    let report = NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), None).unwrap();
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.starts_with("q ran to its bound 0")),
        "{:?}",
        report.warnings
    );
    let q = &report.parameters[0];
    assert_eq!(q.at_bound, Some(kalibra_tune::Bound::Zero));
    let id = report.identifiability.as_ref().unwrap();
    assert_eq!(id.unidentifiable, ["q"], "{}", id.message);
    assert!(
        id.message
            .contains("q is at its bound 0: the data cannot tell it from 0"),
        "{}",
        id.message
    );
    assert!(id.message.contains("r is identified"), "{}", id.message);
    // r keeps its interval, and it covers the truth.
    let [lo, hi] = report.parameters[1].ci95.unwrap();
    assert!(lo < 1.0 && 1.0 < hi, "r in [{lo}, {hi}]");
    // The profile of q gives the upper limit the data put on it.
    let prof = q.profile.as_ref().unwrap();
    assert!(prof.interval[1].is_some(), "{prof:?}");
}

/// A candidate with a singular `S` (a full R whose factor loses its second pivot to
/// rounding, seen directly with P0 = 0) is refused by the likelihood with a typed error; the
/// estimator treats it as infeasible and backs off, and the report comes out.
#[test]
fn a_singular_s_at_a_candidate_is_backed_off() {
    let noise = Parametrisation::new(
        None,
        CovarianceForm::fixed(DMatrix::identity(2, 2) * 0.1),
        CovarianceForm::full(DMatrix::identity(2, 2)),
    )
    .unwrap();
    let sys = System {
        f: DMatrix::identity(2, 2),
        g: DMatrix::identity(2, 2),
        qw: DMatrix::identity(2, 2) * 0.1,
        h: DMatrix::identity(2, 2),
        r: DMatrix::from_row_slice(2, 2, &[1.0, 0.3, 0.3, 1.0]),
        x0: DVector::zeros(2),
    };
    let (zs, _) = sys.simulate(150, 9);
    let problem = NoiseProblem::new(
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        DVector::zeros(2),
        DMatrix::zeros(2, 2),
        Start::UpdateFirst,
        noise,
        vec![zs],
    )
    .unwrap();
    // theta = (ln L00, L10, ln L11) = (0, 1e3, ln 1e-6): R = [[1, 1e3], [1e3, 1e6 + 1e-12]],
    // whose 1e-12 is lost to rounding, so R (and S = R at the first update) is singular.
    let singular = [0.0, 1e3, 1e-6_f64.ln()];
    let err = log_likelihood(&problem, &singular).unwrap_err();
    assert!(
        matches!(err, LikelihoodError::Filter { run: 0, .. }),
        "{err}"
    );
    // Started there, the estimator refuses with the typed error of the likelihood.
    let err = MaximumLikelihood::new()
        .starts(vec![DVector::from_row_slice(&singular)])
        .estimate(&problem);
    assert!(
        matches!(
            err,
            Err(kalibra_tune::MlError::Start(LikelihoodError::Filter {
                run: 0,
                ..
            }))
        ),
        "{err:?}"
    );
    // Started next to it, where the first trial steps fall into it, the line search backs
    // off (an infeasible trial counts as +infinity).
    let near = [0.0, 1e3, 1e-4_f64.ln()];
    assert!(log_likelihood(&problem, &near).is_ok());
    let method = Method::MaximumLikelihood(
        MaximumLikelihood::new().starts(vec![DVector::from_row_slice(&near)]),
    );
    let options = ReportOptions::new().profile(false);
    let report = NoiseReport::estimate(&problem, &method, options, None).unwrap();
    assert!(report.log_likelihood.unwrap() > log_likelihood(&problem, &near).unwrap());
}

/// NaN measurements are a typed error naming the run and step; missing ones (`None`) are
/// skipped by the filter, and the report runs on the rest.
#[test]
fn nan_and_missing_measurements() {
    let (mut zs, xs) = walk(0.5, 1.0).simulate(120, 21);
    let mut bad = zs.clone();
    bad[17] = Some(DVector::from_element(1, f64::NAN));
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(1.0)),
        CovarianceForm::scaled(one(1.0)),
    )
    .unwrap();
    let err = NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(0.0),
        Start::PredictFirst,
        noise,
        vec![zs.clone(), bad],
    )
    .unwrap_err();
    assert_eq!(err, NoiseError::NonFiniteMeasurement { run: 1, step: 17 });
    assert!(err.to_string().contains("run 1, step 17"), "{err}");
    for k in (0..zs.len()).step_by(3) {
        zs[k] = None;
    }
    let problem = scaled_problem(vec![zs]);
    let report = NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), Some(&[xs])).unwrap();
    assert!(report.converged, "{:?}", report.warnings);
    assert!(report.consistency.estimate.unwrap().anees.is_some());
    // A truth that does not fit is a typed error.
    let short = vec![vec![Some(DVector::zeros(1)); 5]];
    let err =
        NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), Some(&short)).unwrap_err();
    assert!(
        matches!(err, ReportError::TruthLength { run: 0, .. }),
        "{err}"
    );
    let mut nan_truth = vec![vec![None; 120]];
    nan_truth[0][4] = Some(DVector::from_element(1, f64::NAN));
    let err =
        NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), Some(&nan_truth)).unwrap_err();
    assert!(
        matches!(
            err,
            ReportError::TruthValue {
                run: 0,
                step: 4,
                ..
            }
        ),
        "{err}"
    );
}

/// The profile of every entry of a full `R`, its covariance among them: the entry is held by
/// fixing it in the form, the others re-maximised; the profile peaks at the estimate and its
/// likelihood-ratio interval is close to the Wald one.
#[test]
fn a_full_form_is_profiled_entry_by_entry() {
    let sys = System {
        f: DMatrix::identity(2, 2),
        g: DMatrix::identity(2, 2),
        qw: DMatrix::identity(2, 2) * 0.3,
        h: DMatrix::identity(2, 2),
        r: DMatrix::from_row_slice(2, 2, &[1.0, 0.6, 0.6, 2.0]),
        x0: DVector::zeros(2),
    };
    let (zs, _) = sys.simulate(300, 4);
    let noise = Parametrisation::new(
        None,
        CovarianceForm::fixed(DMatrix::identity(2, 2) * 0.3),
        CovarianceForm::full(DMatrix::identity(2, 2)),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        DVector::zeros(2),
        DMatrix::zeros(2, 2),
        Start::PredictFirst,
        noise,
        vec![zs],
    )
    .unwrap();
    let report = NoiseReport::estimate(&problem, &ml(), ReportOptions::new(), None).unwrap();
    let ll = report.log_likelihood.unwrap();
    let names: Vec<&str> = report.parameters.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["R[0,0]", "R[1,0]", "R[1,1]"]);
    for p in &report.parameters {
        let prof = p.profile.as_ref().unwrap();
        assert!(prof.points.windows(2).all(|w| w[0].value < w[1].value));
        let lls: Vec<f64> = prof
            .points
            .iter()
            .map(|q| q.log_likelihood.unwrap())
            .collect();
        let best = lls.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(
            best - ll < 1e-4,
            "{}: profile {best} above ln L {ll}",
            p.name
        );
        // Rising to the estimate and falling after it.
        let centre = kalibra_tune::PROFILE_POINTS / 2;
        assert!(
            lls[..centre].windows(2).all(|w| w[0] < w[1] + 1e-6),
            "{}",
            p.name
        );
        assert!(
            lls[centre..].windows(2).all(|w| w[0] + 1e-6 > w[1]),
            "{}",
            p.name
        );
        let [lo, hi] = p.ci95.unwrap();
        let [Some(llo), Some(lhi)] = prof.interval else {
            panic!("{}: no crossing: {prof:?}", p.name)
        };
        let width = hi - lo;
        assert!(
            (llo - lo).abs() < 0.2 * width && (lhi - hi).abs() < 0.2 * width,
            "{}: LR [{llo}, {lhi}] vs Wald [{lo}, {hi}]",
            p.name
        );
    }
}
