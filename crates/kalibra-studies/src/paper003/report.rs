//! What paper 003's report template needs beyond the report's own fields: the claims of
//! every reading with their verdicts, relative gaps of `P_ad` and `Q_ad`, the ITSE minima,
//! the checks of the paper's qualitative Monte Carlo claims, and RMSE / CRLB ratios. The
//! prose is in `report.md`.

use serde::Serialize;

use super::claims::P_AD_TOLERANCE;
use super::run::{Config, McSetting, Report};
use super::scenario::{PLATEAU_TOLERANCE, READINGS, STATE_NAMES, p0_table, r};
use crate::claims::Claim;
use crate::paper000::Entry;
use crate::reentry;

/// RMSE/CRLB ratio up to which the Markdown report calls an RMSE "close to the CRLB". The
/// paper gives no number; 1.5 is this reproduction's reading of "very close".
pub const CRLB_CLOSE_RATIO: f64 = 1.5;

/// What the template sees: the configuration, the report, the claims and the [`View`].
#[derive(Serialize)]
pub(crate) struct Context<'a> {
    /// The configuration run.
    pub(crate) config: &'a Config,
    /// The report.
    pub(crate) report: &'a Report,
    /// The published claims with verdicts.
    pub(crate) claims: Vec<Claim>,
    /// What the template needs beyond the report's fields.
    pub(crate) view: View,
}

/// One published J claim of one reading.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct ClaimRow {
    /// What is claimed.
    claim: &'static str,
    /// Ours beside the paper's (`None`: no crossover).
    entry: Option<Entry>,
    /// The tolerance on `|gap|`.
    tolerance: f64,
    /// Whether `|gap|` is within the tolerance.
    reproduced: bool,
}

/// The J claims of one reading.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct ReadingClaims {
    /// The six claims.
    rows: Vec<ClaimRow>,
    /// How many are reproduced.
    passed: usize,
}

/// An entry with its relative gap.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct Relative {
    /// Ours beside the paper's.
    entry: Entry,
    /// `100 gap / paper` (`None` when the paper's value is 0).
    percent: Option<f64>,
    /// Whether `|percent|` is within [`P_AD_TOLERANCE`] (only meaningful for `P_ad`).
    within: bool,
}

/// `|percent|` of `Q_ad`'s (1,1) entry and the range over the others.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct QAdSummary {
    /// `|gap|` in percent of entry (1,1).
    first: f64,
    /// Smallest and largest `|gap|` in percent of the other entries (`None` if there are none).
    rest: Option<[f64; 2]>,
}

/// ITSE of one state at C, R2 and R3, and whether it grows in that order.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct ItseOrder {
    /// At C, R2, R3.
    itse: [f64; 3],
    /// `C < R2 < R3`.
    ordered: bool,
}

/// The "errors grow from C to R2 to R3" check.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Growth {
    /// Per state.
    itse: Vec<ItseOrder>,
    /// The last step compared (steps `1 ..= last`).
    last: usize,
    /// Per state, the steps `k = 1 ..= last` with RMSE `C < R2 < R3`.
    ordered_steps: Vec<usize>,
}

/// RMSE / CRLB of one state at one setting.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Closeness {
    /// The state index.
    state: usize,
    /// The setting's name.
    setting: &'static str,
    /// Whether the ratio exists and is at most [`CRLB_CLOSE_RATIO`].
    close: bool,
}

/// RMSE and CRLB at one step (setting C).
#[derive(Clone, Debug, Serialize)]
pub(crate) struct CrlbRow {
    /// The step.
    k: usize,
    /// Its time (s).
    t: f64,
    /// RMSE per state.
    rmse: [f64; 4],
    /// CRLB per state.
    crlb: [f64; 4],
}

/// Everything the template needs that is not a field of [`Report`].
#[derive(Clone, Debug, Serialize)]
pub(crate) struct View {
    /// The state names, in state order.
    states: [&'static str; 4],
    /// Sampling period, ballistic coefficient, gravity.
    truth: [f64; 3],
    /// Diagonal of `R`.
    r: [f64; 3],
    /// `|P0(1,3)|` of Table II in thousands.
    p0_13: f64,
    /// The time of the last update (s).
    t_last: f64,
    plateau_tolerance: f64,
    p_ad_tolerance: f64,
    close_ratio: f64,
    /// The asserted reading and the one shown for comparison (`-` if none).
    reading_names: [&'static str; 2],
    /// The names of every reading.
    all_readings: Vec<&'static str>,
    /// Per reading, in the order of [`Report::readings`].
    claims: Vec<ReadingClaims>,
    p_ad: Vec<Relative>,
    q_ad: Vec<Relative>,
    q_ad_summary: Option<QAdSummary>,
    /// Last time (s) of the ITSE integral.
    t_end: f64,
    /// Per state, the index in [`Report::monte_carlo`] of the smallest ITSE.
    itse_min: [Option<usize>; 4],
    /// Per state, the name of that setting (`-` if none).
    itse_min_name: [&'static str; 4],
    /// The C / R2 / R3 check (`None` if a setting is missing).
    growth: Option<Growth>,
    /// The last step `n` and mid-horizon `n / 2`, and its time.
    mid: usize,
    t_mid: f64,
    /// Positions at every setting, at the last step.
    close_end: Vec<Closeness>,
    /// Velocities at the sensitive settings, at mid-horizon.
    close_mid: Vec<Closeness>,
    /// Per setting, RMSE / CRLB of every state at the last step then at mid-horizon.
    ratios: Vec<[Option<f64>; 8]>,
    /// RMSE and CRLB at C at steps 0, 10, ..., 50 and `n`.
    crlb_at_c: Option<Vec<CrlbRow>>,
}

/// `ours / paper - 1` in percent (`None` when the paper value is zero).
fn relative_gap_percent(e: &Entry) -> Option<f64> {
    (e.paper != 0.0).then(|| 100.0 * e.gap / e.paper)
}

/// RMSE / CRLB of `setting` at step `k` and state `i` (`None` outside the horizon or for a
/// zero bound).
fn crlb_ratio(report: &Report, setting: &McSetting, k: usize, i: usize) -> Option<f64> {
    let rmse = setting.rmse.get(k)?[i];
    let bound = report.crlb.get(k)?[i];
    (bound > 0.0).then(|| rmse / bound)
}

fn relative(e: &Entry) -> Relative {
    let percent = relative_gap_percent(e);
    Relative {
        entry: *e,
        percent,
        within: percent.is_some_and(|g| g.abs() <= 100.0 * P_AD_TOLERANCE),
    }
}

fn growth(report: &Report) -> Option<Growth> {
    let (sc, r2, r3) = (
        report.setting("C")?,
        report.setting("R2")?,
        report.setting("R3")?,
    );
    let steps = sc.rmse.len().min(r2.rmse.len()).min(r3.rmse.len());
    Some(Growth {
        itse: (0..4)
            .map(|i| ItseOrder {
                itse: [sc.itse[i], r2.itse[i], r3.itse[i]],
                ordered: sc.itse[i] < r2.itse[i] && r2.itse[i] < r3.itse[i],
            })
            .collect(),
        last: steps.saturating_sub(1),
        ordered_steps: (0..4)
            .map(|i| {
                (1..steps)
                    .filter(|&k| sc.rmse[k][i] < r2.rmse[k][i] && r2.rmse[k][i] < r3.rmse[k][i])
                    .count()
            })
            .collect(),
    })
}

impl View {
    /// Derives the view of `report`.
    pub(crate) fn new(report: &Report) -> Self {
        let n = report.horizon;
        let mid = n / 2;
        let claims = report
            .readings
            .iter()
            .map(|r| {
                let rows: Vec<ClaimRow> = r
                    .claims()
                    .into_iter()
                    .map(|(claim, entry, tolerance)| ClaimRow {
                        claim,
                        entry,
                        tolerance,
                        reproduced: entry.is_some_and(|e| e.gap.abs() <= tolerance),
                    })
                    .collect();
                ReadingClaims {
                    passed: rows.iter().filter(|c| c.reproduced).count(),
                    rows,
                }
            })
            .collect();
        let gaps: Vec<f64> = report
            .q_ad_entries
            .iter()
            .filter_map(relative_gap_percent)
            .map(f64::abs)
            .collect();
        let q_ad_summary = gaps.split_first().map(|(&first, rest)| QAdSummary {
            first,
            rest: (!rest.is_empty()).then(|| {
                [
                    rest.iter().copied().fold(f64::INFINITY, f64::min),
                    rest.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                ]
            }),
        });
        let itse_min: [Option<usize>; 4] = std::array::from_fn(|i| {
            report
                .monte_carlo
                .iter()
                .enumerate()
                .filter(|(_, m)| m.itse[i].is_finite())
                .min_by(|a, b| a.1.itse[i].total_cmp(&b.1.itse[i]))
                .map(|(j, _)| j)
        });
        let itse_min_name = itse_min.map(|j| {
            j.and_then(|j| report.monte_carlo.get(j))
                .map_or("-", |m| m.name)
        });
        let close = |m: Option<&McSetting>, k: usize, i: usize| {
            m.and_then(|m| crlb_ratio(report, m, k, i))
                .is_some_and(|q| q <= CRLB_CLOSE_RATIO)
        };
        // (c): the positions at every setting, at the last step.
        let close_end = (0..4)
            .step_by(2)
            .flat_map(|i| report.monte_carlo.iter().map(move |m| (i, m)))
            .map(|(state, m)| Closeness {
                state,
                setting: m.name,
                close: close(Some(m), n, state),
            })
            .collect();
        // (d): the velocities at the sensitive settings, at mid-horizon.
        let close_mid = (1..4)
            .step_by(2)
            .flat_map(|i| ["S3", "S2", "C"].map(|s| (i, s)))
            .map(|(state, setting)| Closeness {
                state,
                setting,
                close: close(report.setting(setting), mid, state),
            })
            .collect();
        let ratios = report
            .monte_carlo
            .iter()
            .map(|m| {
                std::array::from_fn(|c| crlb_ratio(report, m, if c < 4 { n } else { mid }, c % 4))
            })
            .collect();
        let crlb_at_c = report.setting("C").map(|m| {
            let mut steps: Vec<usize> = (0..=5).map(|j| 10 * j).chain([n]).collect();
            steps.retain(|&k| k < m.rmse.len() && k < report.crlb.len());
            steps.dedup();
            steps
                .into_iter()
                .map(|k| CrlbRow {
                    k,
                    t: report.times.get(k).copied().unwrap_or(f64::NAN),
                    rmse: m.rmse[k],
                    crlb: report.crlb[k],
                })
                .collect()
        });
        let rd = r();
        Self {
            states: STATE_NAMES,
            truth: [reentry::T, reentry::BETA, reentry::G],
            r: [rd[(0, 0)], rd[(1, 1)], rd[(2, 2)]],
            p0_13: p0_table()[(0, 2)] / 1e3,
            t_last: reentry::T * n as f64,
            plateau_tolerance: PLATEAU_TOLERANCE,
            p_ad_tolerance: P_AD_TOLERANCE,
            close_ratio: CRLB_CLOSE_RATIO,
            reading_names: [READINGS[0].name, READINGS.get(1).map_or("-", |r| r.name)],
            all_readings: READINGS.iter().map(|r| r.name).collect(),
            claims,
            p_ad: report.p_ad_diagonal.iter().map(relative).collect(),
            q_ad: report.q_ad_entries.iter().map(relative).collect(),
            q_ad_summary,
            t_end: report.times.last().copied().unwrap_or(0.0),
            itse_min,
            itse_min_name,
            growth: growth(report),
            mid,
            t_mid: report.times.get(mid).copied().unwrap_or(f64::NAN),
            close_end,
            close_mid,
            ratios,
            crlb_at_c,
        }
    }
}
