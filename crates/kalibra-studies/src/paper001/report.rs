//! What the report's template needs beyond the report's own fields: per problem, the rows of
//! the Table I comparison (published value beside ours, gap, seed spread) in the paper's
//! order, and Table II's rows.

use serde::Serialize;

use super::claims::section;
use super::run::{ProblemResult, Report, Spread, value};
use super::scenario::{FILTERS, METRICS, PAPER_FILTERS, TABLE_I, TABLE_II};

/// Everything the template reads.
#[derive(Serialize)]
pub(super) struct Context<'a> {
    /// The report (configuration, claims, costs).
    report: &'a Report,
    /// The filters in column order.
    filters: [&'static str; 6],
    /// One section per problem, in the paper's order.
    problems: Vec<ProblemSection<'a>>,
    /// Table II's rows, [`FILTERS`] order; empty if not timed.
    costs: Vec<CostRow>,
}

/// One problem's section.
#[derive(Serialize)]
struct ProblemSection<'a> {
    /// The paper's name (`I`, `II`, `III`).
    name: &'static str,
    /// The section's anchor, which the claims link to.
    anchor: &'static str,
    /// The problem's results.
    result: &'a ProblemResult,
    /// Table I's metrics, filter by filter.
    rows: Vec<MetricRow>,
}

/// One cell of Table I beside ours.
#[derive(Serialize)]
struct MetricRow {
    metric: &'static str,
    filter: &'static str,
    /// The published value as printed (Rust's shortest form, as the claims give it, so `8`
    /// not `8.0`); `None` where the paper has none (UKF-MAP).
    paper: Option<String>,
    ours: f64,
    /// Ours minus the paper's (dB) for NCI, ours over the paper's minus 1 for the others.
    gap: Option<f64>,
    /// The seed-to-seed spread of our value.
    spread: Option<Spread>,
}

/// One row of Table II.
#[derive(Serialize)]
struct CostRow {
    filter: &'static str,
    /// The published cost relative to the SRF's (%); `None` for UKF-MAP.
    paper: Option<f64>,
    /// Ours relative to the SRF's (1 = the SRF's).
    relative: f64,
    /// Nanoseconds per filter step.
    ns_per_step: f64,
}

impl<'a> Context<'a> {
    /// The template's context for `report`.
    pub(super) fn new(report: &'a Report) -> Self {
        let problems = TABLE_I
            .iter()
            .filter_map(|(name, rows)| {
                let result = report.problems.get(name)?;
                Some(ProblemSection {
                    name,
                    anchor: section(name),
                    result,
                    rows: metric_rows(result, rows),
                })
            })
            .collect();
        let costs = if report.cost_relative_to_srf.is_empty() {
            Vec::new()
        } else {
            FILTERS
                .iter()
                .enumerate()
                .map(|(which, &filter)| CostRow {
                    filter,
                    paper: TABLE_II
                        .get(which)
                        .filter(|_| which < PAPER_FILTERS)
                        .copied(),
                    relative: report.cost_relative_to_srf[filter],
                    ns_per_step: report.cost_ns_per_step[filter],
                })
                .collect()
        };
        Self {
            report,
            filters: FILTERS,
            problems,
            costs,
        }
    }
}

/// Every metric of [`METRICS`] for every filter with a value, published beside ours.
fn metric_rows(p: &ProblemResult, published: &[Option<[f64; 5]>; 4]) -> Vec<MetricRow> {
    let mut out = Vec::new();
    for (metric, row) in METRICS.iter().zip(published) {
        for (which, &filter) in FILTERS.iter().enumerate() {
            let r = &p.filters[filter];
            let Some(ours) = value(r, metric) else {
                continue;
            };
            let published = row.and_then(|row| row.get(which).copied());
            out.push(MetricRow {
                metric,
                filter,
                paper: published.map(|v| format!("{v}")),
                ours,
                gap: published.map(|v| match *metric {
                    "nci" => ours - v,
                    _ => ours / v - 1.0,
                }),
                spread: r.spread.get(metric).copied(),
            });
        }
    }
    out
}
