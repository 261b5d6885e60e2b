//! Sizes and counts at their extremes through every public function of the library crates
//! that takes a `usize`: each is given `0`, `1`, `usize::MAX / 2` and `usize::MAX` in every
//! `usize` position (and, in the property, ordinary and large values mixed), and must return
//! within `LIMIT` (5 s, on a thread of its own, in debug builds) with an answer or a typed
//! error: no panic such as "capacity overflow", no allocation that aborts, no loop of 2^64
//! steps. The few functions whose documentation promises a panic (an index into a fixed batch
//! of lanes, an accumulator horizon beyond `HORIZON_MAX` given to the infallible constructor)
//! must panic with that message, at once.
//!
//! `every_size_function_is_listed` checks [`SIZE_FUNCTIONS`] against the public functions the
//! source scan (`extreme/mod.rs`) finds taking a `usize`.
//!
//! Size: the four extremes in every position of all 97 driven functions (16 calls each),
//! and `CASES` (64) cases of the mixed property; `PROPTEST_CASES` overrides the count.

use crate::extreme;

use std::fmt::Debug;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::Duration;

use crate::extreme::Cover;
use kalibra::bounds::{ErgodicAverage, Surrogate, observability_singular_values};
use kalibra::eval::{Evaluation, FilterLog, Matrices, Vectors};
use kalibra::filters::{
    AngleComponents, ConstantGainKf, FixedLagSmoother, KappaGrid, Kf, SigmaSet, Start,
};
use kalibra::linalg::{
    DMatrix, DVector, Dyn, KernelPolicy, Matrix1, Matrix2, SVector, Vector1, Vector2, check_dim,
};
use kalibra::metrics::{
    BatchMeans, ChiSquareBand, Credibility, CredibilityRows, JHorizon, SquaredErrors, StepMean,
    batch_means, consistent_median_nees, ks_asymptotic_p, ks_two_sample_exact_p, sliding_window,
    whiteness,
};
use kalibra::models::{
    AccelAxis, Bearing, BearingReference, Kinematic, Order, Simulator, Stationary, Target3dParams,
    check_dynamics_jacobian, check_measurement_jacobian, simulate, simulate_until,
};
use kalibra::sim::{MonteCarlo, Shard};
use kalibra::tune::{
    Als, CovarianceForm, Em, MaximumLikelihood, NoiseProblem, Parametrisation, Tuning, p_ad, sweep,
    two_point_init,
};
use proptest::prelude::*;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

/// The most a call may take, on a thread of its own.
const LIMIT: Duration = Duration::from_secs(5);

/// Cases of the mixed property.
const CASES: u32 = 64;

/// The extremes every `usize` position is given.
const EXTREMES: [usize; 4] = [0, 1, usize::MAX / 2, usize::MAX];

/// A call of one public function with the sizes `(a, b)` (a function with one `usize` ignores
/// `b`), returning its result as text.
type Call = Arc<dyn Fn(usize, usize) -> String + Send + Sync>;

fn text<T: Debug>(v: T) -> String {
    let s = format!("{v:?}");
    s.chars().take(200).collect()
}

/// The functions driven: name (as in [`SIZE_FUNCTIONS`]), the documented panic message if it
/// has one, and the call.
fn calls() -> Vec<(&'static str, Option<&'static str>, Call)> {
    fn c(f: impl Fn(usize, usize) -> String + Send + Sync + 'static) -> Call {
        Arc::new(f)
    }
    let series: Vec<f64> = (0..12).map(|i| (i as f64 * 0.7).sin()).collect();
    let s2 = series.clone();
    let s3 = series.clone();
    let s4 = series.clone();
    let small_log = || {
        FilterLog::new(2, 3)
            .and_then(|l| l.with_truth(Vectors::dense(1, vec![0.0; 6])))
            .and_then(|l| l.with_estimate(Vectors::dense(1, vec![0.9, -1.1, 1.0, -0.8, 1.2, -1.0])))
            .and_then(|l| l.with_covariance(Matrices::constant(1, 1, vec![1.0])))
            .unwrap()
    };
    let eval_with = move |e: Result<Evaluation, kalibra::eval::EvalError>| {
        text(
            e.and_then(|e| e.evaluate(&small_log()))
                .map(|r| r.summary.verdict.kind),
        )
    };
    let cv = || {
        let k = Kinematic::constant_velocity(1, 1.0).unwrap();
        (
            k.dynamics(Dyn(2)).unwrap(),
            k.position_measurement(Dyn(2), Dyn(1), DMatrix::identity(1, 1))
                .unwrap(),
        )
    };
    let surrogate = || {
        Surrogate::new(
            &DMatrix::from_vec(2, 1, vec![0.5, 0.1]),
            &(DMatrix::identity(2, 2) * 0.5),
            &DMatrix::from_vec(1, 2, vec![1.0, 0.0]),
            &DMatrix::identity(2, 2),
            &DMatrix::identity(1, 1),
        )
        .unwrap()
    };
    let bearing = |a: usize, b: usize| {
        Bearing::new(
            Dyn(4),
            [a, b],
            BearingReference::XAxis,
            1e-4,
            Stationary(Vector2::new(0.0, -20.0)),
        )
    };
    vec![
        // kalibra-bounds
        (
            "observability_singular_values",
            None,
            c(|a, b| {
                let f = vec![DMatrix::<f64>::identity(2, 2); 3];
                let h = vec![DMatrix::<f64>::from_vec(1, 2, vec![1.0, 0.0]); 4];
                text(observability_singular_values(&f, &h, a, b))
            }),
        ),
        (
            "ErgodicAverage::from_sums",
            None,
            c(|a, _| {
                text(
                    ErgodicAverage::from_sums(
                        DMatrix::<f64>::zeros(2, 1),
                        DMatrix::identity(2, 2),
                        a,
                    )
                    .and_then(|e| e.jacobian()),
                )
            }),
        ),
        (
            "Surrogate::covariance_after",
            None,
            c(move |a, _| text(surrogate().covariance_after(a, &DMatrix::identity(2, 2)))),
        ),
        // kalibra-eval: every option evaluated on a small log.
        (
            "Evaluation::window",
            None,
            c(move |a, _| eval_with(Evaluation::new().window(a))),
        ),
        (
            "Evaluation::lags",
            None,
            c(move |a, _| eval_with(Evaluation::new().lags(a))),
        ),
        (
            "Evaluation::diagnostic_run",
            None,
            c(move |a, _| eval_with(Ok(Evaluation::new().diagnostic_run(a)))),
        ),
        (
            "Evaluation::group",
            None,
            c(move |a, b| eval_with(Evaluation::new().group("g", vec![a, b]))),
        ),
        (
            "Vectors::dense",
            None,
            c(|a, _| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_truth(Vectors::dense(a, vec![0.0; 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Vectors::nan_unlogged",
            None,
            c(|a, _| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_estimate(Vectors::nan_unlogged(a, vec![0.0; 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Vectors::cells",
            None,
            c(|a, _| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_truth(Vectors::cells(a, vec![Some(vec![0.0]); 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::dense",
            None,
            c(|a, b| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_covariance(Matrices::dense(a, b, vec![1.0; 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::nan_unlogged",
            None,
            c(|a, b| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_covariance(Matrices::nan_unlogged(a, b, vec![1.0; 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::diagonal",
            None,
            c(|a, _| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_covariance(Matrices::diagonal(a, vec![1.0; 6])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::cells",
            None,
            c(|a, b| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| {
                            l.with_covariance(Matrices::cells(a, b, vec![Some(vec![1.0]); 6]))
                        })
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::diagonal_cells",
            None,
            c(|a, _| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| {
                            l.with_covariance(Matrices::diagonal_cells(a, vec![Some(vec![1.0]); 6]))
                        })
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::per_step",
            None,
            c(|a, b| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_covariance(Matrices::per_step(a, b, vec![1.0; 3])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "Matrices::constant",
            None,
            c(|a, b| {
                text(
                    FilterLog::new(2, 3)
                        .and_then(|l| l.with_covariance(Matrices::constant(a, b, vec![1.0])))
                        .map(|_| ()),
                )
            }),
        ),
        (
            "FilterLog::new",
            None,
            c(|a, b| text(FilterLog::new(a, b).map(|l| (l.runs(), l.steps())))),
        ),
        (
            "FilterLog::cell",
            Some("out of range"),
            c(move |a, b| text(small_log().cell(a, b).truth)),
        ),
        (
            "Evaluator::push",
            None,
            c(move |a, b| {
                let log = small_log();
                let mut e = Evaluation::new().evaluator(log.contents()).unwrap();
                text(e.push(a, b, &log.cell(0, 0)))
            }),
        ),
        (
            "Evaluator::push_batch",
            None,
            c(move |a, b| {
                let log = small_log();
                let mut e = Evaluation::new().evaluator(log.contents()).unwrap();
                text(e.push_batch(&[(a, b, log.cell(0, 0))]))
            }),
        ),
        (
            "Evaluator::prepare_batch",
            None,
            c(move |a, b| {
                let log = small_log();
                let mut e = Evaluation::new().evaluator(log.contents()).unwrap();
                let cells = [(a, b, log.cell(0, 0))];
                let prepared = e.prepare_batch(&cells);
                text(e.push_prepared(&cells, prepared))
            }),
        ),
        (
            "Evaluator::push_prepared",
            None,
            c(move |a, b| {
                let log = small_log();
                let mut e = Evaluation::new().evaluator(log.contents()).unwrap();
                // Prepared for other cells: set aside, and the cells prepared again.
                let prepared = e.prepare_batch(&[(0, 0, log.cell(0, 0))]);
                text(e.push_prepared(&[(a, b, log.cell(0, 0))], prepared))
            }),
        ),
        (
            "Tuning::threads",
            None,
            c(|a, _| text(Tuning::new().threads(a))),
        ),
        (
            "Tuning::position",
            None,
            c(|a, b| text(Tuning::new().position(vec![a, b]))),
        ),
        // kalibra-filters
        (
            "ConstantGainKf::steady_state_gain",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                text(ConstantGainKf::<Dyn, Dyn, _, _>::steady_state_gain(
                    &f,
                    &h,
                    a,
                    &DVector::zeros(2),
                ))
            }),
        ),
        (
            "FixedLagSmoother::new",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                let kf = Kf::new(f, h, DVector::zeros(2), DMatrix::identity(2, 2)).unwrap();
                let mut s = FixedLagSmoother::new(kf, a, Start::UpdateFirst);
                let z = DVector::from_vec(vec![1.0]);
                let steps: Vec<_> = (0..4).map(|_| s.step(Some(&z)).map(|o| o.len())).collect();
                text((steps, s.finish().map(|(_, v)| v.len())))
            }),
        ),
        (
            "KappaGrid::equidistant",
            None,
            c(|a, _| text(KappaGrid::equidistant(0.0, 1.0, a).map(|k| k.values().len()))),
        ),
        (
            "SigmaSet::recommended",
            None,
            c(|a, _| text(SigmaSet::recommended(a).weights(a))),
        ),
        (
            "SigmaSet::weights",
            None,
            c(|a, _| text(SigmaSet::Symmetric { kappa: 1.0 }.weights(a))),
        ),
        (
            "AngleComponents::new",
            None,
            c(|a, b| text(AngleComponents::new([a, b]))),
        ),
        // kalibra-linalg
        (
            "KernelPolicy::faer_from",
            None,
            c(|a, _| text(KernelPolicy::faer_from(a))),
        ),
        ("check_dim", None, c(|a, b| text(check_dim(a, b, "x")))),
        // kalibra-metrics
        (
            "StepMean::new",
            Some("HORIZON_MAX"),
            c(|a, _| text(StepMean::new(a).steps())),
        ),
        (
            "StepMean::try_new",
            None,
            c(|a, _| text(StepMean::try_new(a).map(|m| m.steps()))),
        ),
        (
            "StepMean::extend_steps",
            Some("HORIZON_MAX"),
            c(|a, _| {
                let mut m = StepMean::new(2);
                m.extend_steps(a);
                text(m.steps())
            }),
        ),
        (
            "StepMean::push",
            None,
            c(|a, _| text(StepMean::new(3).push(a, 1.0))),
        ),
        (
            "StepMean::count",
            None,
            c(|a, _| text(StepMean::new(3).count(a))),
        ),
        (
            "StepMean::mean",
            None,
            c(|a, _| text(StepMean::new(3).mean(a))),
        ),
        (
            "SquaredErrors::new",
            Some("HORIZON_MAX"),
            c(|a, b| text(SquaredErrors::new(a, b).steps())),
        ),
        (
            "SquaredErrors::try_new",
            None,
            c(|a, b| text(SquaredErrors::try_new(a, b).map(|m| m.steps()))),
        ),
        (
            "SquaredErrors::extend_steps",
            Some("HORIZON_MAX"),
            c(|a, _| {
                let mut m = SquaredErrors::new(2, 2);
                m.extend_steps(a);
                text(m.steps())
            }),
        ),
        (
            "SquaredErrors::count",
            None,
            c(|a, _| text(SquaredErrors::new(3, 2).count(a))),
        ),
        (
            "SquaredErrors::push_slice",
            None,
            c(|a, _| text(SquaredErrors::new(3, 2).push_slice(a, &[1.0, 2.0]))),
        ),
        (
            "SquaredErrors::push",
            None,
            c(|a, _| text(SquaredErrors::new(3, 2).push(a, &Vector2::new(1.0, 2.0)))),
        ),
        (
            "SquaredErrors::mse",
            None,
            c(|a, b| {
                let mut m = SquaredErrors::new(3, 2);
                m.push_slice(0, &[1.0, 2.0]).unwrap();
                text(m.mse(a, b))
            }),
        ),
        (
            "SquaredErrors::rmse",
            None,
            c(|a, b| {
                let mut m = SquaredErrors::new(3, 2);
                m.push_slice(0, &[1.0, 2.0]).unwrap();
                text(m.rmse(a, b))
            }),
        ),
        (
            "SquaredErrors::rmse_group",
            None,
            c(|a, b| {
                let mut m = SquaredErrors::new(3, 2);
                m.push_slice(0, &[1.0, 2.0]).unwrap();
                text(m.rmse_group(a, &[b]))
            }),
        ),
        (
            "SquaredErrors::rmse_series",
            None,
            c(|a, b| {
                let mut m = SquaredErrors::new(3, 2);
                m.push_slice(0, &[1.0, 2.0]).unwrap();
                text(m.rmse_series(&[a, b]))
            }),
        ),
        (
            "SquaredErrors::rmse_over_time",
            None,
            c(|a, b| {
                let mut m = SquaredErrors::new(3, 2);
                m.push_slice(0, &[1.0, 2.0]).unwrap();
                text(m.rmse_over_time(&[0], a..b))
            }),
        ),
        (
            "ChiSquareBand::for_mean",
            None,
            c(|a, _| text(ChiSquareBand::for_mean(2.0, a, 0.95))),
        ),
        (
            "ChiSquareBand::for_normalized_mean",
            None,
            c(|a, _| text(ChiSquareBand::for_normalized_mean(2.0, a, 0.95))),
        ),
        (
            "Credibility::new",
            Some("HORIZON_MAX"),
            c(|a, b| text(Credibility::new(a, b).steps())),
        ),
        (
            "Credibility::try_new",
            None,
            c(|a, b| text(Credibility::try_new(a, b).map(|m| m.steps()))),
        ),
        (
            "Credibility::extend_steps",
            Some("HORIZON_MAX"),
            c(|a, _| {
                let mut m = Credibility::new(2, 2);
                m.extend_steps(a);
                text(m.steps())
            }),
        ),
        (
            "Credibility::runs",
            None,
            c(|a, _| text(Credibility::new(3, 2).runs(a))),
        ),
        (
            "Credibility::push",
            None,
            c(|a, _| {
                text(Credibility::new(3, 2).push(a, &Vector2::new(1.0, 0.0), &Matrix2::identity()))
            }),
        ),
        (
            "Credibility::push_nees",
            None,
            c(|a, _| text(Credibility::new(3, 2).push_nees(a, &[1.0, 0.0], 1.0))),
        ),
        (
            "CredibilityRows::push_nees",
            None,
            c(|a, _| {
                let cred = Credibility::new(3, 2);
                text(CredibilityRows::new().push_nees(&cred, a, &[1.0, 0.0], 1.0))
            }),
        ),
        (
            "Credibility::step_summary",
            None,
            c(|a, _| {
                let mut m = Credibility::new(3, 2);
                m.push_nees(0, &[1.0, 0.0], 1.0).unwrap();
                text(m.step_summary(a))
            }),
        ),
        (
            "Credibility::step_nci",
            None,
            c(|a, _| {
                let mut m = Credibility::new(3, 2);
                m.push_nees(0, &[1.0, 0.0], 1.0).unwrap();
                text(m.step_nci(a))
            }),
        ),
        (
            "Credibility::reserve_runs",
            None,
            c(|a, b| {
                let mut m = Credibility::new(3, 2);
                m.reserve_runs(a, 0..b);
                text(m.push_nees(0, &[1.0, 0.0], 1.0))
            }),
        ),
        (
            "Credibility::over_time",
            None,
            c(|a, b| {
                let mut m = Credibility::new(3, 2);
                m.push_nees(0, &[1.0, 0.0], 1.0).unwrap();
                text(m.over_time(a..b))
            }),
        ),
        (
            "consistent_median_nees",
            None,
            c(|a, _| text(consistent_median_nees(a))),
        ),
        (
            "batch_means",
            None,
            c(move |a, b| text(batch_means(&series, a, b))),
        ),
        (
            "BatchMeans::new",
            None,
            c(move |a, b| {
                text(BatchMeans::new(a, b).and_then(|mut m| {
                    for &x in &s2 {
                        m.push(x);
                    }
                    m.finish()
                }))
            }),
        ),
        (
            "ks_two_sample_exact_p",
            None,
            c(|a, b| text(ks_two_sample_exact_p(a, b, 0.5))),
        ),
        (
            "ks_asymptotic_p",
            None,
            c(|a, b| text(ks_asymptotic_p(a, b, 0.5))),
        ),
        (
            "JHorizon::summary",
            None,
            c(|a, _| {
                let mut h = JHorizon::new();
                let step = kalibra::metrics::j_step(
                    &Matrix1::new(1.0),
                    &Matrix1::new(0.5),
                    &Matrix1::new(1.0),
                    &Matrix1::new(0.5),
                )
                .unwrap();
                h.push(&step);
                text(h.summary(a))
            }),
        ),
        (
            "whiteness",
            None,
            c(move |a, _| {
                let normalized: Vec<Option<Vector1<f64>>> =
                    s3.iter().map(|&x| Some(Vector1::new(x))).collect();
                text(whiteness(&normalized, a, 0.95))
            }),
        ),
        (
            "sliding_window",
            None,
            c(move |a, _| text(sliding_window(&s4, a).map(|w| w.len()))),
        ),
        // kalibra-models
        (
            "Bearing::new",
            None,
            c(move |a, b| text(bearing(a, b).map(|_| ()))),
        ),
        (
            "Bearing::relative_position",
            None,
            c(move |a, _| {
                text(
                    bearing(0, 1)
                        .unwrap()
                        .relative_position(a, &DVector::from_vec(vec![1.0, 2.0, 3.0, 4.0])),
                )
            }),
        ),
        (
            "Bearing::shift",
            None,
            c(move |a, _| text(bearing(0, 1).unwrap().shift(a))),
        ),
        (
            "check_dynamics_jacobian",
            None,
            c(move |a, _| {
                let (f, _) = cv();
                text(check_dynamics_jacobian(
                    &f,
                    a,
                    &DVector::from_vec(vec![1.0, 2.0]),
                ))
            }),
        ),
        (
            "check_measurement_jacobian",
            None,
            c(move |a, _| {
                let (_, h) = cv();
                text(check_measurement_jacobian(
                    &h,
                    a,
                    &DVector::from_vec(vec![1.0, 2.0]),
                ))
            }),
        ),
        (
            "Kinematic::new",
            None,
            c(|a, _| text(Kinematic::new(Order::ConstantVelocity, a, 1.0).map(|k| k.state_len()))),
        ),
        (
            "Kinematic::constant_velocity",
            None,
            c(|a, _| text(Kinematic::constant_velocity(a, 1.0).map(|k| k.state_len()))),
        ),
        (
            "Kinematic::constant_acceleration",
            None,
            c(|a, _| text(Kinematic::constant_acceleration(a, 1.0).map(|k| k.state_len()))),
        ),
        (
            "Kinematic::index",
            Some("out of range"),
            c(|a, b| text(Kinematic::constant_velocity(2, 1.0).unwrap().index(a, b))),
        ),
        (
            "Simulator::new",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                text(
                    Simulator::new(f, h, DVector::zeros(2), a)
                        .map(|mut s| s.step(&mut ChaCha8Rng::seed_from_u64(1)).map(|(x, _)| x)),
                )
            }),
        ),
        (
            "simulate",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                text(
                    simulate(
                        f,
                        h,
                        DVector::zeros(2),
                        a,
                        &mut ChaCha8Rng::seed_from_u64(1),
                    )
                    .map(|t| t.len()),
                )
            }),
        ),
        (
            "simulate_until",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                text(
                    simulate_until(
                        f,
                        h,
                        DVector::zeros(2),
                        a,
                        &mut ChaCha8Rng::seed_from_u64(1),
                        |k, _| k >= 5,
                    )
                    .map(|t| t.len()),
                )
            }),
        ),
        (
            "AccelAxis::new",
            None,
            c(|a, _| text(AccelAxis::new(Target3dParams::default(), a).map(|_| ()))),
        ),
        // kalibra-sim
        (
            "MonteCarlo::new",
            None,
            c(|a, _| {
                let mc = MonteCarlo::new(a, 7);
                text((mc.runs(), mc.blocks()))
            }),
        ),
        (
            "MonteCarlo::threads",
            None,
            c(|a, _| {
                let mc = MonteCarlo::new(3, 7).threads(a);
                text(
                    mc.accumulate(
                        || StepMean::new(1),
                        |i, _, acc: &mut StepMean| acc.push(0, i as f64),
                    )
                    .map(|m| m.mean(0)),
                )
            }),
        ),
        (
            "MonteCarlo::rng",
            None,
            c(|a, _| text(MonteCarlo::new(3, 7).rng(a).get_stream())),
        ),
        (
            "MonteCarlo::block_runs",
            None,
            c(|a, _| text(MonteCarlo::new(3, 7).block_runs(a))),
        ),
        ("Shard::new", None, c(|a, b| text(Shard::new(a, b)))),
        (
            "Shard::blocks",
            None,
            c(|a, _| text(Shard::new(0, 2).map(|s| s.blocks(a)))),
        ),
        (
            "sweep",
            None,
            c(|a, _| {
                text(sweep(&[1.0, 2.0], a, |p| {
                    Ok::<f64, std::fmt::Error>(p * 2.0)
                }))
            }),
        ),
        (
            "two_point_init",
            None,
            c(|a, b| {
                let r = kalibra::linalg::SMatrix::<f64, 1, 1>::new(1.0);
                text(two_point_init::<2, 1>(
                    &SVector::<f64, 1>::new(1.0),
                    &SVector::<f64, 1>::new(2.0),
                    &r,
                    &r,
                    1.0,
                    [a],
                    [b],
                ))
            }),
        ),
        (
            "p_ad",
            None,
            c(move |a, _| {
                let (f, h) = cv();
                let states = vec![DVector::from_vec(vec![0.0, 1.0]); 3];
                text(p_ad(&f, &h, &states, a))
            }),
        ),
        // kalibra-tune's noise estimation, on a scalar random walk of 16 steps.
        (
            "Als::lags",
            None,
            c(move |a, _| text(Als::new().lags(a).and_then(|als| als.estimate(&walk())))),
        ),
        (
            "Als::skip",
            None,
            c(move |a, _| text(Als::new().skip(a).estimate(&walk()))),
        ),
        (
            "CovarianceForm::fix",
            None,
            c(|a, b| {
                let form = CovarianceForm::full(DMatrix::identity(2, 2)).fix(a, b);
                text(Parametrisation::new(
                    None,
                    form,
                    CovarianceForm::fixed(DMatrix::identity(2, 2)),
                ))
            }),
        ),
        (
            "CovarianceForm::is_fixed",
            None,
            c(|a, b| {
                text(
                    CovarianceForm::diagonal(DMatrix::identity(2, 2))
                        .fix(a, a)
                        .is_fixed(a, b),
                )
            }),
        ),
        (
            "Em::exact_iterations",
            None,
            c(move |a, _| text(Em::new().exact_iterations(a).estimate(&walk()))),
        ),
        (
            "Em::max_iterations",
            None,
            c(move |a, _| text(Em::new().max_iterations(a).estimate(&walk()))),
        ),
        (
            "MaximumLikelihood::max_iterations",
            None,
            c(move |a, _| {
                text(
                    MaximumLikelihood::new()
                        .max_iterations(a)
                        .estimate(&walk())
                        .map(|e| e.theta),
                )
            }),
        ),
    ]
}

/// A scalar random walk seen directly, 16 steps, both noise multipliers free.
fn walk() -> NoiseProblem {
    let one = |v: f64| DMatrix::from_element(1, 1, v);
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(0.2)),
        CovarianceForm::scaled(one(0.5)),
    )
    .unwrap();
    let run = (0..16)
        .map(|k| {
            let k = k as f64;
            Some(DVector::from_element(1, 0.1 * k + (0.7 * k).sin()))
        })
        .collect();
    NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(1.0),
        Start::PredictFirst,
        noise,
        vec![run],
    )
    .unwrap()
}

/// Silences the default panic message of the calls' own threads (named `call ...`): their
/// panics are caught and reported with the failures; every other thread's panic prints.
fn quiet_calls() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let ours = std::thread::current()
                .name()
                .is_some_and(|n| n.starts_with("call "));
            if !ours {
                default(info);
            }
        }));
    });
}

/// Runs `call(a, b)` on a thread of its own: `Ok(text)` if it returned within [`LIMIT`],
/// `Err(message)` if it panicked, and a failure naming it if it did not return in time (the
/// thread is left to the end of the process).
fn bounded(name: &str, call: &Call, a: usize, b: usize) -> Result<String, String> {
    quiet_calls();
    let (tx, rx) = mpsc::channel();
    let call = Arc::clone(call);
    std::thread::Builder::new()
        .name(format!("call {name}({a}, {b})"))
        .spawn(move || {
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| call(a, b)))
                .map_err(|p| {
                    p.downcast_ref::<String>()
                        .cloned()
                        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default()
                });
            let _ = tx.send(out);
        })
        .expect("a thread can be spawned");
    match rx.recv_timeout(LIMIT) {
        Ok(out) => out,
        Err(_) => Err(format!("did not return within {LIMIT:?}")),
    }
}

/// Checks one call: an answer or a typed error, or the documented panic.
fn check(
    name: &str,
    documented: Option<&str>,
    call: &Call,
    a: usize,
    b: usize,
) -> Result<(), String> {
    match (bounded(name, call, a, b), documented) {
        (Ok(_), _) => Ok(()),
        (Err(message), Some(want)) if message.contains(want) => Ok(()),
        (Err(message), _) => Err(format!("{name}({a}, {b}): {message}")),
    }
}

/// The extremes in every position: every driven function, every pair of [`EXTREMES`].
#[test]
fn every_size_function_returns_promptly() {
    let mut failures = Vec::new();
    for (name, documented, call) in calls() {
        for a in EXTREMES {
            for b in EXTREMES {
                if let Err(e) = check(name, documented, &call, a, b) {
                    failures.push(e);
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

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

/// A size: ordinary, just past a limit, or extreme.
fn size() -> impl Strategy<Value = usize> {
    prop_oneof![
        4 => 0usize..40,
        1 => Just(usize::MAX),
        1 => Just(usize::MAX / 2),
        1 => Just(1usize << 40),
        1 => Just((1usize << 32) + 1),
    ]
}

proptest! {
    #![proptest_config(config())]

    /// Ordinary and extreme sizes mixed, through every driven function.
    #[test]
    fn sizes_mixed(a in size(), b in size()) {
        for (name, documented, call) in calls() {
            let r = check(name, documented, &call, a, b);
            prop_assert!(r.is_ok(), "{}", r.unwrap_err());
        }
    }
}

// ----- the list, checked against the sources ------------------------------------------------

const LANE_INDEX: &str = "an index into a fixed batch of BATCH = 8 lanes: `lane >= BATCH` is a \
    documented panic (misuse of a fixed-size type), checked by an assert before any access";
const STUDY: &str = "a published study's scenario, run with the paper's fixed values by \
    `cargo xtask reproduce`; no user data reaches it";
const IO: &str = "kalibra-io reader plumbing (shapes and columns from files): \
    crates/kalibra-io/tests/readers_fuzz.rs and errors.rs feed it hostile files, and \
    log_from_arrays checks its shape product with checked_mul before anything is allocated";

/// Every public function of the library crates that takes a `usize`, with how it is covered.
pub const SIZE_FUNCTIONS: &[(&str, Cover)] = &[
    // kalibra-bounds
    ("observability_singular_values", Cover::Driven),
    ("ErgodicAverage::from_sums", Cover::Driven),
    ("Surrogate::covariance_after", Cover::Driven),
    // kalibra-eval
    ("Evaluation::window", Cover::Driven),
    ("Evaluation::group", Cover::Driven),
    ("Evaluation::lags", Cover::Driven),
    ("Evaluation::diagnostic_run", Cover::Driven),
    ("Vectors::dense", Cover::Driven),
    ("Vectors::nan_unlogged", Cover::Driven),
    ("Vectors::cells", Cover::Driven),
    ("Matrices::dense", Cover::Driven),
    ("Matrices::nan_unlogged", Cover::Driven),
    ("Matrices::diagonal", Cover::Driven),
    ("Matrices::cells", Cover::Driven),
    ("Matrices::diagonal_cells", Cover::Driven),
    ("Matrices::per_step", Cover::Driven),
    ("Matrices::constant", Cover::Driven),
    ("FilterLog::new", Cover::Driven),
    ("FilterLog::cell", Cover::Driven),
    ("Evaluator::push", Cover::Driven),
    ("Evaluator::push_batch", Cover::Driven),
    ("Evaluator::prepare_batch", Cover::Driven),
    ("Evaluator::push_prepared", Cover::Driven),
    ("Tuning::threads", Cover::Driven),
    ("Tuning::position", Cover::Driven),
    // kalibra-filters
    ("JLanes::a", Cover::Reason(LANE_INDEX)),
    ("JLanes::b", Cover::Reason(LANE_INDEX)),
    ("JLanes::c", Cover::Reason(LANE_INDEX)),
    ("JLanes::r", Cover::Reason(LANE_INDEX)),
    ("JLanes::j1", Cover::Reason(LANE_INDEX)),
    ("JLanes::j2", Cover::Reason(LANE_INDEX)),
    ("JLanes::tr_n", Cover::Reason(LANE_INDEX)),
    ("JLanes::tr_b", Cover::Reason(LANE_INDEX)),
    ("EkfBatch::gain", Cover::Reason(LANE_INDEX)),
    ("KfBatch::set_lane", Cover::Reason(LANE_INDEX)),
    ("KfBatch::cov", Cover::Reason(LANE_INDEX)),
    ("KfBatch::gain", Cover::Reason(LANE_INDEX)),
    ("LaneState::set_lane", Cover::Reason(LANE_INDEX)),
    ("LaneState::write_lane", Cover::Reason(LANE_INDEX)),
    ("LaneState::mean", Cover::Reason(LANE_INDEX)),
    ("LaneState::cov", Cover::Reason(LANE_INDEX)),
    ("LaneState::gain", Cover::Reason(LANE_INDEX)),
    ("mean", Cover::Reason(LANE_INDEX)),
    ("set_lane", Cover::Reason(LANE_INDEX)),
    ("cov", Cover::Reason(LANE_INDEX)),
    (
        "KfSchedule::new",
        Cover::Reason(
            "`updates` is reserved with try_reserve_exact, a typed error when it cannot be had (crates/kalibra-filters/tests/schedule.rs); its model is a fixed-size batch",
        ),
    ),
    (
        "KfSchedule::posterior",
        Cover::Reason(
            "an index into the schedule: `None` beyond its end (crates/kalibra-filters/tests/schedule.rs)",
        ),
    ),
    ("BatchStep::nis", Cover::Reason(LANE_INDEX)),
    ("BatchStep::nees", Cover::Reason(LANE_INDEX)),
    ("BatchStep::error", Cover::Reason(LANE_INDEX)),
    ("UkfBatch::gain", Cover::Reason(LANE_INDEX)),
    ("UkfBatch::kappa", Cover::Reason(LANE_INDEX)),
    ("ConstantGainKf::steady_state_gain", Cover::Driven),
    ("FixedLagSmoother::new", Cover::Driven),
    ("KappaGrid::equidistant", Cover::Driven),
    ("SigmaSet::recommended", Cover::Driven),
    ("SigmaSet::weights", Cover::Driven),
    ("AngleComponents::new", Cover::Driven),
    // kalibra-io
    ("Rows::cell_error", Cover::Reason(IO)),
    ("Rows::header_error", Cover::Reason(IO)),
    ("log_from_arrays", Cover::Reason(IO)),
    ("RawLog::put_cells", Cover::Reason(IO)),
    ("read_series", Cover::Reason(IO)),
    ("parse_series", Cover::Reason(IO)),
    // kalibra-linalg
    ("KernelPolicy::faer_from", Cover::Driven),
    ("check_dim", Cover::Driven),
    ("load", Cover::Reason(LANE_INDEX)),
    ("store", Cover::Reason(LANE_INDEX)),
    // kalibra-metrics
    ("StepMean::new", Cover::Driven),
    ("StepMean::try_new", Cover::Driven),
    ("StepMean::extend_steps", Cover::Driven),
    ("StepMean::push", Cover::Driven),
    (
        "StepMean::push_lanes",
        Cover::Reason(
            "StepMean::push for a batch of lanes, bit-identical to it, with the same step check (accumulate.rs tests)",
        ),
    ),
    ("StepMean::count", Cover::Driven),
    ("StepMean::mean", Cover::Driven),
    ("SquaredErrors::new", Cover::Driven),
    ("SquaredErrors::try_new", Cover::Driven),
    ("SquaredErrors::extend_steps", Cover::Driven),
    ("SquaredErrors::count", Cover::Driven),
    ("SquaredErrors::push_slice", Cover::Driven),
    (
        "SquaredErrors::push_lanes",
        Cover::Reason(
            "SquaredErrors::push_slice for a batch of lanes, bit-identical to it, with the same step check (accumulate.rs tests)",
        ),
    ),
    ("SquaredErrors::push", Cover::Driven),
    ("SquaredErrors::mse", Cover::Driven),
    ("SquaredErrors::rmse", Cover::Driven),
    ("SquaredErrors::rmse_group", Cover::Driven),
    ("SquaredErrors::rmse_series", Cover::Driven),
    ("SquaredErrors::rmse_over_time", Cover::Driven),
    ("ChiSquareBand::for_mean", Cover::Driven),
    ("ChiSquareBand::for_normalized_mean", Cover::Driven),
    ("Credibility::new", Cover::Driven),
    ("Credibility::try_new", Cover::Driven),
    ("Credibility::extend_steps", Cover::Driven),
    ("Credibility::runs", Cover::Driven),
    ("Credibility::push", Cover::Driven),
    ("Credibility::push_nees", Cover::Driven),
    ("CredibilityRows::push_nees", Cover::Driven),
    ("Credibility::step_summary", Cover::Driven),
    ("Credibility::step_nci", Cover::Driven),
    ("Credibility::reserve_runs", Cover::Driven),
    ("Credibility::over_time", Cover::Driven),
    ("consistent_median_nees", Cover::Driven),
    ("batch_means", Cover::Driven),
    ("BatchMeans::new", Cover::Driven),
    ("ks_two_sample_exact_p", Cover::Driven),
    ("ks_asymptotic_p", Cover::Driven),
    ("JHorizon::summary", Cover::Driven),
    ("whiteness", Cover::Driven),
    ("sliding_window", Cover::Driven),
    // kalibra-models
    ("Bearing::new", Cover::Driven),
    ("Bearing::relative_position", Cover::Driven),
    ("Bearing::shift", Cover::Driven),
    ("check_dynamics_jacobian", Cover::Driven),
    ("check_measurement_jacobian", Cover::Driven),
    ("Kinematic::new", Cover::Driven),
    ("Kinematic::constant_velocity", Cover::Driven),
    ("Kinematic::constant_acceleration", Cover::Driven),
    ("Kinematic::index", Cover::Driven),
    ("lane", Cover::Reason(LANE_INDEX)),
    ("set_lane_vector", Cover::Reason(LANE_INDEX)),
    ("set_lane", Cover::Reason(LANE_INDEX)),
    ("Simulator::new", Cover::Driven),
    ("simulate", Cover::Driven),
    ("simulate_until", Cover::Driven),
    ("AccelAxis::new", Cover::Driven),
    // kalibra-sim
    (
        "TruthBatch::new",
        Cover::Reason(
            "a batch of up to BATCH = 8 runs' truths: `first_run` names the runs' streams (crates/kalibra-sim/tests/batch.rs); its count is the rngs slice's length",
        ),
    ),
    (
        "LinearTruthBatch::new",
        Cover::Reason("as TruthBatch::new, for linear models"),
    ),
    ("ChaCha8Lanes::word_pos", Cover::Reason(LANE_INDEX)),
    ("ChaCha8Lanes::lane", Cover::Reason(LANE_INDEX)),
    ("MonteCarlo::new", Cover::Driven),
    ("MonteCarlo::threads", Cover::Driven),
    ("MonteCarlo::rng", Cover::Driven),
    ("Shard::new", Cover::Driven),
    ("Shard::blocks", Cover::Driven),
    ("MonteCarlo::block_runs", Cover::Driven),
    ("sweep", Cover::Driven),
    ("two_point_init", Cover::Driven),
    ("p_ad", Cover::Driven),
    // kalibra-studies
    ("replay", Cover::Reason(STUDY)),
    ("table_p", Cover::Reason(STUDY)),
    ("kappa_grid", Cover::Reason(STUDY)),
    ("Als::lags", Cover::Driven),
    ("Als::skip", Cover::Driven),
    ("CovarianceForm::fix", Cover::Driven),
    ("CovarianceForm::is_fixed", Cover::Driven),
    ("Em::exact_iterations", Cover::Driven),
    ("Em::max_iterations", Cover::Driven),
    ("MaximumLikelihood::max_iterations", Cover::Driven),
    (
        "in_pool",
        Cover::Reason("the thread pool of `sweep`, driven here through `sweep`'s thread count"),
    ),
];

/// The list above is the scanned sources' list, and every `Driven` entry is called above.
#[test]
fn every_size_function_is_listed() {
    let takes_sizes = |f: &extreme::PublicFn| {
        f.params
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .any(|w| w == "usize")
    };
    let problems = extreme::check_list(
        SIZE_FUNCTIONS,
        takes_sizes,
        include_str!("extreme_sizes.rs"),
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
