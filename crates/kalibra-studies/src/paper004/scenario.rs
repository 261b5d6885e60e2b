//! Paper 004's set-up: the printed tables, the level and confidence of the tests, the printed
//! model values with the velocity-row typo fixed, and the three readings of the lost `H` and
//! `R`.

use kalibra_models::Target3dParams;
use serde::Serialize;

/// Component names in the paper's order.
pub const COMPONENTS: [&str; 9] = [
    "p_x", "v_x", "a_x", "p_y", "v_y", "a_y", "p_z", "v_z", "a_z",
];

/// Table 2, empirical quantiles (2.5%, 97.5%) of `e_1000`, as printed.
pub const TABLE2_EMPIRICAL: [(f64, f64); 9] = [
    (-0.344, 0.340),
    (-1.500, 1.535),
    (-7.871, 7.713),
    (-0.403, 0.363),
    (-1.745, 1.534),
    (-8.303, 7.420),
    (-0.395, 0.386),
    (-1.734, 1.711),
    (-7.897, 7.949),
];

/// Table 2, surrogate half-widths, as printed.
pub const TABLE2_SURROGATE: [f64; 9] = [
    0.373, 1.864, 8.906, 0.375, 1.555, 8.031, 0.427, 2.094, 8.915,
];

/// Table 1, p-values (runs, matched-pair t, KS) of one trajectory, as printed.
pub const TABLE1: [[f64; 3]; 9] = [
    [0.34, 0.29, 0.56],
    [1.00, 0.11, 0.17],
    [0.09, 0.14, 0.40],
    [0.46, 0.86, 0.82],
    [0.17, 0.85, 0.82],
    [0.92, 0.85, 0.48],
    [0.92, 0.68, 0.89],
    [0.46, 0.46, 0.48],
    [0.21, 0.42, 0.56],
];

/// Level of the Table 1 tests.
pub const LEVEL: f64 = 0.05;
/// Confidence of the Table 2 intervals.
pub const CONFIDENCE: f64 = 0.95;

/// Sampling interval `Delta T` (printed).
pub const DT: f64 = 0.05;
/// Process-noise scale `sigma_w` (printed).
pub const SIGMA_W: f64 = 4.0;
/// Measurement-noise scale `sigma_v` (printed; how it enters `R` is a reading).
pub const SIGMA_V: f64 = 2.0;

/// The printed model with the velocity-row typo fixed and linear acceleration coefficient
/// `accel_coefficient` (printed -0.5): `dt = 0.05`, `sigma_w = 4`, velocity diagonal 1 (printed
/// 0, which makes velocity forget itself every step), sine/cosine amplitude 0.5, damping -0.1
/// on x and -0.05 on y and z.
pub fn params(accel_coefficient: f64) -> Target3dParams {
    Target3dParams {
        dt: DT,
        sigma_w: SIGMA_W,
        velocity_diagonal: 1.0,
        accel_coefficient,
        accel_amplitude: 0.5,
        damping: [-0.1, -0.05, -0.05],
    }
}

/// One reading of the lost measurement model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Reading {
    /// Key in `results.json`.
    pub name: &'static str,
    /// What it assumes.
    pub description: &'static str,
    /// Velocities observed as well as positions.
    pub observe_velocity: bool,
    /// Measurement noise variance per observed component.
    pub r: f64,
    /// The linear acceleration coefficient in `u` (printed -0.5).
    pub accel_coefficient: f64,
}

/// The three readings.
pub const READINGS: [Reading; 3] = [
    Reading {
        name: "positions",
        description: "positions observed, R = sigma_v^2 I = 4 I (plausible from the text)",
        observe_velocity: false,
        r: 4.0,
        accel_coefficient: -0.5,
    },
    Reading {
        name: "positions-velocities",
        description: "positions and velocities observed, R = 4 I (keeps every printed number)",
        observe_velocity: true,
        r: 4.0,
        accel_coefficient: -0.5,
    },
    Reading {
        name: "fitted",
        description: "positions observed, R = sigma_v^2 dt I = 0.2 I, acceleration coefficient -1 (fitted to Table 2; not stated in the text)",
        observe_velocity: false,
        r: 0.2,
        accel_coefficient: -1.0,
    },
];

impl Reading {
    /// The model parameters of this reading.
    pub fn params(&self) -> Target3dParams {
        params(self.accel_coefficient)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::Vector3;
    use kalibra_models::{AccelAxis, Dynamics};

    #[test]
    fn printed_values_and_the_typo_fix() {
        let p = params(-0.5);
        let x = AccelAxis::new(p, 0).unwrap();
        let j = x.jacobian(0, &Vector3::zeros());
        // Position damped by 0.1 on x; velocity row has 1 (the printed 0 fixed) minus 0.1;
        // acceleration 1 - 0.5 + 0.5 cos(0) = 1.
        assert!((j[(0, 0)] - 0.9).abs() < 1e-15);
        assert!((j[(1, 1)] - 0.9).abs() < 1e-15);
        assert!((j[(2, 2)] - 1.0).abs() < 1e-15);
        // y uses cos: a' = 0.5 a + 0.5 cos a, so a = 0 maps to 0.5.
        let y = AccelAxis::new(p, 1).unwrap();
        assert!((y.transition(0, &Vector3::zeros())[2] - 0.5).abs() < 1e-15);
        let q = x.noise_cov(0);
        let b = Vector3::new(0.00125, 0.05, 1.0);
        assert!((q - b * b.transpose() * 16.0).amax() < 1e-15);
    }

    #[test]
    fn the_readings_are_sigma_v_based_and_only_the_fitted_one_changes_the_model() {
        let [positions, both, fitted] = READINGS;
        assert_eq!(positions.r, SIGMA_V * SIGMA_V);
        assert!(!positions.observe_velocity);
        assert_eq!(both.r, SIGMA_V * SIGMA_V);
        assert!(both.observe_velocity);
        assert!((fitted.r - SIGMA_V * SIGMA_V * DT).abs() < 1e-15);
        assert!(!fitted.observe_velocity);
        assert_eq!(positions.params(), params(-0.5));
        assert_eq!(both.params(), params(-0.5));
        assert_eq!(fitted.params(), params(-1.0));
    }
}
