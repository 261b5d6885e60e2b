//! Error series and sliding-window statistics (paper 002): a hand-checkable case, agreement
//! with a direct two-pass computation of every window (long series, large offsets), the failure
//! of running sums that motivated the method, the RMSE/bias/std identity, and typed errors.

use kalibra_linalg::{DVector, LinalgError, U2, Vector2};
use kalibra_metrics::{
    MetricsError, WindowStats, instantaneous_errors, rmse, rmse_per_state, sliding_window,
};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Every window computed on its own by the corrected two-pass algorithm (Chan, Golub and
/// LeVeque): the mean, then the deviations `d_j = e(j) - mean` with
/// `M2 = sum d_j^2 - (sum d_j)^2 / W`, whose second term removes the first-order effect of the
/// mean's rounding (a plain two-pass computation is itself off by `1e-11` relative on the
/// `1e6`-offset series below). `O(N W)` and free of any sliding update, so it shares no error
/// mechanism with the code under test.
fn direct(series: &[f64], window: usize) -> WindowStats {
    let w = window as f64;
    let mut out = WindowStats {
        window,
        rmse: Vec::new(),
        bias: Vec::new(),
        std: Vec::new(),
    };
    for chunk in series.windows(window) {
        let mean = chunk.iter().sum::<f64>() / w;
        let sum_d: f64 = chunk.iter().map(|x| x - mean).sum();
        let sum_d2: f64 = chunk.iter().map(|x| (x - mean) * (x - mean)).sum();
        let m2 = (sum_d2 - sum_d * sum_d / w).max(0.0);
        let bias = mean + sum_d / w;
        out.bias.push(bias);
        out.std.push((m2 / (w - 1.0)).sqrt());
        out.rmse
            .push((chunk.iter().map(|x| x * x).sum::<f64>() / w).sqrt());
    }
    out
}

/// The textbook `O(N)` method this crate does not use: running sums of `e` and `e^2`, updated
/// as the window slides, and `var = (sum e^2 - W mean^2) / (W - 1)` (clamped at 0).
fn naive_std(series: &[f64], window: usize) -> Vec<f64> {
    let w = window as f64;
    let mut s1: f64 = series[..window].iter().sum();
    let mut s2: f64 = series[..window].iter().map(|x| x * x).sum();
    let mut out = Vec::new();
    for start in 0..=series.len() - window {
        if start > 0 {
            let (x_out, x_in) = (series[start - 1], series[start + window - 1]);
            s1 += x_in - x_out;
            s2 += x_in * x_in - x_out * x_out;
        }
        let mean = s1 / w;
        out.push(((s2 - w * mean * mean) / (w - 1.0)).max(0.0).sqrt());
    }
    out
}

/// A Welford update like the crate's but on the raw samples, without the shift by a reference
/// sample: the ablation that shows why the shift is there.
fn unshifted_welford_std(series: &[f64], window: usize) -> Vec<f64> {
    let w = window as f64;
    let (mut mean, mut m2) = (0.0, 0.0);
    let mut out = Vec::new();
    for start in 0..=series.len() - window {
        if start % window == 0 {
            let chunk = &series[start..start + window];
            mean = chunk.iter().sum::<f64>() / w;
            m2 = chunk.iter().map(|x| (x - mean) * (x - mean)).sum();
        } else {
            let (x_out, x_in) = (series[start - 1], series[start + window - 1]);
            let next = mean + (x_in - x_out) / w;
            m2 = (m2 + (x_in - x_out) * (x_in - next + x_out - mean)).max(0.0);
            mean = next;
        }
        out.push((m2 / (w - 1.0)).sqrt());
    }
    out
}

/// `|a - b| / scale`, but 0 when `a == b` (a constant window's std and its local scale are
/// both 0, and 0/0 would be a NaN that `f64::max` silently drops) and infinite when only the
/// scale is 0.
fn rel(a: f64, b: f64, scale: f64) -> f64 {
    if a == b { 0.0 } else { (a - b).abs() / scale }
}

fn max_rel_std_error(std: &[f64], reference: &WindowStats) -> f64 {
    std.iter()
        .zip(&reference.std)
        .map(|(&s, &r)| rel(s, r, r))
        .fold(0.0, f64::max)
}

/// Largest errors of `ours` against `reference`.
#[derive(Debug)]
struct Errors {
    /// Bias and RMSE, relative to the window's RMSE (the size of its data: a zero-mean series
    /// has biases near zero, where a relative error means nothing).
    bias_rmse: f64,
    /// The std, relative to itself.
    std: f64,
    /// `std^2`, relative to the largest reference `std^2` among the window and the `W` windows
    /// before it. An update's rounding is relative to the spread of the samples it moves, and
    /// a recomputation happens at least every `W` slides, so this is the scale the method
    /// promises; the pointwise relative error of the std grows where a window's spread is far
    /// below its neighbours' (two nearly equal samples with `W = 2`).
    local_var: f64,
}

fn errors(ours: &WindowStats, reference: &WindowStats) -> Errors {
    assert_eq!(ours.window, reference.window);
    assert_eq!(ours.len(), reference.len());
    let var = |s: &f64| s * s;
    let mut worst = Errors {
        bias_rmse: 0.0,
        std: max_rel_std_error(&ours.std, reference),
        local_var: 0.0,
    };
    for i in 0..ours.len() {
        let scale = reference.rmse[i];
        let bias = rel(ours.bias[i], reference.bias[i], scale);
        let rmse = rel(ours.rmse[i], reference.rmse[i], scale);
        worst.bias_rmse = worst.bias_rmse.max(bias).max(rmse);
        let local = reference.std[i.saturating_sub(ours.window)..=i]
            .iter()
            .map(var)
            .fold(0.0, f64::max);
        let local_var = rel(var(&ours.std[i]), var(&reference.std[i]), local);
        worst.local_var = worst.local_var.max(local_var);
    }
    worst
}

fn normal_series(seed: u64, n: usize, offset: f64, sd: f64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sd).unwrap();
    (0..n).map(|_| offset + noise.sample(&mut rng)).collect()
}

// Tolerances are about 10x the largest error measured in the cases they guard (the figures
// are in each test): room for a different libm or summation order, while a lost shift (errors
// of 1e-8 to 1e-6 on the offset series) or a drifting update would fail them by orders of
// magnitude.

/// `std^2` against the local scale (see [`Errors::local_var`]): measured at most 5.5e-15, over
/// all the fixed cases (worst W = 1000) and 3000 random ones.
const LOCAL_VAR_TOL: f64 = 6e-14;

/// Bias and RMSE, and the std for windows of 50 samples and more: measured at most 3.5e-15.
const WIDE_TOL: f64 = 4e-14;

/// The sliding result against the direct one, within `bias_rmse` and `std` (see [`Errors`])
/// and [`LOCAL_VAR_TOL`].
fn assert_matches_direct(series: &[f64], window: usize, bias_rmse: f64, std: f64) {
    let e = errors(
        &sliding_window(series, window).unwrap(),
        &direct(series, window),
    );
    assert!(
        e.bias_rmse <= bias_rmse && e.std <= std && e.local_var <= LOCAL_VAR_TOL,
        "W = {window}: {e:?}"
    );
}

#[test]
fn hand_checkable_case_matches_independent_values() {
    // From an independent implementation; W = 3 over six samples gives four windows.
    let e = [0.3, -0.1, 0.2, 0.0, -0.4, 0.5];
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12;
    assert!(close(rmse(&e).unwrap(), 0.3027650354097492));
    let s = sliding_window(&e, 3).unwrap();
    assert_eq!((s.window, s.len()), (3, 4));
    let expected = [
        [
            0.21602468994692867,
            0.12909944487358058,
            0.25819888974716115,
            0.36968455021364727,
        ],
        [
            0.13333333333333333,
            0.03333333333333333,
            -0.06666666666666667,
            0.033333333333333326,
        ],
        [
            0.20816659994661327,
            0.15275252316519466,
            0.3055050463303894,
            0.4509249752822895,
        ],
    ];
    for (got, want) in [&s.rmse, &s.bias, &s.std].into_iter().zip(&expected) {
        for (g, w) in got.iter().zip(want) {
            assert!(close(*g, *w), "{g} != {w}");
        }
    }
}

#[test]
fn random_series_match_direct_for_several_windows() {
    // Unit-scale data with a mean of its own. The short windows have the larger pointwise
    // errors: among 5000 samples some pairs and triples are nearly equal, so their spread is
    // far below their neighbours' (the local error stays at 1e-15). Measured maxima (bias and
    // RMSE, std): W = 2: 1.8e-13, 3.9e-10; W = 3: 6.2e-14, 7.8e-13; W = 50: 1.5e-15, 7.5e-16;
    // W = 1000: 2.1e-15, 2.8e-15.
    let series = normal_series(1, 5000, 0.3, 1.0);
    assert_matches_direct(&series, 2, 2e-12, 4e-9);
    assert_matches_direct(&series, 3, 7e-13, 8e-12);
    assert_matches_direct(&series, 50, WIDE_TOL, WIDE_TOL);
    assert_matches_direct(&series, 1000, WIDE_TOL, WIDE_TOL);
}

#[test]
fn long_series_does_not_drift() {
    // A million samples, 20000 recomputations: a drift of the updates would show as an error
    // that grows along the series. Measured maxima: bias and RMSE 3.5e-15, std 1.3e-15.
    let series = normal_series(2, 1_000_000, -0.2, 1.0);
    assert_matches_direct(&series, 50, WIDE_TOL, WIDE_TOL);
}

#[test]
fn large_offsets_keep_full_precision() {
    // Spreads of 1e-8 and 1e-10 of the offset. Measured maxima (bias and RMSE, std):
    // 1e8 + N(0, 1): 6.0e-16, 9.2e-16; 1e6 + 1e-4 N(0, 1): 4.7e-16, 1.1e-15.
    assert_matches_direct(&normal_series(3, 100_000, 1e8, 1.0), 50, WIDE_TOL, WIDE_TOL);
    assert_matches_direct(
        &normal_series(4, 100_000, 1e6, 1e-4),
        50,
        WIDE_TOL,
        WIDE_TOL,
    );
}

#[test]
fn running_sums_and_unshifted_updates_fail_on_large_offsets() {
    // The reasons for the method. For 1e8 + N(0, 1), e^2 ~ 1e16 carries no digit of a unit
    // variance: measured, the running-sum std is off by 17 times itself in the worst window,
    // ours by 7.3e-16. A Welford update on the raw samples rounds its mean to the spacing of
    // doubles near 1e8, 1.5e-8: measured 5.8e-8.
    let series = normal_series(5, 10_000, 1e8, 1.0);
    let reference = direct(&series, 50);
    let naive = max_rel_std_error(&naive_std(&series, 50), &reference);
    assert!(naive > 1e-3, "running sums: relative error {naive:e}");
    let unshifted = max_rel_std_error(&unshifted_welford_std(&series, 50), &reference);
    assert!(unshifted > 1e-9, "unshifted: relative error {unshifted:e}");
    let ours = errors(&sliding_window(&series, 50).unwrap(), &reference);
    assert!(ours.std <= WIDE_TOL, "sliding window: {ours:?}");
}

#[test]
fn random_lengths_and_windows_match_direct() {
    // 3000 series of 2 to 399 samples on offsets up to 1e6, every window length from 2 to the
    // series length. Pointwise std errors depend on near-coincident samples (measured up to
    // 1e-10), so only the local error (measured 2.9e-15) and bias and RMSE (8.7e-16) are
    // asserted.
    for seed in 0..3000 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = rng.random_range(2..400);
        let window = rng.random_range(2..=n);
        let offset = rng.random_range(-1e6..1e6);
        let series = normal_series(seed, n, offset, 1.0);
        let e = errors(
            &sliding_window(&series, window).unwrap(),
            &direct(&series, window),
        );
        assert!(
            e.bias_rmse <= 1e-14 && e.local_var <= LOCAL_VAR_TOL,
            "seed {seed}, N = {n}, W = {window}: {e:?}"
        );
    }
}

#[test]
fn constant_stretch_after_noise_has_zero_std() {
    // An update that empties a window of its spread would leave a rounding residue of about
    // 1e-8 times the old std (measured 5e-9 with W = 3 before constant windows were detected).
    // Against the direct computation, measured maxima over the four windows: bias and RMSE
    // 1.4e-15, std 2.7e-13 (W = 2, where the noise ends).
    let mut series = normal_series(7, 100, 0.0, 1.0);
    series.extend(std::iter::repeat_n(0.25, 200));
    for window in [2, 3, 10, 50] {
        let s = sliding_window(&series, window).unwrap();
        assert!(s.std[100..].iter().all(|&v| v == 0.0), "W = {window}");
        assert!(s.bias[100..].iter().all(|&v| v == 0.25), "W = {window}");
        assert_matches_direct(&series, window, WIDE_TOL, 3e-12);
    }
}

#[test]
fn rmse_per_state_hand_case() {
    let errors = [
        Vector2::new(1.0, -2.0),
        Vector2::new(-1.0, 0.0),
        Vector2::new(1.0, 2.0),
        Vector2::new(-1.0, 4.0),
    ];
    // Component 0: all squares 1. Component 1: (4 + 0 + 4 + 16) / 4 = 6.
    let r = rmse_per_state(&errors).unwrap();
    assert_eq!(r[0], 1.0);
    assert!((r[1] - 6.0f64.sqrt()).abs() <= 1e-15);
    // The per-component RMSE is `rmse` of the component's series.
    let component: Vec<f64> = errors.iter().map(|e| e[1]).collect();
    assert_eq!(r[1], rmse(&component).unwrap());
}

#[test]
fn instantaneous_errors_are_estimate_minus_truth() {
    let est = [Vector2::new(1.0, 5.0), Vector2::new(2.0, 0.5)];
    let truth = [Vector2::new(0.5, 6.0), Vector2::new(2.0, 0.0)];
    let e = instantaneous_errors(&est, &truth).unwrap();
    assert_eq!(e, vec![Vector2::new(0.5, -1.0), Vector2::new(0.0, 0.5)]);
    assert!(instantaneous_errors::<U2>(&[], &[]).unwrap().is_empty());
}

#[test]
fn bad_inputs_are_typed_errors() {
    for window in [0, 1] {
        assert!(matches!(
            sliding_window(&[1.0, 2.0, 3.0], window),
            Err(MetricsError::InvalidParameter { name: "window", .. })
        ));
    }
    assert!(matches!(
        sliding_window(&[1.0, 2.0], 3),
        Err(MetricsError::DimensionMismatch {
            expected: 3,
            found: 2,
            ..
        })
    ));
    for bad in [f64::NAN, f64::INFINITY] {
        assert!(matches!(
            sliding_window(&[1.0, bad, 3.0], 2),
            Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
        ));
    }

    assert!(matches!(rmse(&[]), Err(MetricsError::Empty { .. })));
    assert!(matches!(
        rmse(&[0.0, f64::NAN]),
        Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
    ));

    let v = Vector2::new(1.0, 2.0);
    assert!(matches!(
        instantaneous_errors(&[v, v], &[v]),
        Err(MetricsError::DimensionMismatch {
            expected: 2,
            found: 1,
            ..
        })
    ));
    assert!(matches!(
        instantaneous_errors(&[v], &[Vector2::new(f64::NAN, 0.0)]),
        Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
    ));
    let (d2, d3) = (DVector::from_element(2, 1.0), DVector::from_element(3, 1.0));
    assert!(matches!(
        instantaneous_errors(&[d2.clone(), d2.clone()], &[d2.clone(), d3.clone()]),
        Err(MetricsError::DimensionMismatch {
            expected: 2,
            found: 3,
            ..
        })
    ));

    assert!(matches!(
        rmse_per_state::<U2>(&[]),
        Err(MetricsError::Empty { .. })
    ));
    assert!(matches!(
        rmse_per_state(&[d2, d3]),
        Err(MetricsError::DimensionMismatch {
            expected: 2,
            found: 3,
            ..
        })
    ));
    assert!(matches!(
        rmse_per_state(&[Vector2::new(0.0, f64::INFINITY)]),
        Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
    ));
}

/// A finite series of 2 to 300 samples: an offset and a spread each over many orders of
/// magnitude, so the identity is exercised where cancellation would hurt.
fn series_strategy() -> impl Strategy<Value = Vec<f64>> {
    (
        -1e8f64..1e8,
        -6i32..6,
        prop::collection::vec(-1.0f64..1.0, 2..=300),
    )
        .prop_map(|(offset, exp, unit)| {
            let spread = 10f64.powi(exp);
            unit.iter().map(|u| offset + spread * u).collect()
        })
}

proptest! {
    /// `RMSE^2 = bias^2 + (W-1)/W std^2` in every window, the std equals a two-pass sample
    /// std computed independently, and `RMSE >= |bias|`.
    #[test]
    fn rmse_splits_into_bias_and_spread(
        (series, window) in series_strategy()
            .prop_flat_map(|s| { let n = s.len(); (Just(s), 2..=n) }),
    ) {
        let s = sliding_window(&series, window).unwrap();
        prop_assert_eq!(s.len(), series.len() - window + 1);
        let w = window as f64;
        // Two-pass sample variance of each window on differences from its first sample, which
        // are exact (Sterbenz) when the samples share an offset, so no cancellation enters.
        let direct: Vec<f64> = series
            .windows(window)
            .map(|win| {
                let d: Vec<f64> = win.iter().map(|x| x - win[0]).collect();
                let mean = d.iter().sum::<f64>() / w;
                d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (w - 1.0)
            })
            .collect();
        for i in 0..s.len() {
            let (r, b, sd) = (s.rmse[i], s.bias[i], s.std[i]);
            let split = b * b + (w - 1.0) / w * sd * sd;
            prop_assert!((r * r - split).abs() <= 1e-10 * r * r + 1e-300, "window {}", i);
            // The documented accuracy is relative to the largest variance among the window and
            // the W before it (window.rs, numerical choices); allow 1e-12 of it.
            let scale = direct[i.saturating_sub(window)..=i].iter().fold(0.0f64, |m, &v| m.max(v));
            prop_assert!(
                (sd * sd - direct[i]).abs() <= 1e-12 * scale + 1e-300,
                "window {}: std^2 {} against a direct {}", i, sd * sd, direct[i]
            );
            // sqrt(fl(b^2 + x)) >= |b| for x >= 0: rounding is monotone and sqrt(fl(b^2))
            // is |b| in binary floating point (barring underflow, which these values avoid).
            prop_assert!(r >= b.abs(), "window {}: rmse {} < |bias| {}", i, r, b.abs());
        }
    }
}

/// A window of -1e308 and f64::MAX has a sample standard deviation of about 2e308, beyond
/// f64's range: an error naming the window, not `Ok(inf)` (found by the adversarial suite in
/// CI, tests/adversarial.rs `metrics_series`). Its bias is finite and a window of 1e308 and
/// f64::MAX, whose std is finite, is computed.
#[test]
fn a_window_whose_spread_exceeds_f64_is_an_error_not_infinity() {
    use kalibra_metrics::{MetricsError, sliding_window};
    match sliding_window(&[-1e308, f64::MAX], 2) {
        Err(MetricsError::NonFiniteSample { what, index: 0 }) => {
            assert!(what.contains("std"), "{what}")
        }
        other => panic!("{other:?}"),
    }
    let s = sliding_window(&[1e308, f64::MAX, 1.5e308], 2).unwrap();
    assert!(
        s.std
            .iter()
            .chain(&s.rmse)
            .chain(&s.bias)
            .all(|v| v.is_finite())
    );
}
