//! Autocovariance least squares ([`Als`]): `Qw` and `R` from the autocovariances of a stable
//! filter's innovations.

use kalibra_filters::{FilterError, Start, steady_state};
use kalibra_linalg::{DMatrix, DVector, ldexp, spectral_radius};

use crate::em::{Structure, natural_value, structure};
use crate::{NoiseMatrices, NoiseProblem, Parameter};

/// Singular values of the least-squares matrix at or below this fraction of the largest are
/// taken as zero (its rank, and the minimum-norm solution).
pub const ALS_RANK_TOLERANCE: f64 = 1e-9;

/// The default number of lags `N` (autocovariances `C_0 .. C_{N-1}`).
pub const ALS_LAGS: usize = 10;

/// The cap on the projected-gradient iterations of the semi-definite solution.
pub const ALS_MAX_ITERATIONS: usize = 200_000;

/// What made ALS refuse.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AlsError {
    /// The filter's error dynamics `F (I - L H)` are not stable: its innovations have no
    /// stationary autocovariance.
    #[error("use a stable gain: the spectral radius of F (I - L H) is {spectral_radius}")]
    Unstable {
        /// The spectral radius of `F (I - L H)`.
        spectral_radius: f64,
    },
    /// ALS needs every step measured (a gap makes the innovations non-stationary).
    #[error("estimate by ALS: run {run} has no measurement at step {step}")]
    MissingMeasurement {
        /// The run.
        run: usize,
        /// The step (index into the run's sequence).
        step: usize,
    },
    /// Fewer innovations than lags, after the skipped transient.
    #[error("estimate by ALS: {found} innovations after the transient, need more than {lags}")]
    TooShort {
        /// Innovations available in the longest run.
        found: usize,
        /// The lags asked for.
        lags: usize,
    },
    /// A form or case ALS cannot honour.
    #[error("estimate {what} by ALS: {reason}")]
    Unsupported {
        /// Which matrix.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A setting out of its range.
    #[error("use {name} = {value}")]
    InvalidParameter {
        /// Which setting.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The steady-state gain (when none is given) could not be computed.
    #[error("steady-state gain at the starting point: {0}")]
    Gain(#[source] FilterError),
    /// A computed quantity is not finite (a measurement with NaN, an overflow).
    #[error("estimate by ALS: {what} is not finite")]
    NonFinite {
        /// Which quantity.
        what: &'static str,
    },
}

/// Autocovariance least squares (Odelson, Rajamani and Rawlings 2006, *Automatica* 42) for a
/// time-invariant model, and its settings: the number of lags, the filter gain and the
/// transient skipped.
///
/// # The method
/// A filter with any fixed gain `L` (`x+ = x- + L (z - H x-)`, `x-' = F x+`) whose error
/// dynamics `A = F (I - L H)` are stable has prior errors `e_{k+1} = A e_k + G w_k - F L v_k`
/// and innovations `y_k = H e_k + v_k`. Their stationary autocovariances are linear in
/// `(Qw, R)`: with `P = A P A^T + G Qw G^T + F L R L^T F^T` (a discrete Lyapunov equation),
///
/// `C_0 = H P H^T + R`, `C_j = H A^j P H^T - H A^(j-1) F L R` for `j >= 1`
///
/// (the paper's equations 13-15, with its `A L` written `F L` in kalibra's notation). Stacking
/// `C_0 .. C_{N-1}` and writing `Qw` and `R` through their forms' free entries `theta`
/// (`X = X_fixed + sum_i theta_i B_i`) gives `vec(C(theta)) = D theta + d`. The sample
/// autocovariances `C^_j = 1/(T - j) sum_k y_{k+j} y_k^T` (pooled over runs) give the
/// least-squares problem `min |D theta + d - vec(C^)|^2`.
///
/// # Positive semi-definiteness
/// The unconstrained least-squares solution (the minimum-norm one, by the singular value
/// decomposition of `D`) is returned when both matrices it gives are positive semi-definite.
/// Otherwise the same objective is minimised over the semi-definite matrices of the forms by
/// accelerated projected gradient (FISTA, Beck and Teboulle 2009): the problem is convex (a
/// convex quadratic over a convex set), so this converges to the constrained least-squares
/// solution the paper's semi-definite program computes. The projection is, per matrix:
/// clipping its negative eigenvalues at zero (full form; the free entries are scaled so that
/// the Euclidean norm of `theta` is the Frobenius norm of the matrix, which makes the clip the
/// Euclidean projection), clipping negative diagonal entries (diagonal form), `q >= 0`
/// (scaled form). A full form with fixed entries has no such projection; ALS reports
/// [`AlsError::Unsupported`] when its unconstrained solution is not semi-definite.
///
/// # Uniqueness
/// When `D` has fewer independent columns than free entries (rank below the count, with the
/// singular values at or below [`ALS_RANK_TOLERANCE`] of the largest taken as zero), the data
/// cannot separate the parameters: the estimate is one of many with the same fit, and
/// [`AlsEstimate::unique`] is false ([`AlsEstimate::warning`] says so in words).
///
/// # Checked
/// `tests/als.rs`: on data simulated from known `(Qw, R)`, the estimate's error shrinks as the
/// log grows; with the optimal gain the predicted autocovariances are those of white
/// innovations (a unit test in `als.rs`).
///
/// ```
/// use kalibra_tune::Als;
/// let als = Als::new().lags(15)?.skip(50);
/// assert_eq!(als.lag_count(), 15);
/// # Ok::<(), kalibra_tune::AlsError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Als {
    lags: usize,
    skip: Option<usize>,
    gain: Option<DMatrix<f64>>,
}

impl Default for Als {
    fn default() -> Self {
        Self::new()
    }
}

impl Als {
    /// [`ALS_LAGS`] lags, the steady-state gain of the starting `(Qw, R)`, a transient of
    /// `lags` steps skipped.
    pub fn new() -> Self {
        Self {
            lags: ALS_LAGS,
            skip: None,
            gain: None,
        }
    }

    /// Uses the autocovariances at lags `0 .. lags - 1`.
    ///
    /// # Errors
    /// [`AlsError::InvalidParameter`] for zero lags.
    pub fn lags(mut self, lags: usize) -> Result<Self, AlsError> {
        if lags == 0 {
            return Err(AlsError::InvalidParameter {
                name: "ALS lags",
                value: 0.0,
            });
        }
        self.lags = lags;
        Ok(self)
    }

    /// Leaves out the first `skip` innovations of every run (the filter's transient from
    /// `x0`; the default is the number of lags).
    pub fn skip(mut self, skip: usize) -> Self {
        self.skip = Some(skip);
        self
    }

    /// Runs the filter with the gain `L` (n x m) instead of the steady-state gain of the
    /// starting point.
    pub fn gain(mut self, gain: DMatrix<f64>) -> Self {
        self.gain = Some(gain);
        self
    }

    /// The number of lags.
    pub fn lag_count(&self) -> usize {
        self.lags
    }

    /// Estimates the problem's free noise parameters by ALS; see the type's docs.
    /// The steady-state gain (when no gain is given) is that of the forms' given matrices.
    ///
    /// # Errors
    /// [`AlsError::MissingMeasurement`] for a step without a measurement;
    /// [`AlsError::TooShort`] when no run has more innovations than lags;
    /// [`AlsError::Unstable`] for a gain whose error dynamics are not stable;
    /// [`AlsError::Gain`] when the steady-state gain cannot be computed;
    /// [`AlsError::Unsupported`] for a wrongly sized gain, or a full form with fixed entries
    /// whose least-squares solution is indefinite.
    pub fn estimate(&self, problem: &NoiseProblem) -> Result<AlsEstimate, AlsError> {
        let noise = problem.noise();
        let model = AlsModel {
            f: problem.f(),
            h: problem.h(),
            g: noise.g(),
            x0: problem.x0(),
            start: problem.start(),
        };
        let (qw_form, r_form) = (noise.qw_form(), noise.r_form());
        let mut out = self.solve(
            model,
            (&structure(qw_form), qw_form.value()),
            (&structure(r_form), r_form.value()),
            problem.runs(),
        )?;
        out.parameters = noise.parameters();
        out.values = out
            .parameters
            .iter()
            .map(|p| natural_value(p, qw_form, r_form, &out.matrices.qw, &out.matrices.r))
            .collect();
        if !out.values.iter().all(|v| v.is_finite()) {
            return Err(AlsError::NonFinite {
                what: "multiplier (a finite matrix over a tiny nominal one)",
            });
        }
        Ok(out)
    }

    /// The estimate from the model's known parts, the forms' structures and starting values.
    pub(crate) fn solve(
        &self,
        model: AlsModel<'_>,
        qw: (&Structure, &DMatrix<f64>),
        r: (&Structure, &DMatrix<f64>),
        runs: &[Vec<Option<DVector<f64>>>],
    ) -> Result<AlsEstimate, AlsError> {
        let (n, m) = (model.f.nrows(), model.h.nrows());
        let g = model.g.cloned().unwrap_or_else(|| DMatrix::identity(n, n));
        let gain = match &self.gain {
            Some(l) => {
                if l.shape() != (n, m) {
                    return Err(AlsError::Unsupported {
                        what: "gain L",
                        reason: "the gain must be n x m",
                    });
                }
                l.clone()
            }
            None => {
                steady_state(model.f, model.h, &(&g * qw.1 * g.transpose()), r.1)
                    .map_err(AlsError::Gain)?
                    .gain
            }
        };
        let closed = model.f * (DMatrix::identity(n, n) - &gain * model.h);
        let radius = spectral_radius(&closed).map_err(|_| AlsError::NonFinite {
            what: "F (I - L H)",
        })?;
        if radius.is_nan() || radius >= 1.0 {
            return Err(AlsError::Unstable {
                spectral_radius: radius,
            });
        }
        let skip = self.skip.unwrap_or(self.lags);
        let sample = autocovariances(model, &gain, runs, skip, self.lags)?;

        let mut qw_basis = Basis::of(qw.0, qw.1, "Qw")?;
        let mut r_basis = Basis::of(r.0, r.1, "R")?;
        let response = Response::new(model, &g, &gain, &closed, self.lags);
        let rows = self.lags * m * m;
        let free = qw_basis.matrices.len() + r_basis.matrices.len();
        let mut design = DMatrix::zeros(rows, free);
        for (i, b) in qw_basis.matrices.iter().enumerate() {
            design.set_column(i, &response.of_qw(b));
        }
        for (i, b) in r_basis.matrices.iter().enumerate() {
            design.set_column(qw_basis.matrices.len() + i, &response.of_r(b));
        }
        let target =
            &sample - response.of_qw(&qw_basis.constant) - response.of_r(&r_basis.constant);
        // Checked before solving: the projected iterations would otherwise run to their cap
        // on NaN.
        if !design.iter().all(|v| v.is_finite()) {
            return Err(AlsError::NonFinite {
                what: "autocovariance model (the gain's error dynamics overflow)",
            });
        }
        if !target.iter().all(|v| v.is_finite()) {
            return Err(AlsError::NonFinite {
                what: "least-squares target (the fixed matrices' autocovariances)",
            });
        }
        // The solution is linear in the target and the forms' fixed parts: far from 1 (the
        // autocovariances of measurements near 1e150), it is solved at a power-of-two scale
        // near 1, so that no sum of squares inside overflows or underflows, and scaled back
        // exactly; ordinary scales are solved as they are.
        let shift = crate::noise::max_exponent_of(target.as_slice())
            .filter(|e| e.abs() > 256)
            .unwrap_or(0);
        let target = target.map(|v| ldexp(v, -shift));
        for basis in [&mut qw_basis, &mut r_basis] {
            basis.constant = basis.constant.map(|v| ldexp(v, -shift));
        }
        let back = |v: f64| ldexp(v, shift);

        let (theta, rank, condition) = minimum_norm(&design, &target);
        let split = qw_basis.matrices.len();
        let unconstrained_ok = qw_basis.is_feasible(&theta.rows(0, split).into_owned())
            && r_basis.is_feasible(&theta.rows(split, free - split).into_owned());
        let (theta, constrained, clipped_residual) = if unconstrained_ok {
            (theta, false, None)
        } else {
            for basis in [&qw_basis, &r_basis] {
                if basis.projection == Projection::None {
                    return Err(AlsError::Unsupported {
                        what: basis.what,
                        reason: "a full form with fixed entries has no semi-definite projection, \
                                 and its least-squares solution is indefinite",
                    });
                }
            }
            let mut clipped = theta.clone();
            project_both(&mut clipped, &qw_basis, &r_basis);
            let clipped_residual = back((&design * &clipped - &target).norm());
            let solved = projected(&design, &target, clipped, &qw_basis, &r_basis);
            (solved, true, Some(clipped_residual))
        };
        let residual = back((&design * &theta - &target).norm());
        let qw_hat = qw_basis
            .matrix(&theta.rows(0, split).into_owned())
            .map(back);
        let r_hat = r_basis
            .matrix(&theta.rows(split, free - split).into_owned())
            .map(back);
        let q_hat = &g * &qw_hat * g.transpose();
        if !(qw_hat.iter().chain(r_hat.iter()).chain(q_hat.iter()))
            .chain([&residual])
            .chain(clipped_residual.iter())
            .all(|v| v.is_finite())
        {
            return Err(AlsError::NonFinite {
                what: "estimate (its Qw, R, Q or residual leave the range of f64)",
            });
        }
        Ok(AlsEstimate {
            matrices: NoiseMatrices {
                q: q_hat,
                qw: qw_hat,
                r: r_hat,
            },
            parameters: Vec::new(),
            values: Vec::new(),
            gain,
            free,
            rank,
            condition,
            constrained,
            residual,
            clipped_residual,
            lags: self.lags,
        })
    }
}

/// The model's known parts as ALS needs them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AlsModel<'a> {
    pub(crate) f: &'a DMatrix<f64>,
    pub(crate) h: &'a DMatrix<f64>,
    pub(crate) g: Option<&'a DMatrix<f64>>,
    pub(crate) x0: &'a DVector<f64>,
    pub(crate) start: Start,
}

/// ALS's result.
#[derive(Clone, Debug, PartialEq)]
pub struct AlsEstimate {
    /// The estimate: `Qw`, `R` and `Q = G Qw G^T`.
    pub matrices: NoiseMatrices,
    /// The free parameters, in the parametrisation's order.
    pub parameters: Vec<Parameter>,
    /// Their estimates on the matrices' own scale (an entry, or a scaled form's multiplier).
    pub values: Vec<f64>,
    /// The gain `L` whose innovations were used.
    pub gain: DMatrix<f64>,
    /// The number of free entries estimated.
    pub free: usize,
    /// The rank of the least-squares matrix (`free` when the estimate is unique).
    pub rank: usize,
    /// The ratio of its largest to its smallest singular value (infinite when rank-deficient).
    pub condition: f64,
    /// Whether the semi-definite constraint was active (the unconstrained solution was not
    /// semi-definite and the projected one is returned).
    pub constrained: bool,
    /// The Euclidean norm of the least-squares residual.
    pub residual: f64,
    /// When the constraint was active: the residual of the unconstrained solution with its
    /// matrices merely projected (clipped) onto the semi-definite ones, which the constrained
    /// solution never exceeds.
    pub clipped_residual: Option<f64>,
    /// The lags used.
    pub lags: usize,
}

impl AlsEstimate {
    /// Whether the least-squares problem has one solution (its matrix has full column rank).
    pub fn unique(&self) -> bool {
        self.rank == self.free
    }

    /// The uniqueness warning in words, when the estimate is one of many.
    pub fn warning(&self) -> Option<String> {
        (!self.unique()).then(|| {
            format!(
                "the ALS estimate is not unique: the least-squares matrix has rank {} for {} \
                 free entries, so {} combination(s) of them are not determined by the \
                 autocovariances at {} lags (the minimum-norm solution is reported)",
                self.rank,
                self.free,
                self.free - self.rank,
                self.lags
            )
        })
    }
}

/// The innovations' sample autocovariances `C^_0 .. C^_{lags-1}`, pooled over runs, stacked
/// as `vec(C^_0), vec(C^_1), ...` (column-major).
fn autocovariances(
    model: AlsModel<'_>,
    gain: &DMatrix<f64>,
    runs: &[Vec<Option<DVector<f64>>>],
    skip: usize,
    lags: usize,
) -> Result<DVector<f64>, AlsError> {
    let m = model.h.nrows();
    // The counts are checked before anything is reserved by `lags` (which may be any usize).
    for (run, zs) in runs.iter().enumerate() {
        if let Some(step) = zs.iter().position(Option::is_none) {
            return Err(AlsError::MissingMeasurement { run, step });
        }
    }
    let longest = runs
        .iter()
        .map(|zs| zs.len().saturating_sub(skip))
        .max()
        .unwrap_or(0);
    if longest <= lags {
        return Err(AlsError::TooShort {
            found: longest,
            lags,
        });
    }
    let mut all = Vec::with_capacity(runs.len());
    for (run, zs) in runs.iter().enumerate() {
        let mut x = match model.start {
            Start::UpdateFirst => model.x0.clone(),
            Start::PredictFirst => model.f * model.x0,
        };
        let mut innovations = Vec::with_capacity(zs.len().saturating_sub(skip));
        for (step, z) in zs.iter().enumerate() {
            let z = z
                .as_ref()
                .ok_or(AlsError::MissingMeasurement { run, step })?;
            let y = z - model.h * &x;
            x = model.f * (&x + gain * &y);
            if step >= skip {
                innovations.push(y);
            }
        }
        all.push(innovations);
    }
    // The products are summed at a power-of-two scale that brings the largest innovation near
    // 1 and scaled back after the division by the count: exact, and no sum overflows whose
    // mean is finite (innovations near 1e150 have autocovariances near 1e300).
    let shift = crate::noise::max_exponent_of(
        &all.iter().flatten().map(|y| y.amax()).collect::<Vec<f64>>(),
    )
    .unwrap_or(0);
    let mut sums = vec![DMatrix::<f64>::zeros(m, m); lags];
    let mut counts = vec![0usize; lags];
    for innovations in &all {
        let scaled: Vec<DVector<f64>> = innovations
            .iter()
            .map(|y| y.map(|v| ldexp(v, -shift)))
            .collect();
        for j in 0..lags.min(scaled.len()) {
            for k in 0..scaled.len() - j {
                sums[j] += &scaled[k + j] * scaled[k].transpose();
            }
            counts[j] += scaled.len() - j;
        }
    }
    let mut out = DVector::zeros(lags * m * m);
    for (j, (sum, count)) in sums.iter().zip(&counts).enumerate() {
        let c = (sum / *count as f64).map(|v| ldexp(v, 2 * shift));
        out.rows_mut(j * m * m, m * m).copy_from_slice(c.as_slice());
    }
    if !out.iter().all(|v| v.is_finite()) {
        return Err(AlsError::NonFinite {
            what: "innovation autocovariance",
        });
    }
    Ok(out)
}

/// The autocovariances `C_0 .. C_{N-1}` of the innovations as linear functions of `Qw` and `R`.
struct Response {
    /// `(I - A (x) A)^-1`, LU-factored: `vec(P)` from the Lyapunov equation's right side.
    lyapunov: kalibra_linalg::nalgebra::LU<f64, kalibra_linalg::Dyn, kalibra_linalg::Dyn>,
    g: DMatrix<f64>,
    fl: DMatrix<f64>,
    /// `H A^j`, `j = 0 .. N-1`.
    observed: Vec<DMatrix<f64>>,
    h: DMatrix<f64>,
}

impl Response {
    fn new(
        model: AlsModel<'_>,
        g: &DMatrix<f64>,
        gain: &DMatrix<f64>,
        closed: &DMatrix<f64>,
        lags: usize,
    ) -> Self {
        let n = closed.nrows();
        // The stationary covariance solves vec(P) = (A (x) A) vec(P) + vec(Sigma); A is stable
        // (checked), so I - A (x) A is invertible. n^2 x n^2, fine for the small models ALS
        // is used on.
        let kron = closed.kronecker(closed);
        let lyapunov = (DMatrix::identity(n * n, n * n) - kron).lu();
        let mut observed = Vec::with_capacity(lags);
        let mut power = model.h.clone();
        for _ in 0..lags {
            observed.push(power.clone());
            power = &power * closed;
        }
        Self {
            lyapunov,
            g: g.clone(),
            fl: model.f * gain,
            observed,
            h: model.h.clone(),
        }
    }

    fn stationary(&self, sigma: &DMatrix<f64>) -> DMatrix<f64> {
        let n = sigma.nrows();
        let v = DVector::from_column_slice(sigma.as_slice());
        // The LU of an invertible matrix (A stable) solves; zero otherwise, never reached.
        let p = self
            .lyapunov
            .solve(&v)
            .unwrap_or_else(|| DVector::zeros(n * n));
        DMatrix::from_column_slice(n, n, p.as_slice())
    }

    fn stack(&self, p: &DMatrix<f64>, r: Option<&DMatrix<f64>>) -> DVector<f64> {
        let m = self.h.nrows();
        let mut out = DVector::zeros(self.observed.len() * m * m);
        for (j, hj) in self.observed.iter().enumerate() {
            let mut c = hj * p * self.h.transpose();
            if let Some(r) = r {
                if j == 0 {
                    c += r;
                } else {
                    c -= &self.observed[j - 1] * &self.fl * r;
                }
            }
            out.rows_mut(j * m * m, m * m).copy_from_slice(c.as_slice());
        }
        out
    }

    /// `vec(C_0 .. C_{N-1})` for `Qw = b`, `R = 0`.
    fn of_qw(&self, b: &DMatrix<f64>) -> DVector<f64> {
        let p = self.stationary(&(&self.g * b * self.g.transpose()));
        self.stack(&p, None)
    }

    /// `vec(C_0 .. C_{N-1})` for `Qw = 0`, `R = b`.
    fn of_r(&self, b: &DMatrix<f64>) -> DVector<f64> {
        let p = self.stationary(&(&self.fl * b * self.fl.transpose()));
        self.stack(&p, Some(b))
    }
}

/// How a matrix's free entries are kept semi-definite.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Projection {
    /// No free entry (fixed form).
    Nothing,
    /// Each entry of `theta` non-negative (scaled and diagonal forms).
    NonNegative,
    /// The eigenvalues of the matrix clipped at zero (full form).
    Eigen,
    /// None available (full form with fixed entries).
    None,
}

/// A form's matrix as `constant + sum_i theta_i matrices[i]`.
struct Basis {
    what: &'static str,
    constant: DMatrix<f64>,
    matrices: Vec<DMatrix<f64>>,
    projection: Projection,
}

impl Basis {
    fn of(
        structure: &Structure,
        start: &DMatrix<f64>,
        what: &'static str,
    ) -> Result<Self, AlsError> {
        let d = start.nrows();
        let unit = |i: usize, j: usize| {
            let mut b = DMatrix::zeros(d, d);
            if i == j {
                b[(i, i)] = 1.0;
            } else {
                // Scaled so that |theta| is the Frobenius norm of the matrix.
                b[(i, j)] = std::f64::consts::FRAC_1_SQRT_2;
                b[(j, i)] = std::f64::consts::FRAC_1_SQRT_2;
            }
            b
        };
        Ok(match structure {
            Structure::Fixed => Self {
                what,
                constant: start.clone(),
                matrices: Vec::new(),
                projection: Projection::Nothing,
            },
            Structure::Scaled { nominal } => Self {
                what,
                constant: DMatrix::zeros(d, d),
                matrices: vec![nominal.clone()],
                projection: Projection::NonNegative,
            },
            Structure::Diagonal { fixed } => {
                let mut constant = DMatrix::zeros(d, d);
                let mut matrices = Vec::new();
                for i in 0..d {
                    match fixed.get(i).copied().flatten() {
                        Some(value) => constant[(i, i)] = value,
                        None => matrices.push(unit(i, i)),
                    }
                }
                Self {
                    what,
                    constant,
                    matrices,
                    projection: Projection::NonNegative,
                }
            }
            Structure::Full { fixed } => {
                let mut constant = DMatrix::zeros(d, d);
                let mut matrices = Vec::new();
                for j in 0..d {
                    for i in j..d {
                        match fixed
                            .iter()
                            .find(|(a, b, _)| (*a, *b) == (i, j) || (*a, *b) == (j, i))
                        {
                            Some(&(_, _, value)) => {
                                constant[(i, j)] = value;
                                constant[(j, i)] = value;
                            }
                            None => matrices.push(unit(i, j)),
                        }
                    }
                }
                let projection = if fixed.is_empty() {
                    Projection::Eigen
                } else {
                    Projection::None
                };
                Self {
                    what,
                    constant,
                    matrices,
                    projection,
                }
            }
        })
    }

    fn matrix(&self, theta: &DVector<f64>) -> DMatrix<f64> {
        let mut x = self.constant.clone();
        for (t, b) in theta.iter().zip(&self.matrices) {
            x += b * *t;
        }
        x
    }

    fn is_feasible(&self, theta: &DVector<f64>) -> bool {
        match self.projection {
            Projection::Nothing => true,
            Projection::NonNegative => theta.iter().all(|t| *t >= 0.0),
            Projection::Eigen | Projection::None => {
                let x = self.matrix(theta);
                x.symmetric_eigenvalues().iter().all(|l| *l >= 0.0)
            }
        }
    }

    /// The Euclidean projection of `theta` onto the free entries of semi-definite matrices.
    fn project(&self, theta: &mut DVector<f64>) {
        match self.projection {
            Projection::Nothing | Projection::None => {}
            Projection::NonNegative => theta.iter_mut().for_each(|t| *t = t.max(0.0)),
            Projection::Eigen => {
                let mut eigen = self.matrix(theta).symmetric_eigen();
                eigen.eigenvalues.iter_mut().for_each(|l| *l = l.max(0.0));
                let x = eigen.recompose();
                // Read the free entries back (the inverse of `matrix` for the full form).
                let mut k = 0;
                let d = x.nrows();
                for j in 0..d {
                    for i in j..d {
                        theta[k] = if i == j {
                            x[(i, i)]
                        } else {
                            0.5 * (x[(i, j)] + x[(j, i)]) * std::f64::consts::SQRT_2
                        };
                        k += 1;
                    }
                }
            }
        }
    }
}

/// The minimum-norm least-squares solution of `D theta = b` by the SVD, with the rank and the
/// condition number of `D`.
fn minimum_norm(design: &DMatrix<f64>, target: &DVector<f64>) -> (DVector<f64>, usize, f64) {
    let free = design.ncols();
    if free == 0 {
        return (DVector::zeros(0), 0, 1.0);
    }
    let svd = design.clone().svd(true, true);
    let largest = svd.singular_values.max();
    let cutoff = ALS_RANK_TOLERANCE * largest;
    let rank = svd.singular_values.iter().filter(|s| **s > cutoff).count();
    let smallest = svd.singular_values.min();
    let condition = if rank < free {
        f64::INFINITY
    } else {
        largest / smallest
    };
    // `solve` zeroes the singular values at or below the cutoff: the minimum-norm solution.
    let theta = svd
        .solve(target, cutoff)
        .unwrap_or_else(|_| DVector::zeros(free));
    (theta, rank, condition)
}

/// The projection of `theta` (the free entries of `Qw`, then of `R`) onto semi-definite
/// matrices, block by block.
fn project_both(theta: &mut DVector<f64>, qw: &Basis, r: &Basis) {
    let split = qw.matrices.len();
    let rest = theta.len() - split;
    let mut a = theta.rows(0, split).into_owned();
    let mut b = theta.rows(split, rest).into_owned();
    qw.project(&mut a);
    r.project(&mut b);
    theta.rows_mut(0, split).copy_from(&a);
    theta.rows_mut(split, rest).copy_from(&b);
}

/// FISTA on `|D theta - b|^2` over the semi-definite forms, from the projection of `start`.
fn projected(
    design: &DMatrix<f64>,
    target: &DVector<f64>,
    start: DVector<f64>,
    qw: &Basis,
    r: &Basis,
) -> DVector<f64> {
    let project = |theta: &mut DVector<f64>| project_both(theta, qw, r);
    let normal = design.transpose() * design;
    let rhs = design.transpose() * target;
    // The gradient's Lipschitz constant: the largest eigenvalue of D^T D.
    let lipschitz = normal.symmetric_eigenvalues().max().max(f64::MIN_POSITIVE);
    let mut theta = start;
    project(&mut theta);
    let mut y = theta.clone();
    let mut t = 1.0f64;
    for _ in 0..ALS_MAX_ITERATIONS {
        let mut next = &y - (&normal * &y - &rhs) / lipschitz;
        project(&mut next);
        let t_next = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        let step = &next - &theta;
        let moved = step.norm();
        y = &next + step * ((t - 1.0) / t_next);
        theta = next;
        t = t_next;
        if moved <= 1e-14 * theta.norm().max(f64::MIN_POSITIVE) {
            break;
        }
    }
    theta
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optimal_gain_gives_white_innovations() {
        // With the steady-state Kalman gain of the true (Qw, R), the predicted
        // autocovariances are S at lag 0 and zero at every other lag.
        let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 0.9]);
        let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let g = DMatrix::from_row_slice(2, 1, &[0.125, 0.5]);
        let qw = DMatrix::from_element(1, 1, 0.3);
        let r = DMatrix::from_element(1, 1, 0.2);
        let ss = steady_state(&f, &h, &(&g * &qw * g.transpose()), &r).unwrap();
        let x0 = DVector::zeros(2);
        let model = AlsModel {
            f: &f,
            h: &h,
            g: Some(&g),
            x0: &x0,
            start: Start::UpdateFirst,
        };
        let closed = &f * (DMatrix::identity(2, 2) - &ss.gain * &h);
        let response = Response::new(model, &g, &ss.gain, &closed, 5);
        let c = response.of_qw(&qw) + response.of_r(&r);
        let s = (&h * &ss.prior * h.transpose() + &r)[(0, 0)];
        assert!((c[0] - s).abs() < 1e-10 * s, "{} vs {s}", c[0]);
        assert!(c.rows(1, 4).amax() < 1e-10 * s, "{c}");
    }

    #[test]
    fn projection_of_a_full_form_is_the_eigen_clip() {
        let basis = Basis::of(
            &Structure::Full { fixed: vec![] },
            &DMatrix::identity(2, 2),
            "Qw",
        )
        .unwrap();
        // X = [[1, 2], [2, 1]]: eigenvalues 3 and -1; the clip is 1.5 [[1, 1], [1, 1]].
        let mut theta = DVector::from_vec(vec![1.0, 2.0 * std::f64::consts::SQRT_2, 1.0]);
        assert!(!basis.is_feasible(&theta));
        basis.project(&mut theta);
        let x = basis.matrix(&theta);
        assert!((x - DMatrix::from_element(2, 2, 1.5)).amax() < 1e-12);
    }
}
