//! Paper 003's set-up: the published values (J1max, J2max, the crossover, the plateau edges),
//! Tables II and III, the radar noise, the truth's process noise, the readings of the horizon
//! divisor, and the noise-free radar measurements of the shared re-entry truth
//! ([`crate::reentry`]).

use kalibra_linalg::{Matrix3, Matrix4, Vector3, Vector4};
use kalibra_models::{Measurement, RadarRates};
use serde::Serialize;

use crate::StudyError;
use crate::reentry;

/// Number of measurements `m`.
pub const M: usize = 3;
/// Published `J1max`.
pub const J1MAX: f64 = 2.72;
/// Published `J2max`.
pub const J2MAX: f64 = 2.91;
/// Published crossover `nq`.
pub const CROSSOVER_NQ: f64 = 2.11;
/// Published J at the crossover (printed as "Q_comp = 1.49").
pub const CROSSOVER_J: f64 = 1.49;
/// Published plateau edges: J1 = J1max for `nq < -2.18`, J2 = J2max for `nq > 5.82`.
pub const PLATEAU_EDGES: (f64, f64) = (-2.18, 5.82);
/// Tolerance for "at the plateau": the printed two decimals.
pub(crate) const PLATEAU_TOLERANCE: f64 = 0.005;

/// Table II's initial estimate.
pub fn x0_table() -> Vector4<f64> {
    Vector4::new(2.336e5, -0.022e5, 0.889e5, -0.004e5)
}

/// Table II's `P0` with the (1,3) sign corrected to `+22.38e3` (symmetric positive definite).
pub fn p0_table() -> Matrix4<f64> {
    Matrix4::new(
        99.39, -0.56, 22.38, -1.73, //
        -0.56, 0.23, -0.01, 0.04, //
        22.38, -0.01, 9.15, -0.58, //
        -1.73, 0.04, -0.58, 0.09,
    ) * 1e3
}

/// Table III's `Q_nom`.
pub fn q_nom() -> Matrix4<f64> {
    Matrix4::new(
        20.80, 0.06, -0.96, -0.40, //
        0.06, 0.06, -0.12, 0.01, //
        -0.96, -0.12, 6.00, 0.13, //
        -0.40, 0.01, 0.13, 0.04,
    ) * 1e2
}

/// The radar noise `R = Rt`.
pub fn r() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(
        15.0 * 15.0,
        (0.1f64 / 57.3).powi(2),
        (0.01f64 / 57.3).powi(2),
    ))
}

/// The truth's process noise `Qt = blockdiag([[T^3/3, T^2/2], [T^2/2, T]] x 2)`.
pub fn qt() -> Matrix4<f64> {
    let t = reentry::T;
    let (a, b, c) = (t * t * t / 3.0, t * t / 2.0, t);
    Matrix4::new(
        a, b, 0.0, 0.0, //
        b, c, 0.0, 0.0, //
        0.0, 0.0, a, b, //
        0.0, 0.0, b, c,
    )
}

/// One reading of the horizon average.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Reading {
    /// Key in `results.json`.
    pub name: &'static str,
    /// What it assumes.
    pub description: &'static str,
    /// The divisor of the horizon averages.
    pub divisor: usize,
}

/// The two readings; the first reproduces the published values.
pub const READINGS: [Reading; 2] = [
    Reading {
        name: "paper",
        description: "averages over t = 0 .. 118 s: J1, J2 and mean tr(B_k) divided by 60 (59 updates run)",
        divisor: 60,
    },
    Reading {
        name: "plain",
        description: "averages over the 59 updates that run",
        divisor: 59,
    },
];

/// Names of the four states, in state order (`x1` down-range, `x2` altitude).
pub const STATE_NAMES: [&str; 4] = ["x1", "x1dot", "x2", "x2dot"];

/// The fixed inputs of the sweep.
pub(crate) struct Setup {
    /// The noise-free truth `x_0 .. x_59`.
    pub(crate) truth: Vec<Vector4<f64>>,
    /// Its noise-free measurements `y_1 .. y_59`.
    pub(crate) measurements: Vec<Vector3<f64>>,
    /// The radar (eq 3) with [`r`].
    pub(crate) radar: RadarRates,
}

impl Setup {
    /// Measures the noise-free truth.
    pub(crate) fn new() -> Result<Self, StudyError> {
        let truth = reentry::noise_free_truth()?;
        let radar = RadarRates::new(r())?;
        let measurements = truth[1..].iter().map(|x| radar.measure(0, x)).collect();
        Ok(Self {
            truth,
            measurements,
            radar,
        })
    }
}
