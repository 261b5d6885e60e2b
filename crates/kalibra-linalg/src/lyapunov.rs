//! The discrete Lyapunov equation `X = A X A^T + Q`.

use nalgebra::{DefaultAllocator, Dim, OMatrix};

use crate::{
    Alloc, Definiteness, LinalgError, check_covariance, check_dim, check_finite, product,
    propagate, symmetrize,
};

/// Most doublings [`discrete_lyapunov`] runs: `2^64` terms of the series, far beyond any
/// spectral radius that is below 1 in floating point.
pub const LYAPUNOV_MAX_DOUBLINGS: usize = 64;

/// Solves the discrete Lyapunov equation `X = A X A^T + Q` for the stationary covariance of
/// `x_{k+1} = A x_k + w_k`, `w_k ~ N(0, Q)`.
///
/// # Method
/// Smith's doubling iteration: `X_0 = Q`, `A_0 = A`, `X_{j+1} = X_j + A_j X_j A_j^T`,
/// `A_{j+1} = A_j^2`, so `X_j` sums the first `2^j` terms of `sum_i A^i Q (A^i)^T`. It converges
/// quadratically when the spectral radius of `A` is below 1 and needs only products, no
/// eigen-decomposition, so it works for any `Dim`. It stops when an increment is below
/// `2^-52` of `X` in the Frobenius norm; each `X_j` is symmetrised.
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] if `A` and `Q` differ in size or are not square,
/// [`LinalgError::NonFinite`] for non-finite input, [`LinalgError::NotSymmetric`] or
/// [`LinalgError::NotPositiveSemiDefinite`] for a `Q` that is not a covariance (the check of
/// [`check_covariance`](crate::check_covariance)), and [`LinalgError::NotConvergent`] when the series does not converge in
/// [`LYAPUNOV_MAX_DOUBLINGS`] doublings (a spectral radius of 1 or more on a direction `Q`
/// excites: the stationary covariance is unbounded).
///
/// ```
/// use kalibra_linalg::{discrete_lyapunov, Matrix1};
/// // Scalar AR(1): x' = a x + w, var(w) = q, stationary variance q / (1 - a^2).
/// let x = discrete_lyapunov(&Matrix1::new(0.9), &Matrix1::new(1.0))?;
/// assert!((x[(0, 0)] - 1.0 / (1.0 - 0.81)).abs() < 1e-12);
/// assert!(discrete_lyapunov(&Matrix1::new(1.0), &Matrix1::new(1.0)).is_err());
/// # Ok::<(), kalibra_linalg::LinalgError>(())
/// ```
pub fn discrete_lyapunov<N: Dim>(
    a: &OMatrix<f64, N, N>,
    q: &OMatrix<f64, N, N>,
) -> Result<OMatrix<f64, N, N>, LinalgError>
where
    DefaultAllocator: Alloc<N>,
{
    check_dim(a.nrows(), a.ncols(), "Lyapunov matrix A")?;
    check_dim(a.nrows(), q.nrows(), "Lyapunov noise Q")?;
    check_dim(a.nrows(), q.ncols(), "Lyapunov noise Q")?;
    check_finite(a, "Lyapunov matrix A")?;
    check_covariance(q, "Lyapunov noise Q", Definiteness::SemiDefinite)?;
    let mut x = q.clone();
    let mut power = a.clone();
    for _ in 0..LYAPUNOV_MAX_DOUBLINGS {
        let increment = propagate(&power, &x);
        let (inc, total) = (increment.norm(), x.norm());
        if !(inc.is_finite() && total.is_finite()) {
            break;
        }
        x += increment;
        symmetrize(&mut x);
        if inc <= f64::EPSILON * total {
            return Ok(x);
        }
        power = product(&power, &power);
    }
    Err(LinalgError::NotConvergent {
        what: "discrete Lyapunov doubling",
        iterations: LYAPUNOV_MAX_DOUBLINGS,
    })
}

/// Most squarings [`spectral_radius`] runs.
pub const SPECTRAL_MAX_SQUARINGS: usize = 60;

/// `|m|_F` without underflow: entries at most 1 in magnitude (the iteration's), the largest
/// divided out first when it is small enough for squares to underflow.
fn frobenius_norm<N: Dim>(m: &OMatrix<f64, N, N>) -> f64
where
    DefaultAllocator: Alloc<N>,
{
    let big = m.amax();
    if big == 0.0 || big >= 1e-100 {
        return m.norm();
    }
    big * (m / big).norm()
}

/// The spectral radius `rho(A)` (largest eigenvalue modulus) of a square matrix, by Gelfand's
/// formula `rho = lim |A^k|^(1/k)` along `k = 2^j`: repeated squaring with the norm divided
/// out at every step (so nothing overflows) and its logarithm accumulated.
///
/// Products only, so it works for any `Dim` and any (non-symmetric, defective) matrix. The
/// estimates approach `rho` from above; a Jordan block of size `m` adds a relative bias of
/// about `m ln(2^j) / 2^j`, below `1e-13` after the iterations run. It stops when an estimate
/// changes by less than `4 eps` relative.
///
/// # Scale
/// Right across f64's range, subnormal entries to 1e308: `A` is first scaled by the power of
/// two that brings its largest entry into `[1, 2)` (exact), the Frobenius norm in the
/// iteration is taken with the largest entry divided out where a sum of squares could
/// underflow, and the result is scaled back. (The Frobenius norm, not the largest entry, for
/// the estimates: `|B^2| = |B|^2` holds for it only when `B` is rank one, where the estimate
/// is exact, while the largest entry of `B^2` can equal the square of `B`'s by coincidence and
/// stop the iteration at a wrong value.) So `spectral_radius(2^p A) == 2^p spectral_radius(A)` to the bit wherever the result
/// is a normal number. (Before, `1e308 I`, `1e-308 I` and subnormal matrices gave 0.)
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] for a non-square `A`, [`LinalgError::NonFinite`] for
/// non-finite entries, and for a spectral radius beyond f64's range (up to `n` times the
/// largest entry: `2e308` for a 2 x 2 matrix of `1e308`s).
///
/// ```
/// use kalibra_linalg::{spectral_radius, Matrix2};
/// // Eigenvalues 0.5 and -0.9, far from normal.
/// let a = Matrix2::new(0.5, 100.0, 0.0, -0.9);
/// assert!((spectral_radius(&a)? - 0.9).abs() < 1e-12);
/// assert!((spectral_radius(&(Matrix2::identity() * 1e-310))? / 1e-310 - 1.0).abs() < 1e-12);
/// # Ok::<(), kalibra_linalg::LinalgError>(())
/// ```
pub fn spectral_radius<N: Dim>(a: &OMatrix<f64, N, N>) -> Result<f64, LinalgError>
where
    DefaultAllocator: Alloc<N>,
{
    check_dim(a.nrows(), a.ncols(), "matrix A")?;
    check_finite(a, "matrix A")?;
    // Zero matrix (or empty): rho = 0.
    let Some(exponent) = crate::binary_exponent(a.amax()) else {
        return Ok(0.0);
    };
    // m = A^(2^j) 2^-(exponent 2^j) / exp(log_scale), Frobenius norm 1 after each division.
    let mut m = a.map(|v| crate::ldexp(v, -exponent));
    let mut log_scale = 0.0_f64;
    let mut power = 1.0_f64;
    let mut estimate = f64::INFINITY;
    for _ in 0..SPECTRAL_MAX_SQUARINGS {
        let norm = frobenius_norm(&m);
        if norm == 0.0 {
            // Nilpotent: some power vanished exactly.
            return Ok(0.0);
        }
        m /= norm;
        log_scale += norm.ln();
        let next = (log_scale / power).exp();
        if (next - estimate).abs() <= 4.0 * f64::EPSILON * next {
            estimate = next;
            break;
        }
        estimate = next;
        m = product(&m, &m);
        log_scale *= 2.0;
        power *= 2.0;
    }
    let rho = crate::ldexp(estimate, exponent);
    if rho.is_finite() {
        Ok(rho)
    } else {
        Err(LinalgError::NonFinite {
            what: "spectral radius (beyond f64's range)",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, Matrix2, Matrix3};

    #[test]
    fn solves_the_equation() {
        let a = Matrix3::new(0.5, 0.2, 0.0, -0.1, 0.7, 0.3, 0.05, 0.0, 0.9);
        let q = Matrix3::new(1.0, 0.2, 0.0, 0.2, 2.0, 0.1, 0.0, 0.1, 0.5);
        let x = discrete_lyapunov(&a, &q).unwrap();
        let residual = a * x * a.transpose() + q - x;
        assert!(residual.norm() < 1e-12 * x.norm());
        // Dyn sizes run the same code.
        let xd = discrete_lyapunov(
            &DMatrix::from_column_slice(3, 3, a.as_slice()),
            &DMatrix::from_column_slice(3, 3, q.as_slice()),
        )
        .unwrap();
        assert!((xd - DMatrix::from_column_slice(3, 3, x.as_slice())).norm() < 1e-14);
    }

    #[test]
    fn a_unit_root_not_excited_is_fine_and_an_excited_one_is_an_error() {
        let a = Matrix2::new(1.0, 0.0, 0.0, 0.5);
        let x = discrete_lyapunov(&a, &Matrix2::new(0.0, 0.0, 0.0, 1.0)).unwrap();
        assert!((x[(1, 1)] - 4.0 / 3.0).abs() < 1e-12);
        assert!(matches!(
            discrete_lyapunov(&a, &Matrix2::identity()),
            Err(LinalgError::NotConvergent { .. })
        ));
    }

    #[test]
    fn spectral_radius_of_known_matrices() {
        let rotation = Matrix2::new(0.0, -0.8, 0.8, 0.0); // eigenvalues +-0.8i
        assert!((spectral_radius(&rotation).unwrap() - 0.8).abs() < 1e-13);
        let jordan = Matrix3::new(0.7, 1.0, 0.0, 0.0, 0.7, 1.0, 0.0, 0.0, 0.7);
        assert!((spectral_radius(&jordan).unwrap() - 0.7).abs() < 1e-12);
        let nilpotent = Matrix2::new(0.0, 1.0, 0.0, 0.0);
        assert_eq!(spectral_radius(&nilpotent).unwrap(), 0.0);
        assert!((spectral_radius(&Matrix2::identity()).unwrap() - 1.0).abs() < 1e-15);
        assert!(spectral_radius(&DMatrix::<f64>::zeros(2, 3)).is_err());
        // Found by the adversarial suite with the largest entry as the iteration's norm: the
        // largest entry of A^2 is the square of A's (9.89...), so the first two estimates
        // agreed and the iteration stopped at 9.89 instead of 11.595.
        let a = Matrix3::new(
            0.0,
            0.0,
            4.961929881939764,
            5.050040461752875,
            0.0,
            0.0,
            0.0,
            9.138940954463893,
            9.891819944247835,
        );
        let rho = spectral_radius(&a).unwrap();
        assert!((rho - 11.595119079207477).abs() < 1e-12, "{rho}");
    }

    /// Right from subnormal to 1e308 scales, against nalgebra's eigenvalues: `1e308 I`,
    /// `1e-308 I` and subnormal matrices must not give 0 through a Frobenius norm that
    /// overflows or underflows.
    #[test]
    fn spectral_radius_agrees_with_eigenvalues_at_every_scale() {
        use crate::ldexp;
        for seed in 0..24usize {
            let n = 1 + seed % 6;
            let a = DMatrix::from_fn(n, n, |i, j| {
                ((i * 31 + j * 17 + seed * 7919 + (i * j * seed) % 13) % 101) as f64 / 25.0 - 2.0
            });
            let want = a
                .complex_eigenvalues()
                .iter()
                .map(|z| z.norm())
                .fold(0.0, f64::max);
            let rho = spectral_radius(&a).unwrap();
            assert!(
                (rho - want).abs() <= 1e-9 * want.max(1e-300),
                "seed {seed}: {rho} vs {want}\n{a}"
            );
            // A power of two commutes with every step: the same bits, scaled.
            for p in [-1010, -900, -600, -100, 100, 600, 900, 1015] {
                let scaled = a.map(|v| ldexp(v, p));
                let want = ldexp(rho, p);
                match spectral_radius(&scaled) {
                    Ok(got) => assert_eq!(got, want, "seed {seed}, 2^{p}"),
                    Err(e) => assert!(!want.is_finite(), "seed {seed}, 2^{p}: {e}"),
                }
            }
        }
        for (scale, n) in [
            (1e308, 2),
            (1e-308, 3),
            (1e-310, 2),
            (5e-324, 4),
            (1.7e308, 1),
        ] {
            let rho = spectral_radius(&(DMatrix::<f64>::identity(n, n) * scale)).unwrap();
            assert!((rho / scale - 1.0).abs() < 1e-12, "{scale:e}: {rho:e}");
            let rotation = Matrix2::new(0.0, -scale, scale, 0.0);
            let rho = spectral_radius(&rotation).unwrap();
            assert!((rho / scale - 1.0).abs() < 1e-12, "{scale:e}: {rho:e}");
        }
        // A radius beyond f64's range is an error, not inf or 0.
        assert!(matches!(
            spectral_radius(&Matrix2::repeat(1e308)),
            Err(LinalgError::NonFinite { .. })
        ));
        assert_eq!(spectral_radius(&DMatrix::<f64>::zeros(0, 0)).unwrap(), 0.0);
        assert_eq!(spectral_radius(&Matrix2::repeat(0.0)).unwrap(), 0.0);
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let a = Matrix2::identity() * 0.5;
        assert!(discrete_lyapunov(&a, &Matrix2::new(1.0, 0.5, 0.0, 1.0)).is_err());
        assert!(discrete_lyapunov(&(a * f64::NAN), &Matrix2::identity()).is_err());
        assert!(
            discrete_lyapunov(&DMatrix::<f64>::identity(2, 2), &DMatrix::identity(3, 3)).is_err()
        );
    }

    /// An indefinite or negative noise covariance is refused, not turned into an indefinite
    /// "stationary covariance" returned as `Ok`.
    #[test]
    fn a_noise_covariance_that_is_not_one_is_refused() {
        let a = Matrix2::identity() * 0.5;
        for q in [
            Matrix2::new(1.0, 2.0, 2.0, 1.0),
            Matrix2::new(-1.0, 0.0, 0.0, 1.0),
            -Matrix2::identity(),
        ] {
            assert!(
                matches!(
                    discrete_lyapunov(&a, &q),
                    Err(LinalgError::NotPositiveSemiDefinite { .. })
                ),
                "{q}"
            );
        }
        // Rank-deficient noise is a covariance.
        assert!(discrete_lyapunov(&a, &Matrix2::new(1.0, 1.0, 1.0, 1.0)).is_ok());
    }
}
