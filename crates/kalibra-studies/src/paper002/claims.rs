//! Paper 002's claims, each with ours and a verdict.

use super::run::{Report, largest_mean_std};
use super::scenario::{
    PAPER_ORDERING, QUOTED_BIAS, QUOTED_PHASE_RMSE, QUOTED_Q3_ABOVE, QUOTED_STD, STATE_NAMES,
};
use crate::claims::{Claim, Verdict};

/// Relative tolerance on the quoted "about" magnitudes (they are read off a figure).
pub const MAGNITUDE_TOLERANCE: f64 = 0.25;
/// Share of Monte Carlo truths in which the ordering must hold to count as reproduced.
pub const ORDERING_SHARE: f64 = 0.9;

/// The published claims judged on `r`.
pub(super) fn claims(r: &Report) -> Vec<Claim> {
    let q = |name: &str| &r.q_sets[name];
    let mut out = Vec::new();
    for (name, quoted) in QUOTED_PHASE_RMSE {
        let ours = q(name).rmse_theta_phase;
        out.push(Claim {
            id: if name == "Q1" {
                "q1-phase-rmse"
            } else {
                "q2-phase-rmse"
            },
            claim: format!("{name} angle RMSE in the 6-14 s phase"),
            published: format!("about {quoted:.2} deg"),
            ours: format!(
                "{ours:.3} deg (Monte Carlo mean {:.3}; noise floor {:.3})",
                q(name).mc_mean_rmse_theta_phase,
                q(name).noise_floor_theta
            ),
            tolerance: format!("{:.0}% relative", 100.0 * MAGNITUDE_TOLERANCE),
            verdict: Verdict::from_bool((ours - quoted).abs() <= MAGNITUDE_TOLERANCE * quoted),
            section: "magnitudes",
        });
    }
    let q3 = q("Q3").rmse_theta_phase;
    out.push(Claim {
        id: "q3-phase-rmse",
        claim: "Q3 angle RMSE in the 6-14 s phase".into(),
        published: format!("above {QUOTED_Q3_ABOVE:.2} deg"),
        ours: format!(
            "{q3:.3} deg (peak window RMSE {:.3})",
            q("Q3").peak_window_rmse_theta_phase
        ),
        tolerance: "strict inequality".into(),
        verdict: Verdict::from_bool(q3 > QUOTED_Q3_ABOVE),
        section: "magnitudes",
    });
    out.push(Claim {
        id: "ordering",
        claim: "Ordering of the phase angle RMSE".into(),
        published: PAPER_ORDERING.into(),
        ours: format!(
            "default truth {}; holds in {:.1}% of {} truths (Q2 best in {:.1}%)",
            r.ordering_default_truth,
            100.0 * r.fraction_ordering_holds,
            r.config.truths,
            100.0 * r.fraction_q2_best
        ),
        tolerance: format!("in at least {:.0}% of truths", 100.0 * ORDERING_SHARE),
        verdict: Verdict::from_bool(r.fraction_ordering_holds >= ORDERING_SHARE),
        section: "monte-carlo",
    });
    let best_states: Vec<&str> = (0..3)
        .filter(|&s| {
            let m = |n: &str| q(n).mc_mean_rmse[s];
            m("Q2") < m("Q1") && m("Q2") < m("Q3")
        })
        .map(|s| STATE_NAMES[s])
        .collect();
    out.push(Claim {
        id: "q2-lowest-all-states",
        claim: "Q2 gives the lowest RMSE (every state)".into(),
        published: "Q2 lowest".into(),
        ours: format!(
            "Q2 lowest Monte Carlo mean RMSE for: {}",
            if best_states.is_empty() {
                "no state".to_string()
            } else {
                best_states.join(", ")
            }
        ),
        tolerance: "lowest mean over truths, per state".into(),
        verdict: Verdict::from_bool(best_states.len() == 3),
        section: "monte-carlo",
    });
    let bias = q("Q3").max_abs_window_bias_theta;
    out.push(Claim {
        id: "q3-bias",
        claim: "Q3 local angle bias exceeds 0.1 deg at times".into(),
        published: format!("|bias| > {QUOTED_BIAS} deg"),
        ours: format!("largest |window bias| {bias:.3} deg (default truth)"),
        tolerance: "strict inequality".into(),
        verdict: Verdict::from_bool(bias > QUOTED_BIAS),
        section: "windows",
    });
    let std_share = q("Q3").share_windows_std_above_quoted;
    out.push(Claim {
        id: "q3-std",
        claim: "Q3 local angle std exceeds 0.2 deg in many segments".into(),
        published: format!("std > {QUOTED_STD} deg in many segments"),
        ours: format!(
            "{:.1}% of windows (largest mean std of the three sets: {})",
            100.0 * std_share,
            largest_mean_std(&r.q_sets)
        ),
        tolerance: "\"many\" is not a number: at least 10% of windows".into(),
        verdict: Verdict::from_bool(std_share >= 0.1),
        section: "windows",
    });
    out
}
