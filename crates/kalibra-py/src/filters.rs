//! The filters on numpy arrays: `KalmanFilter` (kalibra's `Kf` on run-time sizes),
//! `ExtendedKalmanFilter` and `UnscentedKalmanFilter` (kalibra's `Ekf` and `Ukf` on models
//! whose functions are Python callables, see `callbacks`).

use kalibra_filters::smooth::{Smoothable, Smoothed};
use kalibra_filters::{
    Ekf, Filter, FilterError, KappaCriterion, KappaGrid, Kf, SigmaSet, SigmaSpace, SqrtKf, SqrtUkf,
    Start, StepRecord, Ukf,
};
use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_models::{LinearGaussian, LinearObservation};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use crate::arrays::{Array, new_array, read};
use crate::callbacks::{Failure, PyDynamics, PyMeasurement};
use crate::error;

/// A matrix argument of shape `(rows, cols)`.
fn matrix(obj: &Bound<'_, PyAny>, name: &str, rows: usize, cols: usize) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    if a.shape != [rows, cols] {
        return Err(error(format!(
            "argument {name} has shape {:?}; expected ({rows}, {cols})",
            a.shape
        )));
    }
    Ok(DMatrix::from_row_slice(rows, cols, &a.data))
}

/// `x0` as a vector of `n >= 1` values.
fn initial_mean(x0: &Bound<'_, PyAny>) -> PyResult<DVector<f64>> {
    let x0 = read(x0, "x0")?;
    match x0.shape.as_slice() {
        [n] if *n > 0 => Ok(DVector::from_vec(x0.data)),
        other => Err(error(format!(
            "argument x0 has shape {other:?}; expected (n,) with n >= 1"
        ))),
    }
}

/// A square covariance argument whose size `m` is read from it.
fn square(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    match a.shape.as_slice() {
        [r, c] if r == c && *r > 0 => Ok(DMatrix::from_row_slice(*r, *c, &a.data)),
        other => Err(error(format!(
            "argument {name} has shape {other:?}; expected a square matrix (m, m)"
        ))),
    }
}

fn start_of(start: &str) -> PyResult<Start> {
    match start {
        "predict_first" => Ok(Start::PredictFirst),
        "update_first" => Ok(Start::UpdateFirst),
        other => Err(error(format!(
            "argument start is {other:?}; expected \"predict_first\" or \"update_first\""
        ))),
    }
}

/// The measurements as `(runs, rows, batch)`: `(K, m)` or `(R, K, m)`.
fn layout(z: &Array, m: usize) -> PyResult<(usize, usize, bool)> {
    match z.shape.as_slice() {
        [k, mm] if *mm == m => Ok((1, *k, false)),
        [r, k, mm] if *mm == m => Ok((*r, *k, true)),
        other => Err(error(format!(
            "argument measurements has shape {other:?}; expected (K, {m}) or (R, K, {m}) (the \
             measurement has {m} components)"
        ))),
    }
}

/// The rows of one run: a measurement, or `None` for a row of NaN.
fn rows(z: &[f64], m: usize) -> Result<Vec<Option<DVector<f64>>>, String> {
    z.chunks(m)
        .enumerate()
        .map(|(k, row)| match row.iter().filter(|v| v.is_nan()).count() {
            0 => Ok(Some(DVector::from_column_slice(row))),
            nan if nan == m => Ok(None),
            _ => Err(format!(
                "row {k} holds NaN in some components only; a row is a measurement or all NaN \
                 (none)"
            )),
        })
        .collect()
}

/// The outputs of one run: per row of the measurements, row-major.
#[derive(Default)]
pub(crate) struct Outputs {
    pub estimate: Vec<f64>,
    pub covariance: Vec<f64>,
    pub prior: Vec<f64>,
    pub prior_covariance: Vec<f64>,
    pub innovation: Vec<f64>,
    pub innovation_cov: Vec<f64>,
    pub nis: Vec<f64>,
    pub log_likelihood: Vec<f64>,
    /// The UKF's kappa at each update (empty for other filters).
    pub kappa: Vec<f64>,
    /// The smoothers' lag-one covariance per row (empty for `run`).
    pub lag_one: Vec<f64>,
}

/// One field of [`Outputs`].
type Field = fn(&Outputs) -> &Vec<f64>;

fn push_matrix(out: &mut Vec<f64>, m: &DMatrix<f64>) {
    // nalgebra stores columns; numpy wants rows (read in place: a transposed copy would be an
    // allocation per matrix and step).
    for i in 0..m.nrows() {
        out.extend((0..m.ncols()).map(|j| m[(i, j)]));
    }
}

/// Runs `filter` over `zs` as `Filter::run_all` does (predict, then update where there is a
/// measurement), recording every row; `after` sees the filter after each row.
pub(crate) fn run_filter<F: Filter<Dyn, Dyn>>(
    filter: &mut F,
    zs: &[Option<DVector<f64>>],
    start: Start,
    mut after: impl FnMut(&F, bool, &mut Outputs),
) -> Result<Outputs, FilterError> {
    let mut out = Outputs::default();
    for (i, z) in zs.iter().enumerate() {
        if i > 0 || start == Start::PredictFirst {
            filter.predict()?;
        }
        match z {
            Some(z) => {
                let rec = filter.update(z)?;
                out.prior.extend(rec.prior().mean.iter());
                push_matrix(&mut out.prior_covariance, &rec.prior().cov);
                out.innovation.extend(rec.innovation().iter());
                push_matrix(&mut out.innovation_cov, rec.s_matrix());
                out.nis.push(rec.nis());
                out.log_likelihood.push(rec.log_likelihood());
            }
            None => {
                let m = zs.iter().flatten().next().map_or(0, |z| z.len());
                out.prior.extend(filter.mean().iter());
                push_matrix(&mut out.prior_covariance, filter.covariance());
                out.innovation.extend(std::iter::repeat_n(f64::NAN, m));
                out.innovation_cov
                    .extend(std::iter::repeat_n(f64::NAN, m * m));
                out.nis.push(f64::NAN);
                out.log_likelihood.push(f64::NAN);
            }
        }
        out.estimate.extend(filter.mean().iter());
        push_matrix(&mut out.covariance, filter.covariance());
        after(filter, z.is_some(), &mut out);
    }
    Ok(out)
}

/// The outputs of every run as a dict of arrays, with a leading run axis for a batch.
fn outputs_dict<'py>(
    py: Python<'py>,
    outputs: &[Outputs],
    (runs, rows, batch): (usize, usize, bool),
    (n, m): (usize, usize),
) -> PyResult<Bound<'py, PyDict>> {
    let lead = if batch { vec![runs, rows] } else { vec![rows] };
    let shape = |tail: &[usize]| [lead.as_slice(), tail].concat();
    let gather =
        |f: Field| -> Vec<f64> { outputs.iter().flat_map(|o| f(o).iter().copied()).collect() };
    let mut fields: Vec<(&str, Vec<usize>, Field)> = vec![
        ("estimate", shape(&[n]), |o| &o.estimate),
        ("covariance", shape(&[n, n]), |o| &o.covariance),
        ("prior", shape(&[n]), |o| &o.prior),
        ("prior_covariance", shape(&[n, n]), |o| &o.prior_covariance),
        ("innovation", shape(&[m]), |o| &o.innovation),
        ("innovation_cov", shape(&[m, m]), |o| &o.innovation_cov),
        ("nis", shape(&[]), |o| &o.nis),
        ("log_likelihood", shape(&[]), |o| &o.log_likelihood),
    ];
    if outputs
        .first()
        .is_some_and(|o| o.kappa.len() == rows && rows > 0)
    {
        fields.push(("kappa", shape(&[]), |o| &o.kappa));
    }
    let dict = PyDict::new(py);
    for (key, shape, field) in fields {
        dict.set_item(key, new_array(py, &shape, gather(field)))?;
    }
    Ok(dict)
}

/// The error of run `r` (named only in a batch).
fn run_error(batch: bool, r: usize, e: impl std::fmt::Display) -> PyErr {
    let run = if batch {
        format!(" run {r}:")
    } else {
        String::new()
    };
    error(format!("argument measurements:{run} {e}"))
}

/// Which algebra a filter runs: the covariance (`"standard"`) or a Cholesky factor of it
/// (`"square_root"`, kalibra's `SqrtKf` and `SqrtUkf`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Form {
    Standard,
    SquareRoot,
}

fn form_of(form: &str) -> PyResult<Form> {
    match form {
        "standard" => Ok(Form::Standard),
        "square_root" => Ok(Form::SquareRoot),
        other => Err(error(format!(
            "argument form is {other:?}; expected \"standard\" or \"square_root\""
        ))),
    }
}

/// A filter of either form, so that `run` and `smooth` drive one value whatever the form.
enum EitherForm<A, B> {
    Standard(A),
    SquareRoot(B),
}

impl<A: Smoothable<Dyn, Dyn>, B: Smoothable<Dyn, Dyn>> Filter<Dyn, Dyn> for EitherForm<A, B> {
    fn step_index(&self) -> usize {
        match self {
            Self::Standard(f) => f.step_index(),
            Self::SquareRoot(f) => f.step_index(),
        }
    }
    fn mean(&self) -> &DVector<f64> {
        match self {
            Self::Standard(f) => f.mean(),
            Self::SquareRoot(f) => f.mean(),
        }
    }
    fn covariance(&self) -> &DMatrix<f64> {
        match self {
            Self::Standard(f) => f.covariance(),
            Self::SquareRoot(f) => f.covariance(),
        }
    }
    fn predict(&mut self) -> Result<(), FilterError> {
        match self {
            Self::Standard(f) => f.predict(),
            Self::SquareRoot(f) => f.predict(),
        }
    }
    fn update(&mut self, z: &DVector<f64>) -> Result<&StepRecord<Dyn, Dyn>, FilterError> {
        match self {
            Self::Standard(f) => f.update(z),
            Self::SquareRoot(f) => f.update(z),
        }
    }
    fn last_record(&self) -> Option<&StepRecord<Dyn, Dyn>> {
        match self {
            Self::Standard(f) => f.last_record(),
            Self::SquareRoot(f) => f.last_record(),
        }
    }
}

impl<A: Smoothable<Dyn, Dyn>, B: Smoothable<Dyn, Dyn>> Smoothable<Dyn, Dyn> for EitherForm<A, B> {
    fn predict_with_cross(&mut self) -> Result<DMatrix<f64>, FilterError> {
        match self {
            Self::Standard(f) => f.predict_with_cross(),
            Self::SquareRoot(f) => f.predict_with_cross(),
        }
    }
    fn smoother_space(&self) -> Option<std::sync::Arc<dyn SigmaSpace<Dyn>>> {
        match self {
            Self::Standard(f) => f.smoother_space(),
            Self::SquareRoot(f) => f.smoother_space(),
        }
    }
    // Each form's own smoother: the square-root KF's backward pass runs on its factors.
    fn smooth<'z, I>(&mut self, measurements: I, start: Start) -> Result<Smoothed<Dyn>, FilterError>
    where
        I: IntoIterator<Item = Option<&'z DVector<f64>>>,
    {
        match self {
            Self::Standard(f) => f.smooth(measurements, start),
            Self::SquareRoot(f) => f.smooth(measurements, start),
        }
    }
}

/// The linear Kalman filter `x_k = F x_{k-1} + w`, `z_k = H x_k + v`, `w ~ N(0, Q)`,
/// `v ~ N(0, R)`, run in Rust (kalibra's `Kf`: Joseph-form update, the gain by a Cholesky solve
/// with S, every covariance symmetrised).
///
/// Args:
///     F: (n, n) transition matrix.
///     H: (m, n) measurement matrix.
///     Q: (n, n) process noise covariance, symmetric positive semi-definite.
///     R: (m, m) measurement noise covariance, symmetric positive semi-definite.
///     x0: (n,) initial mean.
///     P0: (n, n) initial covariance, symmetric positive semi-definite.
///     start: "predict_first" (default, FilterPy's order: x0 is one step before the first
///         measurement, so each row is predict then update) or "update_first" (x0 is the prior
///         at the first measurement).
///     form: "standard" (default) or "square_root": kalibra's `SqrtKf`, which carries a
///         Cholesky factor of the covariance (QR prediction, array-form update) and stays
///         positive definite where the standard form's covariance stops being so (a
///         near-perfect measurement against a large prior). The same outputs; `smooth` runs
///         the square-root RTS smoother (its backward pass on the factors too), which
///         carries on where the standard smoother fails.
///
/// Raises:
///     KalibraError: a wrong shape (naming the argument), a non-finite matrix, a Q, R or P0 that
///         is not symmetric positive semi-definite, an unknown form.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> kf = kalibra.KalmanFilter(F=[[1.0, 1.0], [0.0, 1.0]], H=[[1.0, 0.0]],
///     ...                           Q=0.01 * np.eye(2), R=[[1.0]], x0=[0.0, 1.0], P0=np.eye(2))
///     >>> z = np.array([[1.1], [np.nan], [2.9], [4.2]])   # no measurement at row 1
///     >>> out = kf.run(z)
///     >>> out["estimate"].shape, out["covariance"].shape, out["nis"].shape
///     ((4, 2), (4, 2, 2), (4,))
///     >>> bool(np.isnan(out["nis"][1]))
///     True
#[pyclass(module = "kalibra", frozen)]
pub struct KalmanFilter {
    dynamics: LinearGaussian<Dyn>,
    sensor: LinearObservation<Dyn, Dyn>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    start: Start,
    form: Form,
    n: usize,
    m: usize,
}

/// The filter of a `KalmanFilter`, of either form.
type AnyKf<'a> = EitherForm<
    Kf<Dyn, Dyn, &'a LinearGaussian<Dyn>, &'a LinearObservation<Dyn, Dyn>>,
    SqrtKf<Dyn, Dyn, &'a LinearGaussian<Dyn>, &'a LinearObservation<Dyn, Dyn>>,
>;

impl KalmanFilter {
    /// The filter at (x0, P0): the one construction `new` (to check x0 and P0), `run` and
    /// `smooth` go through.
    fn build(&self) -> Result<AnyKf<'_>, FilterError> {
        let (x0, p0) = (self.x0.clone(), self.p0.clone());
        Ok(match self.form {
            Form::Standard => EitherForm::Standard(Kf::new(&self.dynamics, &self.sensor, x0, p0)?),
            Form::SquareRoot => {
                EitherForm::SquareRoot(SqrtKf::new(&self.dynamics, &self.sensor, x0, p0)?)
            }
        })
    }
}

#[pymethods]
impl KalmanFilter {
    #[new]
    #[pyo3(signature = (F, H, Q, R, x0, P0, start="predict_first", form="standard"))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        F: &Bound<'_, PyAny>,
        H: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        start: &str,
        form: &str,
    ) -> PyResult<Self> {
        let x0 = initial_mean(x0)?;
        let n = x0.len();
        let h_array = read(H, "H")?;
        let m = match h_array.shape.as_slice() {
            [m, cols] if *cols == n && *m > 0 => *m,
            other => {
                return Err(error(format!(
                    "argument H has shape {other:?}; expected (m, {n}) (x0 has {n} components)"
                )));
            }
        };
        let h = DMatrix::from_row_slice(m, n, &h_array.data);
        let f = matrix(F, "F", n, n)?;
        let q = matrix(Q, "Q", n, n)?;
        let r = matrix(R, "R", m, m)?;
        let p0 = matrix(P0, "P0", n, n)?;
        let start = start_of(start)?;
        let form = form_of(form)?;
        let model = |e: kalibra_models::ModelError| error(e.to_string());
        let dynamics = LinearGaussian::new(f, q).map_err(model)?;
        let sensor = LinearObservation::new(h, r).map_err(model)?;
        let filter = Self {
            dynamics,
            sensor,
            x0,
            p0,
            start,
            form,
            n,
            m,
        };
        // Checks x0 and P0 once, here, so that a bad one is an error of the constructor.
        filter
            .build()
            .map_err(|e| error(format!("arguments x0, P0: {e}")))?;
        Ok(filter)
    }

    /// The state dimension n.
    #[getter]
    fn state_dim(&self) -> usize {
        self.n
    }

    /// The measurement dimension m.
    #[getter]
    fn measurement_dim(&self) -> usize {
        self.m
    }

    /// Runs the filter from (x0, P0) over a measurement sequence, or over R sequences at once.
    ///
    /// Args:
    ///     measurements: (K, m), one row per step; a row of NaN has no measurement (the filter
    ///         predicts through it). Or (R, K, m): R independent runs, each from (x0, P0),
    ///         run in parallel.
    ///     threads: for (R, K, m): 0 for rayon's pool (one thread per core), 1 for none, or a
    ///         count. The results do not depend on it.
    ///
    /// Returns:
    ///     dict[str, numpy.ndarray]: per row (and run), with a leading R axis for (R, K, m):
    ///     "estimate" (K, n) and "covariance" (K, n, n), the posterior (the prediction at rows
    ///     without a measurement); "prior" (K, n) and "prior_covariance" (K, n, n);
    ///     "innovation" (K, m) and "innovation_cov" (K, m, m), the residual and its covariance
    ///     S; "nis" (K,); "log_likelihood" (K,), ln N(innovation; 0, S). The last four are NaN
    ///     at rows without a measurement. The names are `evaluate`'s arguments.
    ///
    /// Raises:
    ///     KalibraError: a wrong shape, a row that is NaN in some components only, a step
    ///         whose S is not positive definite or whose output is not finite (naming the run
    ///         and step).
    #[pyo3(signature = (measurements, threads=0))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
        threads: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let z = read(measurements, "measurements")?;
        let (runs, k, batch) = layout(&z, self.m)?;
        let size = k * self.m;
        let one = |r: usize| -> PyResult<Outputs> {
            let zs = rows(&z.data[r * size..(r + 1) * size], self.m)
                .map_err(|e| run_error(batch, r, e))?;
            let mut kf = self.build().map_err(|e| error(e.to_string()))?;
            run_filter(&mut kf, &zs, self.start, |_, _, _| {})
                .map_err(|e| run_error(batch, r, format!("{e} (x0 is step 0)")))
        };
        // Runs are independent: in parallel, results in run order, and the error of the first
        // failing run whatever the thread count.
        let outputs = py.detach(|| {
            let all: Vec<PyResult<Outputs>> = match threads {
                1 => (0..runs).map(one).collect(),
                0 => (0..runs).into_par_iter().map(one).collect(),
                t => rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .map_err(|e| error(format!("argument threads: {e}")))?
                    .install(|| (0..runs).into_par_iter().map(one).collect()),
            };
            all.into_iter().collect::<PyResult<Vec<Outputs>>>()
        })?;
        outputs_dict(py, &outputs, (runs, k, batch), (self.n, self.m))
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.KalmanFilter n={} m={} start={:?} form={:?}>",
            self.n, self.m, self.start, self.form
        )
    }

    /// Runs the filter from (x0, P0) over (K, m) measurements (a row of NaN: none) or (R, K, m)
    /// for R runs, and smooths every run with the Rauch-Tung-Striebel smoother (kalibra's
    /// `smooth` module: Cholesky solves with the predicted covariance, symmetrised).
    ///
    /// Returns:
    ///     dict[str, numpy.ndarray], shaped as `run`'s outputs: "estimate" (K, n) and
    ///     "covariance" (K, n, n), each row's state given all the measurements of its run;
    ///     "lag_one_covariance" (K, n, n), Cov(x_k, x_{k-1} | all z) with the row before (for
    ///     row 0 with the initial state x0 under "predict_first"; NaN under "update_first").
    ///
    /// Raises:
    ///     KalibraError: as `run`, and a predicted covariance without a Cholesky factor
    ///         (naming the run and step).
    ///
    /// Example:
    ///     >>> import numpy as np, kalibra
    ///     >>> kf = kalibra.KalmanFilter(F=[[1.0, 1.0], [0.0, 1.0]], H=[[1.0, 0.0]],
    ///     ...                           Q=0.01 * np.eye(2), R=[[1.0]], x0=[0.0, 1.0], P0=np.eye(2))
    ///     >>> out = kf.smooth(np.array([[1.1], [np.nan], [2.9], [4.2]]))
    ///     >>> out["estimate"].shape, out["lag_one_covariance"].shape
    ///     ((4, 2), (4, 2, 2))
    ///     >>> bool(np.allclose(out["estimate"][-1], kf.run([[1.1], [np.nan], [2.9], [4.2]])["estimate"][-1]))
    ///     True
    fn smooth<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let z = read(measurements, "measurements")?;
        let (runs, k, batch) = layout(&z, self.m)?;
        let size = k * self.m;
        let outputs = (0..runs)
            .map(|r| {
                let zs = rows(&z.data[r * size..(r + 1) * size], self.m)
                    .map_err(|e| run_error(batch, r, e))?;
                let mut kf = self.build().map_err(|e| error(e.to_string()))?;
                smooth_rows(&mut kf, &zs, self.start)
                    .map_err(|e| run_error(batch, r, format!("{e} (x0 is step 0)")))
            })
            .collect::<PyResult<Vec<Outputs>>>()?;
        smoothed_dict(py, &outputs, (runs, k, batch), self.n)
    }
}

/// What the EKF and the UKF share: the callables, the noise and the initial estimate.
struct CallbackModel {
    f: Py<PyAny>,
    f_jacobian: Option<Py<PyAny>>,
    h: Py<PyAny>,
    h_jacobian: Option<Py<PyAny>>,
    residual: Option<Py<PyAny>>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    start: Start,
}

impl CallbackModel {
    #[allow(clippy::too_many_arguments)]
    fn new(
        callables: [(&str, Option<&Bound<'_, PyAny>>); 5],
        q: &Bound<'_, PyAny>,
        r: &Bound<'_, PyAny>,
        x0: &Bound<'_, PyAny>,
        p0: &Bound<'_, PyAny>,
        start: &str,
    ) -> PyResult<Self> {
        let mut taken = Vec::with_capacity(5);
        for (name, obj) in callables {
            match obj.filter(|o| !o.is_none()) {
                Some(o) if o.is_callable() => taken.push(Some(o.clone().unbind())),
                Some(o) => {
                    return Err(error(format!(
                        "argument {name} is not callable (a {})",
                        o.get_type()
                    )));
                }
                None => taken.push(None),
            }
        }
        let [f, f_jacobian, h, h_jacobian, residual]: [Option<Py<PyAny>>; 5] =
            taken.try_into().map_err(|_| error("callables"))?;
        let x0 = initial_mean(x0)?;
        let n = x0.len();
        let q = matrix(q, "Q", n, n)?;
        let r = square(r, "R")?;
        let p0 = matrix(p0, "P0", n, n)?;
        let model = Self {
            f: f.ok_or_else(|| error("argument f is required"))?,
            f_jacobian,
            h: h.ok_or_else(|| error("argument h is required"))?,
            h_jacobian,
            residual,
            q,
            r,
            x0,
            p0,
            start: start_of(start)?,
        };
        // Q and R as kalibra's linear models check them (symmetric positive semi-definite).
        let n = model.x0.len();
        LinearGaussian::new(DMatrix::identity(n, n), model.q.clone())
            .map_err(|e| error(e.to_string()))?;
        LinearObservation::new(DMatrix::zeros(model.r.nrows(), n), model.r.clone())
            .map_err(|e| error(e.to_string()))?;
        Ok(model)
    }

    fn dynamics<'a>(&'a self, failure: &'a Failure) -> PyDynamics<'a> {
        PyDynamics {
            f: &self.f,
            jacobian: self.f_jacobian.as_ref(),
            q: &self.q,
            failure,
        }
    }

    fn measurement<'a>(&'a self, failure: &'a Failure) -> PyMeasurement<'a> {
        PyMeasurement {
            h: &self.h,
            jacobian: self.h_jacobian.as_ref(),
            residual: self.residual.as_ref(),
            r: &self.r,
            n: self.x0.len(),
            failure,
        }
    }

    /// Runs every run of `measurements` through `run_one` (which builds a filter on the
    /// model's callables with this failure cell and runs it), with the GIL held (the callables
    /// need it), returning the outputs and their layout `(runs, rows, batch)`. A callable's
    /// failure is raised in place of the filter's error.
    fn run_outputs(
        &self,
        py: Python<'_>,
        measurements: &Bound<'_, PyAny>,
        run_one: impl Fn(&Failure, &[Option<DVector<f64>>]) -> Result<Outputs, FilterError>,
    ) -> PyResult<(Vec<Outputs>, (usize, usize, bool))> {
        let m = self.r.nrows();
        let z = read(measurements, "measurements")?;
        let (runs, k, batch) = layout(&z, m)?;
        let size = k * m;
        let mut outputs = Vec::with_capacity(runs);
        for r in 0..runs {
            let zs =
                rows(&z.data[r * size..(r + 1) * size], m).map_err(|e| run_error(batch, r, e))?;
            let failure = Failure::default();
            let result = run_one(&failure, &zs);
            if let Some(e) = failure.take() {
                if batch {
                    // The run in front, the callable's own exception kept as the cause.
                    let wrapped = error(format!("run {r}: {}", e.value(py)));
                    wrapped.set_cause(py, e.cause(py));
                    return Err(wrapped);
                }
                return Err(e);
            }
            outputs.push(result.map_err(|e| run_error(batch, r, format!("{e} (x0 is step 0)")))?);
        }
        Ok((outputs, (runs, k, batch)))
    }

    /// [`CallbackModel::run_outputs`] as `run`'s dict of arrays.
    fn run<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
        run_one: impl Fn(&Failure, &[Option<DVector<f64>>]) -> Result<Outputs, FilterError>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (outputs, layout) = self.run_outputs(py, measurements, run_one)?;
        outputs_dict(py, &outputs, layout, (self.x0.len(), self.r.nrows()))
    }
}

/// The extended Kalman filter on your own model, given as Python callables:
/// `x_k = f(x_{k-1}, k-1) + w`, `z_k = h(x_k, k) + v`, `w ~ N(0, Q)`, `v ~ N(0, R)`, with the
/// Jacobians `F_jacobian(x, k)` (n, n) and `H_jacobian(x, k)` (m, n). kalibra's `Ekf` runs the
/// algebra in Rust (Joseph-form update, Cholesky solves) and calls back into Python for the
/// model: four calls per step (f, F_jacobian, h, H_jacobian), plus residual if given.
///
/// Cost: each step crosses into Python four times (a numpy array in, one out), so a step
/// costs several times KalmanFilter's and still less than FilterPy's ExtendedKalmanFilter;
/// `crates/kalibra-py/bench/callbacks.py` prints the figures. The model's own Python work
/// comes on top.
///
/// Args:
///     f: f(x, k) -> (n,), the state at step k + 1 from x at step k.
///     F_jacobian: F_jacobian(x, k) -> (n, n), df/dx at x.
///     h: h(x, k) -> (m,), the measurement of x at step k.
///     H_jacobian: H_jacobian(x, k) -> (m, n), dh/dx at x.
///     Q: (n, n), R: (m, m) noise covariances, symmetric positive semi-definite.
///     x0: (n,), P0: (n, n) the initial estimate.
///     residual: residual(z, zhat) -> (m,), for measurements with angles (wrap into
///         (-pi, pi]); default z - zhat.
///     start: "predict_first" (default, FilterPy's order) or "update_first".
///
/// The callables receive x as a new float64 array; vectors may come back as (n,), (n, 1) or
/// (1, n). An exception in a callable, or a result of the wrong shape, stops the run with a
/// KalibraError naming the callable and the step (the exception as its __cause__).
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> F = np.array([[1.0, 1.0], [0.0, 1.0]])
///     >>> ekf = kalibra.ExtendedKalmanFilter(
///     ...     f=lambda x, k: F @ x, F_jacobian=lambda x, k: F,
///     ...     h=lambda x, k: np.array([np.hypot(x[0], 10.0)]),       # range to a point
///     ...     H_jacobian=lambda x, k: np.array([[x[0] / np.hypot(x[0], 10.0), 0.0]]),
///     ...     Q=0.01 * np.eye(2), R=[[0.25]], x0=[0.0, 1.0], P0=np.eye(2))
///     >>> out = ekf.run(np.array([[10.1], [10.2], [10.4]]))
///     >>> out["estimate"].shape
///     (3, 2)
#[pyclass(module = "kalibra", frozen)]
pub struct ExtendedKalmanFilter {
    model: CallbackModel,
}

#[pymethods]
impl ExtendedKalmanFilter {
    #[new]
    #[pyo3(signature = (f, F_jacobian, h, H_jacobian, Q, R, x0, P0, *, residual=None, start="predict_first"))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        f: &Bound<'_, PyAny>,
        F_jacobian: &Bound<'_, PyAny>,
        h: &Bound<'_, PyAny>,
        H_jacobian: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        residual: Option<&Bound<'_, PyAny>>,
        start: &str,
    ) -> PyResult<Self> {
        let model = CallbackModel::new(
            [
                ("f", Some(f)),
                ("F_jacobian", Some(F_jacobian)),
                ("h", Some(h)),
                ("H_jacobian", Some(H_jacobian)),
                ("residual", residual),
            ],
            Q,
            R,
            x0,
            P0,
            start,
        )?;
        if model.f_jacobian.is_none() || model.h_jacobian.is_none() {
            return Err(error(
                "arguments F_jacobian and H_jacobian are required (callables)",
            ));
        }
        let failure = Failure::default();
        Ekf::new(
            model.dynamics(&failure),
            model.measurement(&failure),
            model.x0.clone(),
            model.p0.clone(),
        )
        .map_err(|e| error(format!("arguments x0, P0: {e}")))?;
        Ok(Self { model })
    }

    /// Runs the filter from (x0, P0) over (K, m) measurements (a row of NaN: none) or (R, K, m)
    /// for R runs; returns the arrays of `KalmanFilter.run`.
    fn run<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let model = &self.model;
        model.run(py, measurements, |failure, zs| {
            let mut ekf = Ekf::new(
                model.dynamics(failure),
                model.measurement(failure),
                model.x0.clone(),
                model.p0.clone(),
            )?;
            run_filter(&mut ekf, zs, model.start, |_, _, _| {})
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.ExtendedKalmanFilter n={} m={}>",
            self.model.x0.len(),
            self.model.r.nrows()
        )
    }

    /// Runs the filter and smooths each run with the extended RTS smoother (the forward
    /// pass's linearisation: F_jacobian at each filtered estimate, the one the prediction
    /// used); returns the arrays of `KalmanFilter.smooth`.
    fn smooth<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let model = &self.model;
        let (outputs, layout) = model.run_outputs(py, measurements, |failure, zs| {
            let mut ekf = Ekf::new(
                model.dynamics(failure),
                model.measurement(failure),
                model.x0.clone(),
                model.p0.clone(),
            )?;
            smooth_rows(&mut ekf, zs, model.start)
        })?;
        smoothed_dict(py, &outputs, layout, model.x0.len())
    }
}

/// The unscented Kalman filter on your own model, given as Python callables:
/// `x_k = f(x_{k-1}, k-1) + w`, `z_k = h(x_k, k) + v`, `w ~ N(0, Q)`, `v ~ N(0, R)`; no
/// Jacobians. kalibra's `Ukf` runs the algebra in Rust and calls f and h once per sigma point
/// (2n + 1 each per step; with an adaptive kappa, h once per point and grid value).
///
/// Cost: one callback per sigma point and function (18 per step on a 4-state model), so the
/// crossings into Python dominate, and a step still costs less than FilterPy's
/// UnscentedKalmanFilter; `crates/kalibra-py/bench/callbacks.py` prints the figures.
///
/// The prediction pushes the posterior's sigma points through f; the update draws new sigma
/// points from the prior (x-, P-) and pushes them through h. (FilterPy's UKF reuses the
/// predicted points in the update instead; the two agree when FilterPy's points are redrawn
/// from the prior between predict and update.)
///
/// Args:
///     f, h: f(x, k) -> (n,), h(x, k) -> (m,), as for ExtendedKalmanFilter.
///     Q: (n, n), R: (m, m), x0: (n,), P0: (n, n).
///     points: "symmetric" (Julier and Uhlmann: lambda = kappa, FilterPy's
///         JulierSigmaPoints) or "scaled" (Wan and van der Merwe: lambda = alpha^2 (n + kappa)
///         - n, FilterPy's MerweScaledSigmaPoints).
///     kappa: default 3 - n for n <= 3 and 0 otherwise (symmetric), 0 (scaled).
///     alpha, beta: of the scaled set (defaults 1.0 and 2.0).
///     adaptive_kappa: None, "maximum_likelihood" (minimise log|Pz| + nu' Pz^-1 nu at every
///         update) or "maximum_posterior", choosing kappa from kappa_grid at every update.
///     kappa_grid: the candidate values (required with adaptive_kappa).
///     residual: residual(z, zhat) -> (m,) for angles; start: as for KalmanFilter.
///     form: "standard" (default) or "square_root" (kalibra's `SqrtUkf`: the same points from
///         a Cholesky factor carried by QR factorisations, positive definite where the
///         standard form's covariance stops being so), with or without adaptive_kappa.
///
/// Returns of run: the arrays of `KalmanFilter.run`, and "kappa" (K,): the kappa of each
/// update (NaN without a measurement).
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> F = np.array([[1.0, 1.0], [0.0, 1.0]])
///     >>> ukf = kalibra.UnscentedKalmanFilter(
///     ...     f=lambda x, k: F @ x, h=lambda x, k: np.array([np.hypot(x[0], 10.0)]),
///     ...     Q=0.01 * np.eye(2), R=[[0.25]], x0=[0.0, 1.0], P0=np.eye(2),
///     ...     adaptive_kappa="maximum_likelihood", kappa_grid=[0.0, 1.0, 2.0])
///     >>> out = ukf.run(np.array([[10.1], [10.2], [10.4]]))
///     >>> sorted(set(out["kappa"].tolist())) <= [0.0, 1.0, 2.0]
///     True
#[pyclass(module = "kalibra", frozen)]
pub struct UnscentedKalmanFilter {
    model: CallbackModel,
    set: SigmaSet,
    adaptive: Option<(KappaCriterion, KappaGrid)>,
    form: Form,
}

/// The filter of an `UnscentedKalmanFilter`, of either form.
type AnyUkf<'a> = EitherForm<
    Ukf<Dyn, Dyn, PyDynamics<'a>, PyMeasurement<'a>>,
    SqrtUkf<Dyn, Dyn, PyDynamics<'a>, PyMeasurement<'a>>,
>;

impl AnyUkf<'_> {
    /// The kappa of the last update (the chosen one when adapting).
    fn last_kappa(&self) -> Option<f64> {
        match self {
            Self::Standard(ukf) => ukf.last_kappa(),
            Self::SquareRoot(ukf) => ukf.last_kappa(),
        }
    }
}

impl UnscentedKalmanFilter {
    fn build<'a>(
        &self,
        model: &'a CallbackModel,
        failure: &'a Failure,
    ) -> Result<AnyUkf<'a>, FilterError> {
        let (dynamics, measurement) = (model.dynamics(failure), model.measurement(failure));
        let (x0, p0) = (model.x0.clone(), model.p0.clone());
        if self.form == Form::SquareRoot {
            let ukf = SqrtUkf::new(dynamics, measurement, x0, p0, self.set)?;
            return Ok(EitherForm::SquareRoot(match &self.adaptive {
                Some((criterion, grid)) => ukf.with_adaptive_kappa(*criterion, grid.clone())?,
                None => ukf,
            }));
        }
        let ukf = Ukf::new(dynamics, measurement, x0, p0, self.set)?;
        Ok(EitherForm::Standard(match &self.adaptive {
            Some((criterion, grid)) => ukf.with_adaptive_kappa(*criterion, grid.clone())?,
            None => ukf,
        }))
    }
}

#[pymethods]
impl UnscentedKalmanFilter {
    #[new]
    #[pyo3(signature = (
        f, h, Q, R, x0, P0, *, points="symmetric", kappa=None, alpha=1.0, beta=2.0,
        adaptive_kappa=None, kappa_grid=None, residual=None, start="predict_first",
        form="standard"
    ))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        f: &Bound<'_, PyAny>,
        h: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        points: &str,
        kappa: Option<f64>,
        alpha: f64,
        beta: f64,
        adaptive_kappa: Option<&str>,
        kappa_grid: Option<Vec<f64>>,
        residual: Option<&Bound<'_, PyAny>>,
        start: &str,
        form: &str,
    ) -> PyResult<Self> {
        let form = form_of(form)?;
        let model = CallbackModel::new(
            [
                ("f", Some(f)),
                ("F_jacobian", None),
                ("h", Some(h)),
                ("H_jacobian", None),
                ("residual", residual),
            ],
            Q,
            R,
            x0,
            P0,
            start,
        )?;
        let n = model.x0.len();
        let set = match points {
            "symmetric" => match kappa {
                Some(kappa) => SigmaSet::Symmetric { kappa },
                None => SigmaSet::recommended(n),
            },
            "scaled" => SigmaSet::Scaled {
                alpha,
                beta,
                kappa: kappa.unwrap_or(0.0),
            },
            other => {
                return Err(error(format!(
                    "argument points is {other:?}; expected \"symmetric\" or \"scaled\""
                )));
            }
        };
        let invalid = |e: FilterError| error(e.to_string());
        let adaptive = match (adaptive_kappa, kappa_grid) {
            (None, None) => None,
            (None, Some(_)) => {
                return Err(error(
                    "argument kappa_grid is given without adaptive_kappa (\"maximum_likelihood\" \
                     or \"maximum_posterior\")",
                ));
            }
            (Some(_), None) => {
                return Err(error(
                    "argument adaptive_kappa needs kappa_grid, the candidate values of kappa",
                ));
            }
            (Some(criterion), Some(grid)) => {
                let criterion = match criterion {
                    "maximum_likelihood" => KappaCriterion::MaximumLikelihood,
                    "maximum_posterior" => KappaCriterion::MaximumPosterior,
                    other => {
                        return Err(error(format!(
                            "argument adaptive_kappa is {other:?}; expected \
                             \"maximum_likelihood\" or \"maximum_posterior\""
                        )));
                    }
                };
                Some((criterion, KappaGrid::new(grid).map_err(invalid)?))
            }
        };
        let filter = Self {
            model,
            set,
            adaptive,
            form,
        };
        let failure = Failure::default();
        filter
            .build(&filter.model, &failure)
            .map_err(|e| error(format!("invalid filter: {e}")))?;
        Ok(filter)
    }

    /// Runs the filter from (x0, P0) over (K, m) measurements (a row of NaN: none) or (R, K, m)
    /// for R runs; returns the arrays of `KalmanFilter.run` and "kappa".
    fn run<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        self.model.run(py, measurements, |failure, zs| {
            let mut ukf = self.build(&self.model, failure)?;
            run_filter(&mut ukf, zs, self.model.start, |ukf, updated, out| {
                out.kappa.push(match (updated, ukf.last_kappa()) {
                    (true, Some(kappa)) => kappa,
                    _ => f64::NAN,
                });
            })
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.UnscentedKalmanFilter n={} m={} {:?} form={:?}>",
            self.model.x0.len(),
            self.model.r.nrows(),
            self.set,
            self.form
        )
    }

    /// Runs the filter and smooths each run with the unscented RTS smoother (Sarkka 2008,
    /// the filter's own sigma points through f); returns the arrays of
    /// `KalmanFilter.smooth`. The unscented prediction calls f at the sigma points a second
    /// time to form the smoother's cross-covariance.
    fn smooth<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (outputs, layout) = self.model.run_outputs(py, measurements, |failure, zs| {
            let mut ukf = self.build(&self.model, failure)?;
            smooth_rows(&mut ukf, zs, self.model.start)
        })?;
        smoothed_dict(py, &outputs, layout, self.model.x0.len())
    }
}

/// Runs `filter` over `zs` and smooths the run: per row, the smoothed estimate, covariance
/// and lag-one covariance (NaN where the row has no predecessor in the pass). With
/// predict_first the pass's first step is x0, which is no row.
fn smooth_rows<F: Smoothable<Dyn, Dyn>>(
    filter: &mut F,
    zs: &[Option<DVector<f64>>],
    start: Start,
) -> Result<Outputs, FilterError> {
    let smoothed = filter.smooth(zs.iter().map(Option::as_ref), start)?;
    let steps = smoothed.steps();
    let mut out = Outputs::default();
    for step in &steps[steps.len().saturating_sub(zs.len())..] {
        out.estimate.extend(step.mean().iter());
        push_matrix(&mut out.covariance, step.covariance());
        match step.lag_one() {
            Some(lag_one) => push_matrix(&mut out.lag_one, lag_one),
            None => {
                let n = step.mean().len();
                out.lag_one.extend(std::iter::repeat_n(f64::NAN, n * n));
            }
        }
    }
    Ok(out)
}

/// The smoothed outputs of every run as a dict of arrays, shaped as `outputs_dict`'s.
fn smoothed_dict<'py>(
    py: Python<'py>,
    outputs: &[Outputs],
    (runs, rows, batch): (usize, usize, bool),
    n: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let lead = if batch { vec![runs, rows] } else { vec![rows] };
    let shape = |tail: &[usize]| [lead.as_slice(), tail].concat();
    let fields: [(&str, Vec<usize>, Field); 3] = [
        ("estimate", shape(&[n]), |o| &o.estimate),
        ("covariance", shape(&[n, n]), |o| &o.covariance),
        ("lag_one_covariance", shape(&[n, n]), |o| &o.lag_one),
    ];
    let dict = PyDict::new(py);
    for (key, shape, field) in fields {
        let data = outputs
            .iter()
            .flat_map(|o| field(o).iter().copied())
            .collect();
        dict.set_item(key, new_array(py, &shape, data))?;
    }
    Ok(dict)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<KalmanFilter>()?;
    m.add_class::<ExtendedKalmanFilter>()?;
    m.add_class::<UnscentedKalmanFilter>()?;
    Ok(())
}
