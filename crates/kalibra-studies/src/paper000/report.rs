//! What paper 000's report template needs beyond the report's own fields: per-reading
//! verdicts and the place of the largest gap, the crossover against the claimed range, the
//! J2 spike's row of Table I, the pairs of readings that differ only in `P0`, and the `nq`
//! offset. The prose is in `report.md`.

use serde::Serialize;

use super::claims::TABLE_TOLERANCE;
use super::run::{Config, Entry, ReadingReport, Report, TableRow};
use super::scenario::{
    CROSSOVER_NQ_RANGE, M, P0Use, READINGS, TABLE_I, h, p0_printed, q_nom, spike_row, table_p,
};
use crate::claims::Claim;
use crate::reentry::{self, CrossoverRow};

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

/// The constants of the set-up the report quotes.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct Truth {
    /// Sampling period (s).
    t: f64,
    /// Ballistic coefficient.
    beta: f64,
    /// Gravity.
    g: f64,
}

/// Where a table's largest `|gap|` is.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct GapPlace {
    /// The column (`KF J1` ...).
    column: &'static str,
    /// The `p` run.
    p: f64,
    /// The printed `p` label.
    p_printed: f64,
    /// The entry there.
    entry: Entry,
}

/// One filter's crossover against the claimed range.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct CrossoverView {
    /// `KF` or `EKF`.
    filter: &'static str,
    /// The crossover, if J1 - J2 changes sign.
    crossover: Option<CrossoverRow>,
    /// Whether its `nq` lies in [`CROSSOVER_NQ_RANGE`].
    inside: bool,
}

/// The J2 spike's row in one reading.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct SpikeRow {
    /// The row of Table I.
    row: TableRow,
    /// EKF J2 one row before and one row after, when both exist.
    neighbours: Option<[f64; 2]>,
    /// Whether the largest single-step J2k leaves `[0, m]`.
    above_m: bool,
}

/// Per reading, in the order of [`Report::readings`].
#[derive(Clone, Debug, Serialize)]
pub(crate) struct ReadingView {
    /// Whether every J entry of Table I is within [`TABLE_TOLERANCE`].
    reproduces: bool,
    /// The largest `|gap|` of Table I, if the table has rows.
    largest: Option<GapPlace>,
    /// KF and EKF.
    crossovers: [CrossoverView; 2],
    /// The spike row, if the table has it.
    spike: Option<SpikeRow>,
}

/// Printed KF and EKF J2 of a row of Table I.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct PrintedJ2 {
    /// KF.
    kf: f64,
    /// EKF.
    ekf: f64,
}

/// Table I's J2 spike as printed, and the printed `P0` that causes it.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct Spike {
    /// Printed `nq` of the row.
    nq: f64,
    /// Printed `p` label.
    p_printed: f64,
    /// `p` run.
    p: f64,
    /// Printed J2 at the row.
    j2: PrintedJ2,
    /// The row before, if any.
    before: Option<PrintedJ2>,
    /// The row after, if any.
    after: Option<PrintedJ2>,
    /// `P0` (2,4), 1-based.
    p0_24: f64,
    /// `P0` (4,2), 1-based.
    p0_42: f64,
    /// Determinant of the (1,3) block of `P0`.
    det13: f64,
}

/// A reading with `P0` as printed and its twin with `P0` symmetrised, at the spike row.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Twin {
    /// The reading with `P0` as printed.
    printed: &'static str,
    /// Its symmetrised twin.
    symmetrised: &'static str,
    /// The printed reading's spike row.
    a: TableRow,
    /// The twin's spike row.
    b: TableRow,
}

/// `nq - p` over Table I (ours and printed) and what explains ours.
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct NqOffset {
    /// Smallest of ours.
    lo: f64,
    /// Mean of ours.
    mean: f64,
    /// Largest of ours.
    hi: f64,
    /// Mean of the printed offsets.
    printed_mean: f64,
    /// `log10 tr(H Q_nom H^T)`.
    log_b_nom: f64,
    /// `mean - printed_mean`.
    difference: f64,
}

/// Everything the template needs that is not a field of [`Report`].
#[derive(Clone, Debug, Serialize)]
pub(crate) struct View {
    truth: Truth,
    tolerance: f64,
    crossover_range: [f64; 2],
    m: f64,
    readings: Vec<ReadingView>,
    /// Names of the readings that reproduce Table I.
    winners: Vec<&'static str>,
    /// Index in [`Report::readings`] of the `paper` reading.
    paper: Option<usize>,
    spike: Spike,
    twins: Vec<Twin>,
    nq_offset: Option<NqOffset>,
    /// The reading the figures show.
    figure_reading: &'static str,
}

/// The four J entries of a Table I row with their column names.
fn j_entries(row: &TableRow) -> [(&'static str, Entry); 4] {
    [
        ("KF J1", row.j1_kf),
        ("KF J2", row.j2_kf),
        ("EKF J1", row.j1_ekf),
        ("EKF J2", row.j2_ekf),
    ]
}

/// The row and column of the largest `|gap|` of a table.
fn largest_gap(table: &[TableRow]) -> Option<GapPlace> {
    table
        .iter()
        .flat_map(|row| j_entries(row).map(|(name, e)| (row, name, e)))
        .max_by(|a, b| a.2.gap.abs().total_cmp(&b.2.gap.abs()))
        .map(|(row, column, entry)| GapPlace {
            column,
            p: row.p,
            p_printed: row.p_printed,
            entry,
        })
}

/// Minimum, mean and maximum of `values` (`None` when empty).
fn min_mean_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64, f64)> {
    let (mut lo, mut hi, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
        sum += v;
        n += 1;
    }
    (n > 0).then(|| (lo, sum / n as f64, hi))
}

fn reading_view(r: &ReadingReport, i: usize, both_neighbours: bool) -> ReadingView {
    let (lo, hi) = CROSSOVER_NQ_RANGE;
    let crossover = |filter, crossover: Option<CrossoverRow>| CrossoverView {
        filter,
        crossover,
        inside: crossover.is_some_and(|c| (lo..=hi).contains(&c.nq)),
    };
    let ekf = |j: usize| r.table.get(j).map(|t| t.j2_ekf.ours);
    ReadingView {
        reproduces: r.max_abs_gap <= TABLE_TOLERANCE,
        largest: largest_gap(&r.table),
        crossovers: [
            crossover("KF", r.crossover.kf),
            crossover("EKF", r.crossover.ekf),
        ],
        spike: r.table.get(i).map(|&row| SpikeRow {
            row,
            neighbours: match (i.checked_sub(1).and_then(ekf), ekf(i + 1)) {
                (Some(b), Some(a)) if both_neighbours => Some([b, a]),
                _ => None,
            },
            above_m: row.max_j2k_ekf > M,
        }),
    }
}

impl View {
    /// Derives the view of `report`.
    pub(crate) fn new(report: &Report) -> Self {
        let i = spike_row();
        let printed = |j: Option<usize>| {
            j.and_then(|j| TABLE_I.get(j))
                .map(|&(_, _, _, kf, _, ekf)| PrintedJ2 { kf, ekf })
        };
        let (pp, nq, _, kf, _, ekf) = TABLE_I[i];
        let p0 = p0_printed();
        let spike = Spike {
            nq,
            p_printed: pp,
            p: table_p(i),
            j2: PrintedJ2 { kf, ekf },
            before: printed(i.checked_sub(1)),
            after: printed(Some(i + 1)),
            p0_24: p0[(1, 3)],
            p0_42: p0[(3, 1)],
            det13: p0[(0, 0)] * p0[(2, 2)] - p0[(0, 2)] * p0[(2, 0)],
        };
        let both = spike.before.is_some() && spike.after.is_some();
        let readings: Vec<ReadingView> = report
            .readings
            .iter()
            .map(|r| reading_view(r, i, both))
            .collect();
        // Readings that differ only in how P0 is used: what the asymmetry adds.
        let twins = report
            .readings
            .iter()
            .filter(|r| r.reading.p0 == P0Use::AsPrinted)
            .filter_map(|printed| {
                let twin = report.readings.iter().find(|r| {
                    r.reading.p0 == P0Use::Symmetrised
                        && r.reading.first_step == printed.reading.first_step
                        && r.reading.divide_by_horizon == printed.reading.divide_by_horizon
                        && r.reading.r_scale == printed.reading.r_scale
                })?;
                Some(Twin {
                    printed: printed.reading.name,
                    symmetrised: twin.reading.name,
                    a: *printed.table.get(i)?,
                    b: *twin.table.get(i)?,
                })
            })
            .collect();
        let paper = report
            .readings
            .iter()
            .position(|r| r.reading.name == READINGS[0].name);
        let nq_offset = paper.and_then(|j| {
            let r = &report.readings[j];
            let (lo, mean, hi) = min_mean_max(r.table.iter().map(|t| t.nq.ours - t.p))?;
            let (_, printed_mean, _) = min_mean_max(r.table.iter().map(|t| t.nq.paper - t.p))?;
            Some(NqOffset {
                lo,
                mean,
                hi,
                printed_mean,
                log_b_nom: (h() * q_nom() * h().transpose()).trace().log10(),
                difference: mean - printed_mean,
            })
        });
        Self {
            truth: Truth {
                t: reentry::T,
                beta: reentry::BETA,
                g: reentry::G,
            },
            tolerance: TABLE_TOLERANCE,
            crossover_range: [CROSSOVER_NQ_RANGE.0, CROSSOVER_NQ_RANGE.1],
            m: M,
            winners: report
                .readings
                .iter()
                .zip(&readings)
                .filter(|(_, v)| v.reproduces)
                .map(|(r, _)| r.reading.name)
                .collect(),
            readings,
            paper,
            spike,
            twins,
            nq_offset,
            figure_reading: paper.map_or(READINGS[0].name, |j| report.readings[j].reading.name),
        }
    }
}
