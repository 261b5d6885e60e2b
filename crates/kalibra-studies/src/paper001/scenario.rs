//! The paper's set-up: its three bearings-only problems ([`BotScenario`], in `problems`), the
//! kappa grid its adaptive filters search ([`kappa_grid`]), and the published values.

mod problems;

pub use problems::{BotProblem, BotRun, BotScenario, BotStart};

use kalibra_filters::{FilterError, KappaGrid};

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
