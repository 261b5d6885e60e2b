//! Whiteness of a filter's normalised innovations along one run: the sample autocorrelation at
//! lags `1..=L` with its band (Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2, the test a user
//! with a real log and no truth can run), and the Box-Pierce portmanteau statistic over all
//! lags.
//!
//! # Notation
//! `nu_k` the innovation at step `k`, `S_k = L_k L_k^T` its covariance (Cholesky), and
//! `w_k = L_k^-1 nu_k` the normalised innovation ([`normalized_innovation`]): for a consistent
//! filter the `w_k` are independent standard normal `m`-vectors. Over the pairs of steps
//! `(k, k + l)` at which both are present (`N_l` pairs),
//!
//! ```text
//! rho(l) = sum_k w_k^T w_{k+l} / sqrt( sum_k w_k^T w_k  sum_k w_{k+l}^T w_{k+l} )
//! ```
//!
//! (Bar-Shalom et al. eq. 5.4.2-10, there with scalar innovations). For white `w`, the
//! numerator has mean 0 and variance `N_l m`, the denominator is about `N_l m`, so `rho(l)` is
//! approximately normal with mean 0 and variance `1 / (N_l m)`: the two-sided band at
//! confidence `c` is `+- z_{(1+c)/2} / sqrt(N_l m)`. The Box-Pierce statistic
//! `Q = sum_l N_l m rho(l)^2` is then approximately chi-square with `L` degrees of freedom,
//! one test for all lags together (the per-lag bands, taken together, reject a white sequence
//! at some lag far more often than `1 - c`).

use kalibra_linalg::{Alloc, Covariance, DefaultAllocator, Dim, OVector, check_finite};
use statrs::distribution::{ContinuousCDF, Normal};
use statrs::function::gamma::gamma_ur;

use crate::MetricsError;

/// The normalised innovation `w = L^-1 nu`, `S = L L^T` (Cholesky, as held by `s`): a standard
/// normal vector for a consistent filter, with `w^T w` the NIS.
///
/// ```
/// use kalibra_linalg::{Covariance, Matrix2, Vector2};
/// let s = Covariance::new(Matrix2::new(4.0, 0.0, 0.0, 9.0))?;
/// let w = kalibra_metrics::normalized_innovation(&Vector2::new(2.0, -3.0), &s)?;
/// assert_eq!(w, Vector2::new(1.0, -1.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`MetricsError::Linalg`] if the innovation or the normalised innovation is not finite, or
/// (`Dyn`) its size differs from `S`'s.
pub fn normalized_innovation<M: Dim>(
    innovation: &OVector<f64, M>,
    s: &Covariance<M>,
) -> Result<OVector<f64, M>, MetricsError>
where
    DefaultAllocator: Alloc<M>,
{
    kalibra_linalg::check_dim(s.dim(), innovation.nrows(), "innovation")?;
    check_finite(innovation, "innovation")?;
    let mut w = innovation.clone_owned();
    s.cholesky()
        .l_dirty()
        .solve_lower_triangular_unchecked_mut(&mut w);
    // An innovation near f64::MAX against a variance below 1 (`tests/extreme_floats.rs`).
    check_finite(&w, "normalised innovation (beyond f64's range)")?;
    Ok(w)
}

/// The autocorrelation of the normalised innovations at one lag (see the module notation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagCorrelation {
    /// The lag `l` in steps.
    pub lag: usize,
    /// `rho(l)`.
    pub autocorrelation: f64,
    /// `N_l`, the pairs of present steps `l` apart.
    pub pairs: usize,
    /// The half-width of the band, `z_{(1+c)/2} / sqrt(N_l m)`.
    pub bound: f64,
}

impl LagCorrelation {
    /// Whether `|rho(l)|` lies inside the band (bound included).
    pub fn inside(&self) -> bool {
        self.autocorrelation.abs() <= self.bound
    }
}

/// The whiteness test of one run's normalised innovations ([`whiteness`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Whiteness {
    /// One entry per lag `1..=L`.
    pub lags: Vec<LagCorrelation>,
    /// The confidence of the bands and of the portmanteau test.
    pub confidence: f64,
    /// The Box-Pierce statistic `Q = sum_l N_l m rho(l)^2`.
    pub box_pierce: f64,
    /// Its p-value against chi-square with `L` degrees of freedom.
    pub p_value: f64,
}

impl Whiteness {
    /// The fraction of lags whose autocorrelation lies inside its band.
    pub fn fraction_inside(&self) -> f64 {
        self.lags.iter().filter(|l| l.inside()).count() as f64 / self.lags.len() as f64
    }

    /// Whether the portmanteau test accepts whiteness at the confidence given
    /// (`p_value >= 1 - confidence`).
    pub fn white(&self) -> bool {
        self.p_value >= 1.0 - self.confidence
    }
}

/// The sample autocorrelation of normalised innovations `w_k` ([`normalized_innovation`]) at
/// lags `1..=lags`, each with its band at `confidence`, and the Box-Pierce test over them
/// (definitions in the module documentation). `None` marks a step without an innovation; only
/// pairs of present steps count.
///
/// ```
/// use kalibra_linalg::Vector1;
/// // An alternating sequence is as far from white as can be at lag 1.
/// let w: Vec<_> = (0..40).map(|k| Some(Vector1::new(if k % 2 == 0 { 1.0 } else { -1.0 }))).collect();
/// let t = kalibra_metrics::whiteness(&w, 2, 0.95)?;
/// assert!((t.lags[0].autocorrelation + 1.0).abs() < 1e-12 && !t.lags[0].inside());
/// assert!(!t.white());
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::InvalidParameter`] for `lags == 0` or a confidence outside (0, 1) or so
/// close to 1 that `(1 + confidence) / 2` rounds to 1;
/// [`MetricsError::TooFewSamples`] if some lag has fewer than 2 pairs;
/// [`MetricsError::Linalg`] if a vector is not finite or differs in size from the first;
/// [`MetricsError::Degenerate`] if the innovations of some lag's pairs are all zero.
pub fn whiteness<M: Dim>(
    normalized: &[Option<OVector<f64, M>>],
    lags: usize,
    confidence: f64,
) -> Result<Whiteness, MetricsError>
where
    DefaultAllocator: Alloc<M>,
{
    if lags == 0 {
        return Err(MetricsError::InvalidParameter {
            name: "lags",
            value: 0.0,
        });
    }
    // `(1 + c) / 2` must stay below 1: at 1 (a confidence within 2^-53 of 1) the normal
    // quantile, and with it every bound, is infinite.
    if !(confidence > 0.0 && 0.5 + confidence / 2.0 < 1.0) {
        return Err(MetricsError::InvalidParameter {
            name: "confidence",
            value: confidence,
        });
    }
    let mut m = None;
    for w in normalized.iter().flatten() {
        check_finite(w, "normalised innovation")?;
        let first = *m.get_or_insert(w.nrows());
        kalibra_linalg::check_dim(first, w.nrows(), "normalised innovation")?;
    }
    let m = m.unwrap_or(0).max(1) as f64;
    // The autocorrelations are scale-free: innovations near the ends of f64's range are
    // scaled by a power of two (exact) so that their products neither overflow nor underflow
    // (`tests/extreme_floats.rs`); ordinary ones are used as they are.
    let largest = normalized
        .iter()
        .flatten()
        .flat_map(|w| w.iter())
        .fold(0.0f64, |acc, v| acc.max(v.abs()));
    let scaled: Option<Vec<Option<OVector<f64, M>>>> = crate::scale::extreme_exponent_of(largest)
        .map(|k| {
            normalized
                .iter()
                .map(|w| w.as_ref().map(|w| w.map(|v| crate::scale::ldexp(v, -k))))
                .collect()
        });
    let normalized = scaled.as_deref().unwrap_or(normalized);
    let z = Normal::standard().inverse_cdf(0.5 + confidence / 2.0);
    // Reserved for at most as many lags as there are samples: a lag beyond them has no pair
    // (the loop stops with `TooFewSamples` there), and `usize::MAX` lags must not reserve
    // (`tests/extreme_sizes.rs`).
    let mut out = Vec::with_capacity(lags.min(normalized.len()));
    let mut q = 0.0;
    for lag in 1..=lags {
        let (mut cross, mut head, mut tail, mut pairs) = (0.0, 0.0, 0.0, 0usize);
        for (a, b) in normalized.iter().zip(normalized.iter().skip(lag)) {
            if let (Some(a), Some(b)) = (a, b) {
                cross += a.dot(b);
                head += a.norm_squared();
                tail += b.norm_squared();
                pairs += 1;
            }
        }
        if pairs < 2 {
            return Err(MetricsError::TooFewSamples {
                what: "innovation autocorrelation at the largest lag",
                needed: 2,
                got: pairs,
            });
        }
        // `sqrt(head tail)`; as `sqrt(head) sqrt(tail)` where the product leaves the normal
        // range (innovations beyond 1e77, or tiny ones beside the largest), which would make
        // |rho| far above 1 or 0 (`tests/extreme_floats.rs`).
        let product = head * tail;
        let denominator = if product.is_normal() {
            product.sqrt()
        } else {
            head.sqrt() * tail.sqrt()
        };
        if denominator <= 0.0 {
            return Err(MetricsError::Degenerate {
                what: "innovation autocorrelation",
                reason: "every innovation of a lag's pairs is zero",
            });
        }
        let rho = cross / denominator;
        let scale = pairs as f64 * m;
        q += scale * rho * rho;
        out.push(LagCorrelation {
            lag,
            autocorrelation: rho,
            pairs,
            bound: z / scale.sqrt(),
        });
    }
    Ok(Whiteness {
        lags: out,
        confidence,
        box_pierce: q,
        // The chi-square survival function, computed directly (see `hypothesis`). statrs
        // panics at `x = 0`, which uncorrelated innovations reach (`Q = 0`, every
        // autocorrelation exactly 0, or `Q / 2` below the smallest subnormal:
        // `tests/extreme_floats.rs`), where the survival is 1.
        p_value: match q / 2.0 {
            x if x > 0.0 && x.is_finite() => gamma_ur(lags as f64 / 2.0, x),
            x if x > 0.0 => 0.0,
            _ => 1.0,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::{DVector, Vector2};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// The textbook formula written out on plain arrays, as independent of the code above as
    /// possible: indices instead of iterators, scalar sums component by component.
    fn reference(w: &[Option<[f64; 2]>], lag: usize) -> (f64, usize) {
        let (mut c, mut h, mut t, mut n) = (0.0, 0.0, 0.0, 0);
        for k in 0..w.len() - lag {
            if let (Some(a), Some(b)) = (w[k], w[k + lag]) {
                for i in 0..2 {
                    c += a[i] * b[i];
                    h += a[i] * a[i];
                    t += b[i] * b[i];
                }
                n += 1;
            }
        }
        (c / (h.sqrt() * t.sqrt()), n)
    }

    fn white(len: usize, seed: u64) -> Vec<Option<[f64; 2]>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..len)
            .map(|k| {
                let v = [
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                ];
                (k % 7 != 3).then_some(v)
            })
            .collect()
    }

    fn to_vectors(w: &[Option<[f64; 2]>]) -> Vec<Option<Vector2<f64>>> {
        w.iter().map(|v| v.map(Vector2::from)).collect()
    }

    #[test]
    fn matches_the_formula_written_out_with_gaps() {
        let w = white(200, 1);
        let t = whiteness(&to_vectors(&w), 5, 0.95).unwrap();
        for l in &t.lags {
            let (rho, pairs) = reference(&w, l.lag);
            assert!((l.autocorrelation - rho).abs() < 1e-14, "lag {}", l.lag);
            assert_eq!(l.pairs, pairs);
            assert!((l.bound - 1.959963984540054 / (2.0 * pairs as f64).sqrt()).abs() < 1e-12);
        }
        let q: f64 = t
            .lags
            .iter()
            .map(|l| 2.0 * l.pairs as f64 * l.autocorrelation.powi(2))
            .sum();
        assert!((t.box_pierce - q).abs() < 1e-12);
    }

    #[test]
    fn p_value_is_the_chi_square_survival_function() {
        // chi-square(2) survival is exp(-q/2).
        let w = white(300, 2);
        let t = whiteness(&to_vectors(&w), 2, 0.95).unwrap();
        assert!((t.p_value - (-t.box_pierce / 2.0).exp()).abs() < 1e-14);
    }

    #[test]
    fn white_noise_passes_and_correlated_noise_fails() {
        // Portmanteau false alarms over 100 seeds: about 5 expected; 12 or more has probability
        // below 0.1% for independent seeds.
        let rejected = (0..100)
            .filter(|&s| {
                !whiteness(&to_vectors(&white(500, s)), 10, 0.95)
                    .unwrap()
                    .white()
            })
            .count();
        assert!(rejected < 12, "{rejected} of 100 white series rejected");
        // AR(1) with coefficient 0.5: rho(1) about 0.5, far outside +-0.06.
        let w = white(500, 3);
        let mut prev = [0.0, 0.0];
        let ar: Vec<_> = w
            .iter()
            .map(|v| {
                let v = v.unwrap_or([0.0, 0.0]);
                prev = [0.5 * prev[0] + v[0], 0.5 * prev[1] + v[1]];
                Some(prev)
            })
            .collect();
        let t = whiteness(&to_vectors(&ar), 10, 0.95).unwrap();
        assert!(!t.lags[0].inside() && !t.white());
    }

    #[test]
    fn normalised_innovation_gives_the_nis() {
        let s = Covariance::new(kalibra_linalg::Matrix2::new(4.0, 1.0, 1.0, 3.0)).unwrap();
        let nu = Vector2::new(1.5, -2.0);
        let w = normalized_innovation(&nu, &s).unwrap();
        assert!((w.norm_squared() - crate::nis(&nu, &s).unwrap()).abs() < 1e-14);
    }

    #[test]
    fn errors_are_typed() {
        let w: Vec<Option<DVector<f64>>> = vec![Some(DVector::from_element(1, 1.0)); 3];
        assert!(matches!(
            whiteness(&w, 0, 0.95),
            Err(MetricsError::InvalidParameter { name: "lags", .. })
        ));
        assert!(matches!(
            whiteness(&w, 2, 0.95),
            Err(MetricsError::TooFewSamples { got: 1, .. })
        ));
        let mut bad = w.clone();
        bad[1] = Some(DVector::from_element(2, 1.0));
        assert!(matches!(
            whiteness(&bad, 1, 0.95),
            Err(MetricsError::Linalg(_))
        ));
    }
}
