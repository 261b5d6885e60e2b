//! Batch means and the three stationarity tests: hand-worked cases, reference values from
//! scipy / statsmodels, typed errors, the rejection rate under the null, and the comparison
//! with statrs' own t-test and two-sample Kolmogorov-Smirnov test (kept out of use for the
//! reasons in `kalibra_metrics::hypothesis`).
//!
//! Reference values were computed once with Python (numpy 2.4.6, scipy 1.17.1, statsmodels
//! 0.15.0) on exactly the literal arrays below (generated with
//! `numpy.random.default_rng(20230404)` and rounded to 4 or 3 decimals); each test names the
//! function and arguments it was checked against.

use approx::assert_relative_eq;
use kalibra_metrics::hypothesis::{
    KS_EXACT_MAX_CELLS, TestResult, batch_means, ks_asymptotic_p, ks_two_sample,
    ks_two_sample_exact_p, paired_t_test, runs_test,
};
use kalibra_metrics::{BatchMeans, MetricsError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use statrs::stats_tests::ks_test::{KSTestError, KSTwoSampleAlternativeMethod, ks_twosample};
use statrs::stats_tests::ttest_onesample::ttest_onesample;
use statrs::stats_tests::{Alternative, NaNPolicy};

// ---------------------------------------------------------------------------------------------
// Batch means
// ---------------------------------------------------------------------------------------------

#[test]
fn batch_means_small_case_by_hand() {
    let series: Vec<f64> = (0..10).map(f64::from).collect();
    // Burn-in drops 0; batches [1, 2, 3], [4, 5, 6], [7, 8, 9].
    assert_eq!(batch_means(&series, 3, 1).unwrap(), vec![2.0, 5.0, 8.0]);
    // One more sample forms a partial batch [10], which is dropped.
    let series: Vec<f64> = (0..11).map(f64::from).collect();
    assert_eq!(batch_means(&series, 3, 1).unwrap(), vec![2.0, 5.0, 8.0]);
    // No burn-in, batch of one: the series itself.
    assert_eq!(batch_means(&series, 1, 0).unwrap(), series);
    // Exactly one full batch after the burn-in.
    assert_eq!(batch_means(&series, 5, 6).unwrap(), vec![8.0]);
}

#[test]
fn batch_means_of_a_long_series_after_a_burn_in() {
    // 1e5 steps, burn-in 1e4, batch 250 (the layout of Spall and Wei's Table 1):
    // 90_000 / 250 = 360 batch means.
    let series: Vec<f64> = (0..100_000).map(|k| f64::from(k % 7)).collect();
    let means = batch_means(&series, 250, 10_000).unwrap();
    assert_eq!(means.len(), 360);
    // 250 = 35 * 7 + 5, so batches do not all see the same residues: check the first by hand.
    let first: f64 = (10_000..10_250).map(|k| f64::from(k % 7)).sum::<f64>() / 250.0;
    assert_relative_eq!(means[0], first, max_relative = 1e-15);
}

/// The definition on ordinary data: each batch's samples summed in order, times `1 / batch`.
fn batch_means_by_definition(series: &[f64], batch: usize, burn_in: usize) -> Vec<f64> {
    series[burn_in..]
        .chunks_exact(batch)
        .map(|c| c.iter().sum::<f64>() * (1.0 / batch as f64))
        .collect()
}

#[test]
fn streamed_batch_means_are_the_definition_to_the_bit() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for (len, batch, burn_in) in [
        (1000, 7, 0),
        (1000, 250, 13),
        (5000, 1, 4999),
        (999, 333, 0),
    ] {
        let series: Vec<f64> = (0..len).map(|_| StandardNormal.sample(&mut rng)).collect();
        let mut streamed = BatchMeans::new(batch, burn_in).unwrap();
        for &x in &series {
            streamed.push(x);
        }
        assert_eq!(streamed.samples(), len);
        let expected = batch_means_by_definition(&series, batch, burn_in);
        let got = streamed.finish().unwrap();
        // To the bit, signs of zero included.
        assert_eq!(
            got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            expected.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(batch_means(&series, batch, burn_in).unwrap(), got);
    }
    // A batch of negative zeros has mean -0.0, as the sum of its samples does.
    let zeros = batch_means(&[-0.0, -0.0, 1.0, 1.0], 2, 0).unwrap();
    assert_eq!(zeros[0].to_bits(), (-0.0f64).to_bits());
}

#[test]
fn an_extreme_batch_is_summed_scaled_and_stays_finite() {
    // 1e307 four times overflows a plain sum; the scaled one gives the mean exactly.
    let series = [1e307, 1e307, 1e307, 1e307, 1.0, 2.0, 3.0, 4.0];
    let means = batch_means(&series, 4, 0).unwrap();
    assert_eq!(means, vec![1e307, 2.5]);
    // Near the bottom of the range: subnormal partial sums would lose digits.
    let tiny = [3e-310, 5e-310, 7e-310];
    let m = batch_means(&tiny, 3, 0).unwrap()[0];
    assert_relative_eq!(m, 5e-310, max_relative = 1e-3);
}

#[test]
fn batch_means_errors() {
    let series = [1.0, 2.0, 3.0, 4.0, 5.0];
    assert!(matches!(
        batch_means(&series, 0, 0),
        Err(MetricsError::InvalidParameter { name: "batch", .. })
    ));
    assert_eq!(
        batch_means(&series, 3, 3),
        Err(MetricsError::TooFewSamples {
            what: "batch_means",
            needed: 6,
            got: 5
        })
    );
    assert!(matches!(
        batch_means(&series, 1, usize::MAX),
        Err(MetricsError::TooFewSamples { .. })
    ));
    assert!(matches!(
        batch_means(&[], 1, 0),
        Err(MetricsError::TooFewSamples { .. })
    ));
    // A NaN in the burn-in still fails: the run that produced the series broke.
    assert_eq!(
        batch_means(&[f64::NAN, 1.0, 2.0], 1, 1),
        Err(MetricsError::NonFiniteSample {
            what: "batch_means",
            index: 0
        })
    );
    assert!(matches!(
        batch_means(&[1.0, f64::INFINITY], 2, 0),
        Err(MetricsError::NonFiniteSample { index: 1, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Runs test
// ---------------------------------------------------------------------------------------------

#[test]
fn runs_test_alternating_by_hand() {
    // Median 0 (mean of -1 and 1); signs + - + - + - + -: n1 = n2 = 4, n = 8, R = 8.
    // mu = 2 * 4 * 4 / 8 + 1 = 5; var = 32 (32 - 8) / (64 * 7) = 768 / 448 = 12 / 7;
    // z = 3 / sqrt(12 / 7) = 2.29128784747792...
    // p = 2 * scipy.stats.norm.sf(2.2912878474779204) = 0.021946771003246834.
    let x = [1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0, -4.0];
    let r = runs_test(&x).unwrap();
    assert_relative_eq!(
        r.statistic,
        3.0 / (12.0_f64 / 7.0).sqrt(),
        max_relative = 1e-14
    );
    assert_relative_eq!(r.p_value, 0.021946771003246834, max_relative = 1e-13);
    // Sorting the same values gives two runs, the other tail: z = (2 - 5) / sqrt(12 / 7).
    let mut sorted = x;
    sorted.sort_by(f64::total_cmp);
    let r = runs_test(&sorted).unwrap();
    assert_relative_eq!(
        r.statistic,
        -3.0 / (12.0_f64 / 7.0).sqrt(),
        max_relative = 1e-14
    );
    assert_relative_eq!(r.p_value, 0.021946771003246834, max_relative = 1e-13);
}

#[test]
fn runs_test_matches_statsmodels() {
    // statsmodels.sandbox.stats.runs.runstest_1samp(RUNS30, cutoff='median', correction=False)
    // = (-1.8580583823930164, 0.06316072400287964); by hand in numpy: median -0.1944,
    // n1 = n2 = 15, R = 11, mu = 16, var = 7.241379310344827. (n is even and no value equals
    // the median, so statsmodels' ">= cutoff" convention and ours coincide here.)
    let r = runs_test(&RUNS30).unwrap();
    assert_relative_eq!(r.statistic, -1.8580583823930164, max_relative = 1e-13);
    assert_relative_eq!(r.p_value, 0.06316072400287964, max_relative = 1e-13);
}

#[test]
fn runs_test_drops_the_median_and_attains_p_one() {
    // Odd n = 31: the median -0.2668 is a sample and is dropped, leaving n1 = n2 = 15 with
    // R = 16 = mu exactly (computed by hand in numpy with scipy.stats.norm.sf), so z = 0 and
    // p = 2 * norm.sf(0) = 1 exactly. This is how paper 004's Table 1 can print a runs-test
    // p-value of 1.00: without continuity correction z = 0 gives p = 1, and for 360 batch
    // means (n1 = n2 = 180, sd of R about 9.47) any other run count gives |z| >= 0.105,
    // p <= 0.92.
    let r = runs_test(&RUNS31).unwrap();
    assert_eq!(
        r,
        TestResult {
            statistic: 0.0,
            p_value: 1.0
        }
    );
    // The same at the paper's size: 180 values above and 180 below the median in
    // 181 runs (= mu = 2 * 180 * 180 / 360 + 1). 89 blocks "+ + - -" give 178 runs; a last
    // block "+ - - +" adds 3 more. Values above are positive, below negative, all distinct,
    // so the median falls between them.
    let values = |signs: &[bool]| -> Vec<f64> {
        (0..360_u32)
            .zip(signs)
            .map(|(k, &above)| {
                if above {
                    1.0 + f64::from(k)
                } else {
                    -1.0 - f64::from(k)
                }
            })
            .collect()
    };
    let mut signs = Vec::with_capacity(360);
    for _ in 0..89 {
        signs.extend([true, true, false, false]);
    }
    signs.extend([true, false, false, true]);
    let r = runs_test(&values(&signs)).unwrap();
    assert_eq!(
        r,
        TestResult {
            statistic: 0.0,
            p_value: 1.0
        }
    );
    // The nearest other run count: the last block "+ - + -" has 4 runs, R = 182, so
    // z = 1 / sqrt(89.749...) = 0.1056 and p = 0.9159, which prints as 0.92, not 1.00.
    signs[358] = true;
    signs[359] = false;
    let r = runs_test(&values(&signs)).unwrap();
    assert!(
        r.statistic > 0.105 && r.statistic < 0.106,
        "z = {}",
        r.statistic
    );
    assert!(r.p_value > 0.915 && r.p_value < 0.916, "p = {}", r.p_value);
}

#[test]
fn runs_test_errors() {
    assert!(matches!(
        runs_test(&[1.0, 2.0, 3.0]),
        Err(MetricsError::TooFewSamples {
            needed: 4,
            got: 3,
            ..
        })
    ));
    assert!(matches!(
        runs_test(&[1.0, 2.0, f64::NAN, 3.0]),
        Err(MetricsError::NonFiniteSample { index: 2, .. })
    ));
    // All equal: everything sits on the median.
    assert!(matches!(
        runs_test(&[1.0; 6]),
        Err(MetricsError::Degenerate { .. })
    ));
    // Median 1: one sample above, none below.
    assert!(matches!(
        runs_test(&[1.0, 1.0, 1.0, 2.0]),
        Err(MetricsError::Degenerate { .. })
    ));
    // Median 2: one sample above, one below, Var[R] = 0.
    assert!(matches!(
        runs_test(&[1.0, 2.0, 2.0, 3.0]),
        Err(MetricsError::Degenerate { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Paired t-test
// ---------------------------------------------------------------------------------------------

#[test]
fn paired_t_test_by_hand() {
    // d = [1, 2, 0, 3, 3], mean 1.8; squared deviations 0.64 + 0.04 + 3.24 + 1.44 + 1.44 = 6.8,
    // var = 6.8 / 4 = 1.7, t = 1.8 / sqrt(1.7 / 5) = 1.8 / sqrt(0.34) = 3.0869745325651...,
    // df = 4. scipy.stats.ttest_rel([5, 7, 6, 9, 8], [4, 5, 6, 6, 5]) =
    // (3.0869745325651587, 0.03668198940044108).
    let r = paired_t_test(&[5.0, 7.0, 6.0, 9.0, 8.0], &[4.0, 5.0, 6.0, 6.0, 5.0]).unwrap();
    assert_relative_eq!(r.statistic, 1.8 / 0.34_f64.sqrt(), max_relative = 1e-14);
    assert_relative_eq!(r.p_value, 0.03668198940044108, max_relative = 1e-13);
    // Swapping the samples flips the sign of t and keeps p.
    let s = paired_t_test(&[4.0, 5.0, 6.0, 6.0, 5.0], &[5.0, 7.0, 6.0, 9.0, 8.0]).unwrap();
    assert_eq!(s.statistic, -r.statistic);
    assert_eq!(s.p_value, r.p_value);
}

#[test]
fn paired_t_test_matches_scipy() {
    // scipy.stats.ttest_rel(TA, TB) = (0.31740965936216836, 0.7536777554835825).
    let r = paired_t_test(&TA, &TB).unwrap();
    assert_relative_eq!(r.statistic, 0.31740965936216836, max_relative = 1e-14);
    assert_relative_eq!(r.p_value, 0.7536777554835825, max_relative = 1e-13);
    // scipy.stats.ttest_rel(TA, TB - 0.6) = (3.1255163479098083, 0.0045969260874180315).
    let shifted: Vec<f64> = TB.iter().map(|v| v - 0.6).collect();
    let r = paired_t_test(&TA, &shifted).unwrap();
    assert_relative_eq!(r.statistic, 3.1255163479098083, max_relative = 1e-14);
    assert_relative_eq!(r.p_value, 0.0045969260874180315, max_relative = 1e-13);
}

#[test]
fn paired_t_test_errors() {
    assert_eq!(
        paired_t_test(&[1.0, 2.0], &[1.0]),
        Err(MetricsError::DimensionMismatch {
            what: "paired_t_test: second sample length",
            expected: 2,
            found: 1
        })
    );
    assert!(matches!(
        paired_t_test(&[1.0], &[2.0]),
        Err(MetricsError::TooFewSamples {
            needed: 2,
            got: 1,
            ..
        })
    ));
    assert!(matches!(
        paired_t_test(&[1.0, 2.0], &[1.0, f64::NAN]),
        Err(MetricsError::NonFiniteSample { index: 1, .. })
    ));
    // Constant difference (here 0.1, not exactly representable): zero variance, not a huge t.
    let a = [0.3, 1.3, 2.3, 5.3];
    let b: Vec<f64> = a.iter().map(|v| v - 0.1).collect();
    let constant = a.iter().zip(&b).all(|(x, y)| x - y == a[0] - b[0]);
    if constant {
        assert!(matches!(
            paired_t_test(&a, &b),
            Err(MetricsError::Degenerate { .. })
        ));
    }
    assert!(matches!(
        paired_t_test(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]),
        Err(MetricsError::Degenerate { .. })
    ));
    // Finite inputs whose difference overflows.
    assert!(matches!(
        paired_t_test(&[f64::MAX, 0.0], &[-f64::MAX, 1.0]),
        Err(MetricsError::NonFiniteSample { index: 0, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Kolmogorov-Smirnov
// ---------------------------------------------------------------------------------------------

#[test]
fn ks_statistic_by_hand() {
    // a = [1, 2, 3], b = [2.5, 4, 5, 6]: after 3 the ECDFs are 1 and 1/4, D = 3/4
    // (scipy.stats.ks_2samp gives 0.75 and, method='exact', p = 0.22857142857142862 = 8/35).
    let r = ks_two_sample(&[3.0, 1.0, 2.0], &[6.0, 2.5, 5.0, 4.0]).unwrap();
    assert_eq!(r.statistic, 0.75);
    assert_relative_eq!(r.p_value, 8.0 / 35.0, max_relative = 1e-14);
    // Ties between samples: a = [1, 2, 2, 3], b = [2, 2, 4]. Stepping over both 2s together:
    // at 1: 1/4 - 0; at 2: 3/4 - 2/3; at 3: 1 - 2/3 = 1/3; at 4: 0. D = 1/3
    // (scipy.stats.ks_2samp: 0.3333333333333333). Advancing through a's 2s before b's would
    // wrongly see 3/4 - 0.
    let r = ks_two_sample(&[1.0, 2.0, 2.0, 3.0], &[2.0, 2.0, 4.0]).unwrap();
    assert_relative_eq!(r.statistic, 1.0 / 3.0, max_relative = 1e-15);
    // Identical samples: D = 0, p = 1.
    let r = ks_two_sample(&[1.0, 2.0], &[2.0, 1.0]).unwrap();
    assert_eq!(
        r,
        TestResult {
            statistic: 0.0,
            p_value: 1.0
        }
    );
    // Disjoint samples of 3: D = 1, and only the 2 of the C(6, 3) = 20 interleavings aaabbb
    // and bbbaaa reach it: p = 0.1.
    let r = ks_two_sample(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]).unwrap();
    assert_eq!(r.statistic, 1.0);
    assert_relative_eq!(r.p_value, 0.1, max_relative = 1e-14);
}

#[test]
fn ks_exact_p_enumerated_by_hand() {
    // n = m = 3, C(6, 3) = 20 paths. D >= 1/3 always. |i - j| <= 1 throughout iff each pair of
    // steps is ab or ba: 2^3 = 8 paths, so P(D >= 2/3) = 12/20. P(D >= 1) = 2/20.
    assert_eq!(ks_two_sample_exact_p(3, 3, 1.0 / 3.0).unwrap(), 1.0);
    assert_relative_eq!(
        ks_two_sample_exact_p(3, 3, 2.0 / 3.0).unwrap(),
        0.6,
        max_relative = 1e-14
    );
    assert_relative_eq!(
        ks_two_sample_exact_p(3, 3, 1.0).unwrap(),
        0.1,
        max_relative = 1e-14
    );
    // n = m = 4, C(8, 4) = 70 paths. P(D >= 2/4) = (70 - 2^4) / 70 = 54/70. Reaching
    // |i - j| = 3: by reflection C(8, 1) = 8 paths touch i - j = 3, 8 touch j - i = 3, none
    // both, so P(D >= 3/4) = 16/70. P(D >= 1) = 2/70. The same values from
    // scipy.stats.ks_2samp(method='exact') (via its _attempt_exact_2kssamp(4, 4, 4, d)):
    // 0.7714285714285716, 0.22857142857142862, 0.028571428571428577.
    assert_eq!(ks_two_sample_exact_p(4, 4, 0.25).unwrap(), 1.0);
    assert_relative_eq!(
        ks_two_sample_exact_p(4, 4, 0.5).unwrap(),
        54.0 / 70.0,
        max_relative = 1e-14
    );
    assert_relative_eq!(
        ks_two_sample_exact_p(4, 4, 0.75).unwrap(),
        16.0 / 70.0,
        max_relative = 1e-14
    );
    assert_relative_eq!(
        ks_two_sample_exact_p(4, 4, 1.0).unwrap(),
        2.0 / 70.0,
        max_relative = 1e-14
    );
    // Between attainable values the next one up counts; edge cases.
    assert_eq!(
        ks_two_sample_exact_p(4, 4, 0.6).unwrap(),
        ks_two_sample_exact_p(4, 4, 0.75).unwrap()
    );
    assert_eq!(ks_two_sample_exact_p(4, 4, 0.0).unwrap(), 1.0);
    assert_eq!(ks_two_sample_exact_p(4, 4, 1.5).unwrap(), 0.0);
    assert!(ks_two_sample_exact_p(0, 4, 0.5).is_err());
    assert!(ks_two_sample_exact_p(4, 4, f64::NAN).is_err());
    // Sizes whose exact computation would run for ages are refused up front.
    assert!(ks_two_sample_exact_p(usize::MAX, usize::MAX, 0.5).is_err());
    assert!(ks_two_sample_exact_p(1 << 20, 1 << 20, 0.5).is_err());
    assert!(ks_asymptotic_p(usize::MAX, usize::MAX, 0.5).unwrap() < 1e-300);
}

#[test]
fn ks_exact_p_matches_scipy_180_180() {
    // scipy.stats.ks_2samp(method='exact') for n = m = 180 (its _compute_prob_outside_square,
    // called through _attempt_exact_2kssamp(180, 180, 180, k / 180, 'two-sided')).
    let reference = [
        (10, 0.9449551717490339),
        (20, 0.21682153886258185),
        (25, 0.06199942287900709),
        (30, 0.013350475155083152),
        (40, 0.0002625386903181573),
        (60, 2.9662673562739295e-09),
    ];
    for (k, p) in reference {
        let d = f64::from(k) / 180.0;
        // scipy forms 1 - P(inside): absolute error ~1e-16, hence the absolute floor.
        let ours = ks_two_sample_exact_p(180, 180, d).unwrap();
        assert!(
            (ours - p).abs() <= 1e-13 * p + 1e-15,
            "k = {k}: {ours} vs scipy {p}"
        );
    }
}

#[test]
fn ks_exact_p_matches_scipy_unequal_sizes() {
    // scipy: _attempt_exact_2kssamp(25, 40, 5, k / 200, 'two-sided') (what
    // ks_2samp(method='exact') calls; lcm(25, 40) = 200).
    let reference = [
        (5, 1.0),
        (10, 0.9999999996090091),
        (20, 0.9928643794878317),
        (37, 0.6005020985992211),
        (60, 0.1013339946846),
    ];
    for (k, p) in reference {
        let ours = ks_two_sample_exact_p(25, 40, f64::from(k) / 200.0).unwrap();
        assert!((ours - p).abs() <= 1e-14, "k = {k}: {ours} vs scipy {p}");
    }
}

#[test]
fn ks_two_sample_matches_scipy_unequal_sizes() {
    // scipy.stats.ks_2samp(KC, KD, method='exact') = (0.185, 0.6005020985992211).
    let r = ks_two_sample(&KC, &KD).unwrap();
    assert_relative_eq!(r.statistic, 0.185, max_relative = 1e-15);
    assert_relative_eq!(r.p_value, 0.6005020985992211, max_relative = 1e-13);
    // scipy.stats.kstwobign.sf(sqrt(25 * 40 / 65) * 0.185) = 0.6682540352618902. (scipy's own
    // ks_2samp(method='asymp') gives 0.6188105811719509: it uses kstwo.sf(D, round(n m /
    // (n + m))), not the Kolmogorov limit.)
    assert_relative_eq!(
        ks_asymptotic_p(25, 40, r.statistic).unwrap(),
        0.6682540352618902,
        max_relative = 1e-14
    );
}

#[test]
fn ks_two_sample_matches_scipy_180_180() {
    // The halves of 360 batch means in paper 004 are 180 and 180. The data are rounded to 3
    // decimals, so there are ties (349 distinct values in 360); scipy computes D the same way.
    // scipy.stats.ks_2samp(F180, G180, method='exact') = (0.1388888888888889 = 25/180,
    // 0.06199942287900709).
    let r = ks_two_sample(&F180, &G180).unwrap();
    assert_relative_eq!(r.statistic, 25.0 / 180.0, max_relative = 1e-15);
    assert_relative_eq!(r.p_value, 0.06199942287900709, max_relative = 1e-13);
    // scipy.stats.kstwobign.sf(sqrt(90) * 25 / 180) = 0.062094058460313316.
    assert_relative_eq!(
        ks_asymptotic_p(180, 180, r.statistic).unwrap(),
        0.062094058460313316,
        max_relative = 1e-14
    );
}

#[test]
fn ks_asymptotic_matches_kstwobign() {
    // scipy.stats.kstwobign.sf(lambda); with n = m = 2, sqrt(n m / (n + m)) = 1, so d = lambda.
    // Covers both series (the theta form below lambda = 1).
    let reference = [
        (0.05, 1.0),
        (0.2, 0.999999999999495),
        (0.5, 0.9639452436648751),
        (0.8, 0.5441424115741981),
        (1.0, 0.26999967167735456),
        (1.073, 0.19978547944612823),
        (1.3581, 0.0499996304316674),
        (2.0, 0.0006709252557796953),
        (3.0, 3.045995948942526e-08),
        (5.0, 3.8574996959278356e-22),
    ];
    for (lambda, p) in reference {
        let ours = ks_asymptotic_p(2, 2, lambda).unwrap();
        assert!(
            (ours - p).abs() <= 1e-14 * p + 1e-16,
            "lambda = {lambda}: {ours} vs scipy {p}"
        );
    }
    assert_eq!(ks_asymptotic_p(2, 2, 0.0).unwrap(), 1.0);
    assert_eq!(ks_asymptotic_p(2, 2, -1.0).unwrap(), 1.0);
    assert!(ks_asymptotic_p(0, 2, 0.5).is_err());
    assert!(ks_asymptotic_p(2, 2, f64::NAN).is_err());
}

#[test]
fn ks_exact_and_asymptotic_agree_roughly_at_180() {
    // At 180 / 180 the Kolmogorov limit is within 1.5e-3 of the exact p-value over the whole
    // range of D, and within 1e-4 of it near the 0.05 level (D = 25/180: 0.06200 exact,
    // 0.06209 limit, as scipy's ks_2samp(method='exact') and kstwobign.sf also give).
    for k in 1..=60 {
        let d = f64::from(k) / 180.0;
        let exact = ks_two_sample_exact_p(180, 180, d).unwrap();
        let limit = ks_asymptotic_p(180, 180, d).unwrap();
        assert!((exact - limit).abs() < 2e-3, "k = {k}: {exact} vs {limit}");
    }
    let d = 25.0 / 180.0;
    assert!(
        (ks_two_sample_exact_p(180, 180, d).unwrap() - ks_asymptotic_p(180, 180, d).unwrap()).abs()
            < 2e-4
    );
}

#[test]
fn ks_two_sample_switches_to_asymptotic_for_large_samples() {
    // 4000 * 3000 = 1.2e7 > KS_EXACT_MAX_CELLS. Deterministic low-discrepancy samples, the
    // second slightly skewed so D is moderate.
    let (n, m) = (4000_usize, 3000_usize);
    assert!(n * m > KS_EXACT_MAX_CELLS);
    let golden = (5.0_f64.sqrt() - 1.0) / 2.0;
    let a: Vec<f64> = (0..n).map(|k| (k as f64 * golden).fract()).collect();
    let b: Vec<f64> = (0..m)
        .map(|k| (k as f64 * 2.0_f64.sqrt()).fract().powf(1.05))
        .collect();
    let r = ks_two_sample(&a, &b).unwrap();
    assert_eq!(r.p_value, ks_asymptotic_p(n, m, r.statistic).unwrap());
    // D by brute force: the gap of the ECDFs just after each sample value.
    let ecdf = |s: &[f64], x: f64| s.iter().filter(|&&v| v <= x).count() as f64 / s.len() as f64;
    let brute = a
        .iter()
        .chain(&b)
        .map(|&x| (ecdf(&a, x) - ecdf(&b, x)).abs())
        .fold(0.0, f64::max);
    assert_relative_eq!(r.statistic, brute, max_relative = 1e-12);
}

#[test]
fn ks_errors() {
    assert!(matches!(
        ks_two_sample(&[], &[1.0]),
        Err(MetricsError::TooFewSamples {
            needed: 1,
            got: 0,
            ..
        })
    ));
    assert!(matches!(
        ks_two_sample(&[1.0], &[]),
        Err(MetricsError::TooFewSamples { .. })
    ));
    assert!(matches!(
        ks_two_sample(&[1.0], &[2.0, f64::NEG_INFINITY]),
        Err(MetricsError::NonFiniteSample { index: 1, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Against statrs 0.19
// ---------------------------------------------------------------------------------------------

/// statrs' one-sample t-test of the differences `a - b` against 0: the paired test.
fn statrs_paired_t(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    ttest_onesample(d, 0.0, Alternative::TwoSided, NaNPolicy::Error).unwrap()
}

/// Pairs of samples both t-tests accept: the fixtures above and seeded normal samples of
/// several sizes, with mean differences from none to large.
fn t_test_inputs() -> Vec<(Vec<f64>, Vec<f64>)> {
    let mut inputs = vec![
        (vec![5.0, 7.0, 6.0, 9.0, 8.0], vec![4.0, 5.0, 6.0, 6.0, 5.0]),
        (TA.to_vec(), TB.to_vec()),
        (TA.to_vec(), TB.iter().map(|v| v - 0.6).collect()),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(0x57A7_0019);
    for n in [2_usize, 3, 5, 10, 30, 180, 1000] {
        for shift in [0.0, 0.3, 1.0] {
            let a: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
            let b: Vec<f64> = (0..n)
                .map(|_| StandardNormal.sample(&mut rng))
                .map(|v: f64| v - shift)
                .collect();
            inputs.push((a, b));
        }
    }
    inputs
}

#[test]
fn paired_t_test_agrees_with_statrs_ttest_onesample() {
    // The same t by the same formula (today equal bit for bit; the tolerance leaves room for a
    // reordering). statrs' p-value is 2 (1 - cdf(|t|)), a multiple of 2^-52 (as 2 times a
    // multiple of 2^-53), so it can only agree to that absolute accuracy: the largest
    // difference over these inputs is 1.1e-16.
    for (a, b) in t_test_inputs() {
        let ours = paired_t_test(&a, &b).unwrap();
        let (t, p) = statrs_paired_t(&a, &b);
        assert_relative_eq!(ours.statistic, t, max_relative = 1e-15);
        assert!(
            (ours.p_value - p).abs() <= 5e-16,
            "n = {}: ours {} vs statrs {p}",
            a.len(),
            ours.p_value
        );
    }
}

#[test]
fn paired_t_test_keeps_the_tail_statrs_rounds_away() {
    // The documented difference. With two pairs there is one degree of freedom, Student's t is
    // the Cauchy distribution and the two-sided p-value is 2 atan(1 / |t|) / pi in closed form.
    // At t ~ 2e7 (p ~ 3.2e-8) ours matches it to rounding; statrs' 1 - cdf is good only to
    // ~1e-16 absolute, which here is a relative error of about 3e-9.
    for a in [[1.0, 1.001], [1.0, 1.000_000_1]] {
        let b = [0.0, 0.0];
        let ours = paired_t_test(&a, &b).unwrap();
        let exact = 2.0 * (1.0 / ours.statistic).atan() / std::f64::consts::PI;
        assert_relative_eq!(ours.p_value, exact, max_relative = 1e-13);
        let (_, p) = statrs_paired_t(&a, &b);
        assert!((p - exact).abs() <= 1e-15, "statrs {p} vs {exact}");
    }
    // A drift of about 14 standard errors over 180 pairs: p below 1e-20 is still a number
    // here; statrs' 1 - cdf cannot represent it (it gives 0 or a multiple of 2^-52).
    let mut rng = ChaCha8Rng::seed_from_u64(0x57A7_0020);
    let a: Vec<f64> = (0..180).map(|_| StandardNormal.sample(&mut rng)).collect();
    let b: Vec<f64> = (0..180)
        .map(|_| StandardNormal.sample(&mut rng))
        .map(|v: f64| v - 1.5)
        .collect();
    let ours = paired_t_test(&a, &b).unwrap();
    assert!(
        ours.p_value > 0.0 && ours.p_value < 1e-20,
        "p = {}",
        ours.p_value
    );
    let (_, p) = statrs_paired_t(&a, &b);
    assert!((p - ours.p_value).abs() <= 5e-16, "statrs {p}");
}

/// Pairs of samples statrs' exact two-sample test accepts (`n m <= 10_000`).
fn ks_inputs() -> Vec<(Vec<f64>, Vec<f64>)> {
    let mut inputs = vec![
        (vec![3.0, 1.0, 2.0], vec![6.0, 2.5, 5.0, 4.0]),
        (vec![1.0, 2.0, 2.0, 3.0], vec![2.0, 2.0, 4.0]),
        (KC.to_vec(), KD.to_vec()),
        // 100 x 100 = 10_000 cells, statrs' largest.
        (F180[..100].to_vec(), G180[..100].to_vec()),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(0x57A7_0021);
    for (n, m) in [
        (10_usize, 10_usize),
        (25, 40),
        (50, 50),
        (60, 150),
        (7, 1000),
    ] {
        for shift in [0.0, 0.5, 1.0] {
            let a: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
            let b: Vec<f64> = (0..m)
                .map(|_| StandardNormal.sample(&mut rng))
                .map(|v: f64| v + shift)
                .collect();
            inputs.push((a, b));
        }
    }
    inputs
}

#[test]
fn ks_two_sample_agrees_with_statrs_ks_twosample() {
    // D: statrs sums 1/n steps, so it is off by a few ulps (up to 1.3e-15 relative here).
    // Exact p: statrs returns 1 - inside / total, good to ~1e-13 absolute (the largest
    // difference over these inputs is 8e-14, at 7 x 1000). Asymptotic p: the same Kolmogorov
    // series at the same lambda, summed to a different stopping rule (within 1e-13 relative).
    for (a, b) in ks_inputs() {
        let (n, m) = (a.len(), b.len());
        let ours = ks_two_sample(&a, &b).unwrap();
        let (d, p) = ks_twosample(
            a.clone(),
            b.clone(),
            KSTwoSampleAlternativeMethod::TwoSidedExact,
            NaNPolicy::Error,
        )
        .unwrap();
        assert_relative_eq!(ours.statistic, d, max_relative = 1e-14);
        assert!(
            (ours.p_value - p).abs() <= 2e-13,
            "{n} x {m}: ours {} vs statrs {p}",
            ours.p_value
        );
        let (_, p) = ks_twosample(
            a,
            b,
            KSTwoSampleAlternativeMethod::TwoSidedAsymptotic,
            NaNPolicy::Error,
        )
        .unwrap();
        let limit = ks_asymptotic_p(n, m, ours.statistic).unwrap();
        assert!(
            (limit - p).abs() <= 1e-13 * limit + 1e-13,
            "{n} x {m}: ours {limit} vs statrs {p}"
        );
    }
}

#[test]
fn ks_two_sample_where_statrs_differs() {
    // The documented differences. 1: paper 004's halves of 180 batch means are beyond statrs'
    // exact limit of 10_000 cells; ours gives scipy's exact value (ks_two_sample_matches_scipy_180_180).
    assert_eq!(
        ks_twosample(
            F180.to_vec(),
            G180.to_vec(),
            KSTwoSampleAlternativeMethod::TwoSidedExact,
            NaNPolicy::Error,
        ),
        Err(KSTestError::ExactAndTooLarge)
    );
    // 2: disjoint samples of 50 and 50. Only the two paths "all a, then all b" and the reverse
    // reach D = 1, so p = 2 / C(100, 50) = 1.98e-29. Ours has it to rounding; statrs'
    // 1 - inside / total only to its ~1e-13 absolute accuracy.
    let a: Vec<f64> = (0..50).map(f64::from).collect();
    let b: Vec<f64> = (100..150).map(f64::from).collect();
    let exact = 2.0 / statrs::function::factorial::binomial(100, 50);
    let ours = ks_two_sample(&a, &b).unwrap();
    assert_eq!(ours.statistic, 1.0);
    assert_relative_eq!(ours.p_value, exact, max_relative = 1e-12);
    let (_, p) = ks_twosample(
        a,
        b,
        KSTwoSampleAlternativeMethod::TwoSidedExact,
        NaNPolicy::Error,
    )
    .unwrap();
    assert!((p - exact).abs() <= 2e-13, "statrs {p}");
}

// ---------------------------------------------------------------------------------------------
// Under the null
// ---------------------------------------------------------------------------------------------

/// Rejections at level 0.05 out of `reps` sets of 360 iid standard normal "batch means", for
/// the three tests as paper 004 applies them (all 360 for the runs test, first 180 against
/// last 180 for the other two).
fn null_rejections(seed: u64, reps: usize) -> [usize; 3] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rejections = [0_usize; 3];
    for _ in 0..reps {
        let x: Vec<f64> = (0..360).map(|_| StandardNormal.sample(&mut rng)).collect();
        let (first, last) = x.split_at(180);
        let p = [
            runs_test(&x).unwrap().p_value,
            paired_t_test(first, last).unwrap().p_value,
            ks_two_sample(first, last).unwrap().p_value,
        ];
        for (count, p) in rejections.iter_mut().zip(p) {
            *count += usize::from(p < 0.05);
        }
    }
    rejections
}

#[test]
fn each_test_rejects_about_five_percent_under_the_null() {
    // 1000 repetitions at a true rate of 0.05 give a binomial sd of sqrt(0.05 * 0.95 / 1000)
    // = 0.69 percentage points, so [3%, 7%] is about +-2.9 sd around 5%. The seed is fixed,
    // so the outcome is deterministic (44, 44 and 37 rejections with this seed); the band
    // only guards against a wrong test. (The KS test with its discrete exact distribution is
    // slightly conservative.)
    let rejections = null_rejections(0x5EED_0004, 1000);
    for (name, count) in ["runs", "paired t", "KS"].iter().zip(rejections) {
        assert!(
            (30..=70).contains(&count),
            "{name}: {count} / 1000 rejections"
        );
    }
}

#[test]
fn p_values_are_probabilities() {
    // Cheap sanity over many random inputs of varied sizes, including unequal KS sizes.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for size in [4_usize, 5, 9, 30, 101] {
        for _ in 0..20 {
            let a: Vec<f64> = (0..size).map(|_| StandardNormal.sample(&mut rng)).collect();
            let b: Vec<f64> = (0..size + 3)
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let results = [
                runs_test(&a).unwrap(),
                paired_t_test(&a, &b[..size]).unwrap(),
                ks_two_sample(&a, &b).unwrap(),
                ks_two_sample(&b, &a).unwrap(),
            ];
            for r in results {
                assert!((0.0..=1.0).contains(&r.p_value), "{r:?}");
            }
            // KS is symmetric in its samples (the exact p-value to rounding: the lattice is
            // walked in the transposed order).
            assert_eq!(results[2].statistic, results[3].statistic);
            assert_relative_eq!(results[2].p_value, results[3].p_value, max_relative = 1e-13);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Reference data (numpy.random.default_rng(20230404), see the module docs)
// ---------------------------------------------------------------------------------------------

/// 30 values of an AR(1) with coefficient 0.5 (positively correlated: too few runs).
const RUNS30: [f64; 30] = [
    0.3152, -0.3175, 0.0135, 0.3241, 0.2202, 0.5374, 0.5271, -0.6206, -0.6435, 0.9732, 1.1357,
    -0.6516, -0.0481, 0.3337, -0.7023, -2.1853, -3.0735, -1.0200, -0.5716, 1.1303, 0.0365, -0.1238,
    0.4894, -0.3544, -1.4787, -1.0754, -0.4447, -0.2650, -1.0389, 0.5682,
];

/// 31 iid standard normal values (odd n: the median is a sample).
const RUNS31: [f64; 31] = [
    1.3823, 1.2171, 1.8237, 0.0049, -1.0678, 1.0159, -0.8295, -0.3014, -1.4713, 1.0736, 0.0228,
    -0.2853, -0.4819, 1.8998, -0.2668, 0.6886, -1.1459, -2.4799, -0.3651, 1.9283, -0.3872, 2.5175,
    0.4041, -0.4818, -1.3148, -0.2984, 0.0141, 0.5034, -1.6319, 0.9024, -1.4611,
];

/// 25 iid standard normal values, the first of the paired samples.
const TA: [f64; 25] = [
    -1.3497, -0.0829, -0.3317, 0.2205, 0.2820, -1.9614, -0.2778, 0.8700, 0.3978, 0.3723, 0.7895,
    -0.0158, -0.2493, 0.0599, -0.9639, 0.4804, -0.6114, -2.3294, -0.0568, 0.3533, 0.4001, -0.8062,
    0.7447, -0.3375, -0.5809,
];

/// `0.6 TA + 0.8 N(0, 1) - 0.3`, rounded: the second of the paired samples.
const TB: [f64; 25] = [
    -2.1136, 0.0757, -2.0743, 0.1869, -1.1145, -0.3129, -0.4336, 0.3317, -1.3942, 0.5694, 1.3557,
    -0.1505, -1.2247, 1.3161, -2.2755, -0.4324, -1.3824, -0.1846, 0.3143, 1.8348, -0.0957, 0.4869,
    0.1910, 0.3303, -0.4836,
];

/// 25 iid standard normal values.
const KC: [f64; 25] = [
    0.0116, 0.6121, -1.6893, -1.3679, 0.0332, 1.1397, -1.1860, -0.8798, 1.8166, -0.6571, 1.2454,
    -0.0660, 0.6867, -1.3417, 1.3066, 1.5779, -1.2872, 0.6393, 1.3821, 0.2203, 0.8115, -0.1740,
    0.6112, -0.3208, 1.6299,
];

/// 40 values from N(0.4, 1.3^2).
const KD: [f64; 40] = [
    1.5152, 0.5536, 3.4690, 2.5567, 2.3830, -1.6502, -0.0674, 0.6179, 0.8878, -0.4851, -1.8469,
    -0.8175, 3.4613, 0.1646, -0.2356, -1.0589, 0.7344, -0.9044, -0.6210, 0.5401, 1.8071, -0.8579,
    -1.7996, 2.6590, -0.6195, 1.0632, -1.4911, -0.0847, 2.0122, 1.4904, 0.3494, 0.8933, -0.5421,
    1.6991, -0.1082, 1.3839, 0.5765, -0.0020, 1.6478, 1.0290,
];

/// 180 iid standard normal values, rounded to 3 decimals.
const F180: [f64; 180] = [
    -0.762, 0.315, 0.282, -1.371, 2.179, 2.332, 1.395, 0.315, 0.384, -0.257, -1.235, -0.210, 0.346,
    0.503, -0.366, -1.305, -1.566, 0.480, 1.952, -0.650, 1.914, 0.414, 0.114, -0.371, 1.077, 0.409,
    1.038, 0.280, 2.068, 0.512, 0.795, 0.478, 1.289, 0.144, -0.880, 1.578, 1.197, 0.612, 0.126,
    -0.879, 0.763, -1.001, -0.333, -0.964, -0.104, -0.366, -0.251, 1.666, -0.010, -1.637, 0.933,
    -0.715, 0.453, 0.809, 0.866, 0.354, 0.281, 0.146, -0.851, 1.328, -0.106, 0.549, 1.018, 0.007,
    0.520, -1.375, 0.250, -0.654, -0.989, -0.750, 0.524, -0.402, 0.307, -1.646, -1.289, 2.151,
    -0.708, -0.669, 3.133, -0.278, -0.376, -0.205, -0.207, -2.753, -0.370, -1.499, 0.583, 1.660,
    1.879, 1.132, -1.589, 0.943, 2.214, -0.271, 1.774, 0.308, 0.264, 1.400, 1.181, 0.108, 0.342,
    -0.940, 0.338, 0.558, 0.014, -1.148, 1.174, 0.028, -0.926, 1.121, 1.793, 0.422, 0.398, 0.786,
    0.880, -0.114, -0.883, -0.474, -0.354, -1.208, 1.971, -1.227, 0.893, -0.516, -0.167, 0.019,
    0.760, 1.754, -0.721, -0.420, 1.310, -0.467, 1.530, -0.691, 1.559, -1.480, 0.778, -1.210,
    -1.379, -0.628, 2.179, -0.849, -0.274, -0.001, -0.919, -0.024, 2.328, -0.053, 0.484, 0.028,
    -0.674, -0.740, -0.047, 1.267, 1.534, 0.570, 0.497, 1.877, 0.285, -1.554, 0.448, 0.246, 0.344,
    -2.369, 1.684, -0.603, 0.532, -1.219, -0.346, -1.154, -0.180, 0.889, 0.240, 0.879, 0.045,
    -0.328, -1.434, -1.299, -0.548, -0.710,
];

/// 180 values from N(0.25, 1), rounded to 3 decimals.
// 0.318 is a data value that happens to be close to 1/pi.
#[allow(clippy::approx_constant)]
const G180: [f64; 180] = [
    0.400, -0.605, 0.924, 0.704, 1.476, 0.565, 0.215, 0.805, 1.099, -0.368, 1.211, 0.651, -0.526,
    0.178, 1.606, -0.220, 0.462, -1.211, 0.623, 1.292, 0.356, -0.316, -0.172, -0.499, -0.184,
    -0.693, 0.035, -0.228, -0.801, 2.203, 1.213, 0.318, 0.891, 0.762, 0.571, 0.574, -0.021, 1.788,
    1.798, -0.206, 0.061, 1.355, -1.283, -1.033, 1.158, 0.491, -0.938, 1.013, -0.960, -0.678,
    -0.711, -0.595, 0.258, -0.311, -0.682, 0.916, 0.559, -0.829, -0.469, -0.255, 0.034, 0.728,
    0.535, 0.173, 0.131, 1.648, 0.931, 0.761, -0.435, 0.678, -0.668, -0.287, 0.577, -0.619, 1.887,
    -0.261, 1.546, 1.731, -0.179, -0.330, 0.036, 0.204, -2.053, -0.557, -1.843, 1.027, 0.421,
    0.781, 1.103, 0.017, 0.404, 0.692, 0.177, 1.433, -0.269, 1.156, 1.560, 0.107, -0.727, 2.649,
    -0.779, -0.193, -0.001, 1.601, 1.200, 0.781, -1.517, 1.868, -0.776, -0.609, 1.135, 0.529,
    2.433, -0.757, -0.403, -0.515, -0.342, 0.881, 1.364, -0.062, 1.343, 0.598, 1.327, -0.461,
    0.376, 0.583, -0.064, -0.656, 1.010, 2.018, 0.851, 1.323, -0.022, -0.959, -0.524, -1.265,
    -2.909, 1.034, -0.381, -0.085, 1.129, 0.669, 2.028, 0.673, -0.327, 1.516, 0.751, 1.850, -0.326,
    0.359, -0.682, 2.149, 0.435, -1.234, 0.754, 0.009, 0.084, -0.468, 0.497, -2.269, 0.843, 0.691,
    2.194, 0.911, 1.333, 0.740, -0.433, 1.032, -0.326, -1.372, 1.256, 0.491, -0.900, 2.189, -0.806,
    -0.542, 1.641, 1.625, -1.818, 0.476,
];
