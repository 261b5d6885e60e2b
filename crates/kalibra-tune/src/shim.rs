//! Minimal stand-ins for the parametrisation types of the `noise` and `problem` modules, which
//! another branch is writing (not merged when the estimators were): the same names and signatures for the part EM, ALS and the
//! parameter sweep use, so that their code compiles and is tested here. On merging with
//! `noise`, this file is deleted and `lib.rs` re-exports `noise`'s types instead (the
//! estimators need no change); `noise` is the one definition of these types.

use kalibra_filters::Start;
use kalibra_linalg::{DMatrix, DVector};

/// Why a noise parametrisation or an estimation problem was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseError {
    /// A matrix or vector has the wrong size.
    #[error("matrix {matrix} has the wrong size")]
    Shape {
        /// The matrix's name.
        matrix: &'static str,
    },
    /// More free parameters than innovations can identify.
    #[error("estimate {free} noise parameters: at most {limit} are identifiable")]
    TooManyParameters {
        /// The free parameters asked for.
        free: usize,
        /// `n m + m (m + 1) / 2`.
        limit: usize,
    },
    /// No step of any run has a measurement.
    #[error("estimate noise from a log without measurements")]
    NoMeasurements,
}

/// Which noise matrix a form or a parameter belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum NoiseMatrix {
    /// The process noise of the channels, `Qw`.
    Qw,
    /// The measurement noise `R`.
    R,
}

/// What is known of a noise covariance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum FormKind {
    /// The given matrix, nothing estimated.
    Fixed,
    /// A positive multiple of the given (nominal) matrix.
    Scaled,
    /// A diagonal matrix, each diagonal entry free (unless fixed).
    Diagonal,
    /// Any symmetric positive-definite matrix.
    Full,
}

/// A noise covariance's form, its given matrix and the entries held at their given values.
#[derive(Clone, Debug, PartialEq)]
pub struct CovarianceForm {
    kind: FormKind,
    value: DMatrix<f64>,
    fixed: Vec<(usize, usize)>,
}

impl CovarianceForm {
    /// The given matrix, nothing estimated.
    pub fn fixed(value: DMatrix<f64>) -> Self {
        Self::of(FormKind::Fixed, value)
    }
    /// A positive multiple of the nominal matrix.
    pub fn scaled(nominal: DMatrix<f64>) -> Self {
        Self::of(FormKind::Scaled, nominal)
    }
    /// A diagonal matrix starting at `start`.
    pub fn diagonal(start: DMatrix<f64>) -> Self {
        Self::of(FormKind::Diagonal, start)
    }
    /// Any symmetric positive-definite matrix starting at `start`.
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
    /// Holds entry `(row, col)` (and its mirror) at the given matrix's value.
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
    /// Whether entry `(row, col)` is held at its given value.
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
    /// The free parameters of this form.
    fn parameters(&self, matrix: NoiseMatrix) -> Vec<Parameter> {
        let name = match matrix {
            NoiseMatrix::Qw => "Qw",
            NoiseMatrix::R => "R",
        };
        let entry = |i: usize, j: usize| Parameter {
            name: format!("{name}[{i},{j}]"),
            matrix,
            entry: Some((i, j)),
            kind: if i == j {
                ParameterKind::Variance
            } else {
                ParameterKind::Covariance
            },
        };
        let d = self.dim();
        match self.kind {
            FormKind::Fixed => Vec::new(),
            FormKind::Scaled => vec![Parameter {
                name: match matrix {
                    NoiseMatrix::Qw => "q".to_owned(),
                    NoiseMatrix::R => "r".to_owned(),
                },
                matrix,
                entry: None,
                kind: ParameterKind::Multiplier,
            }],
            FormKind::Diagonal | FormKind::Full => (0..d)
                .flat_map(|i| (0..=i).map(move |j| (i, j)))
                .filter(|&(i, j)| !self.is_fixed(i, j))
                .map(|(i, j)| entry(i, j))
                .collect(),
        }
    }
}

/// What a free parameter is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ParameterKind {
    /// The multiplier of a scaled form.
    Multiplier,
    /// A diagonal entry.
    Variance,
    /// An off-diagonal entry of a full form.
    Covariance,
}

/// One free parameter on the matrices' own scale.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Parameter {
    /// `q` or `r` for a multiplier, `Qw[i,j]` or `R[i,j]` (`i >= j`) for an entry.
    pub name: String,
    /// The matrix it belongs to.
    pub matrix: NoiseMatrix,
    /// The entry `(i, j)`, `i >= j`; `None` for a multiplier.
    pub entry: Option<(usize, usize)>,
    /// What it is.
    pub kind: ParameterKind,
}

/// The noise matrices of one candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseMatrices {
    /// `Qw` (g x g).
    pub qw: DMatrix<f64>,
    /// `R` (m x m).
    pub r: DMatrix<f64>,
    /// `Q = G Qw G^T` (n x n).
    pub q: DMatrix<f64>,
}

/// `Q = G Qw G^T` with an optional `G` and the forms of `Qw` and `R`.
#[derive(Clone, Debug, PartialEq)]
pub struct Parametrisation {
    g: Option<DMatrix<f64>>,
    qw: CovarianceForm,
    r: CovarianceForm,
}

impl Parametrisation {
    /// Checks `G`'s size and the number of free parameters.
    ///
    /// # Errors
    /// [`NoiseError::Shape`] for a `G` whose columns are not `Qw`'s size;
    /// [`NoiseError::TooManyParameters`] beyond `n m + m (m + 1) / 2`.
    pub fn new(
        g: Option<DMatrix<f64>>,
        qw: CovarianceForm,
        r: CovarianceForm,
    ) -> Result<Self, NoiseError> {
        if g.as_ref().is_some_and(|g| g.ncols() != qw.dim()) {
            return Err(NoiseError::Shape { matrix: "G" });
        }
        let out = Self { g, qw, r };
        let (n, m) = (out.state_dim(), out.measurement_dim());
        let (free, limit) = (out.parameters().len(), n * m + m * (m + 1) / 2);
        if free > limit {
            return Err(NoiseError::TooManyParameters { free, limit });
        }
        Ok(out)
    }
    /// `n`, the states.
    pub fn state_dim(&self) -> usize {
        self.g.as_ref().map_or(self.qw.dim(), DMatrix::nrows)
    }
    /// `m`, the measurements.
    pub fn measurement_dim(&self) -> usize {
        self.r.dim()
    }
    /// `G`, if given.
    pub fn g(&self) -> Option<&DMatrix<f64>> {
        self.g.as_ref()
    }
    /// The form of `Qw`.
    pub fn qw_form(&self) -> &CovarianceForm {
        &self.qw
    }
    /// The form of `R`.
    pub fn r_form(&self) -> &CovarianceForm {
        &self.r
    }
    /// The free parameters, those of `Qw` first.
    pub fn parameters(&self) -> Vec<Parameter> {
        let mut out = self.qw.parameters(NoiseMatrix::Qw);
        out.extend(self.r.parameters(NoiseMatrix::R));
        out
    }
}

/// One run's measurements: one entry per step, `None` where there is no measurement.
pub type Run = Vec<Option<DVector<f64>>>;

/// A time-invariant linear model with parametrised noise and the runs to estimate it from.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseProblem {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    start: Start,
    noise: Parametrisation,
    runs: Vec<Run>,
}

impl NoiseProblem {
    /// Checks the sizes and that some step has a measurement.
    ///
    /// # Errors
    /// [`NoiseError::Shape`], [`NoiseError::NoMeasurements`].
    pub fn new(
        f: DMatrix<f64>,
        h: DMatrix<f64>,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        start: Start,
        noise: Parametrisation,
        runs: Vec<Run>,
    ) -> Result<Self, NoiseError> {
        let (n, m) = (noise.state_dim(), noise.measurement_dim());
        for (matrix, found, expected) in [
            ("F", f.shape(), (n, n)),
            ("H", h.shape(), (m, n)),
            ("x0", x0.shape(), (n, 1)),
            ("P0", p0.shape(), (n, n)),
        ] {
            if found != expected {
                return Err(NoiseError::Shape { matrix });
            }
        }
        if runs.iter().flatten().flatten().any(|z| z.len() != m) {
            return Err(NoiseError::Shape {
                matrix: "measurement",
            });
        }
        if runs.iter().flatten().all(Option::is_none) {
            return Err(NoiseError::NoMeasurements);
        }
        Ok(Self {
            f,
            h,
            x0,
            p0,
            start,
            noise,
            runs,
        })
    }
    /// `F`.
    pub fn f(&self) -> &DMatrix<f64> {
        &self.f
    }
    /// `H`.
    pub fn h(&self) -> &DMatrix<f64> {
        &self.h
    }
    /// `x0`.
    pub fn x0(&self) -> &DVector<f64> {
        &self.x0
    }
    /// `P0`.
    pub fn p0(&self) -> &DMatrix<f64> {
        &self.p0
    }
    /// Where `x0`, `P0` sit.
    pub fn start(&self) -> Start {
        self.start
    }
    /// The noise parametrisation.
    pub fn noise(&self) -> &Parametrisation {
        &self.noise
    }
    /// The runs.
    pub fn runs(&self) -> &[Run] {
        &self.runs
    }
}
