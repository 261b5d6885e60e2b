//! Error series over time and their sliding-window statistics (paper 002, Minh et al., EKF
//! angle tracking).
//!
//! # Notation
//! * `e_i(k) = xhat_i(k) - x_i(k)`, the estimate minus the truth (paper 002, eq. 14). This is
//!   the opposite sign of the crate-level `e_k = x_k - x+_k`; only the bias depends on it, and
//!   here a positive bias means the filter overestimates.
//! * `RMSE_i = sqrt(1/N sum_k e_i(k)^2)` over the `N` samples of one run (eq. 15).
//! * Forward windows of `W` samples: the window `k` holds `e(k) .. e(k + W - 1)`, and
//!   * `RMSE^k = sqrt(1/W sum_j e(j)^2)` (eq. 16),
//!   * `bias^k = 1/W sum_j e(j)` (eq. 17),
//!   * `std^k = sqrt(sum_j (e(j) - bias^k)^2 / (W - 1))` (eq. 18 as corrected: the printed
//!     equation is garbled).
//!
//!   In every window `RMSE^2 = bias^2 + (W - 1)/W std^2`, so the three split the squared
//!   error into a systematic and a random part.
//!
//! # Numerical choices
//! Running sums of `e` and `e^2` would give every window in `O(N)`, but
//! `std^2 ~ mean(e^2) - mean(e)^2` cancels catastrophically when the errors sit on an offset
//! large against their spread: for `1e8 + N(0, 1)`, `e^2 ~ 1e16` has a spacing of 2 between
//! neighbouring doubles, so a variance of 1 is lost entirely (the tests show it). Instead
//! [`sliding_window`] keeps the window mean `m` and the sum of squared deviations `M2` and
//! updates them as `x_out` leaves and `x_in` enters (a sliding Welford update):
//!
//! ```text
//! m'  = m + (x_in - x_out) / W
//! M2' = M2 + (x_in - x_out) (x_in - m' + x_out - m)
//! ```
//!
//! Every term is a difference of samples or of a sample and a mean, so nothing of the size of
//! the offset squared is ever formed. Three refinements:
//! * The samples are shifted by a reference `c` (the first sample of the window at the last
//!   recomputation) before the update. Near the offset `x - c` is exact (Sterbenz's lemma), so
//!   `m` is a quantity of the size of the spread and its rounding is relative to the spread,
//!   not to the offset. Without the shift the mean is rounded to the spacing of doubles near
//!   the offset at every update: the tests measure std errors of `6e-8` relative for
//!   `1e8 + N(0, 1)` and `4e-6` for `1e6 + 1e-4 N(0, 1)`, against `1e-15` with it.
//! * Every `W` slides the mean and `M2` of the current window are recomputed exactly by two
//!   passes, so rounding errors of the updates cannot accumulate over a long series. That is
//!   `O(W)` work every `W` slides, so the total stays `O(N)`.
//! * A window whose samples are all equal (tracked in `O(1)` per slide as the length of the
//!   run of equal samples) gets its exact moments, `m = 0` and `M2 = 0` about `c = e(k)`:
//!   otherwise the update that empties a window of its spread leaves a residue of `eps` times
//!   the old `M2`, a std of about `1e-8` times the old one instead of 0.
//!
//! Rounding can still take `M2` a hair below zero for a nearly constant window; it is clamped
//! at 0. The outputs are `bias = c + m`, `std = sqrt(M2/(W - 1))` and
//! `RMSE = sqrt(bias^2 + M2/W)`.
//!
//! # Accuracy
//! The rounding of an update is relative to the spread of the samples it moves, and lives at
//! most `W` slides. Against a (corrected) two-pass computation of every window the tests
//! measure, for unit-scale data, for data on offsets of `1e6` and `1e8` with spreads of `1e-10`
//! and `1e-8` of the offset, and over a million samples:
//! * bias and RMSE within a few `1e-15` of the window's RMSE for `W >= 50`, `6e-14` for
//!   `W = 3` and `2e-13` for `W = 2`;
//! * `std^2` within `6e-15` of the largest `std^2` among the window and the `W` before it;
//! * the std within a few `1e-15` of itself for `W >= 50`. A window whose spread is far below
//!   its neighbours' inherits their rounding, so short windows of noise, where a few samples
//!   can nearly coincide, have larger relative std errors: up to `8e-13` for `W = 3` and
//!   `4e-10` for `W = 2` over 5000 standard normal samples.
//!
//! Values whose squares would overflow `f64` (beyond about `1e154`) or underflow are scaled by a
//! power of two first ([`rmse`], [`rmse_per_state`], [`sliding_window`]); a statistic whose
//! value itself lies beyond f64's range is an error.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, LinalgError, OVector, check_finite};

use crate::MetricsError;

/// Checks that every sample of `series` is finite. The non-short-circuiting `&` reduction
/// vectorises, as in [`kalibra_linalg::all_finite`].
fn check_finite_slice(series: &[f64], what: &'static str) -> Result<(), MetricsError> {
    if series.iter().fold(true, |ok, v| ok & v.is_finite()) {
        Ok(())
    } else {
        Err(LinalgError::NonFinite { what }.into())
    }
}

/// The instantaneous estimation errors `e(k) = xhat(k) - x(k)` (paper 002, eq. 14) of one
/// run, one vector per sample. Empty inputs give an empty series.
///
/// ```
/// use kalibra_linalg::Vector2;
/// let e = kalibra_metrics::instantaneous_errors(
///     &[Vector2::new(1.0, 2.0)],
///     &[Vector2::new(0.5, 3.0)],
/// )?;
/// assert_eq!(e, vec![Vector2::new(0.5, -1.0)]);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::DimensionMismatch`] if the series have different lengths or (for `Dyn`
/// states) a vector's size differs from the first estimate's; [`MetricsError::Linalg`] with
/// [`LinalgError::NonFinite`] if an input holds NaN or an infinity, or if a difference lies
/// beyond f64's range (an estimate and a truth of opposite signs near `±f64::MAX`).
pub fn instantaneous_errors<N: Dim>(
    estimates: &[OVector<f64, N>],
    truth: &[OVector<f64, N>],
) -> Result<Vec<OVector<f64, N>>, MetricsError>
where
    DefaultAllocator: Alloc<N>,
{
    if estimates.len() != truth.len() {
        return Err(MetricsError::DimensionMismatch {
            what: "truth series",
            expected: estimates.len(),
            found: truth.len(),
        });
    }
    let Some(first) = estimates.first() else {
        return Ok(Vec::new());
    };
    let dim = first.nrows();
    estimates
        .iter()
        .zip(truth)
        .map(|(xhat, x)| {
            // All vectors, not only each pair, must agree: the errors feed per-component
            // statistics such as `rmse_per_state`.
            for (what, v) in [("estimate vector", xhat), ("truth vector", x)] {
                if v.nrows() != dim {
                    return Err(MetricsError::DimensionMismatch {
                        what,
                        expected: dim,
                        found: v.nrows(),
                    });
                }
            }
            check_finite(xhat, "estimates")?;
            check_finite(x, "truth")?;
            let e = xhat - x;
            // Two finite values of opposite signs near `f64::MAX` differ by more than f64
            // holds: an error, not an infinity inside `Ok` (`tests/extreme_floats.rs`).
            check_finite(&e, "estimation error (beyond f64's range)")?;
            Ok(e)
        })
        .collect()
}

/// The RMSE over time of a scalar error series, `sqrt(1/N sum_k e(k)^2)` (paper 002, eq. 15).
///
/// ```
/// let r = kalibra_metrics::rmse(&[1.0, -1.0, 7.0, -7.0])?;
/// assert_eq!(r, 5.0);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::Empty`] for an empty series; [`MetricsError::Linalg`] with
/// [`LinalgError::NonFinite`] if it holds NaN or an infinity.
pub fn rmse(series: &[f64]) -> Result<f64, MetricsError> {
    if series.is_empty() {
        return Err(MetricsError::Empty {
            what: "error series",
        });
    }
    check_finite_slice(series, "error series")?;
    // Values near the ends of f64's range are scaled by a power of two (exact), so their
    // squares stay in range; ordinary data is computed as it is.
    if let Some(k) = crate::scale::extreme_exponent(series) {
        return Ok(crate::scale::ldexp(
            rmse(&crate::scale::scaled(series, k))?,
            k,
        ));
    }
    // A sum of non-negative terms: no cancellation, relative rounding error at most N eps.
    let sum: f64 = series.iter().map(|e| e * e).sum();
    Ok((sum / series.len() as f64).sqrt())
}

/// The RMSE over time of each state component, `RMSE_i = sqrt(1/N sum_k e_i(k)^2)` (paper
/// 002, eq. 15), from the errors of one run (see [`instantaneous_errors`]).
///
/// ```
/// use kalibra_linalg::Vector2;
/// let r = kalibra_metrics::rmse_per_state(&[Vector2::new(3.0, 1.0), Vector2::new(-4.0, 1.0)])?;
/// assert_eq!(r, Vector2::new(12.5f64.sqrt(), 1.0));
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::Empty`] for no samples; [`MetricsError::DimensionMismatch`] if (for `Dyn`
/// states) a vector's size differs from the first one's; [`MetricsError::Linalg`] with
/// [`LinalgError::NonFinite`] if an error holds NaN or an infinity.
pub fn rmse_per_state<N: Dim>(errors: &[OVector<f64, N>]) -> Result<OVector<f64, N>, MetricsError>
where
    DefaultAllocator: Alloc<N>,
{
    let Some(first) = errors.first() else {
        return Err(MetricsError::Empty {
            what: "error series",
        });
    };
    let dim = first.nrows();
    let mut sum = first.map(|_| 0.0);
    for e in errors {
        // Checked before `component_mul`, which panics on a size mismatch.
        if e.nrows() != dim {
            return Err(MetricsError::DimensionMismatch {
                what: "error vector",
                expected: dim,
                found: e.nrows(),
            });
        }
        check_finite(e, "error series")?;
        sum += e.component_mul(e);
    }
    let n = errors.len() as f64;
    let mut out = sum.map(|s| (s / n).sqrt());
    // A component whose values are extreme (near `f64::MAX`, or subnormal) takes `rmse`'s
    // power-of-two scaling, so its squares neither overflow nor underflow; ordinary components
    // keep the plain sum above, bit for bit (`tests/extreme_floats.rs`).
    for i in 0..dim {
        let largest = errors.iter().fold(0.0f64, |m, e| m.max(e[i].abs()));
        if crate::scale::extreme_exponent_of(largest).is_some() {
            let series: Vec<f64> = errors.iter().map(|e| e[i]).collect();
            out[i] = rmse(&series)?;
        }
    }
    Ok(out)
}

/// Statistics of every forward window of a scalar error series (paper 002, eqs. 16-18).
///
/// Entry `i` of each vector describes the window of samples `i ..= i + W - 1`, so a series of
/// `N` samples gives `N - W + 1` entries: the statistic at `i` looks ahead, and the last
/// `W - 1` samples start no window of their own.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowStats {
    /// The window length `W`.
    pub window: usize,
    /// `RMSE^i = sqrt(1/W sum_j e(j)^2)` of each window (eq. 16).
    pub rmse: Vec<f64>,
    /// `bias^i = 1/W sum_j e(j)` of each window (eq. 17).
    pub bias: Vec<f64>,
    /// `std^i = sqrt(sum_j (e(j) - bias^i)^2 / (W - 1))` of each window (eq. 18 as
    /// corrected).
    pub std: Vec<f64>,
}

impl WindowStats {
    /// Number of windows.
    pub fn len(&self) -> usize {
        self.rmse.len()
    }

    /// Whether there are no windows (never the case for the output of [`sliding_window`]).
    pub fn is_empty(&self) -> bool {
        self.rmse.is_empty()
    }
}

/// The mean and sum of squared deviations of one window, in coordinates shifted by `shift`
/// (see the module documentation for why).
#[derive(Clone, Copy, Debug)]
struct Moments {
    shift: f64,
    mean: f64,
    m2: f64,
}

impl Moments {
    /// Exact two-pass moments of `window`, shifted by its first sample.
    fn exact(window: &[f64]) -> Self {
        let shift = window[0];
        let w = window.len() as f64;
        let mean = window.iter().map(|x| x - shift).sum::<f64>() / w;
        let m2 = window
            .iter()
            .map(|x| {
                let d = (x - shift) - mean;
                d * d
            })
            .sum();
        Self { shift, mean, m2 }
    }

    /// The sliding Welford update as `x_out` leaves and `x_in` enters a window of `w` samples.
    fn slide(&mut self, x_out: f64, x_in: f64, w: f64) {
        let (y_out, y_in) = (x_out - self.shift, x_in - self.shift);
        let delta = y_in - y_out;
        let mean = self.mean + delta / w;
        self.m2 = (self.m2 + delta * (y_in - mean + y_out - self.mean)).max(0.0);
        self.mean = mean;
    }
}

/// RMSE, bias and local standard deviation of every forward window of `window` samples of a
/// scalar error series (paper 002, eqs. 16-18), in `O(N)` time; see [`WindowStats`] for the
/// indexing and the module documentation for the numerical method.
///
/// ```
/// let s = kalibra_metrics::sliding_window(&[1.0, 3.0, 3.0, 5.0], 2)?;
/// assert_eq!(s.len(), 3);
/// assert_eq!(s.bias, vec![2.0, 3.0, 4.0]);
/// assert_eq!(s.std[1], 0.0);
/// assert_eq!(s.rmse[0], 5.0f64.sqrt());
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::InvalidParameter`] named `"window"` for a window below 2 (the standard
/// deviation divides by `W - 1`); [`MetricsError::DimensionMismatch`] if the series is shorter
/// than the window (`expected` is the window, the least length that gives one window,
/// `found` the series length); [`MetricsError::Linalg`] with [`LinalgError::NonFinite`] if
/// the series holds NaN or an infinity; [`MetricsError::NonFiniteSample`] (index: the
/// window's start) for a window whose RMSE or standard deviation lies beyond f64's range
/// (values near `±f64::MAX` of opposite signs).
pub fn sliding_window(series: &[f64], window: usize) -> Result<WindowStats, MetricsError> {
    if window < 2 {
        return Err(MetricsError::InvalidParameter {
            name: "window",
            value: window as f64,
        });
    }
    if series.len() < window {
        return Err(MetricsError::DimensionMismatch {
            what: "error series length (at least the window)",
            expected: window,
            found: series.len(),
        });
    }
    check_finite_slice(series, "error series")?;
    // Values near the ends of f64's range: the statistics of the series scaled by a power of
    // two (exact), scaled back; ordinary data is computed as it is.
    if let Some(k) = crate::scale::extreme_exponent(series) {
        let mut stats = sliding_window(&crate::scale::scaled(series, k), window)?;
        for v in stats
            .rmse
            .iter_mut()
            .chain(&mut stats.bias)
            .chain(&mut stats.std)
        {
            *v = crate::scale::ldexp(*v, k);
        }
        // Scaling keeps every finite statistic finite; what is left beyond f64's range (the
        // spread of -1e308 and 1.8e308 has a sample std of 2e308) has no f64 value.
        for (what, values) in [
            ("sliding-window RMSE (beyond f64's range)", &stats.rmse),
            ("sliding-window std (beyond f64's range)", &stats.std),
        ] {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                return Err(MetricsError::NonFiniteSample { what, index });
            }
        }
        return Ok(stats);
    }

    let w = window as f64;
    let count = series.len() - window + 1;
    let mut stats = WindowStats {
        window,
        rmse: Vec::with_capacity(count),
        bias: Vec::with_capacity(count),
        std: Vec::with_capacity(count),
    };
    let mut moments = Moments::exact(&series[..window]);
    // Start of the run of equal samples that ends at the window's last sample: the window is
    // constant when the run covers it.
    let mut run_start = (1..window)
        .rev()
        .find(|&k| series[k] != series[k - 1])
        .unwrap_or(0);
    for start in 0..count {
        if run_start <= start {
            // A constant window's moments are known exactly. Without this, an update that
            // empties the window of its spread leaves a rounding residue of `eps` times the old
            // `M2` (a std of about `1e-8` times the old one instead of 0), and the reset also
            // lets the following updates start from exact values.
            moments = Moments {
                shift: series[start],
                mean: 0.0,
                m2: 0.0,
            };
        }
        let bias = moments.shift + moments.mean;
        stats.bias.push(bias);
        stats.std.push((moments.m2 / (w - 1.0)).sqrt());
        stats.rmse.push((bias * bias + moments.m2 / w).sqrt());

        let next = start + 1;
        if next == count {
            break;
        }
        if next % window == 0 {
            moments = Moments::exact(&series[next..next + window]);
        } else {
            moments.slide(series[start], series[start + window], w);
        }
        let last = start + window;
        if series[last] != series[last - 1] {
            run_start = last;
        }
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_series_has_zero_spread_exactly() {
        // Every difference is exactly zero, so neither the updates nor the recomputations can
        // produce rounding noise.
        let s = sliding_window(&[1e8 + 0.5; 23], 4).unwrap();
        assert_eq!(s.len(), 20);
        assert!(s.std.iter().all(|&v| v == 0.0));
        assert!(s.bias.iter().all(|&v| v == 1e8 + 0.5));
        assert!(s.rmse.iter().all(|&v| v == 1e8 + 0.5));
    }

    #[test]
    fn window_equal_to_series_gives_one_entry() {
        let s = sliding_window(&[1.0, 2.0, 6.0], 3).unwrap();
        assert_eq!((s.len(), s.window), (1, 3));
        assert_eq!(s.bias[0], 3.0);
        assert_eq!(s.std[0], 7.0f64.sqrt());
        assert!(!s.is_empty());
    }

    #[test]
    fn updates_and_recomputations_agree_across_the_boundary() {
        // Small integers, so that sums and differences are exact and only the divisions by W
        // round: windows reached by updates must agree with their own recomputation to a few
        // ulps, on both sides of the recomputations at starts 5, 10, ...
        let series: Vec<f64> = (0..40).map(|k| f64::from((k * 7) % 11)).collect();
        let s = sliding_window(&series, 5).unwrap();
        for (i, chunk) in series.windows(5).enumerate() {
            let exact = Moments::exact(chunk);
            let bias = exact.shift + exact.mean;
            assert!(
                (s.bias[i] - bias).abs() <= 1e-14 * (1.0 + bias.abs()),
                "window {i}"
            );
            assert!(
                (s.std[i] - (exact.m2 / 4.0).sqrt()).abs() <= 1e-14,
                "window {i}"
            );
        }
    }
}
