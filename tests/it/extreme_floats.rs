//! Finite but extreme floating-point data, through every public function of the library crates
//! that takes it: values spread over the whole exponent range (subnormals to `f64::MAX`), pairs
//! of opposite signs near the limits, intervals near the smallest normal number. The promise:
//! a finite input whose true result is representable gives a finite, correct answer, and
//! otherwise a typed error; never `Ok` holding an infinity or NaN the inputs did not contain.
//!
//! `every_float_function_is_listed` checks [`FLOAT_FUNCTIONS`] against the public functions
//! that the source scan (`extreme/mod.rs`) finds taking `f64` data, so a new one fails it until
//! it is driven here or listed with the reason it is not.
//!
//! Size: `CASES` (256) cases for each of the 6 properties;
//! `PROPTEST_CASES` overrides the count.

use crate::extreme;

use crate::extreme::{Cover, Finite};
use kalibra::bounds::{
    Ellipsoid, ErgodicAverage, Pcrlb, Surrogate, gaussian_half_widths,
    observability_singular_values,
};
use kalibra::eval::{Evaluation, FilterLog, Matrices, Vectors};
use kalibra::filters::{KappaGrid, SigmaSet, shifted_rayleigh_moments};
use kalibra::linalg::{
    Covariance, DMatrix, DVector, Definiteness, Dyn, Gaussian, Matrix2, Matrix3, PsdMatrix,
    SMatrix, SVector, Vector1, Vector2, all_finite, binary_exponent, check_covariance,
    check_finite, check_symmetric, discrete_lyapunov, ldexp, quad_form_once, quad_form_symmetric,
    semidefinite_factor, sigma_sqrt, spectral_radius,
};
use kalibra::metrics::{
    ChiSquareBand, Credibility, SquaredErrors, StepMean, batch_means, instantaneous_errors, itse,
    j_step, ks_asymptotic_p, ks_two_sample, ks_two_sample_exact_p, median, nees, nis,
    normalized_innovation, paired_t_test, rmse, rmse_per_state, runs_test, sliding_window,
    time_average, whiteness,
};
use kalibra::models::{
    AngularTarget, BearingReference, Kinematic, LinearGaussian, LinearObservation, Order,
    wrap_angle,
};
use kalibra::tune::{grid, p_ad, q_ad, two_point_init};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

/// Cases per property.
const CASES: u32 = 256;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(CASES),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

// ----- strategies -------------------------------------------------------------------------

/// A finite value anywhere in f64's range: a uniform binary exponent from -1074 (subnormal) to
/// 1023, the limits themselves, and ordinary values.
fn wide() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => (any::<bool>(), 1.0..2.0f64, -1074i32..=1023).prop_map(|(neg, m, e)| {
            let v = ldexp(m, e);
            if neg { -v } else { v }
        }),
        1 => Just(f64::MAX),
        1 => Just(-f64::MAX),
        1 => Just(1e308),
        1 => Just(-1e308),
        1 => Just(f64::MIN_POSITIVE),
        1 => Just(5e-324),
        1 => Just(-5e-324),
        1 => Just(0.0),
        3 => -10.0..10.0f64,
    ]
}

/// A value near the limit, `[1e307, f64::MAX]`, with either sign.
fn huge() -> impl Strategy<Value = f64> {
    (any::<bool>(), 1e307..f64::MAX).prop_map(|(neg, v)| if neg { -v } else { v })
}

/// Two values of opposite signs near the limit, whose difference overflows.
fn opposite() -> impl Strategy<Value = (f64, f64)> {
    (1e308..f64::MAX, 1e308..f64::MAX).prop_map(|(a, b)| (a, -b))
}

/// A positive interval: near the smallest normal number, subnormal, or anywhere.
fn interval() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => (1.0..8.0f64).prop_map(|m| m * f64::MIN_POSITIVE),
        1 => Just(f64::MIN_POSITIVE),
        1 => Just(5e-324),
        1 => Just(1e-310),
        2 => wide().prop_map(f64::abs).prop_filter("positive", |v| *v > 0.0),
        1 => 0.01..10.0f64,
    ]
}

/// A confidence level: ordinary, tiny, or the largest f64 below 1 (whose `(1 + c) / 2` rounds
/// to 1).
fn confidence() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.95), Just(1.0 - f64::EPSILON / 2.0), 1e-300..1.0f64]
}

/// A series of wide values, or of ordinary values with opposite huge ones mixed in.
fn series() -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        2 => prop::collection::vec(wide(), 1..24),
        1 => prop::collection::vec(huge(), 1..24),
        1 => (prop::collection::vec(-10.0..10.0f64, 2..24), opposite()).prop_map(|(mut v, (a, b))| {
            v[0] = a;
            let last = v.len() - 1;
            v[last] = b;
            v
        }),
        1 => (prop::collection::vec(1.0..2.0f64, 1..24), -1074i32..=1023)
            .prop_map(|(v, e)| v.into_iter().map(|x| ldexp(x, e)).collect()),
    ]
}

/// An `n x n` symmetric positive definite matrix at a scale from subnormal to near `f64::MAX`,
/// or a symmetric matrix of wide entries.
fn spd(n: usize) -> impl Strategy<Value = DMatrix<f64>> {
    (
        prop::collection::vec(-1.0..1.0f64, n * n),
        -1074i32..=1020,
        prop::collection::vec(wide(), n * n),
        0u8..4,
    )
        .prop_map(move |(v, e, w, kind)| {
            let a = DMatrix::from_vec(n, n, v);
            let base = &a * a.transpose() + DMatrix::identity(n, n);
            match kind {
                0 | 1 => base.map(|x| ldexp(x, e)),
                2 => {
                    let w = DMatrix::from_vec(n, n, w).map(|x| x * 0.5);
                    &w + w.transpose()
                }
                _ => DMatrix::from_fn(n, n, |i, j| if i == j { w[i].abs() } else { 0.0 }),
            }
        })
}

fn vector(n: usize) -> impl Strategy<Value = DVector<f64>> {
    prop::collection::vec(wide(), n).prop_map(DVector::from_vec)
}

fn matrix(r: usize, c: usize) -> impl Strategy<Value = DMatrix<f64>> {
    prop::collection::vec(wide(), r * c).prop_map(move |v| DMatrix::from_vec(r, c, v))
}

/// Whether a value's `Debug` text holds no `inf` or `NaN` number (for report types that do not
/// implement [`Finite`]).
fn debug_finite<T: std::fmt::Debug>(v: &T) -> bool {
    let text = format!("{v:?}");
    !text
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .any(|w| w == "inf" || w == "NaN")
}

/// Fails the case if `r` is an `Ok` holding a non-finite number.
fn ok_finite<T: Finite + std::fmt::Debug, E: std::fmt::Debug>(
    what: &str,
    r: &Result<T, E>,
) -> Result<(), TestCaseError> {
    if let Ok(v) = r {
        prop_assert!(v.finite(), "{what}: Ok({v:?}) is not finite");
    }
    Ok(())
}

// ----- kalibra-linalg -----------------------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    /// Checked covariances, their solves and forms, factors, Lyapunov and spectral radius,
    /// exact power-of-two scaling.
    #[test]
    fn linalg(
        m in (1usize..4).prop_flat_map(spd),
        v in (1usize..4).prop_flat_map(vector),
        b in (1usize..4, 1usize..3).prop_flat_map(|(r, c)| matrix(r, c)),
        x in wide(),
        k in -2200i32..2200,
    ) {
        let fit = |a: &DMatrix<f64>, r: usize, c: usize| a.clone().resize(r, c, 0.0);
        let dim = m.nrows();
        let v = fit(&DMatrix::from_column_slice(v.len(), 1, v.as_slice()), dim, 1).column(0).into_owned();
        let b = fit(&b, dim, 2);
        let c = Covariance::new(m.clone());
        ok_finite("Covariance::named", &Covariance::named(m.clone(), "m").map(|c| c.matrix().clone()))?;
        if let Ok(c) = &c {
            prop_assert!(c.log_det().is_finite());
            ok_finite("quad_form", &c.quad_form(&v))?;
            ok_finite("solve", &c.solve(&b))?;
            ok_finite("trace_solve", &c.trace_solve(&m))?;
            ok_finite("solve_right", &c.solve_right(&b.transpose()))?;
        }
        ok_finite("from_diagonal", &Covariance::from_diagonal(&v.map(f64::abs)).map(|c| c.matrix().clone()))?;
        ok_finite("quad_form_once", &quad_form_once(&m, &v, "m"))?;
        ok_finite("quad_form_symmetric", &quad_form_symmetric(&m, &v, "m"))?;
        let _ = check_covariance(&m, "m", Definiteness::SemiDefinite);
        let _ = check_symmetric(&m, "m");
        prop_assert_eq!(check_finite(&m, "m").is_ok(), all_finite(&m));
        ok_finite("Gaussian::new", &Gaussian::new(v.clone(), m.clone()).map(|g| g.cov))?;
        ok_finite("PsdMatrix::new", &PsdMatrix::new(m.clone()).map(|p| p.factor().clone()))?;
        ok_finite("PsdMatrix::named", &PsdMatrix::named(m.clone(), "m").map(|p| p.factor().clone()))?;
        ok_finite("semidefinite_factor", &semidefinite_factor(&m, "m").map(|(l, _)| l))?;
        ok_finite("sigma_sqrt", &sigma_sqrt(&m, "m").map(|(l, _)| l))?;
        ok_finite("spectral_radius", &spectral_radius(&m))?;
        let a = &b.columns(0, 1).into_owned() * b.columns(0, 1).transpose();
        if let Ok(r) = spectral_radius(&a) && r > 0.0 {
            ok_finite("discrete_lyapunov", &discrete_lyapunov(&(a.map(|x| x * (0.5 / r))), &m))?;
        }
        ok_finite("discrete_lyapunov", &discrete_lyapunov(&m, &m))?;
        // Power-of-two scaling is exact wherever the result is a normal number.
        if let Some(e) = binary_exponent(x) {
            let y = ldexp(x, k);
            if y.is_normal() && x.is_normal() && (e + k).abs() < 1000 {
                prop_assert_eq!(ldexp(y, -k), x);
            }
        }
    }
}

// ----- kalibra-metrics ----------------------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    /// Statistics of scalar series over the whole exponent range.
    #[test]
    fn metrics_series(
        a in series(),
        b in series(),
        window in 2usize..5,
        batch in 1usize..4,
        t in interval(),
        confidence in confidence(),
        dof in prop_oneof![wide().prop_map(f64::abs), 1.0..10.0f64],
        samples in prop_oneof![1usize..100, Just(usize::MAX)],
    ) {
        ok_finite("rmse", &rmse(&a))?;
        ok_finite("time_average", &time_average(&a))?;
        ok_finite("median", &median(&a))?;
        if let Ok(w) = sliding_window(&a, window) {
            prop_assert!(w.rmse.finite() && w.bias.finite() && w.std.finite(), "{w:?}");
        }
        let times: Vec<f64> = (0..a.len()).map(|i| i as f64 * t).collect();
        let squares: Vec<f64> = a.iter().map(|v| v * v).filter(|v| v.is_finite()).collect();
        let times_sq = &times[..squares.len()];
        ok_finite("itse", &itse(times_sq, &squares))?;
        ok_finite("batch_means", &batch_means(&a, batch, 0))?;
        for t in [runs_test(&a), paired_t_test(&a, &b), ks_two_sample(&a, &b)]
            .into_iter()
            .flatten()
        {
            prop_assert!(t.statistic.is_finite() && (0.0..=1.0).contains(&t.p_value), "{t:?}");
        }
        let d = (a[0].abs() / (1.0 + a[0].abs())).min(1.0);
        for p in [ks_two_sample_exact_p(a.len(), b.len(), d), ks_asymptotic_p(a.len(), b.len(), d)] {
            ok_finite("ks p", &p)?;
        }
        for band in [
            ChiSquareBand::for_mean(dof, samples, confidence),
            ChiSquareBand::for_normalized_mean(dof, samples, confidence),
        ]
        .into_iter()
        .flatten()
        {
            prop_assert!(band.lower.is_finite() && band.upper.is_finite(), "{band:?}");
            let _ = band.contains(a[0]);
        }
        // Accumulators: a refused value leaves them as they were; every summary is finite.
        let mut mean = StepMean::new(2);
        let mut sq = SquaredErrors::new(2, 1);
        let mut streamed = kalibra::metrics::BatchMeans::new(batch, 0).unwrap();
        for (i, &v) in a.iter().enumerate() {
            let before = mean.clone();
            if mean.push(i % 2, v).is_err() {
                prop_assert_eq!(&mean, &before);
            }
            let before = sq.clone();
            if sq.push_slice(i % 2, &[v]).is_err() {
                prop_assert_eq!(&sq, &before);
            }
            let before = sq.clone();
            if sq.push(i % 2, &Vector1::new(v)).is_err() {
                prop_assert_eq!(&sq, &before);
            }
            streamed.push(v);
        }
        prop_assert!(mean.means().finite());
        for k in 0..2 {
            ok_finite("mse", &sq.mse(k, 0))?;
        }
        ok_finite("BatchMeans::push", &streamed.finish())?;
    }

    /// Vector metrics: per-state RMSE against the scalar one, errors of opposite-sign pairs,
    /// NEES, NIS, J1/J2, whiteness, credibility.
    #[test]
    fn metrics_vectors(
        estimates in prop::collection::vec((wide(), wide()), 1..12),
        truths in prop::collection::vec((wide(), wide()), 1..12),
        pair in opposite(),
        m in spd(2),
        a in spd(2),
        r in spd(2),
        confidence in confidence(),
    ) {
        let len = estimates.len().min(truths.len());
        let xs: Vec<Vector2<f64>> = estimates[..len].iter().map(|&(p, q)| Vector2::new(p, q)).collect();
        let ts: Vec<Vector2<f64>> = truths[..len].iter().map(|&(p, q)| Vector2::new(p, q)).collect();
        let errors = instantaneous_errors(&xs, &ts);
        ok_finite("instantaneous_errors", &errors)?;
        if let Ok(e) = &errors {
            for ((e, x), t) in e.iter().zip(&xs).zip(&ts) {
                prop_assert_eq!(*e, x - t);
            }
        }
        // One pair whose difference overflows: an error, never an infinite error inside Ok.
        let mut xs_over = xs.clone();
        xs_over[0][0] = pair.0;
        let mut over_truth = xs.clone();
        over_truth[0][0] = pair.1;
        prop_assert!(instantaneous_errors(&xs_over, &over_truth).is_err(), "{:?}", pair);
        // Per-state RMSE is the scalar RMSE of each component, finite where it is.
        let per = rmse_per_state(&xs);
        ok_finite("rmse_per_state", &per)?;
        for i in 0..2 {
            let column: Vec<f64> = xs.iter().map(|x| x[i]).collect();
            let scalar = rmse(&column);
            match (&per, &scalar) {
                (Ok(p), Ok(s)) => prop_assert_eq!(p[i], *s, "component {}", i),
                (Err(_), _) | (_, Err(_)) => {}
            }
        }
        let m2 = Matrix2::from_iterator(m.iter().copied());
        let e = xs[0];
        ok_finite("nees", &nees(&e, &m2))?;
        if let Ok(s) = Covariance::new(m2) {
            ok_finite("nis", &nis(&e, &s))?;
            ok_finite("normalized_innovation", &normalized_innovation(&e, &s))?;
        }
        let a2 = Matrix2::from_iterator(a.iter().copied());
        let r2 = Matrix2::from_iterator(r.iter().copied());
        if let Ok(j) = j_step(&a2, &m2, &r2, &a2) {
            prop_assert!(j.j1.is_finite() && j.j2.is_finite() && j.tr_b.is_finite(), "{j:?}");
        }
        let normalized: Vec<Option<Vector2<f64>>> = xs.iter().map(|x| Some(*x)).collect();
        if let Ok(w) = whiteness(&normalized, 1, confidence) {
            prop_assert!(w.box_pierce.is_finite() && (0.0..=1.0).contains(&w.p_value), "{w:?}");
        }
        let mut cred = Credibility::new(1, 2);
        let _ = cred.push(0, &e, &m2);
        let _ = cred.push_nees(0, e.as_slice(), 2.0);
        if let Ok(s) = cred.step_summary(0) {
            // The NCI is NaN, as documented, when every run was skipped (a singular MSE).
            let nci_defined = s.nci_skipped < s.runs;
            prop_assert!(s.nci.is_finite() || !nci_defined, "{s:?}");
            prop_assert!(s.anees.is_finite() && s.median_nees.is_finite() && s.mse.finite(), "{s:?}");
        }
    }
}

// ----- kalibra-bounds -----------------------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    /// PCRLB, observability, the Spall-Wei surrogate and its ellipsoid at every scale.
    #[test]
    fn bounds(
        j in spd(2),
        q in spd(2),
        r in spd(1),
        gain in matrix(2, 1),
        h in matrix(1, 2),
        point in vector(2),
        confidence in confidence(),
    ) {
        let jac = j.map(|x| x * 0.25);
        if let Ok(mut bound) = Pcrlb::new(&q) {
            let _ = bound.predict(std::slice::from_ref(&jac), &q);
            ok_finite("Pcrlb bound", &bound.bound())?;
        }
        if let Ok(b) = Pcrlb::from_information(q.clone()) {
            ok_finite("Pcrlb::from_information", &b.bound())?;
        }
        ok_finite("observability", &observability_singular_values(std::slice::from_ref(&jac), &[h.clone(), h.clone()], 0, 2))?;
        let mut avg = ErgodicAverage::new(Dyn(2), Dyn(1));
        let _ = avg.push(&gain, &jac);
        ok_finite("ErgodicAverage gain", &avg.gain())?;
        if let Ok(sums) = ErgodicAverage::from_sums(gain.clone(), jac.clone(), 3) {
            ok_finite("from_sums", &sums.jacobian())?;
            if let Ok(s) = Surrogate::from_averages(&sums, &h, &q, &r) {
                ok_finite("from_averages", &s.half_widths(confidence))?;
            }
        }
        if let Ok(s) = Surrogate::new(&gain, &jac, &h, &q, &r) {
            prop_assert!(s.limit_cov().finite());
            ok_finite("half_widths", &s.half_widths(confidence))?;
            ok_finite("covariance_after", &s.covariance_after(3, &q))?;
            if let Ok(e) = s.ellipsoid(confidence) {
                prop_assert!(e.threshold().is_finite());
                let _ = e.contains(&point);
            }
        }
        ok_finite("gaussian_half_widths", &gaussian_half_widths(&q, confidence))?;
        if let Ok(e) = Ellipsoid::new(q.clone(), confidence) {
            prop_assert!(e.threshold().is_finite());
            ok_finite("Ellipsoid::contains", &e.contains(&point))?;
        }
    }
}

// ----- kalibra-models, kalibra-filters, kalibra-sim, kalibra-eval ---------------------------

proptest! {
    #![proptest_config(config())]

    /// Model constructors at extreme intervals and scales, bearing geometry, kappa grids, the
    /// shifted Rayleigh moments, tuning helpers and the two-point initialisation.
    #[test]
    fn models_filters_sim(
        dt in interval(),
        x in wide(),
        y in wide(),
        factor in wide().prop_map(f64::abs),
        q in spd(2),
        z in (wide(), wide(), wide(), wide()),
        pair in opposite(),
        t in interval(),
        r in spd(2),
    ) {
        let w = wrap_angle(x);
        prop_assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI, "wrap_angle({x}) = {w}");
        for reference in [BearingReference::XAxis, BearingReference::North] {
            prop_assert!(reference.angle(x, y).is_finite());
            prop_assert!(reference.direction(x).finite());
            let g = reference.gradient(x, y);
            if x != 0.0 || y != 0.0 {
                // Finite unless its true value, 1 / r, is beyond f64 (r below 2^-1024).
                let r = x.hypot(y);
                if r > 1.0 / f64::MAX {
                    prop_assert!(g.finite(), "gradient({x}, {y}) = {g:?}");
                }
            }
        }
        for (order, n) in [(Order::ConstantVelocity, 2), (Order::ConstantAcceleration, 3)] {
            if let Ok(k) = Kinematic::new(order, 1, dt) {
                ok_finite("Kinematic dynamics", &k.dynamics(Dyn(n)).map(|d| d.f().clone()))?;
            }
        }
        ok_finite("constant_velocity", &Kinematic::constant_velocity(1, dt).and_then(|k| k.dynamics(Dyn(2))).map(|d| d.q().matrix().clone()))?;
        ok_finite("constant_acceleration", &Kinematic::constant_acceleration(1, dt).and_then(|k| k.dynamics(Dyn(3))).map(|d| d.q().matrix().clone()))?;
        ok_finite("AngularTarget::diagonal", &AngularTarget::diagonal(dt, [factor, factor, factor]).map(|_| ()))?;
        let q3 = Matrix3::from_diagonal(&kalibra::linalg::Vector3::new(factor, 1.0, 1.0));
        let _ = AngularTarget::new(dt, q3);
        if let Ok(model) = LinearGaussian::new(DMatrix::identity(2, 2), q.clone()) {
            ok_finite("with_noise_scaled", &model.with_noise_scaled(factor).map(|m| m.q().matrix().clone()))?;
            if let Ok(obs) = LinearObservation::new(DMatrix::identity(2, 2), r.clone()) {
                let states = vec![DVector::from_vec(vec![z.0, z.1]), DVector::from_vec(vec![z.2, z.3])];
                ok_finite("p_ad", &p_ad(&model, &obs, &states, 0))?;
            }
        }
        ok_finite("q_ad", &q_ad(&q, [(&r, &q)]))?;
        if let Ok(g) = grid(x.min(y)..=x.max(y), factor) {
            prop_assert!(g.finite());
        }
        if let Ok(k) = KappaGrid::equidistant(x.min(y), x.max(y), 3) {
            prop_assert!(debug_finite(&k), "{k:?}");
        }
        let _ = KappaGrid::new(vec![x, y]);
        let _ = SigmaSet::Symmetric { kappa: 0.0 }.with_kappa(x);
        let moments = shifted_rayleigh_moments(x);
        prop_assert!(moments.mean.is_finite() && moments.variance.is_finite(), "{x}: {moments:?}");
        // The two-point initialisation: measurements anywhere, opposite pairs, tiny intervals.
        let r1 = SMatrix::<f64, 1, 1>::new(r[(0, 0)].abs());
        for (z1, z2) in [(z.0, z.1), pair, (pair.1, pair.0)] {
            let (v1, v2) = (SVector::<f64, 1>::new(z1), SVector::<f64, 1>::new(z2));
            let init = two_point_init::<2, 1>(&v1, &v2, &r1, &r1, t, [0], [1]);
            ok_finite("two_point_init", &init.clone().map(|g| (g.mean, g.cov)))?;
            // The velocity is (z2 - z1) / t to rounding, wherever that is representable.
            let scale = z1.abs() / t + z2.abs() / t;
            if let Ok(g) = init && scale.is_finite() {
                let want = z2 / t - z1 / t;
                // Relative to the terms, and a few subnormal steps where they underflow.
                let tolerance = (1e-15 * scale).max(1e-322);
                prop_assert!((g.mean[1] - want).abs() <= tolerance, "{} vs {want}", g.mean[1]);
            }
        }
    }

    /// A log judged: truths and estimates of opposite signs near the limit are the log's
    /// error, typed; wide values otherwise give a report with no infinity in it.
    #[test]
    fn eval(
        values in prop::collection::vec((wide(), wide(), wide()), 4),
        pair in opposite(),
        confidence in confidence(),
    ) {
        let truth: Vec<f64> = values.iter().map(|v| v.0).collect();
        let estimate: Vec<f64> = values.iter().map(|v| v.1).collect();
        let cov: Vec<f64> = values.iter().map(|v| v.2.abs().max(f64::MIN_POSITIVE)).collect();
        let log = FilterLog::new(2, 2)
            .and_then(|l| l.with_truth(Vectors::dense(1, truth.clone())))
            .and_then(|l| l.with_estimate(Vectors::dense(1, estimate.clone())))
            .and_then(|l| l.with_covariance(Matrices::dense(1, 1, cov.clone())))
            .and_then(|l| l.with_times(vec![0.0, 1.0]));
        if let Ok(log) = log {
            let evaluation = Evaluation::new().confidence(confidence).unwrap();
            if let Ok(report) = evaluation.evaluate(&log) {
                prop_assert!(debug_finite(&report), "{report:?}");
            }
        }
        let mut over_truth = truth.clone();
        let mut over_estimate = estimate.clone();
        over_truth[0] = pair.0;
        over_estimate[0] = pair.1;
        let log = FilterLog::new(2, 2)
            .and_then(|l| l.with_truth(Vectors::dense(1, over_truth)))
            .and_then(|l| l.with_estimate(Vectors::dense(1, over_estimate)))
            .and_then(|l| l.with_covariance(Matrices::diagonal(1, cov.clone())))
            .unwrap();
        let result = Evaluation::new().evaluate(&log);
        prop_assert!(
            matches!(result, Err(kalibra::eval::EvalError::OutOfRange { .. })),
            "{result:?}"
        );
    }
}

// ----- the list, checked against the sources ------------------------------------------------

/// Passed to the public functions below only by the filters and studies that own them.
const FILTER_SUITE: &str = "filter constructors and steps: tests/adversarial.rs `filters` and \
    `bearings` drive them with entries from 5e-324 to f64::MAX and check no non-finite Ok and \
    a failed step leaving the filter as it was";
const LANES: &str = "lane-wise (SIMD) form of a scalar function driven here, bit-identical or \
    within the stated ulp bound to it (crates/kalibra-filters/tests/batch*.rs, \
    crates/kalibra-sim/tests/batch.rs, crates/kalibra-linalg's simd tests)";
const KERNEL: &str = "infallible filter kernel (no Result): the filter that calls it checks its \
    output for finiteness after every step (tests/adversarial.rs `filters`)";
const STUDY: &str = "a published study's scenario, run with the paper's fixed values by \
    `cargo xtask reproduce`; no user data reaches it";
const STORE: &str = "stores the values for later use, computing nothing from them; what uses \
    them is driven here";
const MODEL_PAPER: &str = "model of a reproduced study with its fixed physical constants \
    (re-entry, manoeuvres); exercised by kalibra-studies' tests";

const TUNE_PENDING: &str = "kalibra-tune's noise estimation (parametrisation, ML, EM, ALS, the \
    per-parameter sweep): not yet driven with extreme values, a known gap; its own tests cover \
    ordinary values";

/// Every public function of the library crates that takes `f64` data (or `Lanes`), with how
/// it is covered. `Type::name` for methods; `$name` is the macro that writes `Kf` and `Ekf`.
pub const FLOAT_FUNCTIONS: &[(&str, Cover)] = &[
    // kalibra-bounds
    ("Pcrlb::new", Cover::Driven),
    ("Pcrlb::from_information", Cover::Driven),
    ("Pcrlb::predict", Cover::Driven),
    ("observability_singular_values", Cover::Driven),
    ("ErgodicAverage::from_sums", Cover::Driven),
    ("ErgodicAverage::push", Cover::Driven),
    ("Surrogate::new", Cover::Driven),
    ("Surrogate::from_averages", Cover::Driven),
    ("Surrogate::covariance_after", Cover::Driven),
    ("Surrogate::half_widths", Cover::Driven),
    ("Surrogate::ellipsoid", Cover::Driven),
    ("gaussian_half_widths", Cover::Driven),
    ("Ellipsoid::new", Cover::Driven),
    ("Ellipsoid::contains", Cover::Driven),
    // kalibra-eval
    ("Evaluation::confidence", Cover::Driven),
    ("Vectors::dense", Cover::Driven),
    ("Vectors::nan_unlogged", Cover::Reason(STORE)),
    ("Vectors::cells", Cover::Reason(STORE)),
    ("Matrices::dense", Cover::Driven),
    ("Matrices::nan_unlogged", Cover::Reason(STORE)),
    ("Matrices::diagonal", Cover::Driven),
    ("Matrices::cells", Cover::Reason(STORE)),
    ("Matrices::diagonal_cells", Cover::Reason(STORE)),
    ("Matrices::per_step", Cover::Reason(STORE)),
    ("Matrices::constant", Cover::Reason(STORE)),
    ("FilterLog::with_times", Cover::Driven),
    (
        "Band::contains",
        Cover::Reason("a comparison with a report's band; returns a bool"),
    ),
    (
        "Evaluator::finish",
        Cover::Reason(
            "the streaming form of `Evaluation::evaluate`, which is driven here and gives the same report (crates/kalibra-eval/tests/stream.rs)",
        ),
    ),
    (
        "matrix_from_rows",
        Cover::Reason("copies rows into a matrix, checking shape and finiteness; computes nothing"),
    ),
    (
        "TuneProblem::new",
        Cover::Reason(
            "the offline Q tuning runs a KF over the problem: filter steps check finiteness (crates/kalibra-eval/tests/tune.rs; tests/adversarial.rs `filters`)",
        ),
    ),
    (
        "TuneProblem::as_given",
        Cover::Reason("as TuneProblem::new, with the initial covariance taken as given"),
    ),
    ("TuneProblem::with_truth", Cover::Reason(STORE)),
    (
        "Tuning::exponents",
        Cover::Reason("a grid of exponents through `grid`, which is driven here"),
    ),
    ("Tuning::grid", Cover::Reason(STORE)),
    // kalibra-filters
    ("EkfBatch::new", Cover::Reason(LANES)),
    ("EkfBatch::predict_update", Cover::Reason(LANES)),
    ("EkfBatch::predict_update_j", Cover::Reason(LANES)),
    ("EkfBatch::update", Cover::Reason(LANES)),
    ("KfBatch::new", Cover::Reason(LANES)),
    ("KfBatch::scheduled", Cover::Reason(LANES)),
    ("KfBatch::set_lane", Cover::Reason(LANES)),
    ("KfBatch::update", Cover::Reason(LANES)),
    ("KfBatch::predict_update", Cover::Reason(LANES)),
    ("LaneState::new", Cover::Reason(LANES)),
    ("LaneState::at_start", Cover::Reason(LANES)),
    ("LaneState::set_lane", Cover::Reason(LANES)),
    ("LaneState::write_lane", Cover::Reason(LANES)),
    ("set_lane", Cover::Reason(LANES)),
    ("BatchModel::new", Cover::Reason(LANES)),
    ("KfSchedule::new", Cover::Reason(LANES)),
    ("UkfBatch::new", Cover::Reason(LANES)),
    ("UkfBatch::predict_update", Cover::Reason(LANES)),
    ("UkfBatch::update", Cover::Reason(LANES)),
    ("ConstantGainKf::new", Cover::Reason(FILTER_SUITE)),
    ("ConstantGainKf::with_options", Cover::Reason(FILTER_SUITE)),
    (
        "ConstantGainKf::steady_state_gain",
        Cover::Reason(
            "the Riccati limit through `steady_state`, which tests/adversarial.rs `filters` drives",
        ),
    ),
    ("$name::new", Cover::Reason(FILTER_SUITE)),
    ("$name::with_options", Cover::Reason(FILTER_SUITE)),
    (
        "$name::as_given",
        Cover::Reason(
            "the paper's unchecked algebra, an explicit opt-in; its records say so (crates/kalibra-filters/tests/kalman.rs)",
        ),
    ),
    ("shifted_rayleigh_moments", Cover::Driven),
    (
        "StepRecord::nees",
        Cover::Reason("`nees` with the record's covariance; `nees` is driven here"),
    ),
    (
        "FixedLagSmoother::step",
        Cover::Reason(
            "a filter step and an RTS pass over its records: crates/kalibra-filters/tests/smooth.rs and tests/adversarial.rs `filters`",
        ),
    ),
    ("SqrtKf::new", Cover::Reason(FILTER_SUITE)),
    ("SqrtKf::with_options", Cover::Reason(FILTER_SUITE)),
    ("SqrtUkf::new", Cover::Reason(FILTER_SUITE)),
    ("SqrtUkf::with_options", Cover::Reason(FILTER_SUITE)),
    ("Srf::new", Cover::Reason(FILTER_SUITE)),
    ("Srf::with_options", Cover::Reason(FILTER_SUITE)),
    ("steady_state", Cover::Reason(FILTER_SUITE)),
    ("Ukf::new", Cover::Reason(FILTER_SUITE)),
    ("Ukf::with_options", Cover::Reason(FILTER_SUITE)),
    ("KappaGrid::new", Cover::Driven),
    ("KappaGrid::equidistant", Cover::Driven),
    ("SigmaSet::with_kappa", Cover::Driven),
    // kalibra-io
    (
        "Model::problem",
        Cover::Reason("reader plumbing: hands a file's matrices to TuneProblem::new"),
    ),
    // kalibra-linalg
    ("Covariance::new", Cover::Driven),
    ("Covariance::named", Cover::Driven),
    (
        "Covariance::from_symmetric",
        Cover::Reason(
            "Covariance::new without the symmetry check, for matrices built symmetric; same factorisation and checks",
        ),
    ),
    ("Covariance::from_diagonal", Cover::Driven),
    ("Covariance::solve", Cover::Driven),
    ("Covariance::solve_right", Cover::Driven),
    ("Covariance::quad_form", Cover::Driven),
    ("Covariance::trace_solve", Cover::Driven),
    ("quad_form_once", Cover::Driven),
    ("quad_form_symmetric", Cover::Driven),
    ("check_covariance", Cover::Driven),
    ("check_symmetric", Cover::Driven),
    ("Gaussian::new", Cover::Driven),
    ("propagate", Cover::Reason(KERNEL)),
    ("product", Cover::Reason(KERNEL)),
    ("innovation_covariance", Cover::Reason(KERNEL)),
    ("add_scatter", Cover::Reason(KERNEL)),
    ("add_cross_scatter", Cover::Reason(KERNEL)),
    ("symmetrize", Cover::Reason(KERNEL)),
    ("joseph_update", Cover::Reason(KERNEL)),
    ("standard_update", Cover::Reason(KERNEL)),
    ("check_finite", Cover::Driven),
    ("all_finite", Cover::Driven),
    ("discrete_lyapunov", Cover::Driven),
    ("spectral_radius", Cover::Driven),
    ("semidefinite_factor", Cover::Driven),
    ("sigma_sqrt", Cover::Driven),
    ("PsdMatrix::new", Cover::Driven),
    ("PsdMatrix::named", Cover::Driven),
    ("binary_exponent", Cover::Driven),
    ("ldexp", Cover::Driven),
    ("LaneCholesky::new", Cover::Reason(LANES)),
    ("LaneCholesky::from_parts", Cover::Reason(LANES)),
    ("LaneCholesky::from_lower", Cover::Reason(LANES)),
    ("LaneCholesky::solve_lower", Cover::Reason(LANES)),
    ("LaneCholesky::solve_upper", Cover::Reason(LANES)),
    ("LaneCholesky::solve", Cover::Reason(LANES)),
    ("atan2", Cover::Reason(LANES)),
    ("sin_cos", Cover::Reason(LANES)),
    ("sin_cos_lanes", Cover::Reason(LANES)),
    ("exp_lanes", Cover::Reason(LANES)),
    ("load", Cover::Reason(LANES)),
    ("store", Cover::Reason(LANES)),
    // kalibra-metrics
    ("StepMean::push", Cover::Driven),
    ("StepMean::push_lanes", Cover::Reason(LANES)),
    ("SquaredErrors::push_slice", Cover::Driven),
    ("SquaredErrors::push_lanes", Cover::Reason(LANES)),
    ("SquaredErrors::push", Cover::Driven),
    ("time_average", Cover::Driven),
    ("nees", Cover::Driven),
    ("nis", Cover::Driven),
    ("ChiSquareBand::for_mean", Cover::Driven),
    ("ChiSquareBand::for_normalized_mean", Cover::Driven),
    ("ChiSquareBand::contains", Cover::Driven),
    ("Credibility::push", Cover::Driven),
    ("Credibility::push_nees", Cover::Driven),
    ("median", Cover::Driven),
    ("batch_means", Cover::Driven),
    ("BatchMeans::push", Cover::Driven),
    ("runs_test", Cover::Driven),
    ("paired_t_test", Cover::Driven),
    ("ks_two_sample", Cover::Driven),
    ("ks_two_sample_exact_p", Cover::Driven),
    ("ks_asymptotic_p", Cover::Driven),
    ("j_step", Cover::Driven),
    ("itse", Cover::Driven),
    ("normalized_innovation", Cover::Driven),
    ("whiteness", Cover::Driven),
    ("instantaneous_errors", Cover::Driven),
    ("rmse", Cover::Driven),
    ("rmse_per_state", Cover::Driven),
    ("sliding_window", Cover::Driven),
    // kalibra-models
    ("AngularTarget::new", Cover::Driven),
    ("AngularTarget::diagonal", Cover::Driven),
    (
        "AngularTarget::angle_measurement",
        Cover::Reason("builds R = [r] through LinearObservation::new, which is driven here"),
    ),
    ("ManoeuvreProfile::acceleration", Cover::Reason(MODEL_PAPER)),
    ("ManoeuvreProfile::scaled", Cover::Reason(MODEL_PAPER)),
    (
        "ManoeuvringTarget::truth_from_noise",
        Cover::Reason(MODEL_PAPER),
    ),
    (
        "ManoeuvringTarget::measurements_from_noise",
        Cover::Reason(MODEL_PAPER),
    ),
    (
        "ManoeuvringTarget::measurements",
        Cover::Reason(MODEL_PAPER),
    ),
    ("AirDensity::at", Cover::Reason(MODEL_PAPER)),
    ("AirDensity::derivative", Cover::Reason(MODEL_PAPER)),
    ("ballistic_f1", Cover::Reason(MODEL_PAPER)),
    ("ballistic_g", Cover::Reason(MODEL_PAPER)),
    ("Ballistic::new", Cover::Reason(MODEL_PAPER)),
    ("Ballistic::with_noise", Cover::Reason(MODEL_PAPER)),
    ("Ballistic::drag", Cover::Reason(MODEL_PAPER)),
    ("Ballistic::drag_jacobian", Cover::Reason(MODEL_PAPER)),
    ("BallisticDragFree::with_noise", Cover::Reason(MODEL_PAPER)),
    ("ConvertedPosition::covariance", Cover::Reason(MODEL_PAPER)),
    ("RadarRates::new", Cover::Reason(MODEL_PAPER)),
    ("wrap_angle", Cover::Driven),
    ("Tabulated::new", Cover::Reason(STORE)),
    ("BearingReference::angle", Cover::Driven),
    ("BearingReference::direction", Cover::Driven),
    ("BearingReference::gradient", Cover::Driven),
    ("Bearing::new", Cover::Reason(FILTER_SUITE)),
    ("Bearing::from_coordinates", Cover::Reason(FILTER_SUITE)),
    (
        "Bearing::with_translational_noise",
        Cover::Reason(
            "checks and stores two variances; the bearing filters using them are in tests/adversarial.rs `bearings`",
        ),
    ),
    (
        "Bearing::relative_position",
        Cover::Reason(
            "a difference of target and platform positions, driven by every bearing filter step (tests/adversarial.rs `bearings`)",
        ),
    ),
    (
        "check_dynamics_jacobian",
        Cover::Reason("a test helper for model authors (finite differences at the caller's point)"),
    ),
    (
        "check_measurement_jacobian",
        Cover::Reason("a test helper for model authors (finite differences at the caller's point)"),
    ),
    ("Kinematic::new", Cover::Driven),
    ("Kinematic::constant_velocity", Cover::Driven),
    ("Kinematic::constant_acceleration", Cover::Driven),
    (
        "Kinematic::position_measurement",
        Cover::Reason("builds H and takes R through LinearObservation::new, which is driven here"),
    ),
    ("wrap_angle_lanes", Cover::Reason(LANES)),
    ("lane", Cover::Reason(LANES)),
    ("set_lane_vector", Cover::Reason(LANES)),
    ("set_lane", Cover::Reason(LANES)),
    ("broadcast", Cover::Reason(LANES)),
    ("LinearGaussian::new", Cover::Driven),
    ("LinearGaussian::with_noise_scaled", Cover::Driven),
    ("LinearObservation::new", Cover::Driven),
    (
        "sample_with_factor",
        Cover::Reason(
            "a draw L w from a factor the caller made with semidefinite_factor (driven here); crates/kalibra-models/tests/value_stability.rs",
        ),
    ),
    (
        "Simulator::new",
        Cover::Reason(
            "stores the initial state; the truth simulation steps the models, whose checks are driven here",
        ),
    ),
    (
        "simulate",
        Cover::Reason("truth simulation of a model: crates/kalibra-models tests"),
    ),
    (
        "simulate_until",
        Cover::Reason("truth simulation of a model: crates/kalibra-models tests"),
    ),
    (
        "AccelAxis::position_measurement",
        Cover::Reason(MODEL_PAPER),
    ),
    (
        "AccelAxis::position_velocity_measurement",
        Cover::Reason(MODEL_PAPER),
    ),
    ("AccelAxis::jacobian_lanes", Cover::Reason(LANES)),
    ("Target3d::position_measurement", Cover::Reason(MODEL_PAPER)),
    (
        "Target3d::position_velocity_measurement",
        Cover::Reason(MODEL_PAPER),
    ),
    // kalibra-plot
    (
        "Series::line",
        Cover::Reason("a figure's points as data; the SVG writer is tested in kalibra-plot"),
    ),
    (
        "Series::markers",
        Cover::Reason("a figure's points as data; the SVG writer is tested in kalibra-plot"),
    ),
    (
        "Series::line_markers",
        Cover::Reason("a figure's points as data; the SVG writer is tested in kalibra-plot"),
    ),
    // kalibra-sim
    ("TruthBatch::new", Cover::Reason(LANES)),
    ("LinearTruthBatch::new", Cover::Reason(LANES)),
    ("LinearTruthBatch::step", Cover::Reason(LANES)),
    ("ChaCha8Lanes::standard_normals", Cover::Reason(LANES)),
    ("grid", Cover::Driven),
    (
        "sweep",
        Cover::Reason("hands each grid point to the caller's closure; computes nothing from it"),
    ),
    ("two_point_init", Cover::Driven),
    ("p_ad", Cover::Driven),
    ("q_ad", Cover::Driven),
    // kalibra-studies
    ("replay", Cover::Reason(STUDY)),
    ("BotScenario::initialize", Cover::Reason(STUDY)),
    ("noise_floor", Cover::Reason(STUDY)),
    ("models", Cover::Reason(STUDY)),
    ("track", Cover::Reason(STUDY)),
    ("params", Cover::Reason(STUDY)),
    ("dynamics", Cover::Reason(STUDY)),
    ("scaled", Cover::Reason(STUDY)),
    ("Als::gain", Cover::Reason(TUNE_PENDING)),
    ("CovarianceForm::diagonal", Cover::Reason(TUNE_PENDING)),
    ("CovarianceForm::fixed", Cover::Reason(TUNE_PENDING)),
    ("CovarianceForm::full", Cover::Reason(TUNE_PENDING)),
    ("CovarianceForm::scaled", Cover::Reason(TUNE_PENDING)),
    ("Em::tolerance", Cover::Reason(TUNE_PENDING)),
    (
        "MaximumLikelihood::gradient_tolerance",
        Cover::Reason(TUNE_PENDING),
    ),
    ("MaximumLikelihood::starts", Cover::Reason(TUNE_PENDING)),
    ("NoiseProblem::new", Cover::Reason(TUNE_PENDING)),
    ("ParameterSweep::grid", Cover::Reason(TUNE_PENDING)),
    ("Parametrisation::jacobian", Cover::Reason(TUNE_PENDING)),
    ("Parametrisation::matrices", Cover::Reason(TUNE_PENDING)),
    ("Parametrisation::natural", Cover::Reason(TUNE_PENDING)),
    ("Parametrisation::new", Cover::Reason(TUNE_PENDING)),
    ("Parametrisation::theta_of", Cover::Reason(TUNE_PENDING)),
    ("log_likelihood", Cover::Reason(TUNE_PENDING)),
];

/// The list above is the scanned sources' list: no public function taking `f64` data is
/// forgotten, none listed is gone, every `Driven` one is called in this file.
#[test]
fn every_float_function_is_listed() {
    let takes_floats =
        |f: &extreme::PublicFn| f.params.contains("f64") || f.params.contains("Lanes");
    let problems = extreme::check_list(
        FLOAT_FUNCTIONS,
        takes_floats,
        include_str!("extreme_floats.rs"),
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
