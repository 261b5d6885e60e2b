//! The paper's set-up: its three bearings-only problems ([`BotScenario`], in `problems`), the
//! filters it compares ([`FILTERS`]), the kappa grid its adaptive filters search
//! ([`kappa_grid`]), and the published values (Tables I and II).

mod problems;

pub use problems::{BotProblem, BotRun, BotScenario, BotStart};

use kalibra_filters::{FilterError, KappaGrid};

/// The filters, in the paper's column order, then our extra pure-MAP variant.
pub const FILTERS: [&str; 6] = ["EKF", "UKF", "UKF-ML", "UKF-MPP", "SRF", "UKF-MAP"];
/// How many of [`FILTERS`] are the paper's.
pub const PAPER_FILTERS: usize = 5;

/// Table I as printed: per problem, per metric, the five filters in [`FILTERS`] order.
/// `None` where the paper gives no value (problem III's velocity).
pub const TABLE_I: [(&str, [Option<[f64; 5]>; 4]); 3] = [
    (
        "I",
        [
            Some([8.00, 1.20, 1.60, 1.15, 0.22]),
            Some([4.34, 2.60, 3.00, 2.58, 2.06]),
            Some([88.59, 3.79, 3.84, 3.72, 3.64]),
            Some([0.612, 0.519, 0.534, 0.519, 0.508]),
        ],
    ),
    (
        "II",
        [
            Some([5.42, -0.62, -2.16, -2.47, -1.11]),
            Some([135.78, 5.96, 3.41, 2.88, 3.64]),
            Some([4.73, 1.68, 1.06, 1.26, 1.52]),
            Some([0.300, 0.081, 0.053, 0.059, 0.075]),
        ],
    ),
    (
        "III",
        [
            Some([2.54, 1.03, 1.59, 0.51, 1.00]),
            Some([4.02, 1.36, 1.51, 1.11, 1.19]),
            Some([1.38, 1.13, 1.20, 1.07, 1.10]),
            None,
        ],
    ),
];
/// Table I's metric rows.
pub const METRICS: [&str; 4] = ["nci", "anees", "rmse_pos", "rmse_vel"];
/// Table II as printed: cost of a time step relative to the SRF's (%), [`FILTERS`] order.
pub const TABLE_II: [f64; 5] = [53.0, 95.0, 661.0, 604.0, 100.0];

/// The paper's kappa grid for state dimension `n`: 10 equidistant values on `[0, 19 n]`. The
/// upper end keeps every non-central weight `W_i = 1/(2(n + kappa))` at least `0.025 / n`;
/// the lower end keeps all weights non-negative, which keeps the unscented covariances
/// positive semi-definite (the paper says only that its minimum "ensures positive
/// definiteness").
///
/// # Errors
/// [`FilterError::InvalidParameter`] for `n == 0`.
pub fn kappa_grid(n: usize) -> Result<KappaGrid, FilterError> {
    if n == 0 {
        return Err(FilterError::InvalidParameter {
            name: "state dimension",
            value: 0.0,
        });
    }
    KappaGrid::equidistant(0.0, 19.0 * n as f64, 10)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kappa_grid_is_the_papers() {
        let g = kappa_grid(4).unwrap();
        assert_eq!(g.values().len(), 10);
        assert_eq!(g.values()[0], 0.0);
        assert_eq!(g.values()[9], 76.0);
        // The largest kappa keeps W_i = 1/(2(n + kappa)) at 0.025/n.
        let smallest_weight = 0.5 / (4.0 + g.values()[9]);
        assert!((smallest_weight - 0.025 / 4.0).abs() <= 1e-15);
        assert_eq!(kappa_grid(2).unwrap().values()[9], 38.0);
        assert!(kappa_grid(0).is_err());
    }
}
