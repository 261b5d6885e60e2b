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
//! Size: `CASES` (256) cases for each of the 9 properties;
//! `PROPTEST_CASES` overrides the count.

use crate::extreme;

use crate::extreme::{Cover, Finite};
use kalibra::bounds::{
    Ellipsoid, ErgodicAverage, Pcrlb, Surrogate, gaussian_half_widths,
    observability_singular_values,
};
use kalibra::eval::{Evaluation, FilterLog, Matrices, Vectors};
use kalibra::filters::{Ekf, Filter, FilterError};
use kalibra::filters::{KappaGrid, SigmaSet, shifted_rayleigh_moments};
use kalibra::linalg::{
    Covariance, DMatrix, DVector, Definiteness, Dyn, Gaussian, Matrix2, Matrix3, PsdMatrix,
    SMatrix, SVector, Vector1, Vector2, all_finite, binary_exponent, check_covariance,
    check_finite, check_symmetric, discrete_lyapunov, ldexp, quad_form_once, quad_form_symmetric,
    semidefinite_factor, sigma_sqrt, spectral_radius,
};
use kalibra::linalg::{Matrix4, Vector3, Vector4};
use kalibra::metrics::{
    ChiSquareBand, Credibility, CredibilityRows, SquaredErrors, StepMean, batch_means,
    instantaneous_errors, itse, j_step, ks_asymptotic_p, ks_two_sample, ks_two_sample_exact_p,
    median, nees, nis, normalized_innovation, paired_t_test, rmse, rmse_per_state, runs_test,
    sliding_window, time_average, whiteness,
};
use kalibra::models::{
    AccelAxis, AngularTarget, Ballistic, BallisticParams, BearingReference, ConvertedPosition,
    ConvertedPositionParams, Dynamics, Kinematic, LinearGaussian, LinearObservation, Manoeuvre,
    ManoeuvreProfile, ManoeuvringTarget, ManoeuvringTargetParams, Measurement, Order, RadarRates,
    Target3d, ballistic_f1, ballistic_g, wrap_angle,
};
use kalibra::tune::{
    Als, CovarianceForm, Em, MaximumLikelihood, NoiseProblem, ParameterSweep, Parametrisation,
    grid, log_likelihood, p_ad, q_ad, two_point_init,
};
use kalibra::tune::{
    LikelihoodFilter, NonlinearNoiseProblem, Start, WithMeasurementNoise, WithProcessNoise,
};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

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
        let mut rows = CredibilityRows::new();
        if rows.push_nees(&cred, 0, e.as_slice(), 2.0).is_ok() {
            cred.settle(&mut rows);
        }
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

// ----- kalibra-tune: maximum likelihood through the EKF and the UKF --------------------------

proptest! {
    #![proptest_config(config())]

    /// A nonlinear noise problem built from extreme `x0`, `P0` and measurements is refused with
    /// a typed error, or gives at the start and at extreme candidates a finite log-likelihood
    /// or a typed error (a filter step that leaves f64); the noise-replacing models keep what
    /// they are given or refuse it.
    #[test]
    fn nonlinear_likelihood(
        x0 in vector(2),
        p0 in spd(2),
        zs in series(),
        theta in (wide(), wide()),
        q in spd(2),
        r in spd(1),
    ) {
        let f = LinearGaussian::new(
            DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
            DMatrix::identity(2, 2),
        ).unwrap();
        let h = LinearObservation::<Dyn, Dyn>::new(
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::identity(1, 1),
        ).unwrap();
        let noise = Parametrisation::new(
            None,
            CovarianceForm::scaled(DMatrix::identity(2, 2)),
            CovarianceForm::scaled(DMatrix::identity(1, 1)),
        ).unwrap();
        let run: Vec<Option<DVector<f64>>> =
            zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
        for filter in [LikelihoodFilter::Ekf, LikelihoodFilter::Ukf(SigmaSet::recommended(2))] {
            let problem = NonlinearNoiseProblem::new(
                &f, &h, filter, x0.clone(), p0.clone(), Start::PredictFirst, noise.clone(),
                vec![run.clone()],
            );
            if let Ok(problem) = problem {
                for t in [[0.0, 0.0], [theta.0, theta.1]] {
                    ok_finite("NonlinearNoiseProblem::log_likelihood", &problem.log_likelihood(&t))?;
                }
            }
        }
        let with_q = WithProcessNoise::new(&f, q.clone());
        ok_finite("WithProcessNoise::new", &with_q.map(|m| m.noise_cov(0).iter().copied().collect::<Vec<f64>>()))?;
        let with_r = WithMeasurementNoise::new(&h, r.clone());
        let x = DVector::from_vec(vec![x0[0], x0[1]]);
        ok_finite("WithMeasurementNoise::new", &with_r.map(|m| m.noise_cov(0, &x).iter().copied().collect::<Vec<f64>>()))?;
    }
}

// ----- kalibra-models: the reproduced studies' models ---------------------------------------

proptest! {
    #![proptest_config(config())]

    /// The studies' models with values anywhere in f64: constructors refuse a period, gravity
    /// or ballistic coefficient whose constant parts leave f64; the plain functions a filter
    /// evaluates (air density, drag and its Jacobian, the converted covariance) are finite, or
    /// the filter's step returns `FilterError::NonFinite`; the manoeuvring target's truths and
    /// measurements are finite or a typed error naming the step.
    #[test]
    fn models_paper(
        state in prop::collection::vec(wide(), 4),
        t in interval(),
        beta in interval(),
        gravity in wide(),
        factor in wide(),
        q in spd(4),
        r3 in spd(3),
        r in wide(),
        point in (wide(), wide()),
        x0 in (wide(), wide(), wide()),
        accel in wide(),
        dt in 0.01..1.0f64,
        noise in series(),
    ) {
        let x = Vector4::new(state[0], state[1], state[2], state[3]);
        let q4 = Matrix4::from_iterator(q.iter().copied());
        prop_assert!(ballistic_f1(t).finite(), "F1({t})");
        let built = Ballistic::new(BallisticParams { period: t, beta, gravity }, Matrix4::identity());
        if !ballistic_g(t).finite() {
            prop_assert!(built.is_err(), "G({t}) is not finite");
        }
        if let Ok(model) = &built {
            ok_finite("Ballistic::with_noise", &model.with_noise(q4).map(|m| m.noise_cov(0)))?;
            ok_finite("BallisticDragFree::with_noise", &model.drag_free().with_noise(q4).map(|m| m.noise_cov(0)))?;
        }
        ok_finite("RadarRates::new", &RadarRates::new(Matrix3::from_iterator(r3.iter().copied())).map(|m| m.noise_cov(0, &x)))?;
        ok_finite("AccelAxis::position_measurement", &AccelAxis::position_measurement(r).map(|_| ()))?;
        ok_finite("AccelAxis::position_velocity_measurement", &AccelAxis::position_velocity_measurement(r).map(|_| ()))?;
        ok_finite("Target3d::position_measurement", &Target3d::position_measurement(r).map(|_| ()))?;
        ok_finite("Target3d::position_velocity_measurement", &Target3d::position_velocity_measurement(r).map(|_| ()))?;
        // The paper's model (and the one built above) with the radar in an EKF started at a
        // state anywhere: a non-finite density, drag or drag Jacobian there is the filter's
        // typed error.
        let paper = Ballistic::new(BallisticParams { period: 2.0, beta: 40_000.0, gravity: 9.81 }, Matrix4::identity()).unwrap();
        let radar = ConvertedPosition::new(ConvertedPositionParams { sigma_range: 100.0, sigma_elevation: 3e-4 }).unwrap();
        let _ = radar.covariance(point.0, point.1);
        for model in std::iter::once(&paper).chain(built.as_ref()) {
            let density = model.density();
            let plain = density.at(x[2]).is_finite()
                && density.derivative(x[2]).is_finite()
                && model.drag(&x).finite()
                && model.drag_jacobian(&x).finite();
            if let Ok(mut ekf) = Ekf::new(model, &radar, x, Matrix4::identity()) {
                let predicted = ekf.predict();
                if !plain {
                    prop_assert!(matches!(predicted, Err(FilterError::NonFinite { .. })), "{x:?}: {predicted:?}");
                }
                if predicted.is_ok() {
                    prop_assert!(ekf.mean().finite() && ekf.covariance().finite());
                    // The converted covariance at the prior: finite, or the update's typed error.
                    let prior = *ekf.mean();
                    let cov = radar.covariance(prior[0].hypot(prior[2]), prior[2].atan2(prior[0]));
                    let updated = ekf.update(&Vector2::new(prior[0], prior[2])).map(|rec| rec.posterior().mean);
                    if !cov.finite() {
                        prop_assert!(updated.is_err(), "{cov:?}: {updated:?}");
                    }
                    ok_finite("EKF update", &updated)?;
                }
            }
        }
        // The manoeuvring target: profiles, truths and measurements.
        let profile = ManoeuvreProfile::new(vec![
            Manoeuvre::Step { start: 0.0, end: 5.0 * dt, acceleration: accel },
            Manoeuvre::Sine { start: 2.0 * dt, end: 8.0 * dt, amplitude: accel, frequency: 1.0 },
        ])
        .unwrap();
        let _ = profile.acceleration(3.0 * dt);
        if let Ok(p) = profile.scaled(factor) {
            prop_assert!(debug_finite(&p), "{p:?}");
        }
        let target = ManoeuvringTarget::new(ManoeuvringTargetParams {
            dt,
            duration: 10.0 * dt,
            profile,
            sigma_input: r.abs(),
            x0: Vector3::new(x0.0, x0.1, x0.2),
        });
        if let Ok(target) = target {
            let draws: Vec<f64> = (0..=target.steps()).map(|i| noise[i % noise.len()]).collect();
            let truth = target.truth_from_noise(&draws);
            ok_finite("truth_from_noise", &truth.clone().map(|t| t.iter().flat_map(|v| v.iter().copied()).collect::<Vec<f64>>()))?;
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            ok_finite("truth", &target.truth(&mut rng).map(|t| t.iter().flat_map(|v| v.iter().copied()).collect::<Vec<f64>>()))?;
            if let Ok(truth) = truth {
                let z = ManoeuvringTarget::measurements_from_noise(&truth, r.abs(), &draws[1..]);
                ok_finite("measurements_from_noise", &z.map(|z| z.iter().map(|v| v[0]).collect::<Vec<f64>>()))?;
                let z = ManoeuvringTarget::measurements(&truth, r.abs(), &mut rng);
                ok_finite("measurements", &z.map(|z| z.iter().map(|v| v[0]).collect::<Vec<f64>>()))?;
            }
        }
    }
}

// ----- kalibra-tune -------------------------------------------------------------------------

fn one(v: f64) -> DMatrix<f64> {
    DMatrix::from_element(1, 1, v)
}

/// A fixed wandering series of `n` ordinary values (a random walk's shape, no randomness).
fn walk(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let k = k as f64;
            0.1 * k + (0.7 * k).sin() + 0.3 * (2.3 * k).cos()
        })
        .collect()
}

/// A scalar random walk seen directly at scale `2^k`: measurements and `x0` times `2^k`, `P0`
/// and the nominal matrices times `2^(2k)`, both noises scaled (so every estimate of a
/// multiplier is the same at every `k`, and log-likelihoods differ by `-N k ln 2`).
fn walk_problem(k: i32, zs: &[f64]) -> Result<NoiseProblem, kalibra::tune::NoiseError> {
    let var = |v: f64| one(ldexp(v, 2 * k));
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(var(0.2)),
        CovarianceForm::scaled(var(0.5)),
    )?;
    let run = zs
        .iter()
        .map(|&z| Some(DVector::from_element(1, ldexp(z, k))))
        .collect();
    NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::from_element(1, ldexp(0.05, k)),
        var(1.0),
        kalibra::tune::Start::PredictFirst,
        noise,
        vec![run],
    )
}

/// Every number of a maximum-likelihood estimate is finite, but the documented interval ends:
/// `f64::INFINITY` for a bound or an end beyond f64.
fn ml_finite(e: &kalibra::tune::MlEstimate) -> bool {
    let parameters = e.parameters.iter().all(|p| {
        p.value.is_finite()
            && p.stderr.is_none_or(f64::is_finite)
            && p.ci95
                .is_none_or(|[lo, hi]| lo.is_finite() && (hi.is_finite() || hi == f64::INFINITY))
    });
    parameters
        && e.theta.iter().all(|v| v.is_finite())
        && debug_finite(&e.matrices)
        && e.log_likelihood.is_finite()
        && e.start_log_likelihood.is_finite()
        && e.information.as_ref().is_none_or(|i| i.finite())
        && debug_finite(&e.identifiability)
        && debug_finite(&e.warnings)
        && debug_finite(&e.starts)
}

proptest! {
    #![proptest_config(config())]

    /// Noise forms at every scale: a parametrisation built from them starts at a finite
    /// candidate; `theta_of` of a scaled, diagonal or full matrix at any scale is its `theta`
    /// (the multiplier of a nominal near f64's limits included), and `matrices` maps it back;
    /// `natural` and `jacobian` are finite or a typed error; the log-likelihood of a problem
    /// scaled by `2^k` is the unscaled one less `N k ln 2`.
    #[test]
    fn tune_forms(
        m in spd(2),
        a in -1020i32..=1020,
        c in -1020i32..=1020,
        r in wide().prop_map(f64::abs),
        theta in prop::collection::vec(wide(), 4),
        k in -500i32..=500,
        zs in series(),
    ) {
        let base = DMatrix::from_row_slice(2, 2, &[1.5, 0.5, 0.5, 1.0]);
        let at = |e: i32| base.map(|x| ldexp(x, e));
        let forms = [
            CovarianceForm::fixed(m.clone()),
            CovarianceForm::scaled(m.clone()),
            CovarianceForm::diagonal(DMatrix::from_diagonal(&m.diagonal().map(f64::abs))),
            CovarianceForm::full(m.clone()).fix(1, 0),
        ];
        for form in forms {
            let Ok(p) = Parametrisation::new(None, form, CovarianceForm::scaled(one(r))) else {
                continue;
            };
            let start = p.start();
            prop_assert!(start.iter().all(|t| t.is_finite()), "{start}");
            let matrices = p.matrices(start.as_slice());
            ok_finite("Parametrisation::matrices", &matrices.clone().map(|m| (m.qw, m.r)))?;
            ok_finite("Parametrisation::natural", &p.natural(start.as_slice()))?;
            ok_finite("Parametrisation::jacobian", &p.jacobian(start.as_slice()))?;
            if let Ok(mats) = &matrices {
                ok_finite("Parametrisation::theta_of", &p.theta_of(&mats.qw, &mats.r))?;
            }
            let wild = &theta[..p.len()];
            ok_finite("matrices at wide theta", &p.matrices(wild).map(|m| (m.q, m.r)))?;
            ok_finite("natural at wide theta", &p.natural(wild))?;
            ok_finite("jacobian at wide theta", &p.jacobian(wild))?;
        }
        // A multiplier of a nominal matrix at 2^a seen at 2^c: theta = (c - a) ln 2, and back.
        let scaled = Parametrisation::new(None, CovarianceForm::scaled(at(a)), CovarianceForm::fixed(one(1.0))).unwrap();
        let t = scaled.theta_of(&at(c), &one(1.0)).unwrap()[0];
        let want = f64::from(c - a) * std::f64::consts::LN_2;
        prop_assert!((t - want).abs() <= 1e-12 * want.abs().max(1.0), "theta {t} vs {want}");
        let back = scaled.matrices(&[t]).unwrap().qw;
        for (x, y) in back.iter().zip(at(c).iter()) {
            prop_assert!((x - y).abs() <= 1e-9 * y.abs(), "{back} vs {}", at(c));
        }
        // A full matrix at 2^c: its log-Cholesky theta maps back to it.
        let full = Parametrisation::new(None, CovarianceForm::full(at(a)), CovarianceForm::fixed(one(1.0))).unwrap();
        let t = full.theta_of(&at(c), &one(1.0)).unwrap();
        let back = full.matrices(t.as_slice()).unwrap().qw;
        for (x, y) in back.iter().zip(at(c).iter()) {
            prop_assert!((x - y).abs() <= 1e-12 * y.abs(), "{back} vs {}", at(c));
        }
        // A diagonal matrix at 2^c.
        let diag = |e: i32| DMatrix::from_diagonal(&DVector::from_vec(vec![ldexp(1.5, e), ldexp(1.0, e)]));
        let diagonal = Parametrisation::new(None, CovarianceForm::diagonal(diag(a)), CovarianceForm::fixed(one(1.0))).unwrap();
        let t = diagonal.theta_of(&diag(c), &one(1.0)).unwrap();
        let back = diagonal.matrices(t.as_slice()).unwrap().qw;
        for (x, y) in back.iter().zip(diag(c).iter()) {
            prop_assert!((x - y).abs() <= 1e-12 * y.abs(), "{back} vs {}", diag(c));
        }
        // The log-likelihood at scale 2^k.
        let path = walk(12);
        let (Ok(scaled), Ok(plain)) = (walk_problem(k, &path), walk_problem(0, &path)) else {
            return Err(TestCaseError::fail("the walk problems are valid"));
        };
        let theta = [0.3, -0.2];
        let (ls, l0) = (log_likelihood(&scaled, &theta), log_likelihood(&plain, &theta));
        let (ls, l0) = (ls.unwrap(), l0.unwrap());
        let shift = 12.0 * f64::from(k) * std::f64::consts::LN_2;
        prop_assert!((ls - (l0 - shift)).abs() <= 1e-9 * (l0.abs() + shift.abs()), "{ls} vs {l0} - {shift}");
        // Measurements anywhere: a finite log-likelihood or a typed error.
        let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
        let problem = Parametrisation::new(None, CovarianceForm::scaled(one(r)), CovarianceForm::scaled(one(r)))
            .and_then(|noise| NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(r), kalibra::tune::Start::UpdateFirst, noise, vec![run]));
        if let Ok(problem) = problem {
            ok_finite("log_likelihood", &log_likelihood(&problem, &[0.0, 0.0]))?;
            ok_finite("log_likelihood at wide theta", &log_likelihood(&problem, &theta[..2]))?;
        }
    }
}

proptest! {
    #![proptest_config(config())]

    /// The estimators on a walk at scale `2^k` (a finite answer exists; EM's and maximum
    /// likelihood's multipliers are those of the unscaled walk) and on measurements anywhere in f64's range, with extreme
    /// tolerances, starts, gains and grids: every `Ok` holds finite numbers (but the
    /// documented infinite interval ends of maximum likelihood), or a typed error.
    #[test]
    fn tune_estimators(
        k in -500i32..=500,
        zs in series(),
        tolerance in wide(),
        start in prop::collection::vec(wide(), 2),
        gain in wide(),
        grid in (wide(), wide()),
    ) {
        let path = walk(16);
        let plain = walk_problem(0, &path).unwrap();
        let scaled = walk_problem(k, &path).unwrap();
        let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)), CovarianceForm::diagonal(one(1.0))).unwrap();
        let run: Vec<Option<DVector<f64>>> = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
        let wild = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0), kalibra::tune::Start::UpdateFirst, noise, vec![run]);
        // EM is scale-equivariant: the same multipliers at every scale.
        let exact = Em::new().exact_iterations(4);
        let (e0, ek) = (exact.estimate(&plain).unwrap(), exact.estimate(&scaled));
        ok_finite("Em at 2^k", &ek.as_ref().map(|e| e.values.clone()))?;
        let ek = ek.unwrap();
        for (a, b) in e0.values.iter().zip(&ek.values) {
            prop_assert!((a - b).abs() <= 1e-9 * a.abs(), "EM at 2^{k}: {b} vs {a}");
        }
        // So is maximum likelihood, to the optimiser's tolerance: the objectives differ by a
        // constant, which changes the finite differences' rounding only.
        let ml = MaximumLikelihood::new();
        static PLAIN_ML: std::sync::OnceLock<kalibra::tune::MlEstimate> = std::sync::OnceLock::new();
        let m0 = PLAIN_ML.get_or_init(|| ml.estimate(&plain).unwrap());
        let mk = ml.estimate(&scaled);
        prop_assert!(mk.as_ref().is_ok_and(ml_finite), "{mk:?}");
        let mk = mk.unwrap();
        let shift = 16.0 * f64::from(k) * std::f64::consts::LN_2;
        let want = m0.log_likelihood - shift;
        prop_assert!((mk.log_likelihood - want).abs() <= 1e-6 * (want.abs() + 1.0), "ML at 2^{k}: {} vs {want}", mk.log_likelihood);
        for (i, (a, b)) in m0.parameters.iter().zip(&mk.parameters).enumerate() {
            // A parameter run to a bound sits anywhere on its flat likelihood.
            if a.at_bound.is_none() && b.at_bound.is_none() {
                prop_assert!((m0.theta[i] - mk.theta[i]).abs() < 1e-3, "ML at 2^{k}: {} vs {}", mk.theta, m0.theta);
            }
        }
        for problem in std::iter::once(&scaled).chain(wild.as_ref()) {
            if let Ok(em) = Em::new().tolerance(tolerance.abs()).map(|e| e.max_iterations(20)) {
                let fit = em.estimate(problem);
                ok_finite("Em::estimate values", &fit.as_ref().map(|f| (f.values.clone(), f.log_likelihood.clone())))?;
                prop_assert!(fit.as_ref().map_or(true, |f| debug_finite(&f.matrices)), "{fit:?}");
            }
            if let Ok(ml) = MaximumLikelihood::new().gradient_tolerance(tolerance.abs()) {
                let fit = ml.max_iterations(20).estimate(problem);
                prop_assert!(fit.as_ref().map_or(true, ml_finite), "{fit:?}");
                let fit = MaximumLikelihood::new()
                    .max_iterations(20)
                    .starts(vec![DVector::from_vec(start.clone())])
                    .estimate(problem);
                prop_assert!(fit.as_ref().map_or(true, ml_finite), "{fit:?}");
            }
            for als in [Als::new().lags(3).unwrap(), Als::new().lags(3).unwrap().gain(one(gain))] {
                let fit = als.estimate(problem);
                if let Ok(f) = &fit {
                    prop_assert!(debug_finite(&f.matrices) && f.values.finite() && f.residual.is_finite(), "{f:?}");
                    prop_assert!(f.condition.is_finite() || !f.unique(), "{f:?}");
                }
            }
            let matrices = problem.noise().matrices(problem.noise().start().as_slice()).unwrap();
            if let Ok(sweep) = ParameterSweep::new().grid(vec![grid.0.min(grid.1), grid.0.max(grid.1)]) {
                let curves = sweep.sweep(problem, &matrices);
                prop_assert!(curves.as_ref().map_or(true, debug_finite), "{curves:?}");
            }
        }
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
    ("product_transpose", Cover::Reason(KERNEL)),
    ("cholesky_solve_right", Cover::Reason(KERNEL)),
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
    ("CredibilityRows::push_nees", Cover::Driven),
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
    ("ManoeuvreProfile::acceleration", Cover::Driven),
    ("ManoeuvreProfile::scaled", Cover::Driven),
    ("ManoeuvringTarget::truth_from_noise", Cover::Driven),
    ("ManoeuvringTarget::measurements_from_noise", Cover::Driven),
    ("ManoeuvringTarget::measurements", Cover::Driven),
    ("AirDensity::at", Cover::Driven),
    ("AirDensity::derivative", Cover::Driven),
    ("ballistic_f1", Cover::Driven),
    ("ballistic_g", Cover::Driven),
    ("Ballistic::new", Cover::Driven),
    ("Ballistic::with_noise", Cover::Driven),
    ("Ballistic::drag", Cover::Driven),
    ("Ballistic::drag_jacobian", Cover::Driven),
    ("BallisticDragFree::with_noise", Cover::Driven),
    ("ConvertedPosition::covariance", Cover::Driven),
    ("RadarRates::new", Cover::Driven),
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
    ("AccelAxis::position_measurement", Cover::Driven),
    ("AccelAxis::position_velocity_measurement", Cover::Driven),
    ("AccelAxis::jacobian_lanes", Cover::Reason(LANES)),
    ("Target3d::position_measurement", Cover::Driven),
    ("Target3d::position_velocity_measurement", Cover::Driven),
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
    ("Als::gain", Cover::Driven),
    ("CovarianceForm::diagonal", Cover::Driven),
    ("CovarianceForm::fixed", Cover::Driven),
    ("CovarianceForm::full", Cover::Driven),
    ("CovarianceForm::scaled", Cover::Driven),
    ("Em::tolerance", Cover::Driven),
    ("MaximumLikelihood::gradient_tolerance", Cover::Driven),
    ("MaximumLikelihood::starts", Cover::Driven),
    ("NoiseProblem::new", Cover::Driven),
    ("ParameterSweep::grid", Cover::Driven),
    ("Parametrisation::jacobian", Cover::Driven),
    ("Parametrisation::matrices", Cover::Driven),
    ("Parametrisation::natural", Cover::Driven),
    ("Parametrisation::new", Cover::Driven),
    ("Parametrisation::theta_of", Cover::Driven),
    ("log_likelihood", Cover::Driven),
    // kalibra-tune: maximum likelihood through the EKF and the UKF
    ("NonlinearNoiseProblem::new", Cover::Driven),
    ("NonlinearNoiseProblem::log_likelihood", Cover::Driven),
    ("WithProcessNoise::new", Cover::Driven),
    ("WithMeasurementNoise::new", Cover::Driven),
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
