//! The numerics of NCI (numerical choices at [`Credibility`](super::Credibility)): the Monte
//! Carlo mean-square-error matrix `Sigma`, the quadratic forms `e_i^T Sigma^+ e_i` through the
//! eigen-decomposition of `Sigma` scaled to unit diagonal, and the runs' log ratios kept as
//! products that neither overflow nor underflow.

use kalibra_linalg::nalgebra::SymmetricEigen;
use kalibra_linalg::{DMatrix, LinalgError};

use crate::MetricsError;

/// Iterations of the symmetric QR algorithm allowed per dimension of `Sigma_k`. It takes two
/// or three per eigenvalue in practice (LAPACK allows 30); running out is reported, not looped
/// on.
const EIGEN_ITERATIONS_PER_DIM: usize = 60;

/// `Sigma = (1 / M) sum_i e_i e_i^T` of run-major errors, summed in run order and exactly
/// symmetric (each product is computed once).
pub(super) fn mse_matrix(errors: &[f64], dim: usize) -> DMatrix<f64> {
    let mut sigma = DMatrix::zeros(dim, dim);
    let mut runs = 0usize;
    for e in errors.chunks_exact(dim) {
        for a in 0..dim {
            for b in 0..=a {
                sigma[(a, b)] += e[a] * e[b];
            }
        }
        runs += 1;
    }
    for a in 0..dim {
        for b in 0..=a {
            let v = sigma[(a, b)] / runs as f64;
            sigma[(a, b)] = v;
            sigma[(b, a)] = v;
        }
    }
    sigma
}

/// NCI of one step and what it was computed with.
pub(super) struct Nci {
    pub(super) value: f64,
    pub(super) skipped: usize,
    pub(super) rank: usize,
}

/// NCI from run-major errors and their NEES (definitions at [`Credibility`](super::Credibility)).
pub(super) fn nci_of_step(errors: &[f64], nees: &[f64], dim: usize) -> Result<Nci, MetricsError> {
    let (quad, rank) = pinv_quad_forms(errors, dim)?;
    // sum_i [log10 q_p - log10 q_sigma] = log10(prod_i q_p / prod_i q_sigma): the products
    // are kept as a mantissa and a power of two each ([`Product`]), so a step costs two
    // logarithms instead of two per run. The products round
    // once per run, as the sum of logarithms did; only the last bits differ from it.
    let (mut p, mut sigma) = (Product::ONE, Product::ONE);
    let mut used = 0usize;
    for (&q_p, &q_sigma) in nees.iter().zip(&quad) {
        // log10(0) = -inf would swamp the mean: such a run has no credibility to measure.
        if q_p > 0.0 && q_sigma > 0.0 {
            p.mul(q_p);
            sigma.mul(q_sigma);
            used += 1;
        }
    }
    Ok(Nci {
        value: if used > 0 {
            10.0 * p.log10_ratio(&sigma) / used as f64
        } else {
            f64::NAN
        },
        skipped: nees.len() - used,
        rank,
    })
}

/// A product of positive finite numbers that neither overflows nor underflows: a mantissa in
/// `[1, 2)` and a power of two, each factor split exactly into its own and the mantissas
/// multiplied (one rounding per factor).
#[derive(Clone, Copy)]
struct Product {
    mantissa: f64,
    exponent: i64,
}

impl Product {
    const ONE: Self = Self {
        mantissa: 1.0,
        exponent: 0,
    };

    /// `x = m 2^e` with `m` in `[1, 2)`, exactly, for a positive finite `x` (subnormals
    /// included).
    fn split(x: f64) -> (f64, i64) {
        const TWO_64: f64 = 18_446_744_073_709_551_616.0;
        let (x, shift) = if x < f64::MIN_POSITIVE {
            (x * TWO_64, 64)
        } else {
            (x, 0)
        };
        let bits = x.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i64;
        let mantissa = f64::from_bits((bits & ((1u64 << 52) - 1)) | (1023u64 << 52));
        (mantissa, biased - 1023 - shift)
    }

    /// Multiplies by the positive finite `x`.
    fn mul(&mut self, x: f64) {
        let (m, e) = Self::split(x);
        let (m, carry) = Self::split(self.mantissa * m);
        self.mantissa = m;
        self.exponent += e + carry;
    }

    /// `log10(self / other)`.
    fn log10_ratio(&self, other: &Self) -> f64 {
        (self.mantissa / other.mantissa).log10()
            + (self.exponent - other.exponent) as f64 * std::f64::consts::LOG10_2
    }
}

/// `e_i^T Sigma^+ e_i` for every run, and the rank of `Sigma` kept, through the eigen-
/// decomposition of `Sigma` scaled to unit diagonal (numerical choices at [`Credibility`](super::Credibility)).
pub(super) fn pinv_quad_forms(
    errors: &[f64],
    dim: usize,
) -> Result<(Vec<f64>, usize), MetricsError> {
    let runs = errors.len() / dim;
    // Largest magnitude of each component: dividing by it keeps every product below 1, so
    // nothing overflows, and errors of any scale keep their precision.
    let mut scale = vec![0.0f64; dim];
    for e in errors.chunks_exact(dim) {
        for (s, v) in scale.iter_mut().zip(e) {
            *s = s.max(v.abs());
        }
    }
    // A component that is exactly 0 in every run has no variance to invert: it takes no part,
    // as in the pseudo-inverse (its row and column of Sigma are 0).
    let active: Vec<usize> = (0..dim).filter(|&j| scale[j] > 0.0).collect();
    let m = active.len();
    if m == 0 {
        return Ok((vec![0.0; runs], 0));
    }
    // The active components with their scales, side by side: the loops over the runs below
    // run once per run and step of a study, and read them without an index through `active`.
    let active_scale: Vec<(usize, f64)> = active.iter().map(|&j| (j, scale[j])).collect();
    let scaled = |e: &[f64], out: &mut [f64]| {
        for (o, &(j, s)) in out.iter_mut().zip(&active_scale) {
            *o = e.get(j).copied().unwrap_or(0.0) / s;
        }
    };

    // Every component active at the common small dimensions: the same arithmetic on arrays
    // of known length, cheaper than the loops over the runs below through the slices'
    // iterators (`fixed_quad_forms_equal_the_generic_ones_to_the_bit` checks the bits).
    macro_rules! sizes {
        ($($n:literal)*) => {
            match dim {
                $($n if m == $n => return fixed_quad_forms::<$n>(errors, &scale),)*
                _ => {}
            }
        };
    }
    sizes!(1 2 3 4 5 6);

    // G = (1 / M) sum g g^T of the scaled errors; its diagonal is at least 1 / M, since one
    // run reaches magnitude 1 in each active component. Its lower triangle row by row, in a
    // plain slice (`m (m + 1) / 2` sums per run).
    let mut g = vec![0.0f64; m * (m + 1) / 2];
    let mut buf = vec![0.0; m];
    for e in errors.chunks_exact(dim) {
        scaled(e, &mut buf);
        let mut at = g.iter_mut();
        for (a, &ba) in buf.iter().enumerate() {
            // `buf` first: `zip` stops on it without taking a sum of the next row.
            for (&bb, sum) in buf[..=a].iter().zip(at.by_ref()) {
                *sum += ba * bb;
            }
        }
    }
    let (d, vectors, values) = kept_eigen(&g, m, runs, dim)?;
    let mut quad = Vec::with_capacity(runs);
    for e in errors.chunks_exact(dim) {
        scaled(e, &mut buf);
        for (f, dj) in buf.iter_mut().zip(&d) {
            *f /= dj;
        }
        // A sum of squares over positive eigenvalues: never negative, 0 only for a zero error
        // (or one entirely along directions counted as null).
        let q: f64 = vectors
            .chunks_exact(m)
            .zip(&values)
            .map(|(v, lambda)| {
                let proj: f64 = v.iter().zip(&buf).map(|(v, f)| v * f).sum();
                proj * proj / lambda
            })
            .sum();
        quad.push(q);
    }
    Ok((quad, values.len()))
}

/// [`pinv_quad_forms`] at dimension `N` with every component active: the same operations in
/// the same order on arrays (a sum that starts from `0.0` rather than `-0.0` differs only in
/// the sign of a zero, which squaring removes), so the values are the same to the bit (a test
/// compares the two).
fn fixed_quad_forms<const N: usize>(
    errors: &[f64],
    scale: &[f64],
) -> Result<(Vec<f64>, usize), MetricsError> {
    let runs = errors.len() / N;
    let s: [f64; N] = std::array::from_fn(|j| scale[j]);
    let scaled = |e: &[f64]| -> [f64; N] { std::array::from_fn(|j| e[j] / s[j]) };
    let mut g = vec![0.0f64; N * (N + 1) / 2];
    for e in errors.chunks_exact(N) {
        let buf = scaled(e);
        let mut at = 0;
        for a in 0..N {
            for b in 0..=a {
                g[at] += buf[a] * buf[b];
                at += 1;
            }
        }
    }
    let (d, vectors, values) = kept_eigen(&g, N, runs, N)?;
    let d: [f64; N] = std::array::from_fn(|j| d[j]);
    let mut v = [[0.0f64; N]; N];
    for (row, column) in v.iter_mut().zip(vectors.chunks_exact(N)) {
        row.copy_from_slice(column);
    }
    let kept = values.len();
    let mut quad = Vec::with_capacity(runs);
    for e in errors.chunks_exact(N) {
        let mut buf = scaled(e);
        for (f, dj) in buf.iter_mut().zip(&d) {
            *f /= dj;
        }
        let mut q = 0.0;
        for (vk, lambda) in v[..kept].iter().zip(&values) {
            let mut proj = 0.0;
            for (a, f) in vk.iter().zip(&buf) {
                proj += a * f;
            }
            q += proj * proj / lambda;
        }
        quad.push(q);
    }
    Ok((quad, kept))
}

/// The scales `d` of `G` (its diagonal's square roots), and the eigenvectors (one after the
/// other, `m` values each) and eigenvalues kept of `G` scaled to unit diagonal, from the lower
/// triangle `g` (row by row) of `M G` over `runs` runs.
#[allow(clippy::type_complexity)]
fn kept_eigen(
    g: &[f64],
    m: usize,
    runs: usize,
    dim: usize,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>), MetricsError> {
    let lower = |a: usize, b: usize| g[a * (a + 1) / 2 + b];
    let d: Vec<f64> = (0..m).map(|a| (lower(a, a) / runs as f64).sqrt()).collect();
    let mut corr = DMatrix::zeros(m, m);
    for a in 0..m {
        for b in 0..=a {
            let v = lower(a, b) / runs as f64 / (d[a] * d[b]);
            corr[(a, b)] = v;
            corr[(b, a)] = v;
        }
    }

    let iterations = EIGEN_ITERATIONS_PER_DIM * m;
    let eig = SymmetricEigen::try_new(corr, f64::EPSILON, iterations).ok_or(
        LinalgError::NotConvergent {
            what: "eigen-decomposition of the mean-square-error matrix",
            iterations,
        },
    )?;
    let lambda_max = eig.eigenvalues.max();
    let tol = dim as f64 * f64::EPSILON * lambda_max;
    // Eigenvalues at or below the tolerance (including rounding-negative ones) count as 0.
    let kept: Vec<usize> = (0..m).filter(|&j| eig.eigenvalues[j] > tol).collect();

    // The kept eigenvectors one after the other, with their eigenvalues: plain slices for the
    // loop over the runs (a column view of the matrix cost more than its arithmetic).
    let vectors: Vec<f64> = kept
        .iter()
        .flat_map(|&j| {
            eig.eigenvectors
                .column(j)
                .iter()
                .copied()
                .collect::<Vec<_>>()
        })
        .collect();
    let values: Vec<f64> = kept.iter().map(|&j| eig.eigenvalues[j]).collect();
    Ok((d, vectors, values))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        StandardNormal.sample(rng)
    }

    /// The generic path of `pinv_quad_forms`, forced (the fixed sizes take every dimension
    /// up to 6): one extra component that is 0 in every run takes no part in it.
    fn generic_quad_forms(errors: &[f64], dim: usize) -> (Vec<f64>, usize) {
        let padded: Vec<f64> = errors
            .chunks_exact(dim)
            .flat_map(|e| e.iter().copied().chain([0.0]))
            .collect();
        pinv_quad_forms(&padded, dim + 1).unwrap()
    }

    #[test]
    fn fixed_quad_forms_equal_the_generic_ones_to_the_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for dim in 1..=6 {
            for rank in [dim, 1.max(dim - 1)] {
                // Errors of mixed scales in a subspace of dimension `rank`.
                let runs = 57;
                let mix: Vec<f64> = (0..dim * rank).map(|_| normal(&mut rng)).collect();
                let mut errors = Vec::new();
                for _ in 0..runs {
                    let z: Vec<f64> = (0..rank).map(|_| normal(&mut rng)).collect();
                    for i in 0..dim {
                        let v: f64 = (0..rank).map(|j| mix[i * rank + j] * z[j]).sum();
                        errors.push(v * 10f64.powi(i as i32 - 2));
                    }
                }
                let fixed = pinv_quad_forms(&errors, dim).unwrap();
                let generic = generic_quad_forms(&errors, dim);
                assert_eq!(fixed.1, generic.1, "dim {dim} rank {rank}");
                assert_eq!(fixed.1, rank, "dim {dim}");
                let bits = |q: &[f64]| q.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fixed.0), bits(&generic.0), "dim {dim} rank {rank}");
            }
        }
    }

    #[test]
    fn products_keep_the_sum_of_logarithms_over_every_scale() {
        // Factors from subnormal to near f64::MAX, whose plain product would underflow or
        // overflow many times over: log10 of the product against the sum of log10s.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (mut p, mut one) = (Product::ONE, Product::ONE);
        let mut sum = 0.0;
        for i in 0..3000 {
            let x = match i % 5 {
                0 => 5e-324 * (1.0 + (i % 7) as f64),
                1 => 1.7e308 / (1.0 + (i % 3) as f64),
                _ => (8.0 * normal(&mut rng)).exp(),
            };
            p.mul(x);
            sum += x.log10();
        }
        one.mul(1.0);
        let got = p.log10_ratio(&one);
        assert!((got - sum).abs() <= 1e-12 * sum.abs(), "{got} vs {sum}");
        // Exact powers of two stay exact.
        let mut q = Product::ONE;
        for x in [0.5, 8.0, 2f64.powi(-1070), 2f64.powi(1000)] {
            q.mul(x);
        }
        assert_eq!((q.mantissa, q.exponent), (1.0, -1 + 3 - 1070 + 1000));
    }
}
