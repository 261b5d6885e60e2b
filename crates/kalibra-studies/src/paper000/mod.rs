//! Paper 000: Saha, Goswami, Ghosh, "Two novel metrics for determining the tuning parameters
//! of the Kalman filter" (ACODS 2012): Table I, J1 and J2 of a KF and an EKF for
//! `Q = 10^p Q_nom`, and the J1/J2 crossover.
//!
//! # Set-up (see [`crate::reentry`] for the truth)
//! Positions measured (`H = [[1,0,0,0],[0,0,1,0]]`); the filters use the printed `x0`, `P0`,
//! `R` and `Q_nom` (section IV). The "KF" is a linear KF on the drag-free model (`F = F1`,
//! prediction `F1 x + G u`); the "EKF" uses the drag model with `F_{k-1} = F1 + G dfkk/dx` at
//! the posterior. (A KF linearised along the truth would equal the EKF, which Table I rules
//! out.) Joseph update. The sweep runs on the noise-free truth with noise-free measurements.
//!
//! # Readings
//! The paper leaves open, or prints inconsistently, four things; each [`Reading`] fixes them
//! and the report shows all of them:
//! * where the filter starts: `x0`, `P0` come from two-point differencing of `y_1, y_2`, so
//!   the filter starts at `k = 2` and processes `y_3 .. y_59`; or it starts at `k = 0` and
//!   processes all 59;
//! * the horizon divisor: `N = 59` even when 57 updates run (the skipped points count as
//!   zeros), or the number of updates;
//! * `R`: as printed, or divided by 10 (no reason is given in the text; with `R` as printed
//!   the whole transition sits one decade of `Q` late);
//! * `P0`: as printed (asymmetric: (2,4) = -1.73e6, (4,2) = -0.73e6; and indefinite: the
//!   (1,3) block has a negative determinant), or symmetrised (still indefinite).
//!
//! `nq` is the mean of `log10 tr(B_k)` over the updates (eq 15; the base-10 logarithm is what
//! makes `nq` step by exactly 1.00 per decade of `Q`, as the table does). The printed `p`
//! column skips -2: the rows printed `-1 .. 6` are `p = -2 .. 5` (their `nq` values say so).
//!
//! # Layout
//! `scenario.rs` holds the printed values and the readings, `run.rs` the filters and the
//! sweeps, `claims.rs` the published claims, `report.rs` and `report.md` the Markdown report,
//! `figures.rs` the figure data.

mod claims;
mod figures;
mod report;
mod run;
mod scenario;

pub use claims::TABLE_TOLERANCE;
pub use run::{Config, Entry, PerFilter, ReadingReport, ReplayStep, Report, TableRow, replay, run};
pub use scenario::{
    CROSSOVER_NQ_RANGE, FilterKind, P0Use, READINGS, Reading, TABLE_I, p0_printed, q_nom,
    r_printed, table_p, x0_printed,
};

use crate::StudyError;
use crate::claims::Claim;
use crate::study::{NamedFigure, Study};

/// The report's template (prose with the numbers filled in from [`Report`]).
const TEMPLATE: &str = include_str!("report.md");

/// The study, as the registry lists it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Paper000;

crate::study_config!(Config);

impl Study for Paper000 {
    type Config = Config;
    type Report = Report;

    fn id(&self) -> &'static str {
        "000"
    }

    fn title(&self) -> &'static str {
        "Saha, Goswami, Ghosh 2012: J1/J2 tuning metrics (KF, EKF)"
    }

    fn paper(&self) -> Option<&'static str> {
        Some(
            "Saha, Goswami, Ghosh, \"Two novel metrics for determining the tuning parameters of the Kalman filter\", ACODS 2012",
        )
    }

    fn describe(&self, _config: &Config) -> String {
        "J1/J2 sweeps of the KF and EKF (4 readings)".to_string()
    }

    fn run(&self, config: &Config) -> Result<Report, StudyError> {
        run(config)
    }

    fn claims(&self, report: &Report) -> Vec<Claim> {
        report.claims()
    }

    fn highlight(&self, _config: &Config, report: &Report) -> Result<String, StudyError> {
        let paper = report
            .reading("paper")
            .ok_or_else(|| StudyError::Report("paper 000 has no 'paper' reading".into()))?;
        let cross = |c: Option<crate::reentry::CrossoverRow>| {
            c.map_or("none".to_string(), |c| format!("{:.2}", c.nq))
        };
        Ok(format!(
            "largest gap {:.3} over 76 entries (paper reading); crossover nq KF {}, EKF {} (claimed 0.21..1.21)",
            paper.max_abs_gap,
            cross(paper.crossover.kf),
            cross(paper.crossover.ekf),
        ))
    }

    fn markdown(&self, config: &Config, report: &Report) -> Result<String, StudyError> {
        crate::template::render(
            "paper000/report.md",
            TEMPLATE,
            &report::Context {
                config,
                report,
                claims: self.claims(report),
                view: report::View::new(report),
            },
        )
    }

    fn figures(&self, report: &Report) -> Vec<NamedFigure> {
        NamedFigure::from_pairs(figures::figures(report))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The template renders at quick size (every field it names exists).
    #[test]
    fn markdown_renders() {
        let config = Paper000.config(&crate::study::Options::quick());
        let report = Paper000.run(&config).unwrap();
        assert!(Paper000.markdown(&config, &report).is_ok());
    }
}
