//! Mean and variance of a shifted Rayleigh variable, the statistics of the shifted Rayleigh
//! filter's update (paper 001, eqs 33-34).
//!
//! # The variable
//! A shifted Rayleigh variable with shift `y` has density proportional to
//! `s exp(-(s - y)^2 / 2)` on `s >= 0`. With `phi`, `Phi` the standard normal density and
//! distribution function its mean is
//! `rho_2(y) = (y phi + (1 + y^2) Phi) / (phi + y Phi)` (eq 34) and its variance
//! `2 + y rho_2 - rho_2^2` (the bracket of eq 33). At `y = 0` it is the Rayleigh distribution:
//! mean `sqrt(pi/2)`, variance `2 - pi/2`.
//!
//! The density is `s e^{-s^2/2}` tilted by `e^{y s}`, an exponential family with natural
//! parameter `y`: the variance is the derivative of the mean in `y`, so the mean is strictly
//! increasing. Facts the tests check:
//! * `mean > max(y, 0)`: `rho_2 - y = Phi / (phi + y Phi) > 0`;
//! * `0 < variance < 1`, increasing in `y`. `variance < 1` reads `lambda (lambda - t) < 1` for
//!   the inverse Mills ratio `lambda` at `t = -y`: the variance of a truncated normal is
//!   positive;
//! * `y -> +inf`: mean `y + 1/y`, variance `1 - 1/y^2`, up to normal tails;
//! * `y -> -inf`, `t = -y`: mean `(2/t) (1 - 3/t^2 + 21/t^4 - ...)`, variance
//!   `(2/t^2) (1 - 9/t^2 + 105/t^4 - ...)`.
//!
//! # Numerical choices
//! The moments are well-conditioned in `y` (condition number below 2), but the closed form is
//! not. Its numerator and denominator cancel catastrophically for large negative `y`, and even
//! with exact arithmetic around it, any formula that goes through `phi / Phi` (or the Mills
//! ratio) for `y < 0` multiplies the relative error of that ratio by 7 at `y = 0`, 56 at
//! `y = -1`, 320 at `y = -2` and 1.4e4 at `y = -5` (variance; the mean fares 7 to 35 times
//! better). And `Phi` itself is not available to full precision: `statrs` 0.19's `erfc`
//! is accurate to only about `1e-10` relative (interval constants truncated to 10 digits,
//! statrs-dev/statrs PR 412). So this module uses no `erfc` and no `Phi` for `y < 0`, and
//! four branches, all free of cancellation beyond a small factor:
//!
//! **`y <= -1`: continued fraction.** With `t = -y` and
//! `J_j(t) = ∫_0^∞ s^j e^{-t s - s^2/2} ds` (the moment integrals with `e^{-y^2/2}` factored
//! out), integration by parts gives `J_{j+1} = j J_{j-1} - t J_j`, so the ratios
//! `c_j = (j - 1) J_{j-2} / J_{j-1}` obey `c_j = t + j / c_{j+1}` (Laplace's continued
//! fraction for the Mills ratio `J_0 = 1 / c_1`), and
//! `mean = J_2 / J_1 = 2 / c_3`,
//! `variance = J_3 / J_1 - mean^2 = (2 + 18 / c_4^2 - 24 / (c_4 c_5)) / c_3^2`,
//! with every `c_j > t > 0` and no cancellation. The fraction is evaluated backward from
//! level `CF_TERMS + 1 = 251`, started at the asymptotic value of the tail
//! `c_m ~ (t + sqrt(t^2 + 4m)) / 2 - 1 / (4 sqrt m) + t / (8m)` (the fixed point of
//! `c = t + m/c`, corrected to order `1/m`), which cuts the truncation error at `t = 1` about
//! a millionfold against starting from `c = t`. Truncation falls as `t` grows; at the switch
//! `t = 1` it is `3e-18` relative with 250 levels. A fixed count keeps the cost constant: 250
//! divisions.
//!
//! **`-1 < y < 0`: Taylor shift from `t = 1`.** For `t < 1`, expanding `e^{(1 - t) s}` in
//! `J_j(t) = ∫ s^j e^{(1 - t) s} e^{-s - s^2/2} ds` gives
//! `J_j(t) = Σ_k (1 - t)^k / k! J_{j+k}(1)`, a series of positive terms, and
//! `J_k(1) / (k! J_0(1)) = 1 / (c_2 c_3 ... c_{k+1})` at `t = 1` from the same continued
//! fraction. `SHIFT_TERMS = 40` terms reach rounding for `1 - t <= 1` (28 would); Horner's
//! rule sums them. The variance `J_3 / J_1 - mean^2` cancels by a factor of about 5.
//!
//! **`0 <= y < 8.5`: closed form through `r = phi(y) / Phi(y)`.** Marsaglia's series
//! `Phi(y) / phi(y) = sqrt(pi/2) e^{y^2/2} + Σ_k y^{2k+1} / (1·3···(2k+1))` has positive
//! terms for `y >= 0` (at most about 100 of them here). With `d = r + y > 0` the closed form
//! rearranges to `mean = y + 1/d` and `variance = 1 + (r - 1/d) / d`.
//!
//! **`y >= 8.5`:** `Phi(y) = 1` to rounding, so `r = phi(y)`, which underflows to 0 beyond
//! `y ~ 38.6` and leaves the exact limits `y + 1/y` and `1 - 1/y^2`; no overflow anywhere.
//!
//! Measured against the closed form in 200-digit arithmetic on dense grids from `-1e6` to
//! `1e7` (the switches included), the relative error is at most `4.5e-16` for the mean and
//! `2.8e-15` for the variance; the worst cases lie in `-1 < y < 0.5`, where the variance's own
//! cancellation (a factor of about 5) and the conditioning of the closed form near 0 cost a
//! few units of rounding. Elsewhere the error is a unit or two.
//!
//! # Extremes
//! Non-finite `y` gives NaN mean and variance; the shifted Rayleigh filter checks finiteness.
//! Every finite `y` gives finite moments and nothing panics. Rounding limits the strict
//! inequalities only far out: the mean rounds to `y` and the variance to 1 beyond `y ~ 1e8`,
//! and the variance (about `2 / y^2`) turns subnormal below `y ~ -1e154` and 0 below
//! `y ~ -6e161`.

/// `y` at and below which the continued fraction gives the moments.
const CF_SWITCH: f64 = -1.0;

/// Levels of the continued fraction: truncation error `3e-18` relative at `t = 1`, less for
/// larger `t`.
const CF_TERMS: u32 = 250;

/// Terms of the Taylor shift from `t = 1` for `-1 < y < 0`; 28 reach rounding at `y = 0`.
const SHIFT_TERMS: usize = 40;

/// `y` from which `Phi(y) = 1` to rounding (`1 - Phi(8.5) = 1e-17`).
const CDF_IS_ONE: f64 = 8.5;

/// Cap on the terms of Marsaglia's series; `y < 8.5` needs at most about 100.
const SERIES_MAX_TERMS: u32 = 200;

/// `sqrt(pi / 2)`.
const SQRT_FRAC_PI_2: f64 = 1.253_314_137_315_500_3;

/// `1 / sqrt(2 pi)`.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Mean and variance of a shifted Rayleigh variable (density proportional to
/// `s exp(-(s - y)^2 / 2)` on `s >= 0`), as returned by [`shifted_rayleigh_moments`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShiftedRayleigh {
    /// The mean `rho_2(y)`; greater than both `y` and 0 for finite `y`.
    pub mean: f64,
    /// The variance `2 + y rho_2(y) - rho_2(y)^2`; between 0 and 1 for finite `y`.
    pub variance: f64,
}

/// Mean and variance of the shifted Rayleigh variable with shift `y`: `rho_2(y)` of eq 34 of
/// paper 001 and the bracket `2 + y rho_2(y) - rho_2(y)^2` of eq 33.
///
/// The closed form `rho_2 = (y phi + (1 + y^2) Phi) / (phi + y Phi)` (`phi`, `Phi` the
/// standard normal density and distribution function) cancels catastrophically for negative
/// `y`, so it is used, rearranged, only for `y >= 0`; below that, a continued fraction derived
/// from Laplace's for the Mills ratio (250 levels, `y <= -1`) and a Taylor shift of its
/// result (`-1 < y < 0`). No `erfc` is involved. Relative error, measured against 200-digit
/// arithmetic: at most `4.5e-16` for the mean and `2.8e-15` for the variance.
///
/// For finite `y`: `mean > max(y, 0)`, `0 < variance < 1`, both increasing in `y`, and the
/// variance is the derivative of the mean. Far out rounding takes over: beyond `y ~ 1e8` the
/// mean rounds to `y` and the variance to 1; below `y ~ -1e154` the variance (about `2 / y^2`)
/// turns subnormal, and 0 below `y ~ -6e161`.
///
/// Non-finite `y` (NaN or infinite) gives NaN in both fields; the caller checks finiteness.
/// Never panics.
///
/// ```
/// use kalibra_filters::{ShiftedRayleigh, shifted_rayleigh_moments};
/// use std::f64::consts::FRAC_PI_2;
///
/// // At y = 0 the variable is Rayleigh: mean sqrt(pi/2), variance 2 - pi/2.
/// let ShiftedRayleigh { mean, variance } = shifted_rayleigh_moments(0.0);
/// assert!((mean - FRAC_PI_2.sqrt()).abs() < 1e-15);
/// assert!((variance - (2.0 - FRAC_PI_2)).abs() < 1e-15);
///
/// // Far below zero the mass piles up near 0: mean ~ 2/t, variance ~ 2/t^2 with t = -y.
/// let far = shifted_rayleigh_moments(-1e6);
/// assert!((far.mean / 2e-6 - 1.0).abs() < 1e-11);
/// assert!((far.variance / 2e-12 - 1.0).abs() < 1e-10);
///
/// assert!(shifted_rayleigh_moments(f64::NAN).mean.is_nan());
/// ```
#[must_use]
pub fn shifted_rayleigh_moments(y: f64) -> ShiftedRayleigh {
    if !y.is_finite() {
        ShiftedRayleigh {
            mean: f64::NAN,
            variance: f64::NAN,
        }
    } else if y <= CF_SWITCH {
        continued_fraction(-y, CF_TERMS)
    } else if y < 0.0 {
        taylor_shift(y)
    } else {
        closed_form(y, pdf_over_cdf(y))
    }
}

/// The levels `c_1 ..= c_L` (at indices `0 .. L`) of `c_j = t + j / c_{j+1}`, evaluated
/// backward from level `terms >= L` with the asymptotic tail as `c_{terms + 1}`.
fn levels<const L: usize>(t: f64, terms: u32) -> [f64; L] {
    let m = f64::from(terms + 1);
    let sqrt_m = m.sqrt();
    // Halves added separately so that t near f64::MAX does not overflow.
    let mut c = 0.5 * t + 0.5 * t.hypot(2.0 * sqrt_m) - 0.25 / sqrt_m + t / (8.0 * m);
    let mut out = [0.0; L];
    for j in (1..=terms).rev() {
        c = t + f64::from(j) / c;
        if let Some(slot) = out.get_mut(j as usize - 1) {
            *slot = c;
        }
    }
    out
}

/// The moments from the continued fraction at `t = -y > 0`.
fn continued_fraction(t: f64, terms: u32) -> ShiftedRayleigh {
    let [_, _, c3, c4, c5] = levels::<5>(t, terms);
    ShiftedRayleigh {
        mean: 2.0 / c3,
        // Divided twice rather than by c3^2, which would overflow for t above 1e154.
        variance: (2.0 + 18.0 / (c4 * c4) - 24.0 / (c4 * c5)) / c3 / c3,
    }
}

/// The moments for `-1 < y < 0` from `J_1, J_2, J_3` at `t = -y`, each a positive series in
/// `1 - t = 1 + y` around `t = 1`, all scaled by `1 / J_0(1)`.
fn taylor_shift(y: f64) -> ShiftedRayleigh {
    let c = levels::<{ SHIFT_TERMS + 3 }>(-CF_SWITCH, CF_TERMS);
    // a_k = J_k(1) / (k! J_0(1)) = 1 / (c_2 ... c_{k+1}); c_{k+1} sits at index k.
    let mut a = [1.0; SHIFT_TERMS + 3];
    let mut product = 1.0;
    for (ak, ck) in a.iter_mut().zip(c).skip(1) {
        product /= ck;
        *ak = product;
    }
    // J_j(t) / J_0(1) = Σ_k (1 + y)^k (j + k)! / k! a_{j+k}, by Horner's rule (a third of the
    // rounding error of summing powers here).
    let delta = 1.0 + y;
    let (mut j1, mut j2, mut j3) = (0.0, 0.0, 0.0);
    for (k, w) in a[1..].windows(3).enumerate().rev() {
        let k1 = k as f64 + 1.0;
        let k12 = k1 * (k1 + 1.0);
        j1 = j1 * delta + k1 * w[0];
        j2 = j2 * delta + k12 * w[1];
        j3 = j3 * delta + k12 * (k1 + 2.0) * w[2];
    }
    let mean = j2 / j1;
    ShiftedRayleigh {
        mean,
        variance: j3 / j1 - mean * mean,
    }
}

/// `phi(y) / Phi(y)` for `y >= 0`: Marsaglia's series below [`CDF_IS_ONE`], `phi(y)` above.
fn pdf_over_cdf(y: f64) -> f64 {
    let y2 = y * y;
    if y >= CDF_IS_ONE {
        return FRAC_1_SQRT_2PI * (-0.5 * y2).exp();
    }
    // Phi / phi = sqrt(pi/2) e^{y^2/2} + y + y^3/3 + y^5/(3·5) + ...
    let (mut term, mut sum) = (y, y);
    for k in 1..=SERIES_MAX_TERMS {
        term *= y2 / f64::from(2 * k + 1);
        sum += term;
        if term.abs() <= sum.abs() * f64::EPSILON / 8.0 {
            break;
        }
    }
    1.0 / (SQRT_FRAC_PI_2 * (0.5 * y2).exp() + sum)
}

/// The closed form through `r = phi(y) / Phi(y)`, for `y >= 0`.
fn closed_form(y: f64, r: f64) -> ShiftedRayleigh {
    // d = (phi + y Phi) / Phi > 0.
    let inv_d = (r + y).recip();
    ShiftedRayleigh {
        mean: y + inv_d,
        variance: 1.0 + (r - inv_d) * inv_d,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    /// Gauss-Legendre nodes and weights on [-1, 1], by Newton's method on `P_n`.
    fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
        // (P_n(x), P_n'(x)) by the three-term recurrence.
        let legendre = |x: f64| {
            let (mut p0, mut p1) = (1.0, x);
            for k in 1..n {
                let k = k as f64;
                let p2 = ((2.0 * k + 1.0) * x * p1 - k * p0) / (k + 1.0);
                p0 = p1;
                p1 = p2;
            }
            (p1, n as f64 * (x * p1 - p0) / (x * x - 1.0))
        };
        (1..=n)
            .map(|i| {
                let mut x = (std::f64::consts::PI * (i as f64 - 0.25) / (n as f64 + 0.5)).cos();
                for _ in 0..100 {
                    let (p, dp) = legendre(x);
                    let dx = p / dp;
                    x -= dx;
                    if dx.abs() < 1e-16 {
                        break;
                    }
                }
                let (_, dp) = legendre(x);
                (x, 2.0 / ((1.0 - x * x) * dp * dp))
            })
            .collect()
    }

    /// Composite Gauss-Legendre, 20 nodes per panel, with compensated (Neumaier) summation.
    struct Quadrature(Vec<(f64, f64)>);

    impl Quadrature {
        fn new() -> Self {
            Self(gauss_legendre(20))
        }

        fn integrate(&self, f: impl Fn(f64) -> f64, a: f64, b: f64, panels: usize) -> f64 {
            let h = (b - a) / panels as f64;
            let (mut sum, mut carry) = (0.0_f64, 0.0_f64);
            for p in 0..panels {
                let mid = a + (p as f64 + 0.5) * h;
                for &(x, w) in &self.0 {
                    let term = 0.5 * h * w * f(mid + 0.5 * h * x);
                    let next = sum + term;
                    carry += if sum.abs() >= term.abs() {
                        (sum - next) + term
                    } else {
                        (term - next) + sum
                    };
                    sum = next;
                }
            }
            sum + carry
        }

        /// Mean and variance of the density proportional to `w` on `[a, b]`; the variance as
        /// the centred second moment, free of cancellation.
        fn moments(&self, w: impl Fn(f64) -> f64, a: f64, b: f64, panels: usize) -> (f64, f64) {
            let mass = self.integrate(&w, a, b, panels);
            let mean = self.integrate(|v| v * w(v), a, b, panels) / mass;
            let var = self.integrate(|v| (v - mean).powi(2) * w(v), a, b, panels) / mass;
            (mean, var)
        }
    }

    /// Mean and variance of the shifted Rayleigh variable by quadrature, in a variable where
    /// the integrand neither underflows nor loses its location to rounding.
    fn by_quadrature(q: &Quadrature, y: f64) -> (f64, f64) {
        if y >= 0.0 {
            // v = s - y on [-min(y, 40), 40]: weight (y + v) e^{-v^2/2}.
            let w = |v: f64| (y + v) * (-0.5 * v * v).exp();
            let (m, var) = q.moments(w, -y.min(40.0), 40.0, 200);
            (y + m, var)
        } else if y > -1.0 {
            // s on [0, 40].
            q.moments(|s| s * (-0.5 * (s - y).powi(2)).exp(), 0.0, 40.0, 200)
        } else {
            // e^{-y^2/2} factored out and u = t s: weight u e^{-u - u^2 / (2 t^2)} on [0, 80].
            let t = -y;
            let w = |u: f64| u * (-u - 0.5 * (u / t).powi(2)).exp();
            let (m, var) = q.moments(w, 0.0, 80.0, 160);
            (m / t, var / (t * t))
        }
    }

    #[test]
    fn quadrature_rule_is_exact_for_polynomials_and_gaussians() {
        let q = Quadrature::new();
        let poly = q.integrate(|x| x.powi(39) + 3.0 * x * x, 0.0, 1.0, 1);
        assert!(rel(poly, 1.0 / 40.0 + 1.0) < 1e-15, "{poly}");
        let gauss = q.integrate(|x| (-0.5 * x * x).exp(), -40.0, 40.0, 200);
        let sqrt_2pi = (2.0 * std::f64::consts::PI).sqrt();
        assert!(rel(gauss, sqrt_2pi) < 1e-15, "{gauss}");
    }

    #[test]
    fn moments_match_quadrature_from_minus_1e6_to_1e3() {
        let q = Quadrature::new();
        let ys = [
            -1e6, -1e3, -100.0, -30.0, -10.0, -6.0, -5.0, -4.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0,
            3.0, 10.0, 40.0, 1e3,
        ];
        for y in ys {
            let got = shifted_rayleigh_moments(y);
            let (mean, var) = by_quadrature(&q, y);
            let (em, ev) = (rel(got.mean, mean), rel(got.variance, var));
            // Measured: at most 1.7e-16 (mean) and 9.6e-16 (variance), the quadrature's own
            // rounding included.
            assert!(
                em < 4e-15 && ev < 4e-15,
                "y = {y}: mean {em:e}, variance {ev:e}"
            );
        }
    }

    /// The closed form in 200-digit arithmetic (mpmath; it cancels some 24 digits at
    /// `y = -1e6`), rounded to f64, at and around every switch.
    #[test]
    fn moments_match_high_precision_references() {
        let refs = [
            (-1e6, 1.999999999994e-06, 1.999999999982e-12),
            (-1e3, 0.0019999940000419996, 1.999982000209997e-06),
            (-30.0, 0.0664461541624189, 0.0022002837244569926),
            (-5.0, 0.36181624128808854, 0.060007801099717054),
            (-1.5, 0.7795806941564462, 0.2228829000638843),
            (-1.0, 0.9042712333296918, 0.2780223032427062),
            (-0.999, 0.9045493173589594, 0.27814576442384004),
            (-0.5, 1.0598731483480797, 0.34673233523668967),
            (-0.1, 1.2112733937140518, 0.4116894263090382),
            (0.0, 1.2533141373155003, 0.4292036732051034),
            (0.1, 1.2971291666918845, 0.4471688415864059),
            (0.5, 1.49092271800411, 0.5226108079412922),
            (2.0, 2.4865593187852837, 0.7901413917326328),
            (8.5, 8.617647058823529, 0.986159169550173),
            (10.0, 10.1, 0.99),
            (40.0, 40.025, 0.999375),
        ];
        for (y, mean, var) in refs {
            let got = shifted_rayleigh_moments(y);
            let (em, ev) = (rel(got.mean, mean), rel(got.variance, var));
            assert!(
                em < 1e-15 && ev < 5e-15,
                "y = {y}: mean {em:e}, variance {ev:e}"
            );
        }
    }

    #[test]
    fn asymptotic_series_at_minus_1e4() {
        let t = 1e4_f64;
        let x = 1.0 / (t * t);
        let mean = 2.0 / t * (1.0 - 3.0 * x + 21.0 * x * x);
        let var = 2.0 * x * (1.0 - 9.0 * x + 105.0 * x * x);
        let got = shifted_rayleigh_moments(-t);
        assert!(rel(got.mean, mean) < 1e-15, "{got:?}");
        assert!(rel(got.variance, var) < 1e-15, "{got:?}");
        // The leading term alone is off by the next order, 9e-8 for the variance.
        assert!(rel(got.variance, 2.0 * x) > 8e-8, "{got:?}");
    }

    #[test]
    fn branches_agree_across_the_switches() {
        // One step of rounding across each switch.
        for s in [CF_SWITCH, 0.0, CDF_IS_ONE] {
            let (below, above) = (
                shifted_rayleigh_moments(s.next_down()),
                shifted_rayleigh_moments(s),
            );
            assert!(
                rel(below.mean, above.mean) < 1e-14,
                "{s}: {below:?} {above:?}"
            );
            assert!(
                rel(below.variance, above.variance) < 1e-14,
                "{s}: {below:?} {above:?}"
            );
        }
        // Neighbouring branches evaluated on both sides of each switch.
        type Branch = fn(f64) -> ShiftedRayleigh;
        let pairs: [(f64, Branch, Branch); 3] = [
            (
                CF_SWITCH,
                |y| continued_fraction(-y, CF_TERMS),
                taylor_shift,
            ),
            (0.0, taylor_shift, |y| closed_form(y, pdf_over_cdf(y))),
            (
                CDF_IS_ONE,
                |y| closed_form(y, pdf_over_cdf(y)),
                |y| closed_form(y, FRAC_1_SQRT_2PI * (-0.5 * y * y).exp()),
            ),
        ];
        for (s, lower, upper) in pairs {
            for k in -20..=20 {
                let y = s + 0.01 * f64::from(k);
                let (l, u) = (lower(y), upper(y));
                assert!(rel(l.mean, u.mean) < 1e-14, "y = {y}: {l:?} {u:?}");
                assert!(rel(l.variance, u.variance) < 1e-14, "y = {y}: {l:?} {u:?}");
            }
        }
    }

    #[test]
    fn continued_fraction_has_converged_at_the_switch() {
        // Four times the levels changes nothing at t = 1 beyond rounding; a tenth of them does.
        let t = -CF_SWITCH;
        let used = continued_fraction(t, CF_TERMS);
        let long = continued_fraction(t, 4 * CF_TERMS);
        assert!(rel(used.mean, long.mean) < 3e-16, "{used:?} {long:?}");
        assert!(
            rel(used.variance, long.variance) < 1e-15,
            "{used:?} {long:?}"
        );
        let short = continued_fraction(t, CF_TERMS / 10);
        assert!(
            rel(short.variance, long.variance) > 1e-12,
            "{short:?} {long:?}"
        );
    }

    #[test]
    fn mean_and_variance_increase_and_variance_lies_in_0_1() {
        let mut last = shifted_rayleigh_moments(-1e6);
        let wide = [-1e5, -1e4, -1e3, -300.0].into_iter();
        let fine = (-3999..=4000).map(|k| 0.025 * f64::from(k));
        for y in wide.chain(fine).chain([300.0, 1e3, 1e4, 1e5, 1e6]) {
            let now = shifted_rayleigh_moments(y);
            assert!(now.mean > last.mean, "mean at {y}: {last:?} {now:?}");
            assert!(
                now.variance > last.variance,
                "variance at {y}: {last:?} {now:?}"
            );
            assert!(now.variance > 0.0 && now.variance < 1.0, "y = {y}: {now:?}");
            last = now;
        }
    }

    #[test]
    fn variance_is_the_derivative_of_the_mean() {
        // An exponential family in y: d mean / dy = variance. Central differences with
        // h = 1e-4 max(|y|, 1): the mean varies on the scale max(|y|, 1) (it is ~ 2/|y| far
        // below 0), so truncation is ~1e-8 relative and rounding ~1e-12.
        for y in [-1e3_f64, -30.0, -3.0, -1.0, -0.3, 0.0, 0.7, 2.0, 8.5, 50.0] {
            let h = 1e-4 * y.abs().max(1.0);
            let up = shifted_rayleigh_moments(y + h).mean;
            let down = shifted_rayleigh_moments(y - h).mean;
            let slope = (up - down) / (2.0 * h);
            let var = shifted_rayleigh_moments(y).variance;
            assert!(
                rel(slope, var) < 1e-7,
                "y = {y}: slope {slope}, variance {var}"
            );
        }
    }

    #[test]
    fn non_finite_input_gives_nan_and_extremes_stay_finite() {
        for y in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let m = shifted_rayleigh_moments(y);
            assert!(m.mean.is_nan() && m.variance.is_nan(), "{y}: {m:?}");
        }
        let extremes = [
            f64::MAX,
            1e200,
            1e8,
            f64::MIN_POSITIVE,
            -5e-324,
            -1e160,
            -1e300,
            f64::MIN,
        ];
        for y in extremes {
            let m = shifted_rayleigh_moments(y);
            assert!(
                m.mean.is_finite() && m.mean > 0.0 && m.mean >= y,
                "{y}: {m:?}"
            );
            assert!((0.0..=1.0).contains(&m.variance), "{y}: {m:?}");
        }
        assert_eq!(shifted_rayleigh_moments(f64::MAX).variance, 1.0);
        assert_eq!(shifted_rayleigh_moments(-1e300).variance, 0.0);
    }

    /// Uniform over [-1e6, 1e6], uniform near 0, and log-uniform magnitudes from 1e-8 to 1e6.
    fn wide_y() -> impl Strategy<Value = f64> {
        let log_uniform = (any::<bool>(), -8.0..6.0_f64)
            .prop_map(|(negative, e)| if negative { -1.0 } else { 1.0 } * 10f64.powf(e));
        prop_oneof![-1e6..1e6_f64, -10.0..10.0_f64, log_uniform]
    }

    proptest! {
        #[test]
        fn mean_exceeds_y_and_zero_and_variance_is_in_0_1(y in wide_y()) {
            let m = shifted_rayleigh_moments(y);
            prop_assert!(m.mean.is_finite() && m.variance.is_finite(), "{y}: {m:?}");
            prop_assert!(m.mean > y.max(0.0), "{y}: {m:?}");
            prop_assert!(m.variance > 0.0 && m.variance < 1.0, "{y}: {m:?}");
        }
    }
}
