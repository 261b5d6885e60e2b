//! Tune the process noise of a linear model from recorded measurements: the offline method of
//! Saha, Goswami and Ghosh (2012) and Saha, Ghosh and Goswami (IEEE TIM 2014), on any linear
//! model. This is the library behind `kalibra tune`.
//!
//! The documentation of the method and its conventions is on [`Tuning`].

use kalibra_filters::{Filter, FilterError, FilterOptions, Kf, Start, StepRecord};
use kalibra_linalg::{DMatrix, DVector, Dyn, LinalgError, PsdMatrix};
use kalibra_metrics::{
    Crossover, JHorizon, JStep, JSummary, MetricsError, SweepPoint, crossover, j_step,
};
use kalibra_models::{LinearGaussian, LinearObservation, ModelError};
use kalibra_sim::SimError;
use serde::{Deserialize, Serialize};

/// The version of [`TuneReport`]'s schema, written to [`TuneReport::schema_version`]. A change
/// that renames or removes a field, or changes its meaning, increments it.
pub const TUNE_SCHEMA_VERSION: u32 = 1;

/// Why a tuning problem could not be built or tuned. Messages are lowercase fragments that read
/// after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TuneError {
    /// A matrix that must be square is not.
    #[error("matrix {matrix} is {rows}x{cols}, not square")]
    NotSquare {
        /// The matrix's name (`"F"`, `"Q_nom"`, `"R"`, `"P0"`).
        matrix: &'static str,
        /// Its rows.
        rows: usize,
        /// Its columns.
        cols: usize,
    },
    /// A matrix or vector has the wrong size for the model.
    #[error(
        "matrix {matrix} is {found_rows}x{found_cols}, expected {expected_rows}x{expected_cols}"
    )]
    Shape {
        /// The matrix's name (`"H"`, `"Q_nom"`, `"R"`, `"P0"`, `"x0"`: vectors are `n`x1).
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
    /// Rows of different lengths given for one matrix ([`matrix_from_rows`]).
    #[error("matrix {matrix} row {row} holds {found} values, expected {expected}")]
    Ragged {
        /// The matrix's name.
        matrix: &'static str,
        /// The first row of the wrong length.
        row: usize,
        /// The length of row 0.
        expected: usize,
        /// This row's length.
        found: usize,
    },
    /// A state or measurement dimension of zero (`F` or `H` with no rows).
    #[error("{what} is zero")]
    Empty {
        /// What is zero.
        what: &'static str,
    },
    /// A value that must be finite is not.
    #[error("{what} holds a non-finite value{}", step.map(|s| format!(" at step {s}")).unwrap_or_default())]
    NonFinite {
        /// Which input (`"F"`, ..., `"measurement"`, `"truth"`).
        what: &'static str,
        /// For a sequence, the index in it.
        step: Option<usize>,
    },
    /// A matrix that must be symmetric is not, beyond rounding.
    #[error("matrix {matrix} is not symmetric (relative asymmetry {asymmetry:e})")]
    NotSymmetric {
        /// The matrix's name.
        matrix: &'static str,
        /// Largest `|a_ij - a_ji| / sqrt(|a_ii a_jj|)`.
        asymmetry: f64,
    },
    /// A matrix that must be positive semi-definite has a clearly negative pivot.
    #[error("matrix {matrix} is not positive semi-definite (pivot {pivot:e} at index {index})")]
    NotPositiveSemiDefinite {
        /// The matrix's name.
        matrix: &'static str,
        /// Index of the offending pivot.
        index: usize,
        /// Its value.
        pivot: f64,
    },
    /// A measurement of the wrong length.
    #[error("measurement at step {step} holds {found} values, expected m = {expected}")]
    MeasurementLength {
        /// Index in the sequence.
        step: usize,
        /// `m`, the rows of `H`.
        expected: usize,
        /// The length given.
        found: usize,
    },
    /// A truth state of the wrong length.
    #[error("truth at step {step} holds {found} values, expected n = {expected}")]
    TruthLength {
        /// Index in the sequence.
        step: usize,
        /// `n`, the rows of `F`.
        expected: usize,
        /// The length given.
        found: usize,
    },
    /// A truth sequence whose length differs from the measurements'.
    #[error("truth sequence has {found} steps, the measurements {expected}")]
    TruthSteps {
        /// The measurement sequence's length.
        expected: usize,
        /// The truth sequence's length.
        found: usize,
    },
    /// A measurement sequence with no measurement present: nothing to tune on.
    #[error("measurement sequence holds no measurement")]
    NoMeasurements,
    /// A grid that is empty, not finite, not strictly increasing, or whose `10^p` is not a
    /// positive finite number.
    #[error("grid point {index} (p = {p}) {reason}")]
    InvalidGrid {
        /// Index of the offending point (0 for an empty grid).
        index: usize,
        /// Its exponent (NaN for an empty grid).
        p: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// A position index beyond the state.
    #[error("position component {index} is beyond the state dimension {dim}")]
    PositionIndex {
        /// The index given.
        index: usize,
        /// `n`.
        dim: usize,
    },
    /// An option outside its valid range (the grid's step or ends).
    #[error("invalid option {name} = {value}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// The model at one `p` could not be built (`Q` overflowed).
    #[error("model at p = {p}: {source}")]
    Model {
        /// The exponent.
        p: f64,
        /// The model's error.
        #[source]
        source: ModelError,
    },
    /// The filter failed at one `p` (a singular innovation covariance, an overflow).
    #[error("filter at p = {p}: {source}")]
    Filter {
        /// The exponent.
        p: f64,
        /// The filter's error.
        #[source]
        source: FilterError,
    },
    /// The `J1`/`J2` metrics failed at one update (a singular `A_k + B_k`, for instance with
    /// `Q = 0` and `P0 = 0`).
    #[error("J metrics at p = {p}, update {update}: {source}")]
    Metrics {
        /// The exponent.
        p: f64,
        /// The update's index among the updates (0-based), or the count for horizon errors.
        update: usize,
        /// The metric's error.
        #[source]
        source: MetricsError,
    },
    /// The thread pool for an explicit thread count could not be built.
    #[error("build a thread pool of {threads} threads: {message}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// rayon's message.
        message: String,
    },
}

/// A dense matrix from its rows (as a TOML or JSON file gives them), with a typed error for
/// ragged rows or no rows.
///
/// ```
/// let f = kalibra_tune::matrix_from_rows("F", &[vec![1.0, 1.0], vec![0.0, 1.0]])?;
/// assert_eq!(f[(0, 1)], 1.0);
/// assert!(kalibra_tune::matrix_from_rows("F", &[vec![1.0, 1.0], vec![0.0]]).is_err());
/// # Ok::<(), kalibra_tune::TuneError>(())
/// ```
///
/// # Errors
/// [`TuneError::Empty`] for no rows or empty rows, [`TuneError::Ragged`] for rows of
/// different lengths.
pub fn matrix_from_rows(
    matrix: &'static str,
    rows: &[Vec<f64>],
) -> Result<DMatrix<f64>, TuneError> {
    let cols = rows.first().map_or(0, Vec::len);
    if cols == 0 {
        return Err(TuneError::Empty { what: matrix });
    }
    if let Some((row, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
        return Err(TuneError::Ragged {
            matrix,
            row,
            expected: cols,
            found: r.len(),
        });
    }
    Ok(DMatrix::from_fn(rows.len(), cols, |i, j| rows[i][j]))
}

/// The rows of a matrix, as the report serialises matrices.
fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// How the initial covariance was taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitialCovariance {
    /// Checked symmetric positive semi-definite ([`TuneProblem::new`]).
    Checked,
    /// Taken as given, sizes and finiteness checked only ([`TuneProblem::as_given`]).
    AsGiven,
}

/// A linear model and a measurement sequence to tune `Q` on, validated at construction.
///
/// `n` is the rows of `F`, `m` the rows of `H`. Matrices are stored as given; the filter's model
/// (`LinearGaussian`) symmetrises `Q` within rounding, as it always does.
#[derive(Clone, Debug, PartialEq)]
pub struct TuneProblem {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q_nom: DMatrix<f64>,
    r: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    initial: InitialCovariance,
    measurements: Vec<Option<DVector<f64>>>,
    truth: Option<Vec<Option<DVector<f64>>>>,
    start: Start,
}

fn check_finite(what: &'static str, values: &[f64], step: Option<usize>) -> Result<(), TuneError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(TuneError::NonFinite { what, step })
    }
}

fn check_shape(
    matrix: &'static str,
    m: &DMatrix<f64>,
    rows: usize,
    cols: usize,
) -> Result<(), TuneError> {
    if m.shape() == (rows, cols) {
        Ok(())
    } else {
        Err(TuneError::Shape {
            matrix,
            expected_rows: rows,
            expected_cols: cols,
            found_rows: m.nrows(),
            found_cols: m.ncols(),
        })
    }
}

/// Symmetric positive semi-definite, through the library's own check (the one the filter's
/// models apply), with the error renamed to the matrix.
fn check_psd(matrix: &'static str, m: &DMatrix<f64>) -> Result<(), TuneError> {
    match PsdMatrix::named(m.clone(), matrix) {
        Ok(_) => Ok(()),
        Err(LinalgError::NotSymmetric { asymmetry, .. }) => {
            Err(TuneError::NotSymmetric { matrix, asymmetry })
        }
        Err(LinalgError::NotPositiveSemiDefinite { index, pivot, .. }) => {
            Err(TuneError::NotPositiveSemiDefinite {
                matrix,
                index,
                pivot,
            })
        }
        // Finiteness and squareness are checked before; anything else is reported as the
        // nearest typed error rather than hidden.
        Err(_) => Err(TuneError::NonFinite {
            what: matrix,
            step: None,
        }),
    }
}

impl TuneProblem {
    /// A problem whose `P0` is checked symmetric positive semi-definite, like `Q_nom` and `R`.
    ///
    /// `f` is `n`x`n`, `h` `m`x`n`, `q_nom` and `p0` `n`x`n`, `r` `m`x`m`, `x0` has `n` values;
    /// `measurements[i]` is the measurement at index `i` of the sequence (`None`: no
    /// measurement at that step), `m` values each.
    ///
    /// # Errors
    /// [`TuneError::NotSquare`] for a non-square `F`, `Q_nom`, `R` or `P0`;
    /// [`TuneError::Empty`] for `n = 0` or `m = 0`; [`TuneError::Shape`] for a matrix or `x0`
    /// whose size disagrees with `n` and `m` (`H`'s columns with `n`, `R` with `m`, ...);
    /// [`TuneError::NonFinite`] for NaN or infinite values (a measurement's names its step);
    /// [`TuneError::NotSymmetric`] and [`TuneError::NotPositiveSemiDefinite`] for `Q_nom`, `R`
    /// or `P0`; [`TuneError::MeasurementLength`] for a measurement whose length is not `m`;
    /// [`TuneError::NoMeasurements`] if every step is `None` (or the sequence is empty).
    pub fn new(
        f: DMatrix<f64>,
        h: DMatrix<f64>,
        q_nom: DMatrix<f64>,
        r: DMatrix<f64>,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        measurements: Vec<Option<DVector<f64>>>,
    ) -> Result<Self, TuneError> {
        Self::build(
            f,
            h,
            q_nom,
            r,
            x0,
            p0,
            measurements,
            InitialCovariance::Checked,
        )
    }

    /// The explicit opt-in to an initial covariance taken as given: `P0` is checked for its
    /// size and finiteness only, and may be asymmetric or indefinite (the 2012 paper's printed
    /// `P0` is both). The filter is `kalibra_filters::Kf::as_given` (nothing symmetrised, the
    /// gain by LU), and the metrics of each update come from LU solves of `S_k` and
    /// `A_k + B_k` in the filter's arithmetic; updates with an `A_k + B_k` that is not
    /// positive definite are counted ([`TunePoint::indefinite_updates`], [`TuneFindings`]).
    ///
    /// # Errors
    /// As [`TuneProblem::new`], without the symmetry and definiteness checks of `P0`.
    pub fn as_given(
        f: DMatrix<f64>,
        h: DMatrix<f64>,
        q_nom: DMatrix<f64>,
        r: DMatrix<f64>,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        measurements: Vec<Option<DVector<f64>>>,
    ) -> Result<Self, TuneError> {
        Self::build(
            f,
            h,
            q_nom,
            r,
            x0,
            p0,
            measurements,
            InitialCovariance::AsGiven,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn build(
        f: DMatrix<f64>,
        h: DMatrix<f64>,
        q_nom: DMatrix<f64>,
        r: DMatrix<f64>,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        measurements: Vec<Option<DVector<f64>>>,
        initial: InitialCovariance,
    ) -> Result<Self, TuneError> {
        if f.nrows() != f.ncols() {
            return Err(TuneError::NotSquare {
                matrix: "F",
                rows: f.nrows(),
                cols: f.ncols(),
            });
        }
        let n = f.nrows();
        if n == 0 {
            return Err(TuneError::Empty {
                what: "state dimension n (rows of F)",
            });
        }
        let m = h.nrows();
        if m == 0 {
            return Err(TuneError::Empty {
                what: "measurement dimension m (rows of H)",
            });
        }
        for (name, mat) in [("Q_nom", &q_nom), ("R", &r), ("P0", &p0)] {
            if mat.nrows() != mat.ncols() {
                return Err(TuneError::NotSquare {
                    matrix: name,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                });
            }
        }
        check_shape("H", &h, m, n)?;
        check_shape("Q_nom", &q_nom, n, n)?;
        check_shape("R", &r, m, m)?;
        check_shape("P0", &p0, n, n)?;
        if x0.len() != n {
            return Err(TuneError::Shape {
                matrix: "x0",
                expected_rows: n,
                expected_cols: 1,
                found_rows: x0.len(),
                found_cols: 1,
            });
        }
        for (name, values) in [
            ("F", f.as_slice()),
            ("H", h.as_slice()),
            ("Q_nom", q_nom.as_slice()),
            ("R", r.as_slice()),
            ("x0", x0.as_slice()),
            ("P0", p0.as_slice()),
        ] {
            check_finite(name, values, None)?;
        }
        check_psd("Q_nom", &q_nom)?;
        check_psd("R", &r)?;
        if initial == InitialCovariance::Checked {
            check_psd("P0", &p0)?;
        }
        for (step, z) in measurements.iter().enumerate() {
            if let Some(z) = z {
                if z.len() != m {
                    return Err(TuneError::MeasurementLength {
                        step,
                        expected: m,
                        found: z.len(),
                    });
                }
                check_finite("measurement", z.as_slice(), Some(step))?;
            }
        }
        if measurements.iter().all(Option::is_none) {
            return Err(TuneError::NoMeasurements);
        }
        Ok(Self {
            f,
            h,
            q_nom,
            r,
            x0,
            p0,
            initial,
            measurements,
            truth: None,
            start: Start::PredictFirst,
        })
    }

    /// Adds the true state at each step of the sequence (`None` where unknown), for the RMSE
    /// at every `p` ([`TunePoint::rmse`]).
    ///
    /// # Errors
    /// [`TuneError::TruthSteps`] if the length differs from the measurements',
    /// [`TuneError::TruthLength`] for a state whose length is not `n`,
    /// [`TuneError::NonFinite`] for NaN or infinite values (naming the step).
    pub fn with_truth(mut self, truth: Vec<Option<DVector<f64>>>) -> Result<Self, TuneError> {
        if truth.len() != self.measurements.len() {
            return Err(TuneError::TruthSteps {
                expected: self.measurements.len(),
                found: truth.len(),
            });
        }
        let n = self.state_dim();
        for (step, x) in truth.iter().enumerate() {
            if let Some(x) = x {
                if x.len() != n {
                    return Err(TuneError::TruthLength {
                        step,
                        expected: n,
                        found: x.len(),
                    });
                }
                check_finite("truth", x.as_slice(), Some(step))?;
            }
        }
        self.truth = Some(truth);
        Ok(self)
    }

    /// Where `x0`, `P0` sit relative to the first measurement (default
    /// [`Start::PredictFirst`]: one step before it).
    pub fn with_start(mut self, start: Start) -> Self {
        self.start = start;
        self
    }

    /// The state dimension `n`.
    pub fn state_dim(&self) -> usize {
        self.f.nrows()
    }

    /// The measurement dimension `m`.
    pub fn meas_dim(&self) -> usize {
        self.h.nrows()
    }

    /// The number of steps in the sequence.
    pub fn steps(&self) -> usize {
        self.measurements.len()
    }

    /// The number of measurements present (the filter's updates).
    pub fn updates(&self) -> usize {
        self.measurements.iter().flatten().count()
    }

    /// The transition matrix `F`.
    pub fn f(&self) -> &DMatrix<f64> {
        &self.f
    }

    /// The measurement matrix `H`.
    pub fn h(&self) -> &DMatrix<f64> {
        &self.h
    }

    /// The nominal process noise `Q_nom`.
    pub fn q_nom(&self) -> &DMatrix<f64> {
        &self.q_nom
    }

    /// The measurement noise `R`.
    pub fn r(&self) -> &DMatrix<f64> {
        &self.r
    }

    /// The initial mean `x0`.
    pub fn x0(&self) -> &DVector<f64> {
        &self.x0
    }

    /// The initial covariance `P0`.
    pub fn p0(&self) -> &DMatrix<f64> {
        &self.p0
    }

    /// How `P0` was taken.
    pub fn initial_covariance(&self) -> InitialCovariance {
        self.initial
    }

    /// The measurement sequence.
    pub fn measurements(&self) -> &[Option<DVector<f64>>] {
        &self.measurements
    }

    /// The truth sequence, if given.
    pub fn truth(&self) -> Option<&[Option<DVector<f64>>]> {
        self.truth.as_deref()
    }

    /// The alignment of `x0` and the first measurement.
    pub fn start(&self) -> Start {
        self.start
    }
}

/// What the sums of `J1k` and `J2k` over a run are divided by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JDivisor {
    /// The number of updates (measurements present): `J1`, `J2` are averages over the updates
    /// the filter made, in `[0, m]` whatever the gaps. The default.
    #[default]
    Updates,
    /// The sequence length (the papers' horizon): a step without a measurement counts as zero.
    Steps,
}

/// The options of a tuning sweep: the grid of exponents `p`, threads, the horizon divisor and
/// the position components for the RMSE. [`Tuning::tune`] runs it on a [`TuneProblem`].
///
/// # The method
/// Given `F`, `H`, a nominal `Q_nom`, `R`, `x0`, `P0` and a measurement sequence (with gaps),
/// [`Tuning::tune`] runs a Kalman filter with `Q = 10^p Q_nom` at every exponent `p` of a grid
/// and reports per `p` the horizon averages of the innovation-covariance metrics
/// (`kalibra_metrics::j_step`, notation there): `J1 = tr(S^-1 R)` (sensitivity, falls with `p`)
/// and `J2 = tr((A + B)^-1 B)` (robustness, rises with `p`), both in `[0, m]`, and the
/// process-noise level `nq` in both of the papers' definitions. Where the two curves cross
/// ([`kalibra_metrics::crossover`]: `p_c`, `nq_c`, `J_c`) the papers take the compromise
/// `Q = 10^p_c Q_nom`, the report's recommended `Q`. With a truth sequence the report adds the
/// RMSE at every `p`, so a user with a simulation can see how well the crossover predicted the
/// RMSE optimum.
///
/// # Conventions
/// * Scaling: the filter at `p` uses `Q = Q_nom * 10f64.powf(p)` (this exact expression), in
///   `LinearGaussian::new(F, Q)`; the recommended `Q` is `Q_nom * 10f64.powf(p_c)`.
/// * Alignment ([`Start`]): by default `x0`, `P0` are the estimate at the step before the
///   first measurement (predict first, as in both papers: `x_0` and then `y_1`); measurement
///   `i` of the sequence is then step `i + 1`. [`TuneProblem::with_start`] chooses update
///   first. A `None` measurement is a step the filter predicts through without an update.
/// * Horizon: `J1` and `J2` are sums over the updates divided by [`JDivisor`]: by default the
///   number of updates (measurements present), so that they are averages over the updates the
///   filter made and lie in `[0, m]` whatever the gaps; [`JDivisor::Steps`] divides by the
///   sequence length instead (the papers' horizon, where a missing update counts as zero).
///   `nq` is always averaged over the updates.
/// * Initial covariance: checked (symmetric positive semi-definite) by default;
///   [`TuneProblem::as_given`] is the explicit opt-in for a `P0` taken as given (asymmetric or
///   indefinite, as printed in the 2012 paper), which runs `kalibra_filters::Kf::as_given`
///   and computes the metrics of each update by LU solves in the filter's own arithmetic
///   (the checked `j_step` refuses the asymmetric `A_k` such a run produces). Updates where
///   `A_k + B_k` is not positive definite are counted per point and in the report's findings.
///
/// Points run in parallel ([`crate::sweep`]); each is a deterministic filter run, so the
/// report is identical for any thread count.
#[derive(Clone, Debug, PartialEq)]
pub struct Tuning {
    grid: Vec<f64>,
    threads: usize,
    divisor: JDivisor,
    position: Option<Vec<usize>>,
}

impl Default for Tuning {
    fn default() -> Self {
        Self::new()
    }
}

/// The default grid: `p` from -6 to 6 in steps of 0.5, 25 points computed as
/// `crate::grid(-6.0..=6.0, 0.5)` computes them (`from + i step`; a unit test checks the
/// two agree), written out so that no fallible call sits in a constructor.
fn default_grid() -> Vec<f64> {
    (0..=24).map(|i| -6.0 + f64::from(i) * 0.5).collect()
}

impl Tuning {
    /// The default options: `p` from -6 to 6 in steps of 0.5, rayon's global pool, `J`
    /// averaged over the updates ([`JDivisor::Updates`]), no position components.
    pub fn new() -> Self {
        Self {
            grid: default_grid(),
            threads: 0,
            divisor: JDivisor::Updates,
            position: None,
        }
    }

    /// The grid `from, from + step, ..., to` ([`crate::grid`]: each point
    /// `from + i step`, `to` included within `step / 1000`), as `--p FROM:TO:STEP` gives it.
    ///
    /// # Errors
    /// [`TuneError::InvalidOption`] unless `step > 0`, `to >= from` and all are finite.
    pub fn exponents(mut self, from: f64, to: f64, step: f64) -> Result<Self, TuneError> {
        self.grid = crate::grid(from..=to, step).map_err(|e| match e {
            crate::TuningError::InvalidParameter { name, value } => {
                TuneError::InvalidOption { name, value }
            }
            _ => TuneError::InvalidOption {
                name: "grid",
                value: step,
            },
        })?;
        Ok(self)
    }

    /// An explicit grid of exponents, strictly increasing (checked by [`Tuning::tune`]).
    pub fn grid(mut self, grid: Vec<f64>) -> Self {
        self.grid = grid;
        self
    }

    /// Threads for the sweep (0: rayon's global pool). Results do not depend on it.
    pub fn threads(mut self, threads: usize) -> Self {
        self.threads = threads;
        self
    }

    /// What the `J` sums are divided by (default [`JDivisor::Updates`]).
    pub fn divisor(mut self, divisor: JDivisor) -> Self {
        self.divisor = divisor;
        self
    }

    /// The state components that form the position, for [`PointRmse::position`] (checked
    /// against `n` by [`Tuning::tune`]).
    pub fn position(mut self, components: Vec<usize>) -> Self {
        self.position = Some(components);
        self
    }

    /// The grid of exponents.
    pub fn exponents_grid(&self) -> &[f64] {
        &self.grid
    }

    /// Runs the sweep: a Kalman filter with `Q = Q_nom * 10f64.powf(p)` at every `p` of the
    /// grid, its `J1`, `J2`, `nq` (and RMSE with a truth), the crossover and the recommended
    /// `Q`. Points run in parallel and come back in grid order; the report does not depend on
    /// the thread count.
    ///
    /// ```
    /// use kalibra_tune::{TuneProblem, Tuning};
    /// use kalibra_linalg::{DMatrix, DVector};
    ///
    /// // A scalar random walk seen directly: x_{k+1} = x_k + w, z_k = x_k + v.
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let zs: Vec<Option<DVector<f64>>> = [0.3, -0.1, 0.8, 1.1, 0.6, 1.9, 2.2, 1.7]
    ///     .iter()
    ///     .map(|&z| Some(DVector::from_element(1, z)))
    ///     .collect();
    /// let problem = TuneProblem::new(one(1.0), one(1.0), one(0.1), one(0.5),
    ///     DVector::zeros(1), one(1.0), zs)?;
    /// let report = Tuning::new().exponents(-3.0, 3.0, 0.25)?.tune(&problem)?;
    /// assert_eq!(report.points.len(), 25);
    /// // J1 falls and J2 rises with p; they cross once, and the recommended Q is 10^p_c Q_nom.
    /// let c = report.crossover.expect("J1 and J2 cross on this grid");
    /// let q = report.recommended_q.expect("a crossover gives a Q");
    /// assert!((q[0][0] - 0.1 * 10f64.powf(c.p)).abs() < 1e-12);
    /// # Ok::<(), kalibra_tune::TuneError>(())
    /// ```
    ///
    /// # Errors
    /// [`TuneError::InvalidGrid`] for an empty grid, a non-finite or non-increasing `p` or a
    /// `10^p` that is not a positive finite number; [`TuneError::PositionIndex`] for a
    /// position component beyond `n`; [`TuneError::Model`], [`TuneError::Filter`] and
    /// [`TuneError::Metrics`] for the first failing point in grid order (naming its `p`);
    /// [`TuneError::ThreadPool`] if the thread pool cannot be built.
    pub fn tune(&self, problem: &TuneProblem) -> Result<TuneReport, TuneError> {
        self.check_grid()?;
        let n = problem.state_dim();
        if let Some(position) = &self.position
            && let Some(&index) = position.iter().find(|&&i| i >= n)
        {
            return Err(TuneError::PositionIndex { index, dim: n });
        }
        let divisor = match self.divisor {
            JDivisor::Updates => problem.updates(),
            JDivisor::Steps => problem.steps(),
        };
        let points = crate::sweep(&self.grid, self.threads, |p| {
            point(problem, p, divisor, self.position.as_deref())
        })
        .map_err(|e| match e {
            SimError::Run { source, .. } => source,
            SimError::ThreadPool { threads, message } => TuneError::ThreadPool { threads, message },
            // SimError is non-exhaustive; nothing else is produced by a sweep.
            _ => TuneError::ThreadPool {
                threads: self.threads,
                message: e.to_string(),
            },
        })?;
        let crossing = crossing(&points)?;
        let recommended_q = crossing
            .as_ref()
            .map(|c| rows_of(&(problem.q_nom() * 10f64.powf(c.p))));
        let findings = findings(&points, problem.meas_dim(), crossing.is_some());
        let rmse_minimum = rmse_minimum(&points);
        Ok(TuneReport {
            schema_version: TUNE_SCHEMA_VERSION,
            state_dim: n,
            meas_dim: problem.meas_dim(),
            steps: problem.steps(),
            updates: problem.updates(),
            predict_first: problem.start() == Start::PredictFirst,
            initial_covariance: problem.initial_covariance(),
            divisor: self.divisor,
            divisor_value: divisor,
            q_nom: rows_of(problem.q_nom()),
            points,
            crossover: crossing,
            recommended_q,
            rmse_minimum,
            findings,
        })
    }

    fn check_grid(&self) -> Result<(), TuneError> {
        if self.grid.is_empty() {
            return Err(TuneError::InvalidGrid {
                index: 0,
                p: f64::NAN,
                reason: "is missing: the grid is empty",
            });
        }
        for (index, &p) in self.grid.iter().enumerate() {
            let bad = |reason| Err(TuneError::InvalidGrid { index, p, reason });
            if !p.is_finite() {
                return bad("is not finite");
            }
            let scale = 10f64.powf(p);
            if !(scale.is_finite() && scale.is_normal()) {
                return bad("gives a scale 10^p that is zero, subnormal or infinite");
            }
            if index > 0 && p <= self.grid[index - 1] {
                return bad("does not increase p");
            }
        }
        Ok(())
    }
}

/// The RMSE of one filter run against the truth, over the steps where the truth is given.
///
/// With `e_k = xhat_k - x_k` at every step `k` with a truth (the posterior where there was a
/// measurement, the prediction where there was none): `state = sqrt(mean_k sum_i e_ki^2)`,
/// `per_component[i] = sqrt(mean_k e_ki^2)`, `position = sqrt(mean_k sum_{i in position}
/// e_ki^2)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointRmse {
    /// RMSE of the whole state vector.
    pub state: f64,
    /// RMSE of each component.
    pub per_component: Vec<f64>,
    /// RMSE of the position components ([`Tuning::position`]), if chosen.
    pub position: Option<f64>,
    /// Number of steps with a truth.
    pub steps: usize,
}

/// One point of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TunePoint {
    /// The exponent `p`.
    pub p: f64,
    /// The scale `10^p` applied to `Q_nom`.
    pub scale: f64,
    /// Horizon `J1 = sum_k J1k / divisor`.
    pub j1: f64,
    /// Horizon `J2 = sum_k J2k / divisor`.
    pub j2: f64,
    /// `log10` of the mean of `tr(B_k)` over the updates (the 2014 paper's `nq`); `None` if
    /// not finite (`tr(B_k) = 0` throughout: `Q_nom` unseen by `H`).
    pub nq_log10_mean: Option<f64>,
    /// Mean over the updates of `log10 tr(B_k)` (the 2012 paper's `nq`); `None` if not finite
    /// (some `tr(B_k) = 0`).
    pub nq_mean_log10: Option<f64>,
    /// Updates made (measurements present).
    pub updates: usize,
    /// Updates whose `A_k + B_k` was not positive definite (possible with an indefinite `P0`).
    pub indefinite_updates: usize,
    /// Largest single-update `J1k`.
    pub max_j1k: f64,
    /// Largest single-update `J2k` (above `m` only at an indefinite update).
    pub max_j2k: f64,
    /// RMSE against the truth, if one was given and holds at least one state.
    pub rmse: Option<PointRmse>,
}

/// Where `J1` and `J2` cross ([`kalibra_metrics::crossover`], linear interpolation between
/// the bracketing points).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TuneCrossover {
    /// `p_c`: the recommended `Q` is `Q_nom * 10^p_c`.
    pub p: f64,
    /// `J_c = J1 = J2` at the crossing.
    pub j: f64,
    /// `nq_c` in the 2014 paper's definition (`log10` of the mean `tr(B_k)`); `None` if some
    /// point's is not finite.
    pub nq_log10_mean: Option<f64>,
    /// `nq_c` in the 2012 paper's definition (mean of `log10 tr(B_k)`); `None` if some point's
    /// is not finite.
    pub nq_mean_log10: Option<f64>,
}

/// Which curve lies above along a sweep without a crossing: where to move the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoCrossover {
    /// `J1 > J2` at every point: the crossing lies above the grid (raise its upper end).
    J1AboveJ2,
    /// `J2 > J1` at every point: the crossing lies below the grid (lower its lower end).
    J2AboveJ1,
}

/// What the sweep found that a user should know.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TuneFindings {
    /// Points with at least one update whose `A_k + B_k` was not positive definite.
    pub points_with_indefinite_updates: usize,
    /// Total such updates over all points.
    pub indefinite_updates: usize,
    /// The first such point's `p`.
    pub first_indefinite_p: Option<f64>,
    /// Points whose `J1` or `J2` lies outside `[0, m]` (the papers' bound; broken only by an
    /// indefinite covariance).
    pub points_outside_bounds: usize,
    /// Without a crossing, which curve is above: where the grid should move.
    pub no_crossover: Option<NoCrossover>,
}

/// The point with the smallest RMSE, to set beside the crossover.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RmseMinimum {
    /// `p` of the smallest state RMSE.
    pub p_state: f64,
    /// That RMSE.
    pub state: f64,
    /// `p` of the smallest position RMSE, if positions were chosen.
    pub p_position: Option<f64>,
    /// That RMSE.
    pub position: Option<f64>,
}

/// The result of [`Tuning::tune`], serialisable (what `kalibra tune` writes as JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TuneReport {
    /// [`TUNE_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// `n`.
    pub state_dim: usize,
    /// `m`.
    pub meas_dim: usize,
    /// Length of the measurement sequence.
    pub steps: usize,
    /// Measurements present (updates per run).
    pub updates: usize,
    /// Whether `x0` was one step before the first measurement (else at it).
    pub predict_first: bool,
    /// How `P0` was taken.
    pub initial_covariance: InitialCovariance,
    /// What the `J` sums were divided by.
    pub divisor: JDivisor,
    /// Its value.
    pub divisor_value: usize,
    /// `Q_nom`, row by row.
    pub q_nom: Vec<Vec<f64>>,
    /// Every point, in grid order.
    pub points: Vec<TunePoint>,
    /// The crossing of `J1` and `J2`, if the grid holds one.
    pub crossover: Option<TuneCrossover>,
    /// `Q_nom * 10^p_c`, row by row, if there is a crossing.
    pub recommended_q: Option<Vec<Vec<f64>>>,
    /// The points of smallest RMSE, with a truth.
    pub rmse_minimum: Option<RmseMinimum>,
    /// What the sweep found.
    pub findings: TuneFindings,
}

/// The metrics of one update of a checked filter: the library's `j_step` on the record's
/// projections.
fn j_checked(rec: &StepRecord<Dyn, Dyn>) -> Result<JStep, MetricsError> {
    j_step(
        &rec.compute_a(),
        &rec.compute_b(),
        rec.r(),
        &rec.compute_c(),
    )
}

/// The metrics of one update of an as-given filter, in its own arithmetic: `S_k` as the filter
/// formed it and `A_k + B_k` unsymmetrised, each solved by LU with partial pivoting, as the
/// filter solved for its gain. `a_plus_b_definite` says whether the symmetric part of
/// `A_k + B_k` has a Cholesky factor.
fn j_as_given(rec: &StepRecord<Dyn, Dyn>) -> Result<JStep, MetricsError> {
    let (a, b, c) = (rec.compute_a(), rec.compute_b(), rec.compute_c());
    let ab = &a + &b;
    let s_lu = rec.s_matrix().clone().lu();
    let ab_lu = ab.clone().lu();
    let trace_solve =
        |lu: &kalibra_linalg::nalgebra::LU<f64, Dyn, Dyn>, y: &DMatrix<f64>, what: &'static str| {
            lu.solve(y)
                .map(|z| z.trace())
                .ok_or(MetricsError::Singular { what })
        };
    let j1 = trace_solve(&s_lu, rec.r(), "S")?;
    let j2 = trace_solve(&ab_lu, &b, "A + B")?;
    let tr_n = trace_solve(&ab_lu, &(&a - &c), "A + B")?;
    let tr_b = b.trace();
    if !(j1.is_finite() && j2.is_finite() && tr_n.is_finite() && tr_b.is_finite()) {
        return Err(LinalgError::NonFinite {
            what: "J1/J2 traces (overflow or a singular S or A + B)",
        }
        .into());
    }
    let sym = (&ab + ab.transpose()) * 0.5;
    Ok(JStep {
        j1,
        j2,
        tr_n,
        tr_b,
        a_plus_b_definite: sym.cholesky().is_some(),
    })
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One point: the filter at `Q = Q_nom 10^p` over the sequence, its J horizon and the RMSE.
fn point(
    problem: &TuneProblem,
    p: f64,
    divisor: usize,
    position: Option<&[usize]>,
) -> Result<TunePoint, TuneError> {
    let scale = 10f64.powf(p);
    let dynamics = LinearGaussian::new(problem.f.clone(), &problem.q_nom * scale)
        .map_err(|source| TuneError::Model { p, source })?;
    let sensor = LinearObservation::new(problem.h.clone(), problem.r.clone())
        .map_err(|source| TuneError::Model { p, source })?;
    let (x0, p0) = (problem.x0.clone(), problem.p0.clone());
    let zs = problem.measurements.iter().map(Option::as_ref);
    let filter_err = |source| TuneError::Filter { p, source };
    // The records are needed for J; the estimates at every step only with a truth.
    let (records, estimates): RunOutput = match problem.initial {
        InitialCovariance::Checked => {
            let kf = Kf::new(&dynamics, &sensor, x0, p0).map_err(filter_err)?;
            run(kf, zs, problem.start, problem.truth.is_some()).map_err(filter_err)?
        }
        InitialCovariance::AsGiven => {
            let kf = Kf::as_given(&dynamics, &sensor, x0, p0, FilterOptions::default())
                .map_err(filter_err)?;
            run(kf, zs, problem.start, problem.truth.is_some()).map_err(filter_err)?
        }
    };
    let j_of = match problem.initial {
        InitialCovariance::Checked => j_checked,
        InitialCovariance::AsGiven => j_as_given,
    };
    let mut horizon = JHorizon::new();
    for (update, rec) in records.iter().enumerate() {
        let step = j_of(rec).map_err(|source| TuneError::Metrics { p, update, source })?;
        horizon.push(&step);
    }
    let summary: JSummary = horizon
        .summary(divisor)
        .map_err(|source| TuneError::Metrics {
            p,
            update: records.len(),
            source,
        })?;
    let rmse = match (&problem.truth, &estimates) {
        (Some(truth), Some(estimates)) => point_rmse(truth, estimates, position),
        _ => None,
    };
    Ok(TunePoint {
        p,
        scale,
        j1: summary.j1,
        j2: summary.j2,
        nq_log10_mean: finite(summary.nq_log10_mean),
        nq_mean_log10: finite(summary.nq_mean_log10),
        updates: summary.updates,
        indefinite_updates: summary.indefinite_updates,
        max_j1k: summary.max_j1k,
        max_j2k: summary.max_j2k,
        rmse,
    })
}

type RunOutput = (Vec<StepRecord<Dyn, Dyn>>, Option<Vec<DVector<f64>>>);

/// Runs a filter over the sequence: every update's record and, if asked, the estimate at every
/// step of the sequence (posterior or prediction).
fn run<'z, F: Filter<Dyn, Dyn>>(
    mut filter: F,
    zs: impl Iterator<Item = Option<&'z DVector<f64>>>,
    start: Start,
    estimates: bool,
) -> Result<RunOutput, FilterError> {
    if estimates {
        let trajectory = filter.run_all(zs, start)?;
        let records = trajectory.records().cloned().collect();
        // Entry 0 is the initial estimate; entry i + 1 belongs to sequence index i.
        let means = trajectory.entries()[1..]
            .iter()
            .map(|e| e.mean().clone())
            .collect();
        Ok((records, Some(means)))
    } else {
        Ok((filter.run_collect(zs, start)?, None))
    }
}

fn point_rmse(
    truth: &[Option<DVector<f64>>],
    estimates: &[DVector<f64>],
    position: Option<&[usize]>,
) -> Option<PointRmse> {
    let n = estimates.first()?.len();
    let mut sums = vec![0.0; n];
    let mut steps = 0usize;
    for (x, xhat) in truth.iter().zip(estimates) {
        let Some(x) = x else { continue };
        for (i, sum) in sums.iter_mut().enumerate() {
            let e = xhat[i] - x[i];
            *sum += e * e;
        }
        steps += 1;
    }
    if steps == 0 {
        return None;
    }
    let k = steps as f64;
    let state_sum = sums.iter().sum::<f64>();
    if !state_sum.is_finite() {
        // Errors, or their squares, beyond f64's range (truths and estimates near 1e308):
        // the same sums of halved errors over their largest `s`, scaled back by `2 s`; an
        // ordinary log keeps the plain sums above, bit for bit (`tests/extreme_floats.rs`).
        let halves = || {
            truth.iter().zip(estimates).filter_map(|(x, xhat)| {
                x.as_ref()
                    .map(|x| (0..n).map(move |i| (i, xhat[i] / 2.0 - x[i] / 2.0)))
            })
        };
        let s = halves().flatten().fold(0.0f64, |m, (_, e)| m.max(e.abs()));
        sums = vec![0.0; n];
        for (i, e) in halves().flatten() {
            sums[i] += (e / s) * (e / s);
        }
        let root = |sum: f64| 2.0 * s * (sum / k).sqrt();
        return Some(PointRmse {
            state: root(sums.iter().sum::<f64>()),
            per_component: sums.iter().map(|&s| root(s)).collect(),
            position: position.map(|idx| root(idx.iter().map(|&i| sums[i]).sum::<f64>())),
            steps,
        });
    }
    let root = |sum: f64| (sum / k).sqrt();
    Some(PointRmse {
        state: root(state_sum),
        per_component: sums.iter().map(|&s| root(s)).collect(),
        position: position.map(|idx| root(idx.iter().map(|&i| sums[i]).sum::<f64>())),
        steps,
    })
}

/// The crossing through `kalibra_metrics::crossover`: once with `nq = p` (always finite and
/// increasing) for `p_c` and `J_c`, and once per `nq` definition whose values are all finite.
/// The interpolation weight depends on `J1 - J2` only, so every call brackets the same pair and
/// gives the same `p_c` and `J_c`.
fn crossing(points: &[TunePoint]) -> Result<Option<TuneCrossover>, TuneError> {
    let with_nq = |nq: &dyn Fn(&TunePoint) -> Option<f64>| -> Option<Vec<SweepPoint>> {
        points
            .iter()
            .map(|pt| {
                Some(SweepPoint {
                    p: pt.p,
                    nq: nq(pt)?,
                    j1: pt.j1,
                    j2: pt.j2,
                })
            })
            .collect()
    };
    let cross = |pts: &[SweepPoint]| -> Result<Option<Crossover>, TuneError> {
        crossover(pts).map_err(|source| TuneError::Metrics {
            p: f64::NAN,
            update: 0,
            source,
        })
    };
    let Some(base) = cross(&with_nq(&|pt| Some(pt.p)).unwrap_or_default())? else {
        return Ok(None);
    };
    let nq_of = |nq: &dyn Fn(&TunePoint) -> Option<f64>| -> Result<Option<f64>, TuneError> {
        match with_nq(nq) {
            Some(pts) => Ok(cross(&pts)?.map(|c| c.nq)),
            None => Ok(None),
        }
    };
    Ok(Some(TuneCrossover {
        p: base.p,
        j: base.j,
        nq_log10_mean: nq_of(&|pt| pt.nq_log10_mean)?,
        nq_mean_log10: nq_of(&|pt| pt.nq_mean_log10)?,
    }))
}

fn findings(points: &[TunePoint], m: usize, crossed: bool) -> TuneFindings {
    let m = m as f64;
    let inside = |j: f64| (0.0..=m).contains(&j);
    let no_crossover = if crossed {
        None
    } else if points.iter().all(|pt| pt.j1 > pt.j2) {
        Some(NoCrossover::J1AboveJ2)
    } else if points.iter().all(|pt| pt.j2 > pt.j1) {
        Some(NoCrossover::J2AboveJ1)
    } else {
        None
    };
    TuneFindings {
        points_with_indefinite_updates: points
            .iter()
            .filter(|pt| pt.indefinite_updates > 0)
            .count(),
        indefinite_updates: points.iter().map(|pt| pt.indefinite_updates).sum(),
        first_indefinite_p: points
            .iter()
            .find(|pt| pt.indefinite_updates > 0)
            .map(|pt| pt.p),
        points_outside_bounds: points
            .iter()
            .filter(|pt| !(inside(pt.j1) && inside(pt.j2)))
            .count(),
        no_crossover,
    }
}

fn rmse_minimum(points: &[TunePoint]) -> Option<RmseMinimum> {
    let argmin = |value: &dyn Fn(&PointRmse) -> Option<f64>| -> Option<(f64, f64)> {
        points
            .iter()
            .filter_map(|pt| Some((pt.p, value(pt.rmse.as_ref()?)?)))
            .fold(None, |best: Option<(f64, f64)>, (p, v)| match best {
                Some((_, b)) if b <= v => best,
                _ => Some((p, v)),
            })
    };
    let (p_state, state) = argmin(&|r| Some(r.state))?;
    let position = argmin(&|r| r.position);
    Some(RmseMinimum {
        p_state,
        state,
        p_position: position.map(|(p, _)| p),
        position: position.map(|(_, v)| v),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_is_the_sim_grid() {
        assert_eq!(default_grid(), crate::grid(-6.0..=6.0, 0.5).unwrap());
        assert_eq!(Tuning::new().exponents_grid(), default_grid().as_slice());
    }
}
