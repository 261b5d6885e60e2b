//! Parametrised noise: what the user knows of `Q = G Qw G^T` and `R`, and the map between an
//! optimiser's unconstrained vector `theta` and the matrices.
//!
//! # Forms
//! `Qw` (the noise of the `g` channels through which noise enters; `Q` itself without `G`) and
//! `R` are each given in one [`FormKind`]:
//!
//! | form | matrix | free parameters (names) | `theta` |
//! |---|---|---|---|
//! | fixed | the given matrix | none | none |
//! | scaled | `s V` for the nominal `V` | the multiplier (`q` or `r`) | `ln s` |
//! | diagonal | `diag(d_1, ..., d_k)` | each `d_i` (`Qw[i,i]`, `R[i,i]`) | `ln d_i` |
//! | full | any SPD `L L^T` | the lower triangle (`Qw[i,j]`, `i >= j`) | log-Cholesky |
//!
//! A diagonal or full form may fix chosen entries ([`CovarianceForm::fix`]) at the given
//! matrix's values. In the full form the parameters are the entries of the Cholesky factor
//! `L` at the free positions (`ln L_ii` on the diagonal, `L_ij` below it); the factor's
//! entries at fixed positions follow from the Cholesky recurrence so that the fixed entries of
//! `L L^T` equal the given ones exactly (to rounding):
//! `L_ij = (V_ij - sum_{k<j} L_ik L_jk) / L_jj` and `L_ii = sqrt(V_ii - sum_{k<i} L_ik^2)`.
//! A candidate for which that square root has no positive argument is refused
//! ([`NoiseError::Infeasible`]): no SPD matrix with those free entries has the fixed ones.
//!
//! # Why these scales
//! Logarithms and the log-Cholesky factor make every `theta` in `R^p` a valid covariance, so
//! the optimiser needs no bounds, and positive quantities whose size is unknown by orders of
//! magnitude (the papers sweep `10^-6` to `10^6`) are searched on the scale they vary on.
//!
//! # Natural parameters
//! The estimates are reported on the matrices' own scale ([`Parameter`]): the multiplier `s`,
//! or the covariance entry `Qw[i,j]`, never `theta`. [`Parametrisation::jacobian`] gives
//! `d natural / d theta`, which carries the covariance of `theta` to theirs.

use kalibra_linalg::{
    DMatrix, DVector, Definiteness, LinalgError, binary_exponent, check_covariance, ldexp,
};
use serde::{Deserialize, Serialize};

use crate::NoiseError;

/// Which noise matrix a form or a parameter belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum NoiseMatrix {
    /// The process noise of the channels, `Qw` (`Q = G Qw G^T`; `Q` itself without `G`).
    Qw,
    /// The measurement noise `R`.
    R,
}

impl NoiseMatrix {
    /// The matrix's name: `"Qw"` or `"R"`.
    pub fn name(self) -> &'static str {
        match self {
            NoiseMatrix::Qw => "Qw",
            NoiseMatrix::R => "R",
        }
    }

    /// The name of a scaled form's multiplier: `"q"` or `"r"`.
    pub fn multiplier(self) -> &'static str {
        match self {
            NoiseMatrix::Qw => "q",
            NoiseMatrix::R => "r",
        }
    }
}

/// What is known of a noise covariance (see the module docs for the table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FormKind {
    /// The given matrix, nothing estimated.
    Fixed,
    /// A positive multiple of the given (nominal) matrix: one parameter.
    Scaled,
    /// A diagonal matrix, each diagonal entry free and positive (unless fixed).
    Diagonal,
    /// Any symmetric positive-definite matrix, by its log-Cholesky factor.
    Full,
}

/// A noise covariance's form: the [`FormKind`], the given matrix (the fixed value, the nominal
/// matrix of a scaled form, or the starting point of a diagonal or full one) and the entries
/// held at their given values. Checked when a [`Parametrisation`] is built from it.
///
/// ```
/// use kalibra_tune::{CovarianceForm, DMatrix, FormKind};
///
/// // A full 2x2 R whose correlation is known to be zero: only the variances are free.
/// let r = CovarianceForm::full(DMatrix::from_diagonal_element(2, 2, 1.0)).fix(1, 0);
/// assert_eq!(r.kind(), FormKind::Full);
/// assert!(r.is_fixed(0, 1) && !r.is_fixed(0, 0));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct CovarianceForm {
    kind: FormKind,
    value: DMatrix<f64>,
    /// Lower-triangle positions `(i, j)`, `i >= j`, held at `value`'s entries.
    fixed: Vec<(usize, usize)>,
}

impl CovarianceForm {
    /// The given matrix, nothing estimated (symmetric positive semi-definite).
    pub fn fixed(value: DMatrix<f64>) -> Self {
        Self::of(FormKind::Fixed, value)
    }

    /// A positive multiple `s V` of the nominal `V` (symmetric positive semi-definite, not
    /// zero); the estimate starts at `s = 1`.
    pub fn scaled(nominal: DMatrix<f64>) -> Self {
        Self::of(FormKind::Scaled, nominal)
    }

    /// A diagonal matrix starting at `start` (diagonal, positive on the diagonal).
    pub fn diagonal(start: DMatrix<f64>) -> Self {
        Self::of(FormKind::Diagonal, start)
    }

    /// Any symmetric positive-definite matrix, starting at `start` (positive definite).
    pub fn full(start: DMatrix<f64>) -> Self {
        Self::of(FormKind::Full, start)
    }

    fn of(kind: FormKind, value: DMatrix<f64>) -> Self {
        Self {
            kind,
            value,
            fixed: Vec::new(),
        }
    }

    /// Holds entry `(row, col)` (and its mirror `(col, row)`) at the given matrix's value.
    /// Off-diagonal entries of a diagonal form are zero and fixed already, and every entry of
    /// a fixed form is; a scaled form's entries cannot be fixed (refused when the
    /// [`Parametrisation`] is built, as is an entry outside the matrix).
    #[must_use]
    pub fn fix(mut self, row: usize, col: usize) -> Self {
        let at = (row.max(col), row.min(col));
        if !self.fixed.contains(&at) {
            self.fixed.push(at);
        }
        self
    }

    /// The form.
    pub fn kind(&self) -> FormKind {
        self.kind
    }

    /// The given matrix.
    pub fn value(&self) -> &DMatrix<f64> {
        &self.value
    }

    /// Whether entry `(row, col)` is held at its given value (always for a fixed form, and
    /// off the diagonal of a diagonal form).
    pub fn is_fixed(&self, row: usize, col: usize) -> bool {
        match self.kind {
            FormKind::Fixed => true,
            FormKind::Scaled => false,
            FormKind::Diagonal if row != col => true,
            FormKind::Diagonal | FormKind::Full => {
                self.fixed.contains(&(row.max(col), row.min(col)))
            }
        }
    }

    /// The matrix's size.
    pub fn dim(&self) -> usize {
        self.value.nrows()
    }
}

/// What a free parameter is, which decides how its interval is mapped
/// ([`Parameter::positive`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParameterKind {
    /// The multiplier `s` of a scaled form (`theta = ln s`).
    Multiplier,
    /// A diagonal entry (a variance) of a diagonal or full form.
    Variance,
    /// An off-diagonal entry (a covariance) of a full form.
    Covariance,
}

/// One free parameter on the matrices' own scale.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Parameter {
    /// `q` or `r` for a multiplier, `Qw[i,j]` or `R[i,j]` (`i >= j`) for an entry.
    pub name: String,
    /// The matrix it belongs to.
    pub matrix: NoiseMatrix,
    /// The entry `(i, j)`, `i >= j`, for an entry; `None` for a multiplier.
    pub entry: Option<(usize, usize)>,
    /// What it is.
    pub kind: ParameterKind,
}

impl Parameter {
    /// Whether the parameter is positive by construction (a multiplier or a variance), so that
    /// its interval is best mapped on the log scale.
    pub fn positive(&self) -> bool {
        self.kind != ParameterKind::Covariance
    }
}

/// The noise matrices of one candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseMatrices {
    /// The channels' process noise `Qw` (`g`x`g`).
    pub qw: DMatrix<f64>,
    /// The measurement noise `R` (`m`x`m`).
    pub r: DMatrix<f64>,
    /// The state's process noise `Q = G Qw G^T` (`n`x`n`; `Qw` itself without `G`).
    pub q: DMatrix<f64>,
}

/// A checked form with its free slots laid out.
#[derive(Clone, Debug, PartialEq)]
struct Checked {
    matrix: NoiseMatrix,
    form: CovarianceForm,
    /// The free lower-triangle positions in `theta` order (row by row); empty for scaled
    /// and fixed forms.
    slots: Vec<(usize, usize)>,
}

impl Checked {
    fn new(matrix: NoiseMatrix, form: CovarianceForm) -> Result<Self, NoiseError> {
        let name = matrix.name();
        let v = &form.value;
        let k = v.nrows();
        if k == 0 {
            return Err(NoiseError::Empty { what: name });
        }
        if v.ncols() != k {
            return Err(NoiseError::Shape {
                matrix: name,
                expected_rows: k,
                expected_cols: k,
                found_rows: k,
                found_cols: v.ncols(),
            });
        }
        let check = |definiteness| {
            check_covariance(v, name, definiteness).map_err(|source| NoiseError::Matrix {
                matrix: name,
                source,
            })
        };
        check(Definiteness::SemiDefinite)?;
        if let Some(&(row, col)) = form.fixed.iter().find(|&&(i, _)| i >= k) {
            return Err(NoiseError::FixedEntryOutOfRange {
                matrix: name,
                row,
                col,
                dim: k,
            });
        }
        let free = |i: usize, j: usize| !form.is_fixed(i, j);
        let slots: Vec<(usize, usize)> = match form.kind {
            FormKind::Fixed => Vec::new(),
            FormKind::Scaled => {
                if !form.fixed.is_empty() {
                    return Err(NoiseError::FixedEntryInScaled { matrix: name });
                }
                if v.iter().all(|&x| x == 0.0) {
                    return Err(NoiseError::ZeroNominal { matrix: name });
                }
                Vec::new()
            }
            FormKind::Diagonal => {
                for j in 0..k {
                    for i in 0..k {
                        if i != j && v[(i, j)] != 0.0 {
                            return Err(NoiseError::NotDiagonal {
                                matrix: name,
                                row: i,
                                col: j,
                                value: v[(i, j)],
                            });
                        }
                    }
                }
                let slots: Vec<_> = (0..k).filter(|&i| free(i, i)).map(|i| (i, i)).collect();
                if let Some(&(i, _)) = slots.iter().find(|&&(i, _)| v[(i, i)] <= 0.0) {
                    return Err(NoiseError::NotPositive {
                        name: entry_name(name, i, i),
                        value: v[(i, i)],
                    });
                }
                slots
            }
            FormKind::Full => {
                check(Definiteness::Definite)?;
                (0..k)
                    .flat_map(|i| (0..=i).map(move |j| (i, j)))
                    .filter(|&(i, j)| free(i, j))
                    .collect()
            }
        };
        Ok(Self {
            matrix,
            form,
            slots,
        })
    }

    /// Free parameters of this form.
    fn len(&self) -> usize {
        match self.form.kind {
            FormKind::Scaled => 1,
            _ => self.slots.len(),
        }
    }

    fn parameters(&self) -> Vec<Parameter> {
        let name = self.matrix.name();
        match self.form.kind {
            FormKind::Fixed => Vec::new(),
            FormKind::Scaled => vec![Parameter {
                name: self.matrix.multiplier().to_string(),
                matrix: self.matrix,
                entry: None,
                kind: ParameterKind::Multiplier,
            }],
            FormKind::Diagonal | FormKind::Full => self
                .slots
                .iter()
                .map(|&(i, j)| Parameter {
                    name: entry_name(name, i, j),
                    matrix: self.matrix,
                    entry: Some((i, j)),
                    kind: if i == j {
                        ParameterKind::Variance
                    } else {
                        ParameterKind::Covariance
                    },
                })
                .collect(),
        }
    }

    /// The matrix at `theta` (this form's part of the vector).
    fn matrix(&self, theta: &[f64]) -> Result<DMatrix<f64>, NoiseError> {
        let v = &self.form.value;
        match self.form.kind {
            FormKind::Fixed => Ok(v.clone()),
            FormKind::Scaled => Ok(scaled_by_exp(v, theta[0])),
            FormKind::Diagonal => {
                let mut d = v.clone();
                for (&(i, _), t) in self.slots.iter().zip(theta) {
                    d[(i, i)] = t.exp();
                }
                Ok(d)
            }
            FormKind::Full => {
                let l = self.factor(theta)?;
                let mut m = &l * l.transpose();
                // Exactly symmetric (the filters' models symmetrise within rounding anyway).
                for j in 0..m.ncols() {
                    for i in (j + 1)..m.nrows() {
                        m[(j, i)] = m[(i, j)];
                    }
                }
                Ok(m)
            }
        }
    }

    /// The full form's Cholesky factor at `theta`: free entries from `theta`, fixed ones by the
    /// Cholesky recurrence so that `L L^T` has the given value there.
    fn factor(&self, theta: &[f64]) -> Result<DMatrix<f64>, NoiseError> {
        let v = &self.form.value;
        let k = v.nrows();
        let mut l = DMatrix::<f64>::zeros(k, k);
        let mut slot = self.slots.iter().zip(theta).peekable();
        for i in 0..k {
            for j in 0..=i {
                let from_theta = match slot.peek() {
                    Some(&(&(si, sj), &t)) if (si, sj) == (i, j) => {
                        slot.next();
                        Some(t)
                    }
                    _ => None,
                };
                let dot: f64 = (0..j).map(|c| l[(i, c)] * l[(j, c)]).sum();
                l[(i, j)] = match (from_theta, i == j) {
                    (Some(t), true) => t.exp(),
                    (Some(t), false) => t,
                    (None, false) => (v[(i, j)] - dot) / l[(j, j)],
                    (None, true) => {
                        let pivot = v[(i, i)] - dot;
                        // Not `pivot <= 0.0` alone: a NaN pivot (from an overflowing
                        // candidate) is refused too.
                        if pivot.is_nan() || pivot <= 0.0 {
                            return Err(NoiseError::Infeasible {
                                matrix: self.matrix.name(),
                                index: i,
                            });
                        }
                        pivot.sqrt()
                    }
                };
            }
        }
        Ok(l)
    }

    /// The derivative of the full form's factor along this form's parameter `p`.
    fn factor_derivative(&self, l: &DMatrix<f64>, p: usize) -> DMatrix<f64> {
        let k = l.nrows();
        let target = self.slots[p];
        let mut dl = DMatrix::<f64>::zeros(k, k);
        for i in 0..k {
            for j in 0..=i {
                // `slots` is in row-major order, the order of this loop.
                let free = self.slots.binary_search(&(i, j)).is_ok();
                let ddot: f64 = (0..j)
                    .map(|c| dl[(i, c)] * l[(j, c)] + l[(i, c)] * dl[(j, c)])
                    .sum();
                dl[(i, j)] = match (free, i == j) {
                    (true, true) => {
                        if (i, j) == target {
                            l[(i, i)]
                        } else {
                            0.0
                        }
                    }
                    (true, false) => f64::from(u8::from((i, j) == target)),
                    (false, false) => (-ddot - l[(i, j)] * dl[(j, j)]) / l[(j, j)],
                    // From L_ii^2 = V_ii - sum_{k<i} L_ik^2.
                    (false, true) => {
                        let s: f64 = (0..i).map(|c| l[(i, c)] * dl[(i, c)]).sum();
                        -s / l[(i, i)]
                    }
                };
            }
        }
        dl
    }

    /// Natural values of this form's parameters at `theta`, given its matrix there.
    fn natural(&self, theta: &[f64], m: &DMatrix<f64>) -> Vec<f64> {
        match self.form.kind {
            FormKind::Fixed => Vec::new(),
            FormKind::Scaled => vec![theta[0].exp()],
            FormKind::Diagonal | FormKind::Full => {
                self.slots.iter().map(|&(i, j)| m[(i, j)]).collect()
            }
        }
    }

    /// `d natural / d theta` of this form (square, this form's parameters).
    fn jacobian(&self, theta: &[f64], m: &DMatrix<f64>) -> Result<DMatrix<f64>, NoiseError> {
        let p = self.len();
        match self.form.kind {
            FormKind::Fixed => Ok(DMatrix::zeros(0, 0)),
            FormKind::Scaled => Ok(DMatrix::from_element(1, 1, theta[0].exp())),
            FormKind::Diagonal => Ok(DMatrix::from_diagonal(&DVector::from_iterator(
                p,
                self.slots.iter().map(|&(i, _)| m[(i, i)]),
            ))),
            FormKind::Full => {
                let l = self.factor(theta)?;
                let mut jac = DMatrix::zeros(p, p);
                for col in 0..p {
                    let dl = self.factor_derivative(&l, col);
                    let dm = &dl * l.transpose() + &l * dl.transpose();
                    for (row, &(i, j)) in self.slots.iter().enumerate() {
                        jac[(row, col)] = dm[(i, j)];
                    }
                }
                Ok(jac)
            }
        }
    }

    /// This form's parameters of a matrix `m` (its part of `theta`).
    fn theta_of(&self, m: &DMatrix<f64>) -> Result<Vec<f64>, NoiseError> {
        let name = self.matrix.name();
        let v = &self.form.value;
        let k = v.nrows();
        if m.shape() != (k, k) {
            return Err(NoiseError::Shape {
                matrix: name,
                expected_rows: k,
                expected_cols: k,
                found_rows: m.nrows(),
                found_cols: m.ncols(),
            });
        }
        if m.iter().any(|x| !x.is_finite()) {
            return Err(NoiseError::NonFinite { what: name });
        }
        match self.form.kind {
            FormKind::Fixed => Ok(Vec::new()),
            FormKind::Scaled => {
                // The least-squares multiplier: exact for a multiple of the nominal matrix.
                // Its logarithm is taken from the rescaled ratio, so that a multiplier beyond
                // f64 (a matrix near f64::MAX over a tiny nominal) still has its `theta`.
                let (s, e) = multiplier_parts(m, v);
                if s.is_nan() || s <= 0.0 {
                    return Err(NoiseError::NotPositive {
                        name: self.matrix.multiplier().to_string(),
                        value: ldexp(s, e),
                    });
                }
                Ok(vec![s.ln() + f64::from(e) * std::f64::consts::LN_2])
            }
            FormKind::Diagonal => self
                .slots
                .iter()
                .map(|&(i, _)| {
                    let d = m[(i, i)];
                    if d > 0.0 {
                        Ok(d.ln())
                    } else {
                        Err(NoiseError::NotPositive {
                            name: entry_name(name, i, i),
                            value: d,
                        })
                    }
                })
                .collect(),
            FormKind::Full => {
                // The fixed entries are the form's, whatever `m` holds there.
                let mut with_fixed = m.clone();
                for &(i, j) in &self.form.fixed {
                    with_fixed[(i, j)] = v[(i, j)];
                    with_fixed[(j, i)] = v[(i, j)];
                }
                for j in 0..k {
                    for i in (j + 1)..k {
                        with_fixed[(j, i)] = with_fixed[(i, j)];
                    }
                }
                // Factored at a power-of-two scale near 1 (exact), so that entries near
                // f64::MAX do not overflow the factorisation's sums and subnormal ones keep
                // their digits; the factor's entries (at most the square root of the largest
                // entry) are representable at the matrix's own scale.
                let half = max_exponent(&with_fixed).map_or(0, |e| e / 2);
                let l = with_fixed
                    .map(|x| ldexp(x, -2 * half))
                    .cholesky()
                    .ok_or(NoiseError::Matrix {
                        matrix: name,
                        source: LinalgError::NotPositiveDefinite { what: name },
                    })?
                    .unpack()
                    .map(|x| ldexp(x, half));
                Ok(self
                    .slots
                    .iter()
                    .map(|&(i, j)| if i == j { l[(i, i)].ln() } else { l[(i, j)] })
                    .collect())
            }
        }
    }
}

/// The binary exponent of the largest entry in magnitude (`None` for a zero matrix).
fn max_exponent(m: &DMatrix<f64>) -> Option<i32> {
    max_exponent_of(m.as_slice())
}

/// The binary exponent of the largest value in magnitude (`None` if all are zero).
pub(crate) fn max_exponent_of(values: &[f64]) -> Option<i32> {
    binary_exponent(values.iter().fold(0.0f64, |a, x| a.max(x.abs())))
}

/// The least-squares multiplier `<X, V> / <V, V>` of a nominal `V` (not zero) as `(s, e)`
/// with the multiplier `s 2^e`: both matrices are brought to a largest entry near 1 by
/// powers of two before the sums, so that neither sum overflows or underflows for finite
/// matrices of any scale, and the multiplier's exponent is kept apart from `s` (it may be
/// beyond f64 while its logarithm is not).
pub(crate) fn multiplier_parts(x: &DMatrix<f64>, v: &DMatrix<f64>) -> (f64, i32) {
    let ev = max_exponent(v).unwrap_or(0);
    let Some(ex) = max_exponent(x) else {
        return (0.0, 0);
    };
    let xs = x.map(|a| ldexp(a, -ex));
    let vs = v.map(|a| ldexp(a, -ev));
    (xs.dot(&vs) / vs.dot(&vs), ex - ev)
}

/// The least-squares multiplier `<X, V> / <V, V>`: infinite only when the multiplier itself
/// leaves f64 (see [`multiplier_parts`]).
pub(crate) fn multiplier(x: &DMatrix<f64>, v: &DMatrix<f64>) -> f64 {
    let (s, e) = multiplier_parts(x, v);
    ldexp(s, e)
}

/// `V e^t`, with `e^t` applied as a power of two and a factor in `[2^-1/2, 2^1/2]` when `e^t`
/// alone overflows or underflows, so that `V e^t` is finite wherever its entries are (a tiny
/// nominal with a large multiplier); the plain product otherwise.
fn scaled_by_exp(v: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
    let plain = t.exp();
    if plain.is_normal() {
        let out = v * plain;
        if out.iter().all(|x| x.is_finite()) {
            return out;
        }
    }
    let k = (t / std::f64::consts::LN_2).round().clamp(-4400.0, 4400.0);
    let factor = (t - k * std::f64::consts::LN_2).exp();
    // `k` is within +-4400 after the clamp, so the cast is exact.
    #[allow(clippy::cast_possible_truncation)]
    let k = k as i32;
    // The power of two first where it grows the entries (exact until the result itself
    // overflows), last where it shrinks them (halved first so that `x factor` cannot
    // overflow for `x` near f64::MAX).
    if k >= 0 {
        v.map(|x| ldexp(x, k) * factor)
    } else {
        v.map(|x| ldexp(ldexp(x, -1) * factor, k + 1))
    }
}

/// The index of the largest `|theta_i|`: which parameter overflowed is not known where a
/// result is found non-finite; the largest is the likeliest, and the message says the vector
/// is at fault either way.
fn largest(theta: &[f64]) -> usize {
    theta
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map_or(0, |(i, _)| i)
}

/// `Ok` if every value is finite, else [`NoiseError::NonFiniteTheta`]: a natural value
/// (a multiplier `e^theta`) or a derivative beyond f64.
fn all_finite_or_theta_error(theta: &[f64], values: &[f64]) -> Result<(), NoiseError> {
    if values.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(NoiseError::NonFiniteTheta {
            index: largest(theta),
        })
    }
}

/// `Qw[i,j]`, the name of a matrix entry.
fn entry_name(matrix: &str, i: usize, j: usize) -> String {
    format!("{matrix}[{i},{j}]")
}

/// What is known and what is estimated of the noise: `Q = G Qw G^T` with an optional `G`
/// (`n`x`g`), and the forms of `Qw` and `R`; checked at construction, with the free
/// parameters laid out in one vector `theta` (those of `Qw` first, then those of `R`; within a
/// form, entries row by row of the lower triangle).
///
/// ```
/// use kalibra_tune::{CovarianceForm, DMatrix, Parametrisation};
///
/// // Two states driven by one noise channel through G, a scalar measurement:
/// // Q = G q Qw_nom G^T with q unknown, R diagonal (one unknown variance).
/// let g = DMatrix::from_column_slice(2, 1, &[0.5, 1.0]);
/// let noise = Parametrisation::new(
///     Some(g),
///     CovarianceForm::scaled(DMatrix::from_element(1, 1, 1.0)),
///     CovarianceForm::diagonal(DMatrix::from_element(1, 1, 4.0)),
/// )?;
/// let params = noise.parameters();
/// let names: Vec<_> = params.iter().map(|p| p.name.as_str()).collect();
/// assert_eq!(names, ["q", "R[0,0]"]);
/// let theta = noise.start();
/// let m = noise.matrices(theta.as_slice())?;
/// assert_eq!(m.q[(0, 1)], 0.5);
/// assert_eq!(noise.theta_of(&m.qw, &m.r)?, theta);
/// # Ok::<(), kalibra_tune::NoiseError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Parametrisation {
    g: Option<DMatrix<f64>>,
    qw: Checked,
    r: Checked,
    n: usize,
    start: DVector<f64>,
}

impl Parametrisation {
    /// Checks the forms (see [`CovarianceForm`]'s constructors for what each value must be)
    /// and `G`, and refuses a parametrisation with more free parameters than measurements can
    /// identify.
    ///
    /// # Errors
    /// [`NoiseError::Shape`] for a non-square value or a `G` whose columns are not `Qw`'s
    /// size; [`NoiseError::Empty`] for a 0x0 matrix or a `G` without rows;
    /// [`NoiseError::NonFinite`] for a non-finite `G`; [`NoiseError::Matrix`] for a value that
    /// is not symmetric positive semi-definite (positive definite for a full form);
    /// [`NoiseError::NotDiagonal`], [`NoiseError::NotPositive`] (a diagonal form's free
    /// variance), [`NoiseError::ZeroNominal`], [`NoiseError::FixedEntryOutOfRange`],
    /// [`NoiseError::FixedEntryInScaled`]; [`NoiseError::Infeasible`] for a full form whose
    /// fixed entries its own starting point cannot meet; [`NoiseError::TooManyParameters`]
    /// for more than `n m + m (m + 1) / 2` free parameters.
    pub fn new(
        g: Option<DMatrix<f64>>,
        qw: CovarianceForm,
        r: CovarianceForm,
    ) -> Result<Self, NoiseError> {
        let qw = Checked::new(NoiseMatrix::Qw, qw)?;
        let r = Checked::new(NoiseMatrix::R, r)?;
        let n = match &g {
            None => qw.form.dim(),
            Some(g) => {
                if g.nrows() == 0 {
                    return Err(NoiseError::Empty { what: "G" });
                }
                if g.ncols() != qw.form.dim() {
                    return Err(NoiseError::Shape {
                        matrix: "G",
                        expected_rows: g.nrows(),
                        expected_cols: qw.form.dim(),
                        found_rows: g.nrows(),
                        found_cols: g.ncols(),
                    });
                }
                if g.iter().any(|x| !x.is_finite()) {
                    return Err(NoiseError::NonFinite { what: "G" });
                }
                g.nrows()
            }
        };
        let m = r.form.dim();
        let free = qw.len() + r.len();
        let limit = n * m + m * (m + 1) / 2;
        if free > limit {
            return Err(NoiseError::TooManyParameters { free, limit, n, m });
        }
        let part = |c: &Checked| match c.form.kind {
            FormKind::Scaled => Ok(vec![0.0]),
            _ => c.theta_of(&c.form.value),
        };
        let mut start = part(&qw)?;
        start.extend(part(&r)?);
        let out = Self {
            g,
            qw,
            r,
            n,
            start: DVector::from_vec(start),
        };
        // The starting point must itself be a valid candidate.
        out.matrices(out.start.as_slice())?;
        Ok(out)
    }

    /// `n`, the states (rows of `G`, or `Qw`'s size without `G`).
    pub fn state_dim(&self) -> usize {
        self.n
    }

    /// `m`, the measurements (`R`'s size).
    pub fn measurement_dim(&self) -> usize {
        self.r.form.dim()
    }

    /// `g`, the noise channels (`Qw`'s size).
    pub fn channels(&self) -> usize {
        self.qw.form.dim()
    }

    /// `G`, if given.
    pub fn g(&self) -> Option<&DMatrix<f64>> {
        self.g.as_ref()
    }

    /// The form of `Qw`.
    pub fn qw_form(&self) -> &CovarianceForm {
        &self.qw.form
    }

    /// The form of `R`.
    pub fn r_form(&self) -> &CovarianceForm {
        &self.r.form
    }

    /// The number of free parameters, the length of `theta`.
    pub fn len(&self) -> usize {
        self.qw.len() + self.r.len()
    }

    /// Whether nothing is free (both forms fixed).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `n m + m (m + 1) / 2`, the most free parameters innovations can identify.
    pub fn identifiable_limit(&self) -> usize {
        let (n, m) = (self.n, self.measurement_dim());
        n * m + m * (m + 1) / 2
    }

    /// The free parameters, in `theta` order.
    pub fn parameters(&self) -> Vec<Parameter> {
        let mut out = self.qw.parameters();
        out.extend(self.r.parameters());
        out
    }

    /// `theta` at the forms' given matrices (multipliers 1, the diagonal and full forms'
    /// starting points).
    pub fn start(&self) -> DVector<f64> {
        self.start.clone()
    }

    fn split<'t>(&self, theta: &'t [f64]) -> Result<(&'t [f64], &'t [f64]), NoiseError> {
        if theta.len() != self.len() {
            return Err(NoiseError::ThetaLength {
                expected: self.len(),
                found: theta.len(),
            });
        }
        if let Some(index) = theta.iter().position(|t| !t.is_finite()) {
            return Err(NoiseError::NonFiniteTheta { index });
        }
        Ok(theta.split_at(self.qw.len()))
    }

    /// `Qw`, `R` and `Q = G Qw G^T` at `theta`.
    ///
    /// # Errors
    /// [`NoiseError::ThetaLength`]; [`NoiseError::NonFiniteTheta`] for a non-finite value or
    /// one whose matrices overflow; [`NoiseError::Infeasible`] when a full form's fixed
    /// entries cannot be met at this candidate.
    pub fn matrices(&self, theta: &[f64]) -> Result<NoiseMatrices, NoiseError> {
        let (tq, tr) = self.split(theta)?;
        let qw = self.qw.matrix(tq)?;
        let r = self.r.matrix(tr)?;
        let q = match &self.g {
            None => qw.clone(),
            Some(g) => {
                let mut q = g * &qw * g.transpose();
                for j in 0..q.ncols() {
                    for i in (j + 1)..q.nrows() {
                        q[(j, i)] = q[(i, j)];
                    }
                }
                q
            }
        };
        if qw
            .iter()
            .chain(r.iter())
            .chain(q.iter())
            .any(|x| !x.is_finite())
        {
            return Err(NoiseError::NonFiniteTheta {
                index: largest(theta),
            });
        }
        Ok(NoiseMatrices { qw, r, q })
    }

    /// The free parameters on the matrices' own scale at `theta` ([`Parametrisation::parameters`]
    /// order): multipliers and covariance entries.
    ///
    /// # Errors
    /// As [`Parametrisation::matrices`]; [`NoiseError::NonFiniteTheta`] also for a multiplier
    /// `e^theta` beyond f64 (its matrix may be finite: a tiny nominal).
    pub fn natural(&self, theta: &[f64]) -> Result<DVector<f64>, NoiseError> {
        let (tq, tr) = self.split(theta)?;
        let m = self.matrices(theta)?;
        let mut out = self.qw.natural(tq, &m.qw);
        out.extend(self.r.natural(tr, &m.r));
        all_finite_or_theta_error(theta, &out)?;
        Ok(DVector::from_vec(out))
    }

    /// `d natural / d theta` at `theta` (square, block diagonal: `Qw`'s block, then `R`'s),
    /// exact (the log-Cholesky factor differentiated through its recurrence), for carrying a
    /// covariance of `theta` to the natural parameters (`J C J^T`).
    ///
    /// # Errors
    /// As [`Parametrisation::natural`], and [`NoiseError::NonFiniteTheta`] for a derivative
    /// beyond f64.
    pub fn jacobian(&self, theta: &[f64]) -> Result<DMatrix<f64>, NoiseError> {
        let (tq, tr) = self.split(theta)?;
        let m = self.matrices(theta)?;
        let jq = self.qw.jacobian(tq, &m.qw)?;
        let jr = self.r.jacobian(tr, &m.r)?;
        let (a, b) = (jq.nrows(), jr.nrows());
        let mut jac = DMatrix::zeros(a + b, a + b);
        jac.view_mut((0, 0), (a, a)).copy_from(&jq);
        jac.view_mut((a, a), (b, b)).copy_from(&jr);
        all_finite_or_theta_error(theta, jac.as_slice())?;
        Ok(jac)
    }

    /// `theta` of given `Qw` and `R` (the inverse of [`Parametrisation::matrices`] on its
    /// image): a scaled form's multiplier is the least-squares one (`<M, V> / <V, V>`, exact
    /// for a multiple of `V`), a diagonal form reads the diagonal, a full form the Cholesky
    /// factor of the matrix with its fixed entries set to the given ones. Entries a form
    /// holds fixed are not read.
    ///
    /// # Errors
    /// [`NoiseError::Shape`], [`NoiseError::NonFinite`]; [`NoiseError::NotPositive`] for a
    /// non-positive multiplier or free variance; [`NoiseError::Matrix`] when a full form's
    /// matrix is not positive definite.
    pub fn theta_of(
        &self,
        qw: &DMatrix<f64>,
        r: &DMatrix<f64>,
    ) -> Result<DVector<f64>, NoiseError> {
        let mut theta = self.qw.theta_of(qw)?;
        theta.extend(self.r.theta_of(r)?);
        Ok(DVector::from_vec(theta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn spd(k: usize, seed: &[f64]) -> DMatrix<f64> {
        let a = DMatrix::from_fn(k, k, |i, j| seed[(i * k + j) % seed.len()]);
        &a * a.transpose() + DMatrix::identity(k, k)
    }

    #[test]
    fn names_follow_the_forms() {
        let p = Parametrisation::new(
            None,
            CovarianceForm::full(spd(2, &[0.3, -0.2, 0.5, 0.1])).fix(0, 1),
            CovarianceForm::diagonal(DMatrix::from_diagonal_element(2, 2, 2.0)).fix(1, 1),
        )
        .unwrap();
        let names: Vec<_> = p.parameters().into_iter().map(|p| p.name).collect();
        assert_eq!(names, ["Qw[0,0]", "Qw[1,1]", "R[0,0]"]);
        let kinds: Vec<_> = p.parameters().into_iter().map(|p| p.kind).collect();
        assert_eq!(kinds, [ParameterKind::Variance; 3]);
        let full = Parametrisation::new(
            None,
            CovarianceForm::full(spd(2, &[0.3, -0.2, 0.5, 0.1])),
            CovarianceForm::scaled(DMatrix::identity(2, 2)),
        )
        .unwrap();
        let names: Vec<_> = full.parameters().into_iter().map(|p| p.name).collect();
        assert_eq!(names, ["Qw[0,0]", "Qw[1,0]", "Qw[1,1]", "r"]);
        assert!(!full.parameters()[1].positive());
    }

    #[test]
    fn fixed_entries_of_a_full_form_hold_at_every_candidate() {
        let v = spd(3, &[0.4, -0.3, 0.2, 0.7, 0.1]);
        let p = Parametrisation::new(
            None,
            CovarianceForm::full(v.clone()).fix(2, 0).fix(1, 1),
            CovarianceForm::fixed(DMatrix::identity(1, 1)),
        )
        .unwrap();
        assert_eq!(p.len(), 4);
        let theta = [0.3, -0.4, 0.2, -0.1];
        let m = p.matrices(&theta).unwrap();
        assert!((m.qw[(2, 0)] - v[(2, 0)]).abs() < 1e-12);
        assert!((m.qw[(0, 2)] - v[(2, 0)]).abs() < 1e-12);
        assert!((m.qw[(1, 1)] - v[(1, 1)]).abs() < 1e-12);
        assert!(m.qw.clone().cholesky().is_some());
        // A candidate whose free entries already exceed the fixed variance is refused.
        let too_big = [0.0, 10.0, 0.0, 0.0];
        assert_eq!(
            p.matrices(&too_big),
            Err(NoiseError::Infeasible {
                matrix: "Qw",
                index: 1
            })
        );
    }

    #[test]
    fn too_many_parameters_are_refused_with_the_reason() {
        // n = 3 states, m = 1 measurement: at most 3 + 1 = 4; a full Qw has 6.
        let err = Parametrisation::new(
            None,
            CovarianceForm::full(DMatrix::identity(3, 3)),
            CovarianceForm::fixed(DMatrix::identity(1, 1)),
        )
        .unwrap_err();
        assert_eq!(
            err,
            NoiseError::TooManyParameters {
                free: 6,
                limit: 4,
                n: 3,
                m: 1
            }
        );
        assert!(err.to_string().contains("steady-state gain"));
    }

    #[test]
    fn bad_forms_are_typed_errors() {
        let id = |k| DMatrix::<f64>::identity(k, k);
        let new = |q: CovarianceForm, r: CovarianceForm| Parametrisation::new(None, q, r);
        assert!(matches!(
            new(
                CovarianceForm::scaled(id(2)).fix(0, 0),
                CovarianceForm::fixed(id(1))
            ),
            Err(NoiseError::FixedEntryInScaled { matrix: "Qw" })
        ));
        assert!(matches!(
            new(
                CovarianceForm::scaled(DMatrix::zeros(2, 2)),
                CovarianceForm::fixed(id(1))
            ),
            Err(NoiseError::ZeroNominal { .. })
        ));
        assert!(matches!(
            new(
                CovarianceForm::fixed(id(2)),
                CovarianceForm::diagonal(DMatrix::from_element(2, 2, 1.0))
            ),
            Err(NoiseError::NotDiagonal { matrix: "R", .. })
        ));
        assert!(matches!(
            new(
                CovarianceForm::fixed(id(2)),
                CovarianceForm::full(id(1)).fix(3, 0)
            ),
            Err(NoiseError::FixedEntryOutOfRange { .. })
        ));
        let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(
            new(
                CovarianceForm::full(indefinite),
                CovarianceForm::fixed(id(1))
            ),
            Err(NoiseError::Matrix { matrix: "Qw", .. })
        ));
        let g = DMatrix::zeros(2, 3);
        assert!(matches!(
            Parametrisation::new(
                Some(g),
                CovarianceForm::fixed(id(2)),
                CovarianceForm::fixed(id(1))
            ),
            Err(NoiseError::Shape { matrix: "G", .. })
        ));
        let p = new(CovarianceForm::scaled(id(2)), CovarianceForm::fixed(id(1))).unwrap();
        assert_eq!(
            p.matrices(&[0.0, 1.0]),
            Err(NoiseError::ThetaLength {
                expected: 1,
                found: 2
            })
        );
        assert_eq!(
            p.matrices(&[f64::NAN]),
            Err(NoiseError::NonFiniteTheta { index: 0 })
        );
        assert_eq!(
            p.matrices(&[1e3]),
            Err(NoiseError::NonFiniteTheta { index: 0 })
        );
    }

    #[test]
    fn g_carries_qw_into_q() {
        let g = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.5, 1.0, 0.0, 2.0]);
        let p = Parametrisation::new(
            Some(g.clone()),
            CovarianceForm::diagonal(DMatrix::from_diagonal_element(2, 2, 1.0)),
            CovarianceForm::scaled(DMatrix::identity(2, 2)),
        )
        .unwrap();
        assert_eq!(
            (p.state_dim(), p.channels(), p.measurement_dim()),
            (3, 2, 2)
        );
        let m = p
            .matrices(&[0.5_f64.ln(), 2.0_f64.ln(), 3.0_f64.ln()])
            .unwrap();
        let qw = DMatrix::from_diagonal(&DVector::from_vec(vec![0.5, 2.0]));
        assert!((&m.q - &g * qw * g.transpose()).abs().max() < 1e-12);
        assert!((&m.r - DMatrix::identity(2, 2) * 3.0).abs().max() < 1e-12);
        let natural = p
            .natural(&[0.5_f64.ln(), 2.0_f64.ln(), 3.0_f64.ln()])
            .unwrap();
        assert!(
            (natural - DVector::from_vec(vec![0.5, 2.0, 3.0]))
                .abs()
                .max()
                < 1e-12
        );
    }

    /// A full form with a fixed variance and a fixed covariance, and a diagonal form: the
    /// parametrisation whose Jacobian and round trip the properties check.
    fn mixed() -> Parametrisation {
        let v = spd(3, &[0.4, -0.3, 0.2, 0.7, 0.1]);
        Parametrisation::new(
            None,
            CovarianceForm::full(v).fix(1, 0).fix(2, 2),
            CovarianceForm::diagonal(DMatrix::from_diagonal_element(2, 2, 0.5)),
        )
        .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// theta -> matrices -> theta is the identity (to rounding), for every form.
        #[test]
        fn theta_round_trips(t in proptest::collection::vec(-1.0f64..1.0, 6)) {
            let p = mixed();
            prop_assert_eq!(p.len(), 6);
            // Small free entries keep the fixed variance reachable; a refused candidate is
            // checked to be genuinely infeasible and skipped.
            let theta: Vec<f64> = t.iter().map(|x| 0.2 * x).collect();
            let m = match p.matrices(&theta) {
                Ok(m) => m,
                Err(e) => {
                    let infeasible = matches!(e, NoiseError::Infeasible { .. });
                    prop_assert!(infeasible, "{}", e);
                    return Ok(());
                }
            };
            let back = p.theta_of(&m.qw, &m.r).unwrap();
            for (a, b) in back.iter().zip(&theta) {
                prop_assert!((a - b).abs() < 1e-10, "{a} vs {b}");
            }
            // Scaled forms too.
            let s = Parametrisation::new(
                None,
                CovarianceForm::scaled(spd(2, &[0.1, 0.9, -0.4])),
                CovarianceForm::scaled(DMatrix::identity(1, 1) * 3.0),
            )
            .unwrap();
            let ts = [t[0] * 5.0, t[1] * 5.0];
            let ms = s.matrices(&ts).unwrap();
            let back = s.theta_of(&ms.qw, &ms.r).unwrap();
            prop_assert!((back[0] - ts[0]).abs() < 1e-10 && (back[1] - ts[1]).abs() < 1e-10);
        }

        /// The exact Jacobian equals central differences of `natural`.
        #[test]
        fn jacobian_matches_differences(t in proptest::collection::vec(-1.0f64..1.0, 6)) {
            let p = mixed();
            let theta: Vec<f64> = t.iter().map(|x| 0.2 * x).collect();
            let Ok(jac) = p.jacobian(&theta) else { return Ok(()) };
            let h = 1e-6;
            for c in 0..theta.len() {
                let (mut up, mut down) = (theta.clone(), theta.clone());
                up[c] += h;
                down[c] -= h;
                let (Ok(a), Ok(b)) = (p.natural(&up), p.natural(&down)) else { continue };
                let fd = (a - b) / (2.0 * h);
                for r in 0..theta.len() {
                    prop_assert!(
                        (jac[(r, c)] - fd[r]).abs() < 1e-6 * (1.0 + fd[r].abs()),
                        "d{r}/d{c}: {} vs {}", jac[(r, c)], fd[r]
                    );
                }
            }
        }
    }
}
