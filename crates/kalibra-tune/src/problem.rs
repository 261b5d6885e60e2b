//! [`NoiseProblem`]: a time-invariant linear model with parametrised noise and the measurements
//! to estimate the noise from.

use kalibra_filters::Start;
use kalibra_linalg::{DMatrix, DVector, Definiteness, check_covariance};

use crate::{NoiseError, Parametrisation};

/// One run's measurements: one entry per step, `None` where there is no measurement.
pub type Run = Vec<Option<DVector<f64>>>;

/// What the noise estimators work on, checked at construction: the model
/// `x_k = F x_{k-1} + w_k`, `z_k = H x_k + v_k` with `w_k ~ N(0, G Qw G^T)`,
/// `v_k ~ N(0, R)` and the noise [`Parametrisation`]; the initial estimate `x0`, `P0` and
/// where it sits ([`Start`]: predict first, `x0` at the step before the first measurement;
/// update first, `x0` the prior at the first measurement's step); and one or more runs of
/// the same system, each started from `x0`, `P0`.
///
/// ```
/// use kalibra_tune::{CovarianceForm, DMatrix, DVector, NoiseProblem, Parametrisation, Start};
///
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
///     CovarianceForm::scaled(one(1.0)))?;
/// let run = vec![Some(DVector::from_element(1, 0.3)), None, Some(DVector::from_element(1, 0.1))];
/// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(10.0),
///     Start::PredictFirst, noise, vec![run])?;
/// assert_eq!(problem.measurement_count(), 2);
/// # Ok::<(), kalibra_tune::NoiseError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseProblem {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    start: Start,
    noise: Parametrisation,
    runs: Vec<Run>,
    measurements: usize,
}

/// `Ok` if `found` is `expected`, else [`NoiseError::Shape`] naming `matrix`.
pub(crate) fn shape(
    matrix: &'static str,
    found: (usize, usize),
    expected: (usize, usize),
) -> Result<(), NoiseError> {
    if found == expected {
        Ok(())
    } else {
        Err(NoiseError::Shape {
            matrix,
            expected_rows: expected.0,
            expected_cols: expected.1,
            found_rows: found.0,
            found_cols: found.1,
        })
    }
}

impl NoiseProblem {
    /// Checks sizes against the parametrisation (`n` states, `m` measurements), finiteness,
    /// `P0` symmetric positive semi-definite, and every measurement.
    ///
    /// # Errors
    /// [`NoiseError::Shape`] for `F` not `n`x`n`, `H` not `m`x`n`, `x0` not `n`, `P0` not
    /// `n`x`n`; [`NoiseError::NonFinite`] for a non-finite `F`, `H` or `x0`;
    /// [`NoiseError::Matrix`] for a `P0` that is not symmetric positive semi-definite;
    /// [`NoiseError::MeasurementLength`] and [`NoiseError::NonFiniteMeasurement`] (a
    /// missing measurement is `None`, never NaN) naming the run and step;
    /// [`NoiseError::NoMeasurements`] if no step of any run has a measurement.
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
        shape("F", f.shape(), (n, n))?;
        shape("H", h.shape(), (m, n))?;
        shape("x0", x0.shape(), (n, 1))?;
        shape("P0", p0.shape(), (n, n))?;
        for (what, values) in [
            ("F", f.as_slice()),
            ("H", h.as_slice()),
            ("x0", x0.as_slice()),
        ] {
            if values.iter().any(|v| !v.is_finite()) {
                return Err(NoiseError::NonFinite { what });
            }
        }
        check_covariance(&p0, "P0", Definiteness::SemiDefinite).map_err(|source| {
            NoiseError::Matrix {
                matrix: "P0",
                source,
            }
        })?;
        let mut measurements = 0;
        for (r, run) in runs.iter().enumerate() {
            for (k, z) in run.iter().enumerate() {
                let Some(z) = z else { continue };
                if z.len() != m {
                    return Err(NoiseError::MeasurementLength {
                        run: r,
                        step: k,
                        expected: m,
                        found: z.len(),
                    });
                }
                if z.iter().any(|v| !v.is_finite()) {
                    return Err(NoiseError::NonFiniteMeasurement { run: r, step: k });
                }
                measurements += 1;
            }
        }
        if measurements == 0 {
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
            measurements,
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

    /// The initial estimate `x0`.
    pub fn x0(&self) -> &DVector<f64> {
        &self.x0
    }

    /// The initial covariance `P0`.
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

    /// `n`, the states.
    pub fn state_dim(&self) -> usize {
        self.noise.state_dim()
    }

    /// `m`, the measurements.
    pub fn measurement_dim(&self) -> usize {
        self.noise.measurement_dim()
    }

    /// The measurements present, over all runs.
    pub fn measurement_count(&self) -> usize {
        self.measurements
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CovarianceForm;

    fn noise() -> Parametrisation {
        Parametrisation::new(
            None,
            CovarianceForm::scaled(DMatrix::identity(2, 2)),
            CovarianceForm::scaled(DMatrix::identity(1, 1)),
        )
        .unwrap()
    }

    fn build(runs: Vec<Run>) -> Result<NoiseProblem, NoiseError> {
        NoiseProblem::new(
            DMatrix::identity(2, 2),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DVector::zeros(2),
            DMatrix::identity(2, 2),
            Start::UpdateFirst,
            noise(),
            runs,
        )
    }

    #[test]
    fn measurements_are_checked_by_run_and_step() {
        let z = |v: f64| Some(DVector::from_element(1, v));
        assert_eq!(
            build(vec![vec![z(1.0)], vec![None, z(f64::NAN)]]),
            Err(NoiseError::NonFiniteMeasurement { run: 1, step: 1 })
        );
        assert!(matches!(
            build(vec![vec![Some(DVector::zeros(2))]]),
            Err(NoiseError::MeasurementLength {
                run: 0,
                step: 0,
                expected: 1,
                found: 2
            })
        ));
        assert_eq!(
            build(vec![vec![None, None]]),
            Err(NoiseError::NoMeasurements)
        );
        assert_eq!(build(vec![]), Err(NoiseError::NoMeasurements));
        let ok = build(vec![vec![z(1.0), None], vec![z(2.0)]]).unwrap();
        assert_eq!(ok.measurement_count(), 2);
        assert_eq!(ok.runs().len(), 2);
    }

    #[test]
    fn model_sizes_follow_the_parametrisation() {
        let err = NoiseProblem::new(
            DMatrix::identity(3, 3),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DVector::zeros(2),
            DMatrix::identity(2, 2),
            Start::UpdateFirst,
            noise(),
            vec![vec![Some(DVector::zeros(1))]],
        );
        assert!(matches!(err, Err(NoiseError::Shape { matrix: "F", .. })));
    }
}
