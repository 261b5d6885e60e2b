//! Paper 004's claims, each with ours and a verdict.

use super::run::ReadingReport;
use super::scenario::{LEVEL, TABLE2_EMPIRICAL, TABLE2_SURROGATE};
use crate::claims::{Claim, Verdict};

/// Relative tolerance on the printed surrogate half-widths (the independent implementation
/// matched the fitted reading to 0.2%).
pub const SURROGATE_TOLERANCE: f64 = 0.02;
/// Tolerance on the printed empirical quantiles, relative to the printed half-range. Both
/// sides are Monte Carlo estimates from 10^4 replicates: the standard error of a 2.5% or
/// 97.5% normal quantile is `2.65 sigma / sqrt(n)`, 1.35% of the half-width `1.96 sigma`, so
/// the difference of two has a standard error of about 1.9% and 7.5% is 4 of them.
pub const QUANTILE_TOLERANCE: f64 = 0.075;

/// The largest `|gap / scale|`.
fn max_rel(entries: impl Iterator<Item = (f64, f64)>) -> f64 {
    entries
        .map(|(gap, scale)| (gap / scale).abs())
        .fold(0.0, f64::max)
}

/// The published claims judged on every reading's results.
pub(super) fn claims(readings: &[ReadingReport]) -> Vec<Claim> {
    let mut out = Vec::new();
    for r in readings {
        let name = r.reading.name;
        let surrogate_gap = max_rel(r.surrogate_vs_paper.iter().map(|e| (e.gap, e.paper)));
        out.push(Claim {
            id: "surrogate-halfwidths",
            claim: format!("Table 2 surrogate half-widths (reading `{name}`)"),
            published: "9 printed half-widths".into(),
            ours: format!("largest relative gap {:.1}%", 100.0 * surrogate_gap),
            tolerance: format!("{:.0}% relative", 100.0 * SURROGATE_TOLERANCE),
            verdict: Verdict::from_bool(surrogate_gap <= SURROGATE_TOLERANCE),
            section: "table-2",
        });
        let quantile_gap = max_rel(r.quantiles_vs_paper.iter().enumerate().flat_map(
            |(i, (lo, hi))| {
                let half = 0.5 * (TABLE2_EMPIRICAL[i].1 - TABLE2_EMPIRICAL[i].0);
                [(lo.gap, half), (hi.gap, half)]
            },
        ));
        out.push(Claim {
            id: "empirical-quantiles",
            claim: format!("Table 2 empirical quantiles of e_1000 (reading `{name}`)"),
            published: "18 printed quantiles".into(),
            ours: format!(
                "largest gap {:.1}% of the printed half-range",
                100.0 * quantile_gap
            ),
            tolerance: format!("{:.0}% of the half-range", 100.0 * QUANTILE_TOLERANCE),
            verdict: Verdict::from_bool(quantile_gap <= QUANTILE_TOLERANCE),
            section: "table-2",
        });
        // The paper's own largest surrogate-vs-empirical gap is the yardstick of "close".
        let paper_close = (0..9)
            .map(|i| {
                let half = 0.5 * (TABLE2_EMPIRICAL[i].1 - TABLE2_EMPIRICAL[i].0);
                (TABLE2_SURROGATE[i] / half - 1.0).abs()
            })
            .fold(0.0, f64::max);
        let ours_close = (0..9)
            .map(|i| {
                let half = 0.5 * (r.empirical_q975[i] - r.empirical_q025[i]);
                (r.surrogate_halfwidth[i] / half - 1.0).abs()
            })
            .fold(0.0, f64::max);
        out.push(Claim {
            id: "surrogate-close",
            claim: format!(
                "Surrogate intervals close to the empirical quantiles (reading `{name}`)"
            ),
            published: format!(
                "largest relative difference in Table 2: {:.0}%",
                100.0 * paper_close
            ),
            ours: format!("largest relative difference {:.1}%", 100.0 * ours_close),
            tolerance: "no larger than the paper's own".into(),
            verdict: Verdict::from_bool(ours_close <= paper_close),
            section: "table-2",
        });
        let rejections = r
            .table1
            .p_runs
            .iter()
            .chain(&r.table1.p_t)
            .chain(&r.table1.p_ks)
            .filter(|&&p| p < LEVEL)
            .count();
        out.push(Claim {
            id: "table1-no-rejection",
            claim: format!("Table 1: no test rejects at 0.05 on one trajectory (reading `{name}`)"),
            published: "0 of 27 rejections".into(),
            ours: format!(
                "{rejections} of 27 on trajectory 0; rejection rate {:.1}% over {} trajectories",
                100.0 * r.table1.rejection_rate.overall,
                r.table1.trajectories
            ),
            tolerance: "single p-values are random: the rate should be near 5%".into(),
            verdict: Verdict::NotTestable,
            section: "table-1",
        });
    }
    out
}
