//! The M-step of EM for one covariance in its form: the maximiser of
//! `-c/2 (ln det X + tr(X^-1 S))` over the matrices `X` the form allows, where `S` is the
//! smoother's statistic divided by its count `c`.
//!
//! # Derivations (Shumway and Stoffer 1982; Shumway and Stoffer, *Time Series Analysis*, 6.3)
//! The expected complete-data log-likelihood of `x_k = F x_{k-1} + G u_k`, `u_k ~ N(0, Qw)`,
//! `z_k = H x_k + v_k`, `v_k ~ N(0, R)`, given the measurements and the current parameters,
//! has one term in `Qw` and one in `R`, each of the shape
//! `-c/2 (ln det X + tr(X^-1 S))`:
//! * `R`: `c` the number of steps with a measurement, `S = 1/c sum_k E[(z_k - H x_k)(.)^T]`
//!   `= 1/c sum_k (z_k - H x_{k|n})(.)^T + H P_{k|n} H^T` over those steps.
//! * `Q = G Qw G^T`: `c` the number of transitions, `S_Q = 1/c sum_k E[e_k e_k^T]` with
//!   `e_k = x_k - F x_{k-1}`, i.e. `(x_{k|n} - F x_{k-1|n})(.)^T + P_{k|n} + F P_{k-1|n} F^T
//!   - P_{k,k-1|n} F^T - F P_{k,k-1|n}^T` (pykalman's `_em_transition_covariance`).
//!   With `G` of full column rank `g` (n x g), the increment is `e_k = G u_k`: it lies in the
//!   range of `G` (a constraint that does not involve `Qw`) and `u_k = G^+ e_k` with
//!   `G^+ = (G^T G)^-1 G^T`, since `G^+ G = I_g`. The transition density is that of `u_k`,
//!   `N(0, Qw)`, on the range of `G`, so the term is the same shape in `Qw` with
//!   `S = G^+ S_Q G^+T` (`E[u u^T] = G^+ E[e e^T] G^+T`). Without `G`, `G = I` and
//!   `S = S_Q`.
//!
//! The maximiser for each form:
//! * **full** (any symmetric positive-definite `X`): `X = S` (the derivative
//!   `-c/2 (X^-1 - X^-1 S X^-1)` vanishes there; pykalman's M-step).
//! * **diagonal** `X = diag(d)`: `tr(X^-1 S) = sum_i S_ii / d_i`, so the objective separates
//!   into `-c/2 (ln d_i + S_ii / d_i)`, maximised at `d_i = S_ii`: the diagonal of the
//!   unconstrained statistic. A fixed diagonal entry leaves the others' maximisers unchanged
//!   (the objective separates), so diagonal forms with fixed entries are supported.
//! * **scaled** `X = q N` with a nominal `N` of rank `r`: on the range of `N` the density is
//!   `-c/2 (r ln q + tr(N^+ S) / q) + const`, maximised at `q = tr(N^+ S) / r`
//!   (`tr(N^-1 S) / g` for a positive-definite `N`).
//! * **fixed**: unchanged.
//! * **full with fixed entries**: the maximiser has no closed form (a constrained covariance
//!   estimate, solved iteratively); EM refuses it with a typed error rather than zeroing
//!   entries of the unconstrained one, which would not maximise the expected log-likelihood
//!   and could break EM's monotonicity.

use kalibra_linalg::DMatrix;

use super::EmError;

/// Eigenvalues of a nominal matrix below this fraction of its largest are taken as zero
/// (its rank and pseudo-inverse in the scaled form's M-step).
pub(crate) const RANK_TOLERANCE: f64 = 1e-12;

/// The M-step's structure for one covariance: what EM may change.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Structure {
    /// The matrix stays as given.
    Fixed,
    /// A non-negative multiple of the nominal matrix.
    Scaled {
        /// The nominal matrix `N`.
        nominal: DMatrix<f64>,
    },
    /// A diagonal matrix; `fixed[i]` holds a diagonal entry that stays as given.
    Diagonal {
        /// One `Option` per diagonal entry.
        fixed: Vec<Option<f64>>,
    },
    /// Any symmetric positive-definite matrix; `fixed` holds entries `(i, j, value)` that
    /// stay as given (EM supports none: see the module docs).
    Full {
        /// The fixed entries, each once (either triangle).
        fixed: Vec<(usize, usize, f64)>,
    },
}

/// The maximiser of `-c/2 (ln det X + tr(X^-1 S))` over `structure`, given the statistic
/// `s` (already divided by its count) and the current matrix (kept by [`Structure::Fixed`]).
///
/// # Errors
/// [`EmError::Unsupported`] for a scaled form whose nominal matrix is zero, and for a full
/// form with fixed entries.
pub(crate) fn maximise(
    structure: &Structure,
    s: &DMatrix<f64>,
    current: &DMatrix<f64>,
    what: &'static str,
) -> Result<DMatrix<f64>, EmError> {
    Ok(match structure {
        Structure::Fixed => current.clone(),
        Structure::Full { fixed } if fixed.is_empty() => (s + s.transpose()) * 0.5,
        Structure::Full { .. } => {
            return Err(EmError::Unsupported {
                what,
                reason: "a full form with fixed entries has no closed-form M-step; \
                         use maximum likelihood, or a diagonal or fixed form",
            });
        }
        Structure::Diagonal { fixed } => {
            DMatrix::from_fn(s.nrows(), s.ncols(), |i, j| match (i == j, fixed.get(i)) {
                (false, _) => 0.0,
                (true, Some(Some(value))) => *value,
                (true, _) => s[(i, i)],
            })
        }
        Structure::Scaled { nominal } => nominal * scale(nominal, s, what)?,
    })
}

/// `q = tr(N^+ S) / rank(N)`, the scaled form's maximiser, with `N^+` from the symmetric
/// eigen-decomposition of `N` (eigenvalues at or below [`RANK_TOLERANCE`] of the largest
/// dropped).
///
/// # Errors
/// [`EmError::Unsupported`] when `N` has rank 0.
pub(crate) fn scale(
    nominal: &DMatrix<f64>,
    s: &DMatrix<f64>,
    what: &'static str,
) -> Result<f64, EmError> {
    let eigen = nominal.clone().symmetric_eigen();
    let largest = eigen.eigenvalues.amax();
    let mut trace = 0.0;
    let mut rank = 0usize;
    for (k, &lambda) in eigen.eigenvalues.iter().enumerate() {
        if lambda > RANK_TOLERANCE * largest {
            let v = eigen.eigenvectors.column(k);
            trace += (v.transpose() * s * v)[(0, 0)] / lambda;
            rank += 1;
        }
    }
    if rank == 0 {
        return Err(EmError::Unsupported {
            what,
            reason: "a scaled form with a zero nominal matrix has no multiplier to estimate",
        });
    }
    Ok(trace / rank as f64)
}

/// The left pseudo-inverse `G^+ = (G^T G)^-1 G^T` of a noise-input matrix of full column rank.
///
/// # Errors
/// [`EmError::Unsupported`] when `G^T G` has no Cholesky factor (`G` is not of full column
/// rank: `Qw` is then not determined by `Q`).
pub(crate) fn left_pseudo_inverse(g: &DMatrix<f64>) -> Result<DMatrix<f64>, EmError> {
    let gram = g.transpose() * g;
    let chol = gram.cholesky().ok_or(EmError::Unsupported {
        what: "noise input matrix G",
        reason: "G must have full column rank for EM (Qw = G^+ S G^+T)",
    })?;
    Ok(chol.solve(&g.transpose()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The objective `ln det X + tr(X^-1 S)` (to be minimised).
    fn objective(x: &DMatrix<f64>, s: &DMatrix<f64>) -> f64 {
        let chol = x.clone().cholesky().unwrap();
        2.0 * chol.l().diagonal().map(f64::ln).sum() + (chol.inverse() * s).trace()
    }

    fn statistic() -> DMatrix<f64> {
        DMatrix::from_row_slice(3, 3, &[2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5])
    }

    #[test]
    fn each_form_beats_its_perturbations() {
        // Each maximiser must be at least as good as nearby members of its own family.
        let s = statistic();
        let id = DMatrix::identity(3, 3);
        let full = maximise(&Structure::Full { fixed: vec![] }, &s, &id, "Q").unwrap();
        let nominal =
            DMatrix::from_diagonal(&kalibra_linalg::DVector::from_vec(vec![1.0, 2.0, 0.5]));
        let scaled_structure = Structure::Scaled {
            nominal: nominal.clone(),
        };
        let scaled = maximise(&scaled_structure, &s, &id, "Q").unwrap();
        let diag_structure = Structure::Diagonal {
            fixed: vec![None, Some(0.7), None],
        };
        let diag = maximise(&diag_structure, &s, &id, "Q").unwrap();
        assert_eq!(diag[(1, 1)], 0.7);
        assert_eq!(diag[(0, 0)], 2.0);
        assert_eq!(diag[(0, 1)], 0.0);
        for k in 0..6 {
            let h = 1e-3 * (k as f64 - 2.5);
            let mut e = DMatrix::zeros(3, 3);
            e[(k % 3, (k + 1) % 3)] = h;
            e[((k + 1) % 3, k % 3)] = h;
            e[(k % 3, k % 3)] += h;
            assert!(objective(&full, &s) <= objective(&(&full + &e), &s));
            assert!(objective(&scaled, &s) <= objective(&(&scaled * (1.0 + h)), &s));
            let mut d = diag.clone();
            d[(2 - k % 2 * 2, 2 - k % 2 * 2)] += h;
            assert!(objective(&diag, &s) <= objective(&d, &s));
        }
    }

    #[test]
    fn scaled_form_with_a_singular_nominal_uses_its_range() {
        // N = v v^T with v = (1, 1)/sqrt 2 (rank 1): q = v^T S v.
        let nominal = DMatrix::from_element(2, 2, 0.5);
        let s = DMatrix::from_row_slice(2, 2, &[3.0, 1.0, 1.0, 5.0]);
        let q = scale(&nominal, &s, "Q").unwrap();
        assert!((q - 0.5 * (3.0 + 1.0 + 1.0 + 5.0)).abs() < 1e-12);
        assert!(scale(&DMatrix::zeros(2, 2), &s, "Q").is_err());
    }

    #[test]
    fn pseudo_inverse_recovers_the_noise_input() {
        let g = DMatrix::from_row_slice(3, 2, &[0.5, 0.0, 1.0, 0.1, 0.0, 1.0]);
        let qw = DMatrix::from_row_slice(2, 2, &[0.3, 0.05, 0.05, 0.2]);
        let q = &g * &qw * g.transpose();
        let pinv = left_pseudo_inverse(&g).unwrap();
        assert!((&pinv * q * pinv.transpose() - qw).amax() < 1e-14);
        let rank_one = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
        assert!(left_pseudo_inverse(&rank_one).is_err());
    }
}
