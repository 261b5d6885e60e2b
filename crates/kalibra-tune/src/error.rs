//! [`NoiseError`]: why a noise parametrisation or an estimation problem was refused.

use kalibra_linalg::LinalgError;

/// Why a noise parametrisation ([`Parametrisation`](crate::Parametrisation)), a candidate of it,
/// or an estimation problem ([`NoiseProblem`](crate::NoiseProblem)) was refused. Messages are
/// lowercase fragments that read after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseError {
    /// A matrix or vector has the wrong size.
    #[error(
        "matrix {matrix} is {found_rows}x{found_cols}, expected {expected_rows}x{expected_cols}"
    )]
    Shape {
        /// The matrix's name (`"F"`, `"H"`, `"G"`, `"Qw"`, `"R"`, `"x0"`, `"P0"`).
        matrix: &'static str,
        /// The rows required.
        expected_rows: usize,
        /// The columns required.
        expected_cols: usize,
        /// The rows given.
        found_rows: usize,
        /// The columns given.
        found_cols: usize,
    },
    /// A dimension is zero (no state, no measurement or no noise channel).
    #[error("{what} has dimension 0")]
    Empty {
        /// Which matrix.
        what: &'static str,
    },
    /// A model matrix holds NaN or an infinity.
    #[error("{what} holds a non-finite value")]
    NonFinite {
        /// Which matrix.
        what: &'static str,
    },
    /// A measurement holds NaN or an infinity. A missing measurement is `None`, not NaN.
    #[error(
        "measurement at run {run}, step {step} holds a non-finite value (give None for a \
         missing measurement)"
    )]
    NonFiniteMeasurement {
        /// The run (0 for a single log).
        run: usize,
        /// The step within the run.
        step: usize,
    },
    /// A measurement of the wrong length.
    #[error("measurement at run {run}, step {step} has {found} values, expected {expected}")]
    MeasurementLength {
        /// The run.
        run: usize,
        /// The step.
        step: usize,
        /// `m`, the rows of `H`.
        expected: usize,
        /// The values given.
        found: usize,
    },
    /// No run holds a measurement: there is nothing to estimate from.
    #[error("no measurements: every step of every run is missing")]
    NoMeasurements,
    /// A given matrix failed the library's covariance check (symmetric, and positive
    /// semi-definite; positive definite for the starting point of a full form).
    #[error("matrix {matrix}: {source}")]
    Matrix {
        /// The matrix's name.
        matrix: &'static str,
        /// The check that failed.
        #[source]
        source: LinalgError,
    },
    /// The value of a diagonal form has a non-zero entry off its diagonal.
    #[error("{matrix} has the diagonal form but holds {value:e} at ({row}, {col})")]
    NotDiagonal {
        /// The matrix's name.
        matrix: &'static str,
        /// Row of the entry.
        row: usize,
        /// Column of the entry.
        col: usize,
        /// Its value.
        value: f64,
    },
    /// A quantity that the parametrisation keeps positive (a multiplier, a free variance)
    /// is not positive at the starting point or in a matrix mapped back to the parameters.
    #[error("{name} = {value:e} must be positive")]
    NotPositive {
        /// The parameter's name (`q`, `r`, `Qw[1,1]`, ...).
        name: String,
        /// Its value.
        value: f64,
    },
    /// The nominal matrix of a scaled form is zero, so no multiple of it is a noise.
    #[error("{matrix} has the scaled form but its nominal matrix is zero")]
    ZeroNominal {
        /// The matrix's name.
        matrix: &'static str,
    },
    /// A fixed entry outside the matrix.
    #[error("fixed entry ({row}, {col}) of {matrix} is outside a {dim}x{dim} matrix")]
    FixedEntryOutOfRange {
        /// The matrix's name.
        matrix: &'static str,
        /// Row asked for.
        row: usize,
        /// Column asked for.
        col: usize,
        /// The matrix's size.
        dim: usize,
    },
    /// Entries of a scaled form cannot be fixed: it has one multiplier for all of them.
    #[error("{matrix} has the scaled form, whose entries cannot be fixed one by one")]
    FixedEntryInScaled {
        /// The matrix's name.
        matrix: &'static str,
    },
    /// More free covariance parameters than innovations can identify. The likelihood of a
    /// time-invariant model depends on `(Q, R)` only through the steady-state gain `K`
    /// (`n m` values) and innovation covariance `S` (`m (m + 1) / 2` values), so at most
    /// that many combinations of the parameters can be estimated from measurements.
    #[error(
        "{free} free noise parameters asked for, but innovations identify at most \
         n m + m (m + 1) / 2 = {limit} (n = {n} states, m = {m} measurements: the likelihood \
         depends on Q and R only through the steady-state gain and innovation covariance); \
         fix or scale some entries"
    )]
    TooManyParameters {
        /// Free parameters of the parametrisation.
        free: usize,
        /// `n m + m (m + 1) / 2`.
        limit: usize,
        /// States.
        n: usize,
        /// Measurements.
        m: usize,
    },
    /// A parameter vector of the wrong length.
    #[error("parameter vector has {found} values, expected {expected}")]
    ThetaLength {
        /// The free parameters.
        expected: usize,
        /// The values given.
        found: usize,
    },
    /// A parameter vector with NaN or an infinity, or one whose matrices, natural values or
    /// their derivatives leave the range of f64.
    #[error(
        "parameter {index} of the vector is not finite, or its matrices or natural values \
         leave the range of f64"
    )]
    NonFiniteTheta {
        /// The first offending parameter.
        index: usize,
    },
    /// The fixed entries of a full form cannot be met by a positive-definite matrix at this
    /// candidate: the fixed variance at `index` is not larger than what the free entries of
    /// its row already explain.
    #[error(
        "{matrix} with its fixed entries is not positive definite at this candidate \
         (fixed variance at index {index})"
    )]
    Infeasible {
        /// The matrix's name.
        matrix: &'static str,
        /// The diagonal index whose pivot is not positive.
        index: usize,
    },
}
