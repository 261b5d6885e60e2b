//! Paper 003's published claims beside ours: `J1max`, `J2max`, the crossover's `J` and `nq`,
//! the plateau edges (per reading; only the `paper` reading is asserted), and Table II's `P0`
//! diagonal recovered by `P_ad`.

use super::run::{ReadingReport, Report};
use super::scenario::READINGS;
use crate::claims::{Claim, Verdict};
use crate::paper000::Entry;

/// Closeness asked of `J1max`, `J2max` and the J at the crossover (published to 2 decimals).
pub const J_TOLERANCE: f64 = 0.01;
/// Closeness asked of the crossover `nq` and the plateau-edge `nq` values.
pub const NQ_TOLERANCE: f64 = 0.03;
/// Relative closeness asked of the diagonal of `P_ad` against Table II.
pub const P_AD_TOLERANCE: f64 = 0.05;

impl ReadingReport {
    /// The six published claims of one reading: (claim, our entry if any, tolerance).
    pub(crate) fn claims(&self) -> [(&'static str, Option<Entry>, f64); 6] {
        [
            ("J1max", Some(self.j1max), J_TOLERANCE),
            ("J2max", Some(self.j2max), J_TOLERANCE),
            ("J at the crossover (Q_comp)", self.crossover_j, J_TOLERANCE),
            ("nq at the crossover", self.crossover_nq, NQ_TOLERANCE),
            ("J1 plateau edge nq", Some(self.j1_edge.0), NQ_TOLERANCE),
            ("J2 plateau edge nq", Some(self.j2_edge.0), NQ_TOLERANCE),
        ]
    }
}

impl Report {
    /// The published claims beside ours (the `paper` reading, the one asserted): `J1max`,
    /// `J2max`, the crossover `J` and `nq`, the plateau edges, and Table II's `P0` diagonal
    /// recovered by `P_ad` within [`P_AD_TOLERANCE`].
    pub fn claims(&self) -> Vec<Claim> {
        let mut out = Vec::new();
        if let Some(r) = self
            .readings
            .iter()
            .find(|r| r.reading.name == READINGS[0].name)
        {
            for (claim, entry, tol) in r.claims() {
                out.push(Claim {
                    id: "j_claims",
                    claim: claim.to_string(),
                    published: entry.map_or("-".into(), |e| format!("{:.2}", e.paper)),
                    ours: entry.map_or("no crossover".into(), |e| format!("{:.3}", e.ours)),
                    tolerance: format!("±{tol}"),
                    verdict: Verdict::from_bool(entry.is_some_and(|e| e.gap.abs() <= tol)),
                    section: "claims",
                });
            }
        }
        let worst = self
            .p_ad_diagonal
            .iter()
            .map(|e| (e.ours / e.paper - 1.0).abs())
            .fold(0.0, f64::max);
        out.push(Claim {
            id: "p_ad",
            claim: "P_ad (eq 22) gives Table II's P0 diagonal".into(),
            published: "Table II".into(),
            ours: format!("largest relative gap {:.1}%", 100.0 * worst),
            tolerance: format!("±{:.0}%", 100.0 * P_AD_TOLERANCE),
            verdict: Verdict::from_bool(worst <= P_AD_TOLERANCE),
            section: "initial-tuning",
        });
        out
    }
}
