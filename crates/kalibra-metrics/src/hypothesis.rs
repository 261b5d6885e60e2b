//! Hypothesis tests on a series: batch means and three classical tests of a stationary
//! distribution along one long trajectory.
//!
//! Successive filter errors along one trajectory are strongly correlated, so no textbook test
//! applies to them directly. Batch means (averages over long non-overlapping windows) are
//! nearly independent and nearly normal when the error is stationary with short memory; the
//! tests then ask whether the batch means look like one random sample: the runs test about the
//! median (randomness of the order), the matched-pair t-test of the first half against the
//! second (a drift of the mean), and the two-sample Kolmogorov-Smirnov test of the two halves
//! (any change of the distribution).
//!
//! The p-value conventions follow what reproduces published tables: the runs test uses the
//! normal approximation without continuity correction, the Kolmogorov-Smirnov test the exact
//! null distribution (or the plain Kolmogorov limit for large samples).
//!
//! # Against statrs
//! statrs 0.19 has neither batch means nor a runs test. It has a one-sample t-test
//! (`statrs::stats_tests::ttest_onesample`, which on the differences is the paired test) and a
//! two-sample Kolmogorov-Smirnov test (`statrs::stats_tests::ks_test::ks_twosample`); both are
//! kept here rather than called, for the reasons given in [`paired_t_test`] and
//! [`ks_two_sample`]: in short, statrs forms its two-sided p-values as `1 - (something)`, good to
//! about `1e-16` (t) and `1e-13` (KS) absolute but with no relative accuracy below that, and its
//! exact KS p-value refuses more than 10^4 cells, which excludes paper 004's 180 against 180.
//! `tests/hypothesis.rs` compares both with statrs on inputs both accept.

use statrs::distribution::{ContinuousCDF, StudentsT};
use statrs::function::gamma::gamma_ur;

use crate::{MetricsError, median};

/// Largest `n * m` for which [`ks_two_sample`] computes the exact p-value.
///
/// The exact computation walks the `(n + 1) x (m + 1)` lattice once, `O(n m)` time and
/// `O(m)` memory, so 10^7 cells stay cheap. Beyond that the asymptotic Kolmogorov p-value
/// ([`ks_asymptotic_p`]) is used, whose error decays like `1 / sqrt(n m / (n + m))` and is
/// small at such sizes.
pub const KS_EXACT_MAX_CELLS: usize = 10_000_000;

/// A test statistic and its two-sided p-value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TestResult {
    /// The statistic: `z` for the runs test, `t` for the paired t-test, `D` for the
    /// Kolmogorov-Smirnov test.
    pub statistic: f64,
    /// The probability, under the null hypothesis, of a statistic at least as extreme as the
    /// one observed.
    pub p_value: f64,
}

/// Reports the first non-finite sample, if any.
fn check_finite(what: &'static str, x: &[f64]) -> Result<(), MetricsError> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(MetricsError::NonFiniteSample { what, index }),
        None => Ok(()),
    }
}

/// Means of consecutive non-overlapping batches of `batch` samples, after dropping the first
/// `burn_in` samples.
///
/// A trailing partial batch is dropped: its mean would have a different variance from the
/// others and spoil tests that assume identically distributed batch means. The whole series,
/// burn-in included, must be finite: a NaN anywhere means the run itself failed.
///
/// # Errors
/// [`MetricsError::InvalidParameter`] named `"batch"` if `batch` is zero or above
/// [`BATCH_MAX`], [`MetricsError::TooFewSamples`] (`needed = burn_in + batch`) if fewer than `batch` samples
/// remain after the burn-in, [`MetricsError::NonFiniteSample`] for a NaN or
/// infinite sample.
///
/// # Example
/// ```
/// use kalibra_metrics::batch_means;
/// let series: Vec<f64> = (0..10).map(f64::from).collect();
/// // Drop 0; batches [1, 2, 3], [4, 5, 6], [7, 8, 9].
/// assert_eq!(batch_means(&series, 3, 1)?, vec![2.0, 5.0, 8.0]);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
pub fn batch_means(series: &[f64], batch: usize, burn_in: usize) -> Result<Vec<f64>, MetricsError> {
    let mut means = BatchMeans::new(batch, burn_in)?;
    for &x in series {
        means.push(x);
    }
    means.finish()
}

/// The largest batch [`BatchMeans`] and [`batch_means`] accept: the most `f64` samples one
/// vector can hold (`isize::MAX` bytes). A larger batch could never be completed, so it is an
/// [`MetricsError::InvalidParameter`] rather than a reservation that cannot succeed.
pub const BATCH_MAX: usize = isize::MAX as usize / std::mem::size_of::<f64>();

/// [`batch_means`] of a series that arrives one sample at a time: the means of the batches
/// completed so far are kept, the samples are not (a trajectory of 10^5 steps needs a few
/// hundred numbers, not 10^5).
///
/// Each batch's sum is formed in the order of its samples and multiplied by `1 / batch`, so
/// the result is [`batch_means`]'s to the bit (which is this accumulator fed the whole
/// series). A batch whose largest magnitude is extreme (beyond `2^480` or below `2^-480`) is
/// summed scaled by a power of two and scaled back, which is exact wherever the plain sum
/// neither overflows nor underflows and keeps the mean finite and accurate where it would.
///
/// ```
/// use kalibra_metrics::{BatchMeans, batch_means};
/// let series: Vec<f64> = (0..10).map(|i| f64::from(i).sin()).collect();
/// let mut streamed = BatchMeans::new(3, 1)?;
/// for &x in &series {
///     streamed.push(x);
/// }
/// assert_eq!(streamed.finish()?, batch_means(&series, 3, 1)?);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct BatchMeans {
    batch: usize,
    burn_in: usize,
    seen: usize,
    first_non_finite: Option<usize>,
    // The current batch: its running sum (from -0.0, as `Iterator::sum` starts), its largest
    // magnitude, and its samples (kept for the scaled sum of an extreme batch).
    sum: f64,
    largest: f64,
    current: Vec<f64>,
    means: Vec<f64>,
}

impl BatchMeans {
    /// An empty accumulator: batches of `batch` samples after the first `burn_in`.
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] named `"batch"` if `batch` is zero or above
    /// [`BATCH_MAX`] (a batch no vector of samples can hold).
    pub fn new(batch: usize, burn_in: usize) -> Result<Self, MetricsError> {
        if batch == 0 || batch > BATCH_MAX {
            return Err(MetricsError::InvalidParameter {
                name: "batch",
                value: batch as f64,
            });
        }
        Ok(Self {
            batch,
            burn_in,
            seen: 0,
            first_non_finite: None,
            sum: -0.0,
            largest: 0.0,
            // Reserved up to a page of samples: a batch is validated, not trusted, and a
            // batch of 2^40 samples must not reserve 8 TiB before the first sample arrives
            // (`tests/extreme_sizes.rs`); past that the vector grows with the samples.
            current: Vec::with_capacity(batch.min(512)),
            means: Vec::new(),
        })
    }

    /// Adds the next sample of the series.
    #[inline]
    pub fn push(&mut self, x: f64) {
        let index = self.seen;
        self.seen += 1;
        if !x.is_finite() && self.first_non_finite.is_none() {
            self.first_non_finite = Some(index);
        }
        if index < self.burn_in {
            return;
        }
        self.sum += x;
        self.largest = self.largest.max(x.abs());
        self.current.push(x);
        if self.current.len() == self.batch {
            self.close_batch();
        }
    }

    fn close_batch(&mut self) {
        let scale = 1.0 / self.batch as f64;
        let mean = match crate::scale::extreme_exponent_of(self.largest) {
            None => self.sum * scale,
            Some(k) => {
                let sum: f64 = self
                    .current
                    .iter()
                    .map(|&v| crate::scale::ldexp(v, -k))
                    .sum();
                crate::scale::ldexp(sum * scale, k)
            }
        };
        self.means.push(mean);
        self.sum = -0.0;
        self.largest = 0.0;
        self.current.clear();
    }

    /// Samples pushed so far, burn-in included.
    pub fn samples(&self) -> usize {
        self.seen
    }

    /// The means of the completed batches (a trailing partial batch is dropped).
    ///
    /// # Errors
    /// As [`batch_means`]: [`MetricsError::TooFewSamples`] (`needed = burn_in + batch`) if no
    /// batch was completed, [`MetricsError::NonFiniteSample`] with the index of the first NaN
    /// or infinite sample, burn-in included.
    pub fn finish(self) -> Result<Vec<f64>, MetricsError> {
        const WHAT: &str = "batch_means";
        let needed = self.burn_in.saturating_add(self.batch);
        if self.seen < needed {
            return Err(MetricsError::TooFewSamples {
                what: WHAT,
                needed,
                got: self.seen,
            });
        }
        if let Some(index) = self.first_non_finite {
            return Err(MetricsError::NonFiniteSample { what: WHAT, index });
        }
        Ok(self.means)
    }
}

/// Wald-Wolfowitz runs test for randomness about the median, two-sided.
///
/// Samples equal to the median are dropped (they are on neither side); of the rest, `n1` lie
/// above and `n2` below. With `n = n1 + n2` and `R` the number of runs (maximal blocks of
/// consecutive samples on the same side), under randomness
/// `E[R] = 2 n1 n2 / n + 1` and `Var[R] = 2 n1 n2 (2 n1 n2 - n) / (n^2 (n - 1))`.
/// The statistic is `z = (R - E[R]) / sqrt(Var[R])` with **no continuity correction**, and
/// `p = 2 (1 - Phi(|z|))`. Both choices are deliberate: they are what reproduces published
/// p-values (a printed p-value of 1.00 needs `z` within 0.006 of zero, which for a few hundred
/// samples only `R = E[R]` exactly gives, and then `p = 1` exactly).
/// Too few runs indicate positive correlation or a trend, too many an oscillation.
///
/// # Errors
/// [`MetricsError::TooFewSamples`] for fewer than 4 samples (with 3 or fewer the run count
/// cannot vary), [`MetricsError::NonFiniteSample`] for a NaN or infinite sample,
/// [`MetricsError::Degenerate`] if every sample off the median lies on one side of it, or if
/// exactly one lies on each side (then `Var[R] = 0`).
pub fn runs_test(x: &[f64]) -> Result<TestResult, MetricsError> {
    const WHAT: &str = "runs_test";
    if x.len() < 4 {
        return Err(MetricsError::TooFewSamples {
            what: WHAT,
            needed: 4,
            got: x.len(),
        });
    }
    check_finite(WHAT, x)?;
    let med = median(x)?;
    let (mut above, mut below, mut runs) = (0_usize, 0_usize, 0_usize);
    let mut previous: Option<bool> = None;
    for &v in x.iter().filter(|&&v| v != med) {
        let side = v > med;
        if side {
            above += 1;
        } else {
            below += 1;
        }
        if previous != Some(side) {
            runs += 1;
        }
        previous = Some(side);
    }
    if above == 0 || below == 0 {
        return Err(MetricsError::Degenerate {
            what: WHAT,
            reason: "all samples off the median lie on one side of it",
        });
    }
    let (n1, n2) = (above as f64, below as f64);
    let n = n1 + n2;
    let two_n1_n2 = 2.0 * n1 * n2;
    let mean = two_n1_n2 / n + 1.0;
    let var = two_n1_n2 * (two_n1_n2 - n) / (n * n * (n - 1.0));
    if var <= 0.0 {
        return Err(MetricsError::Degenerate {
            what: WHAT,
            reason: "one sample above and one below the median: the run count cannot vary",
        });
    }
    let z = (runs as f64 - mean) / var.sqrt();
    Ok(TestResult {
        statistic: z,
        p_value: two_sided_normal_p(z),
    })
}

/// `2 (1 - Phi(|z|))`, as the upper regularized incomplete gamma function `Q(1/2, z^2 / 2)`
/// (the chi-square(1) survival function at `z^2`).
///
/// A complement computed directly, so small p-values keep their digits. Not through statrs'
/// `Normal::sf`: its `erfc` (statrs 0.19) is off by up to ~1e-10 relative, where `Q` is good
/// to ~1e-14 against scipy's `norm.sf`.
fn two_sided_normal_p(z: f64) -> f64 {
    let x = 0.5 * z * z;
    if x == 0.0 {
        // Also covers |z| so small that z^2 underflows; statrs rejects x = 0.
        1.0
    } else if x.is_finite() {
        gamma_ur(0.5, x).min(1.0)
    } else {
        0.0
    }
}

/// Matched-pair t-test of `a` against `b`, two-sided.
///
/// With `d_i = a_i - b_i`, `t = mean(d) / (sd(d) / sqrt(n))`, `sd` with the `n - 1` divisor,
/// and the p-value from Student's t with `n - 1` degrees of freedom. Pairing is by index: for
/// batch means, `a` is the first half and `b` the second, so a drift of the mean shows up as a
/// non-zero mean difference.
///
/// # Why not statrs' `ttest_onesample`
/// On the differences with `popmean = 0`, statrs 0.19's `ttest_onesample` computes the same
/// `t` by the same formula in the same order (equal bit for bit on every input tried), but its
/// two-sided p-value is `2 (1 - cdf(|t|))`: `1 - cdf` is a multiple of `2^-53 = 1.1e-16`, so a
/// p-value of `1e-13` keeps only three or four correct digits and one below about `1e-16` comes
/// out as 0 (it does for `t = 9.4` with 179 degrees of freedom, where the p-value is
/// `3.5e-17`). Here the p-value is `2 sf(|t|)`, the survival function computed
/// directly, which keeps its relative accuracy in the tail (checked against the closed form of
/// one degree of freedom). statrs also accepts infinite samples and a zero variance (returning
/// an infinite or NaN `t`), where this function returns a typed error.
///
/// # Errors
/// [`MetricsError::DimensionMismatch`] if the lengths differ (`expected` the length of `a`,
/// `found` that of `b`), [`MetricsError::TooFewSamples`] for
/// fewer than 2 pairs, [`MetricsError::NonFiniteSample`] for a NaN or infinite sample or difference,
/// [`MetricsError::Degenerate`] if all differences are equal (zero variance: `t` undefined).
pub fn paired_t_test(a: &[f64], b: &[f64]) -> Result<TestResult, MetricsError> {
    const WHAT: &str = "paired_t_test";
    if a.len() != b.len() {
        return Err(MetricsError::DimensionMismatch {
            what: "paired_t_test: second sample length",
            expected: a.len(),
            found: b.len(),
        });
    }
    if a.len() < 2 {
        return Err(MetricsError::TooFewSamples {
            what: WHAT,
            needed: 2,
            got: a.len(),
        });
    }
    check_finite(WHAT, a)?;
    check_finite(WHAT, b)?;
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    // Finite inputs of huge opposite magnitudes can still overflow when subtracted.
    check_finite("paired_t_test (difference a - b)", &d)?;
    // Checked on the data, not on the computed variance: the rounded mean of equal values
    // need not equal them, which would leave a spurious tiny variance and a huge `t`.
    if d.iter().all(|&v| v == d[0]) {
        return Err(MetricsError::Degenerate {
            what: WHAT,
            reason: "all differences are equal: zero variance",
        });
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    // Two passes: the sum of squared deviations does not cancel like sum(d^2) - n mean^2.
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if !(var > 0.0 && var.is_finite()) {
        return Err(MetricsError::Degenerate {
            what: WHAT,
            reason: "the variance of the differences underflows or overflows",
        });
    }
    let t = mean / (var / n).sqrt();
    let student = StudentsT::new(0.0, 1.0, n - 1.0).map_err(|_| MetricsError::Degenerate {
        what: WHAT,
        reason: "invalid degrees of freedom",
    })?;
    Ok(TestResult {
        statistic: t,
        p_value: (2.0 * student.sf(t.abs())).min(1.0),
    })
}

/// Two-sample Kolmogorov-Smirnov test, two-sided.
///
/// `D = sup_x |F_a(x) - F_b(x)|` over the empirical distribution functions. Ties, within or
/// between samples, are handled in computing `D` (equal values are stepped over together),
/// but the p-value assumes continuous data: with ties the true null distribution of `D` is
/// different (the test becomes conservative).
///
/// The p-value is exact ([`ks_two_sample_exact_p`]) when `n m <= KS_EXACT_MAX_CELLS`, and the
/// plain Kolmogorov limit ([`ks_asymptotic_p`]) otherwise.
///
/// # Why not statrs' `ks_twosample`
/// statrs 0.19's `ks_twosample(.., TwoSidedExact, ..)` uses the same null distribution and the
/// same convention (`P(D >= D_obs)`), but:
/// * it refuses `n m > 10_000` (`ExactAndTooLarge`), so paper 004's two halves of 180 batch
///   means (32 400 cells) would fall back to an approximation; here the exact p-value goes to
///   [`KS_EXACT_MAX_CELLS`] = 10^7 cells;
/// * it fills the whole `(n + 1) x (m + 1)` table of path counts, `O(n m)` memory (it would
///   take 80 MB at 10^7 cells), where one row of probabilities, `O(m)`, suffices (25 KB at 3162 x 3162);
/// * it returns `1 - inside / total`, good to about `1e-13` absolute: below that its p-values
///   are rounding noise, and can be negative (for disjoint samples of 50 and 50 it gives
///   `2.8e-15` where the exact value is `2 / C(100, 50) = 2.0e-29`); summing the mass that
///   leaves the region keeps the relative accuracy of small p-values;
/// * it accumulates the empirical distribution functions by adding `1 / n` repeatedly, so `D`
///   is off by a few ulps (1.0000000000000002 for disjoint samples); here `D n m` is an
///   integer, and `D` is one division.
///
/// Its `TwoSidedAsymptotic` method is the same Kolmogorov limit as [`ks_asymptotic_p`] at the
/// same `lambda`; the two agree to about `1e-13` relative.
///
/// # Errors
/// [`MetricsError::TooFewSamples`] if either sample is empty, [`MetricsError::NonFiniteSample`] for a
/// NaN or infinite sample.
pub fn ks_two_sample(a: &[f64], b: &[f64]) -> Result<TestResult, MetricsError> {
    const WHAT: &str = "ks_two_sample";
    for sample in [a, b] {
        if sample.is_empty() {
            return Err(MetricsError::TooFewSamples {
                what: WHAT,
                needed: 1,
                got: 0,
            });
        }
    }
    check_finite(WHAT, a)?;
    check_finite(WHAT, b)?;
    let (n, m) = (a.len(), b.len());
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort_unstable_by(f64::total_cmp);
    b.sort_unstable_by(f64::total_cmp);
    // `D n m` as an integer: `|i m - j n|` after `i` values of `a` and `j` of `b`. Keeping it
    // integral lets the exact p-value count the observed `D` itself as "at least as extreme"
    // without any floating-point tolerance.
    let (nm, mm) = (n as u128, m as u128);
    let (mut i, mut j) = (0_usize, 0_usize);
    let mut largest: u128 = 0;
    while i < n && j < m {
        let v = if a[i] <= b[j] { a[i] } else { b[j] };
        while i < n && a[i] == v {
            i += 1;
        }
        while j < m && b[j] == v {
            j += 1;
        }
        largest = largest.max((i as u128 * mm).abs_diff(j as u128 * nm));
    }
    // Once one sample is exhausted its ECDF is 1 and the gap only shrinks: no need to go on.
    let statistic = largest as f64 / (n as f64 * m as f64);
    let p_value = if n
        .checked_mul(m)
        .is_some_and(|cells| cells <= KS_EXACT_MAX_CELLS)
    {
        exact_p_outside(n, m, largest)
    } else {
        ks_asymptotic_p(n, m, statistic)?
    };
    Ok(TestResult { statistic, p_value })
}

/// Exact null probability `P(D >= d)` of the two-sample Kolmogorov-Smirnov statistic for
/// samples of sizes `n` and `m` from the same continuous distribution.
///
/// Under the null every interleaving of the two sorted samples is equally likely; an
/// interleaving is a monotone lattice path from `(0, 0)` to `(n, m)`, and
/// `D = max |i/n - j/m|` over its points. The probability that the path reaches a point with
/// `|i m - j n| >= d n m` is accumulated by dynamic programming with the uniform-path measure
/// (from `(i, j)` the next value comes from the first sample with probability
/// `(n - i) / (n - i + m - j)`). Working with probabilities instead of path counts never
/// overflows (there are `C(360, 180) ~ 10^107` paths for two samples of 180), and summing the
/// mass absorbed at the boundary instead of subtracting the inside mass from 1 keeps relative
/// accuracy for tiny p-values.
///
/// `d` is compared with a relative tolerance of `1e-9`, so that a `D` computed in floating
/// point counts as reached: at every attainable value of `D` this is `P(D >= D_obs)`, the
/// value of scipy's `ks_2samp(method='exact')`. (Between attainable values scipy rounds `d` to
/// the nearest one, this function to the next one up.) Returns 1 for `d <= 0`, 0 for `d > 1`.
/// Cost `O(n m)` time, `O(m)` memory.
///
/// # Errors
/// [`MetricsError::Empty`] for a size of zero, [`MetricsError::InvalidParameter`] for a NaN
/// `d` or for `n m` beyond [`KS_EXACT_MAX_CELLS`] (use [`ks_asymptotic_p`] there).
pub fn ks_two_sample_exact_p(n: usize, m: usize, d: f64) -> Result<f64, MetricsError> {
    check_ks_input(n, m, d)?;
    // O(n m) time: the size is checked up front instead of running for hours (or failing to
    // allocate) on sizes whose asymptotic p-value is accurate anyway.
    let cells = n.checked_mul(m).filter(|&c| c <= KS_EXACT_MAX_CELLS);
    if cells.is_none() {
        return Err(MetricsError::InvalidParameter {
            name: "n m of the exact KS p-value (at most KS_EXACT_MAX_CELLS)",
            value: n as f64 * m as f64,
        });
    }
    if d <= 0.0 {
        return Ok(1.0);
    }
    if d > 1.0 {
        return Ok(0.0);
    }
    let scaled = d * n as f64 * m as f64;
    let threshold = (scaled * (1.0 - 1e-9)).ceil();
    Ok(exact_p_outside(n, m, threshold as u128))
}

/// The sizes and statistic a KS p-value needs: both sizes positive, the statistic a number.
fn check_ks_input(n: usize, m: usize, d: f64) -> Result<(), MetricsError> {
    if n == 0 || m == 0 {
        return Err(MetricsError::Empty {
            what: "a sample of the KS test",
        });
    }
    if d.is_nan() {
        return Err(MetricsError::InvalidParameter {
            name: "KS statistic",
            value: d,
        });
    }
    Ok(())
}

/// `P(max |i m - j n| >= threshold)` over a uniformly random lattice path from `(0, 0)` to
/// `(n, m)`; see [`ks_two_sample_exact_p`].
fn exact_p_outside(n: usize, m: usize, threshold: u128) -> f64 {
    if threshold == 0 {
        // The start point already has |0 - 0| >= 0.
        return 1.0;
    }
    // row[j] holds the probability of reaching (i, j) without having touched the boundary:
    // before the update of column j it is still the value for (i - 1, j).
    let mut row = vec![0.0_f64; m + 1];
    let mut outside = 0.0_f64;
    // The columns where `row` may be non-zero: the mass lives in a band about the diagonal
    // (|i m - j n| < threshold), so each row visits only the band and the cells one step
    // beyond it. A skipped cell would add a zero mass to `outside` and leave a zero in `row`:
    // the sums are the full grid's, to the bit.
    let (mut lo, mut hi) = (0usize, 0usize);
    for i in 0..=n {
        let mut first = None;
        let mut last = lo;
        for j in lo..=m {
            lattice_step(&mut row, &mut outside, (i, j), (n, m), threshold);
            if row[j] != 0.0 {
                first.get_or_insert(j);
                last = j;
            } else if j >= hi && (i > 0 || j > 0) {
                // Beyond the previous row's band nothing comes from below, and nothing
                // comes from the left past a zero: the rest of the row stays zero.
                break;
            }
        }
        match first {
            Some(f) => (lo, hi) = (f, last),
            // No mass left inside: every later cell adds zero.
            None => break,
        }
    }
    outside.min(1.0)
}

/// One cell `(i, j)` of [`exact_p_outside`]'s lattice-path recursion: the probability of
/// reaching it without having touched the boundary, from `(i - 1, j)` (still in `row[j]`) and
/// `(i, j - 1)` (already in `row[j - 1]`); a cell on or beyond the boundary
/// (`|i m - j n| >= threshold`) adds its mass to `outside` and keeps none.
#[inline(always)]
fn lattice_step(
    row: &mut [f64],
    outside: &mut f64,
    (i, j): (usize, usize),
    (n, m): (usize, usize),
    threshold: u128,
) {
    let mass = if i == 0 && j == 0 {
        1.0
    } else {
        let from_below = if i > 0 {
            // From (i - 1, j): n - i + 1 values of the first sample left, m - j of the second.
            let (ra, rb) = ((n - i + 1) as f64, (m - j) as f64);
            row[j] * ra / (ra + rb)
        } else {
            0.0
        };
        let from_left = if j > 0 {
            // From (i, j - 1): n - i left of the first sample, m - j + 1 of the second.
            let (ra, rb) = ((n - i) as f64, (m - j + 1) as f64);
            row[j - 1] * rb / (ra + rb)
        } else {
            0.0
        };
        from_below + from_left
    };
    if (i as u128 * m as u128).abs_diff(j as u128 * n as u128) >= threshold {
        *outside += mass;
        row[j] = 0.0;
    } else {
        row[j] = mass;
    }
}

/// Asymptotic null probability `P(D >= d)` of the two-sample Kolmogorov-Smirnov statistic:
/// the Kolmogorov limit `Q(lambda)` at `lambda = sqrt(n m / (n + m)) d`, **without** the
/// Stephens small-sample correction.
///
/// `Q(lambda) = 2 sum_{k >= 1} (-1)^{k-1} exp(-2 k^2 lambda^2)` (scipy's
/// `kstwobign.sf(lambda)`). This series converges slowly for small `lambda`, so below
/// `lambda = 1` the equivalent theta-function form of the distribution function,
/// `1 - Q = sqrt(2 pi) / lambda sum_{k >= 1} exp(-(2k - 1)^2 pi^2 / (8 lambda^2))`, is summed
/// instead (a few terms suffice either way). Returns 1 for `d <= 0`.
///
/// Note that scipy's `ks_2samp(method='asymp')` is a different approximation
/// (`kstwo.sf(d, round(n m / (n + m)))`, the one-sample finite-`n` distribution).
///
/// # Errors
/// [`MetricsError::Empty`] for a size of zero, [`MetricsError::InvalidParameter`] for a NaN
/// `d`.
pub fn ks_asymptotic_p(n: usize, m: usize, d: f64) -> Result<f64, MetricsError> {
    check_ks_input(n, m, d)?;
    let (nf, mf) = (n as f64, m as f64);
    Ok(kolmogorov_sf((nf * mf / (nf + mf)).sqrt() * d))
}

/// Survival function of the Kolmogorov distribution, `P(K >= lambda)`.
fn kolmogorov_sf(lambda: f64) -> f64 {
    use std::f64::consts::PI;
    // Below 0.05 the distribution function is below exp(-pi^2 / 0.02) ~ 1e-214, so the
    // survival function is 1 to double precision; the series below would divide by a
    // subnormal lambda (0 inf = NaN, found by the adversarial suite).
    if lambda < 0.05 {
        return 1.0;
    }
    if lambda < 1.0 {
        // Terms fall by at least exp(-pi^2) ~ 5e-5 each; their sum is below 0.73 here, so
        // 1 - cdf loses nothing to cancellation.
        let c = -PI * PI / (8.0 * lambda * lambda);
        let mut cdf = 0.0;
        for k in 1..=20_u32 {
            let odd = f64::from(2 * k - 1);
            let term = (c * odd * odd).exp();
            cdf += term;
            if term <= f64::EPSILON * cdf {
                break;
            }
        }
        cdf *= (2.0 * PI).sqrt() / lambda;
        return (1.0 - cdf).clamp(0.0, 1.0);
    }
    // lambda >= 1: terms fall by at least exp(-6) ~ 2.5e-3 each.
    let c = -2.0 * lambda * lambda;
    let mut sum = 0.0;
    let mut sign = 1.0;
    for k in 1..=100_u32 {
        let kf = f64::from(k);
        let term = (c * kf * kf).exp();
        sum += sign * term;
        if term <= f64::EPSILON * sum.abs() {
            break;
        }
        sign = -sign;
    }
    (2.0 * sum).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lattice-path recursion over the whole grid, as before the band: every cell
    /// visited.
    fn exact_p_outside_full_grid(n: usize, m: usize, threshold: u128) -> f64 {
        if threshold == 0 {
            return 1.0;
        }
        let mut row = vec![0.0_f64; m + 1];
        let mut outside = 0.0_f64;
        for i in 0..=n {
            for j in 0..=m {
                lattice_step(&mut row, &mut outside, (i, j), (n, m), threshold);
            }
        }
        outside.min(1.0)
    }

    /// The band skips only cells whose mass is zero: the same p to the bit, for every
    /// threshold of small grids and a spread of them at Table 1's 180 x 180.
    #[test]
    fn the_banded_recursion_is_the_full_grid_to_the_bit() {
        for n in 1..=14 {
            for m in 1..=14 {
                for threshold in 0..=(n * m + 1) as u128 {
                    let (a, b) = (
                        exact_p_outside(n, m, threshold),
                        exact_p_outside_full_grid(n, m, threshold),
                    );
                    assert_eq!(a.to_bits(), b.to_bits(), "{n} x {m}, threshold {threshold}");
                }
            }
        }
        for (n, m) in [(180, 180), (180, 97), (33, 250)] {
            let cells = (n * m) as u128;
            for k in [1, 2, 5, 17, 60, 111, 250, 800, 1000] {
                let threshold = cells * k / 1000;
                assert_eq!(
                    exact_p_outside(n, m, threshold).to_bits(),
                    exact_p_outside_full_grid(n, m, threshold).to_bits(),
                    "{n} x {m}, threshold {threshold}"
                );
            }
        }
    }

    /// Found by the adversarial suite: a statistic near the smallest subnormal gave NaN inside
    /// `Ok`.
    #[test]
    fn asymptotic_p_of_a_tiny_statistic_is_one() {
        for d in [5e-324, 1e-308, 1e-300, 1e-3] {
            assert_eq!(ks_asymptotic_p(1, 1, d), Ok(1.0), "{d:e}");
        }
        assert!((ks_asymptotic_p(100, 100, 0.01).unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn median_odd_and_even() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Ok(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Ok(2.5));
    }

    #[test]
    fn kolmogorov_branches_meet_at_one() {
        // Both series at lambda = 1 must agree: evaluate the small-lambda form just below and
        // the alternating form at 1; Q is smooth with |Q'| < 1 there.
        let below = kolmogorov_sf(1.0 - 1e-12);
        let at = kolmogorov_sf(1.0);
        assert!((below - at).abs() < 1e-11, "{below} vs {at}");
    }

    #[test]
    fn exact_threshold_zero_is_certain() {
        assert_eq!(exact_p_outside(5, 7, 0), 1.0);
    }
}
