//! Paper 000's published claims beside ours: Table I's J entries within [`TABLE_TOLERANCE`]
//! and the J1/J2 crossover of each filter inside [`CROSSOVER_NQ_RANGE`].

use super::run::Report;
use super::scenario::{CROSSOVER_NQ_RANGE, READINGS};
use crate::claims::{Claim, Verdict};

/// Largest `|gap|` between our J values and Table I's that counts as a reproduction (the
/// table prints two decimals).
pub const TABLE_TOLERANCE: f64 = 0.02;

impl Report {
    /// The published claims beside ours (the `paper` reading, the one asserted): Table I's 76
    /// J entries within [`TABLE_TOLERANCE`], and the crossover `nq` of each filter inside
    /// [`CROSSOVER_NQ_RANGE`].
    pub fn claims(&self) -> Vec<Claim> {
        let Some(r) = self.reading(READINGS[0].name) else {
            return Vec::new();
        };
        let entries = r.table.len() * 4;
        let mut out = vec![Claim {
            id: "table1",
            claim: format!("Table I: all {entries} J1/J2 entries (KF and EKF, 19 values of p)"),
            published: "printed to two decimals".into(),
            ours: format!("largest gap {:.3}", r.max_abs_gap),
            tolerance: format!("±{TABLE_TOLERANCE} each"),
            verdict: Verdict::from_bool(r.max_abs_gap <= TABLE_TOLERANCE),
            section: "largest-gap-per-reading",
        }];
        let (lo, hi) = CROSSOVER_NQ_RANGE;
        for (filter, c) in [("KF", &r.crossover.kf), ("EKF", &r.crossover.ekf)] {
            out.push(Claim {
                id: "crossover",
                claim: format!("{filter}: J1 and J2 cross at nq between {lo} and {hi}"),
                published: format!("{lo} .. {hi}"),
                ours: c.map_or("no crossover".into(), |c| format!("nq {:.3}", c.nq)),
                tolerance: "inside the range".into(),
                verdict: Verdict::from_bool(c.is_some_and(|c| c.nq >= lo && c.nq <= hi)),
                section: "crossover",
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper000::{Config, run};

    /// At quick size the three claims hold, and their verdicts follow the report's numbers.
    #[test]
    fn claims_follow_the_report() {
        let report = run(&Config::quick()).unwrap();
        let claims = report.claims();
        assert_eq!(
            claims.iter().map(|c| c.id).collect::<Vec<_>>(),
            ["table1", "crossover", "crossover"]
        );
        assert!(claims.iter().all(|c| c.verdict == Verdict::Reproduced));
        let paper = report.reading("paper").unwrap();
        assert!(paper.max_abs_gap <= TABLE_TOLERANCE);
        let (lo, hi) = CROSSOVER_NQ_RANGE;
        for c in [paper.crossover.kf, paper.crossover.ekf] {
            assert!(c.is_some_and(|c| (lo..=hi).contains(&c.nq)), "{c:?}");
        }
    }
}
