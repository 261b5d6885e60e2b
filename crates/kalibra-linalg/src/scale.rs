//! Exact power-of-two scaling, for computations on values near the ends of f64's range
//! (1e308, subnormals) whose answer is finite.
//!
//! Multiplying by a power of two is exact (away from overflow and underflow) and commutes with
//! every rounding, so a computation on scaled values, scaled back, equals the unscaled
//! computation to the bit wherever the latter neither overflows nor underflows.
//! [`spectral_radius`](crate::spectral_radius) and kalibra-metrics' statistics of series use
//! these.

/// The binary exponent `k` of a finite `x != 0`: `|x| = f 2^k` with `f` in `[1, 2)`,
/// subnormals included; `None` for zero, NaN and infinities.
///
/// ```
/// use kalibra_linalg::binary_exponent;
/// assert_eq!(binary_exponent(-3.0), Some(1));
/// assert_eq!(binary_exponent(f64::MAX), Some(1023));
/// assert_eq!(binary_exponent(5e-324), Some(-1074));
/// assert_eq!(binary_exponent(0.0), None);
/// ```
pub fn binary_exponent(x: f64) -> Option<i32> {
    if x == 0.0 || !x.is_finite() {
        return None;
    }
    let bits = x.abs().to_bits();
    let field = ((bits >> 52) & 0x7ff) as i32;
    Some(if field == 0 {
        // Subnormal: the value is `mantissa 2^-1074`.
        let mantissa = bits & ((1u64 << 52) - 1);
        63 - mantissa.leading_zeros() as i32 - 1074
    } else {
        field - 1023
    })
}

/// `x 2^k`, exact whenever the result is representable (normal, or subnormal without lost
/// bits): applied in steps so that no intermediate power of two leaves the range.
///
/// ```
/// use kalibra_linalg::ldexp;
/// assert_eq!(ldexp(1.0, -1076), 0.0); // a quarter of the smallest subnormal rounds to zero
/// assert_eq!(ldexp(ldexp(1.25, 1023), -1023), 1.25);
/// assert_eq!(ldexp(1.0, -1074), 5e-324);
/// ```
pub fn ldexp(x: f64, k: i32) -> f64 {
    let (mut x, mut k) = (x, k);
    while k > 1000 {
        x *= 2f64.powi(1000);
        k -= 1000;
    }
    while k < -1000 {
        x *= 2f64.powi(-1000);
        k += 1000;
    }
    x * 2f64.powi(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponents_and_exact_scaling() {
        assert_eq!(binary_exponent(1.0), Some(0));
        assert_eq!(binary_exponent(f64::MIN_POSITIVE), Some(-1022));
        assert_eq!(binary_exponent(f64::NAN), None);
        assert_eq!(binary_exponent(f64::INFINITY), None);
        for x in [1e308, 3.7e-310, 5e-324, 1.25, -7e200] {
            let k = binary_exponent(x).unwrap();
            let s = ldexp(x, -k);
            assert!((1.0..2.0).contains(&s.abs()), "{x:e}");
            assert_eq!(ldexp(s, k), x, "{x:e}");
        }
    }
}
