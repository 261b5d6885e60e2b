//! The integral of time-weighted squared error.

use crate::MetricsError;

/// `ITSE = integral of t e(t)^2 dt`, by the trapezoid rule over samples `(t_k, e_k^2)`.
/// Pass mean squared errors over Monte Carlo runs to get the mean ITSE (the integral is
/// linear). Weighting by `t` makes late errors count more than the initial transient, which is
/// why Saha, Ghosh and Goswami (2014) use it to compare tunings.
///
/// ```
/// // e^2 = 1 on [0, 2]: ITSE = 2^2 / 2 = 2.
/// let v = kalibra_metrics::itse(&[0.0, 1.0, 2.0], &[1.0, 1.0, 1.0])?;
/// assert_eq!(v, 2.0);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::DimensionMismatch`] if the lengths differ; [`MetricsError::Empty`] for fewer
/// than two samples; [`MetricsError::InvalidParameter`] for non-finite values, times that do
/// not increase strictly, or a negative squared error.
pub fn itse(times: &[f64], squared_errors: &[f64]) -> Result<f64, MetricsError> {
    if times.len() != squared_errors.len() {
        return Err(MetricsError::DimensionMismatch {
            what: "squared errors",
            expected: times.len(),
            found: squared_errors.len(),
        });
    }
    if times.len() < 2 {
        return Err(MetricsError::Empty {
            what: "ITSE interval (two samples at least)",
        });
    }
    for (&t, &e2) in times.iter().zip(squared_errors) {
        if !t.is_finite() {
            return Err(MetricsError::InvalidParameter {
                name: "time",
                value: t,
            });
        }
        if !(e2.is_finite() && e2 >= 0.0) {
            return Err(MetricsError::InvalidParameter {
                name: "squared error",
                value: e2,
            });
        }
    }
    // Times or squared errors near the ends of f64's range: the integral of the scaled series
    // (each by a power of two, exact), scaled back; ordinary data is computed as it is.
    let (a, b) = (
        crate::scale::extreme_exponent(times),
        crate::scale::extreme_exponent(squared_errors),
    );
    if a.is_some() || b.is_some() {
        let (a, b) = (a.unwrap_or(0), b.unwrap_or(0));
        let total = itse(
            &crate::scale::scaled(times, a),
            &crate::scale::scaled(squared_errors, b),
        )?;
        // dt and t each carry 2^a, the squared error 2^b.
        let total = crate::scale::ldexp(total, 2 * a + b);
        return if total.is_finite() {
            Ok(total)
        } else {
            Err(MetricsError::InvalidParameter {
                name: "ITSE (beyond the range of f64)",
                value: total,
            })
        };
    }
    let mut total = 0.0;
    for k in 1..times.len() {
        let dt = times[k] - times[k - 1];
        if dt <= 0.0 {
            return Err(MetricsError::InvalidParameter {
                name: "time step",
                value: dt,
            });
        }
        total += 0.5 * dt * (times[k] * squared_errors[k] + times[k - 1] * squared_errors[k - 1]);
    }
    if !total.is_finite() {
        // Ordinary values whose products `t e^2 dt` overflow (each below 2^480, the three
        // together beyond 2^1024; `tests/extreme_floats.rs`): the scaled form, which is an
        // error where the integral itself leaves f64.
        let exponent = |v: &[f64]| {
            kalibra_linalg::binary_exponent(v.iter().fold(0.0f64, |m, x| m.max(x.abs())))
                .unwrap_or(0)
        };
        let (a, b) = (exponent(times), exponent(squared_errors));
        let scaled = itse(
            &crate::scale::scaled(times, a),
            &crate::scale::scaled(squared_errors, b),
        )?;
        let total = crate::scale::ldexp(scaled, 2 * a + b);
        if !total.is_finite() {
            return Err(MetricsError::InvalidParameter {
                name: "ITSE (beyond the range of f64)",
                value: total,
            });
        }
        return Ok(total);
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_is_exact_for_linear_integrands() {
        // e^2 = 3 constant: t e^2 is linear, so the trapezoid rule is exact: 3 T^2 / 2.
        let t: Vec<f64> = (0..=59).map(|k| 2.0 * k as f64).collect();
        let e2 = vec![3.0; t.len()];
        assert!((itse(&t, &e2).unwrap() - 3.0 * 118.0 * 118.0 / 2.0).abs() < 1e-9);
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        assert!(itse(&[0.0, 1.0], &[1.0]).is_err());
        assert!(itse(&[0.0], &[1.0]).is_err());
        assert!(itse(&[1.0, 0.0], &[1.0, 1.0]).is_err());
        assert!(itse(&[0.0, 1.0], &[1.0, -1.0]).is_err());
        assert!(itse(&[0.0, f64::NAN], &[1.0, 1.0]).is_err());
    }
}
