//! Paper 000's set-up: the printed `x0`, `P0`, `R` and `Q_nom`, Table I as printed, the
//! claimed crossover range, the readings of what the paper leaves open, and the noise-free
//! position measurements of the shared re-entry truth ([`crate::reentry`]).
//!
//! The paper's eq 18 converts radar range and elevation to Cartesian position with a noise
//! covariance that depends on the range and elevation
//! ([`kalibra_models::ConvertedPosition`]); it calls `sr` and `se` variances, but its values,
//! 100 m and 0.017/57.3 rad, are standard deviations. Its filters use the constant printed `R`
//! instead, and so does this study.

use kalibra_linalg::{Matrix2, Matrix4, SMatrix, Vector2, Vector4};
use serde::Serialize;

use crate::StudyError;
use crate::reentry;

/// The printed initial estimate.
pub fn x0_printed() -> Vector4<f64> {
    Vector4::new(2.25e5, -2.81e3, 9.26e4, 6.75e3)
}

/// The printed initial covariance, entry by entry (asymmetric and indefinite).
pub fn p0_printed() -> Matrix4<f64> {
    Matrix4::new(
        2.48e6, 0.0, -6.76e6, 0.0, //
        0.0, 1.24e6, 0.0, -1.73e6, //
        -6.76e6, 0.0, 1.47e7, 0.0, //
        0.0, -0.73e6, 0.0, 7.34e6,
    )
}

/// The printed measurement-noise covariance.
pub fn r_printed() -> Matrix2<f64> {
    Matrix2::new(10.54, -3.85, -3.85, 37.15)
}

/// The printed nominal process-noise covariance.
pub fn q_nom() -> Matrix4<f64> {
    Matrix4::new(
        2.48e5, 6.32e4, -5.10e5, -1.04e5, //
        6.32e4, 2.34e4, -1.04e5, -2.88e4, //
        -5.10e5, -1.04e5, 1.44e6, 3.45e5, //
        -1.04e5, -2.88e4, 3.45e5, 1.20e5,
    )
}

/// Table I as printed: `(p printed, nq, J1 KF, J2 KF, J1 EKF, J2 EKF)`.
pub const TABLE_I: [(f64, f64, f64, f64, f64, f64); 19] = [
    (-13.0, -6.79, 1.51, 0.00, 1.51, 0.00),
    (-12.0, -5.79, 1.51, 0.00, 1.51, 0.00),
    (-11.0, -4.79, 1.51, 0.00, 1.51, 0.00),
    (-10.0, -3.79, 1.50, 0.00, 1.51, 0.00),
    (-9.0, -2.79, 1.46, 0.00, 1.48, 0.00),
    (-8.0, -1.79, 1.35, 0.01, 1.39, 0.02),
    (-7.0, -0.79, 1.13, 0.07, 1.17, 0.08),
    (-6.0, 0.21, 0.78, 0.30, 0.81, 0.31),
    (-5.0, 1.21, 0.37, 0.80, 0.38, 0.81),
    (-4.0, 2.21, 0.10, 1.31, 0.11, 1.33),
    (-3.0, 3.21, 0.02, 1.59, 0.02, 1.60),
    (-1.0, 4.21, 0.00, 1.65, 0.00, 1.66),
    (0.0, 5.21, 0.00, 1.65, 0.00, 1.66),
    (1.0, 6.21, 0.00, 1.65, 0.00, 1.67),
    (2.0, 7.21, 0.00, 1.75, 0.00, 1.76),
    (3.0, 8.21, 0.00, 1.71, 0.00, 1.72),
    (4.0, 9.21, 0.00, 1.72, 0.00, 1.73),
    (5.0, 10.21, 0.00, 1.72, 0.00, 1.73),
    (6.0, 11.21, 0.00, 1.72, 0.00, 1.73),
];

/// The `p` of Table I's row `i`: `-13 + i` (the printed labels skip -2).
pub fn table_p(row: usize) -> f64 {
    -13.0 + row as f64
}

/// The paper's claim about the crossover: `nq` between 0.21 and 1.21 for both filters.
pub const CROSSOVER_NQ_RANGE: (f64, f64) = (0.21, 1.21);

/// How the filter is started and `P0` is used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum P0Use {
    /// Entry by entry as printed.
    AsPrinted,
    /// `(P0 + P0^T) / 2` (still indefinite).
    Symmetrised,
}

/// One way of reading the paper's set-up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Reading {
    /// Short name, used as the key in `results.json`.
    pub name: &'static str,
    /// What it assumes.
    pub description: &'static str,
    /// The filter starts at step `first_step` (2: after two-point differencing; 0: at once).
    pub first_step: usize,
    /// Divide J1, J2 by the horizon `N = 59` (true) or by the updates run (false).
    pub divide_by_horizon: bool,
    /// Factor applied to the printed `R`.
    pub r_scale: f64,
    /// How `P0` is used.
    pub p0: P0Use,
}

/// The readings the report shows; the first is the one that reproduces Table I.
pub const READINGS: [Reading; 4] = [
    Reading {
        name: "paper",
        description: "start at k = 2 (two-point differencing used y1, y2), divide by N = 59, R as printed / 10, P0 as printed",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 0.1,
        p0: P0Use::AsPrinted,
    },
    Reading {
        name: "paper-symmetric-p0",
        description: "as 'paper', with P0 symmetrised",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 0.1,
        p0: P0Use::Symmetrised,
    },
    Reading {
        name: "paper-r-as-printed",
        description: "as 'paper', with R as printed",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 1.0,
        p0: P0Use::AsPrinted,
    },
    Reading {
        name: "plain",
        description: "start at k = 0 with all 59 measurements, divide by the updates run, R as printed, P0 symmetrised",
        first_step: 0,
        divide_by_horizon: false,
        r_scale: 1.0,
        p0: P0Use::Symmetrised,
    },
];

/// The two filters of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum FilterKind {
    /// Linear KF on the drag-free model.
    Kf,
    /// EKF on the drag model.
    Ekf,
}

/// The fixed inputs of every filter run: noise-free measurements `y_1 .. y_59`.
pub(crate) struct Setup {
    /// `y_k` is `measurements[k - 1]`.
    pub(crate) measurements: Vec<Vector2<f64>>,
}

impl Setup {
    /// Measures the positions of the noise-free truth.
    pub(crate) fn new() -> Result<Self, StudyError> {
        let truth = reentry::noise_free_truth()?;
        Ok(Self {
            measurements: truth[1..]
                .iter()
                .map(|x| Vector2::new(x[0], x[2]))
                .collect(),
        })
    }

    /// The number of measurements, `N = 59`.
    pub(crate) fn horizon(&self) -> usize {
        self.measurements.len()
    }
}

/// The measurement matrix: positions measured, `H = [[1,0,0,0],[0,0,1,0]]`.
pub(crate) fn h() -> SMatrix<f64, 2, 4> {
    SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// The measurement dimension `m`: every `J1k` and `J2k` lies in `[0, m]` for valid covariances.
pub(crate) const M: f64 = 2.0;

/// The index of Table I's J2 spike: the row with the largest printed KF J2.
pub(crate) fn spike_row() -> usize {
    TABLE_I
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.3.total_cmp(&b.1.3))
        .map_or(0, |(i, _)| i)
}
