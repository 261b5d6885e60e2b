//! Exact power-of-two scaling, so that statistics of values near the ends of f64's range
//! (1e308, subnormals) neither overflow nor underflow when the answer itself is finite.
//!
//! Multiplying by a power of two is exact (away from overflow and underflow), and it commutes
//! with every rounding: `fl(a s) = fl(a) s`, `fl((a s)^2) = fl(a^2) s^2`, `sqrt(x s^2) =
//! sqrt(x) s`. So a statistic computed on a scaled series and scaled back equals the unscaled
//! computation to the bit wherever the latter does not overflow or underflow. The callers
//! still scale only series that hold extreme values ([`extreme_exponent`]), so that ordinary
//! data takes exactly the path it always took.

/// Values whose magnitude is beyond `2^LIMIT` or below `2^-LIMIT` count as extreme: their
/// squares, or sums of a few million of them, would leave f64's range.
const LIMIT: i32 = 480;

pub(crate) use kalibra_linalg::ldexp;

/// The exponent of the largest magnitude in `values` if it is extreme (beyond `2^480` or
/// below `2^-480`, zero excepted), `None` for ordinary data (and for all-zero or empty).
pub(crate) fn extreme_exponent(values: &[f64]) -> Option<i32> {
    extreme_exponent_of(values.iter().fold(0.0f64, |m, v| m.max(v.abs())))
}

/// [`extreme_exponent`] of values whose largest magnitude is `largest`.
pub(crate) fn extreme_exponent_of(largest: f64) -> Option<i32> {
    if largest == 0.0 || !largest.is_finite() {
        return None;
    }
    let k = kalibra_linalg::binary_exponent(largest)?;
    (k.abs() > LIMIT).then_some(k)
}

/// `values` multiplied by `2^-k`.
pub(crate) fn scaled(values: &[f64], k: i32) -> Vec<f64> {
    values.iter().map(|&v| ldexp(v, -k)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extreme_exponents() {
        assert_eq!(extreme_exponent(&[1.0, -1e100, 0.0]), None);
        assert_eq!(extreme_exponent(&[1e-200, 1e300]), Some(996));
        assert_eq!(extreme_exponent(&[0.0, 1e-300]), Some(-997));
    }

    /// The statistics of a series scaled by `2^p` are the statistics scaled by `2^p` (`2^2p`
    /// for ITSE's squared errors), to the bit, from 2^-1000 to 2^1000: where the unscaled
    /// computation overflowed (1e308) or underflowed (subnormals), before this scaling.
    #[test]
    fn statistics_follow_a_power_of_two_scaling_exactly() {
        let series: Vec<f64> = (0..40)
            .map(|i| ((i * 7919 % 97) as f64 - 48.0) / 17.0)
            .collect();
        let squares: Vec<f64> = series.iter().map(|e| e * e).collect();
        let times: Vec<f64> = (0..40).map(|i| 0.5 * i as f64).collect();
        let base_rmse = crate::rmse(&series).unwrap();
        let base_window = crate::sliding_window(&series, 8).unwrap();
        let base_batches = crate::hypothesis::batch_means(&series, 5, 3).unwrap();
        let base_itse = crate::itse(&times, &squares).unwrap();
        for p in [-1000, -900, -600, 600, 900, 1000] {
            let x = scaled(&series, -p);
            assert_eq!(crate::rmse(&x).unwrap(), ldexp(base_rmse, p), "rmse 2^{p}");
            let w = crate::sliding_window(&x, 8).unwrap();
            for (got, want) in [
                (&w.rmse, &base_window.rmse),
                (&w.bias, &base_window.bias),
                (&w.std, &base_window.std),
            ] {
                let want: Vec<f64> = want.iter().map(|&v| ldexp(v, p)).collect();
                assert_eq!(got, &want, "window 2^{p}");
            }
            let b = crate::hypothesis::batch_means(&x, 5, 3).unwrap();
            let want: Vec<f64> = base_batches.iter().map(|&v| ldexp(v, p)).collect();
            assert_eq!(b, want, "batch means 2^{p}");
            // Squared errors scaled by 2^p (p even keeps them representable at both ends).
            let e2 = scaled(&squares, -p / 2 * 2);
            let got = crate::itse(&times, &e2);
            let want = ldexp(base_itse, p / 2 * 2);
            match got {
                Ok(v) => assert_eq!(v, want, "itse 2^{p}"),
                Err(_) => assert!(!want.is_finite(), "itse 2^{p}: {want:e} is finite"),
            }
        }
    }
}
