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

mod figures;

use crate::claims::Claim;
use crate::study::{NamedFigure, Options, Size, Study};
use kalibra_linalg::{Matrix2, Matrix4, SMatrix, U2, U4, Vector2, Vector4};
use serde::Serialize;

use crate::StudyError;
use crate::reentry::{self, CrossoverRow, SweepRow};

/// The printed initial estimate.
pub fn x0_printed() -> Vector4<f64> {
    Vector4::new(2.25e5, -2.81e3, 9.26e4, 6.75e3)
}

/// The printed initial covariance, entry by entry (asymmetric and indefinite).
pub fn p0_printed() -> Matrix4<f64> {
    Matrix4::new(
        2.48e6, 0.0, -6.76e6, 0.0, //
        0.0, 1.24e6, 0.0, -1.73e6, //
        -6.76e6, 0.0, 1.47e7, 0.0, //
        0.0, -0.73e6, 0.0, 7.34e6,
    )
}

/// The printed measurement-noise covariance.
pub fn r_printed() -> Matrix2<f64> {
    Matrix2::new(10.54, -3.85, -3.85, 37.15)
}

/// The printed nominal process-noise covariance.
pub fn q_nom() -> Matrix4<f64> {
    Matrix4::new(
        2.48e5, 6.32e4, -5.10e5, -1.04e5, //
        6.32e4, 2.34e4, -1.04e5, -2.88e4, //
        -5.10e5, -1.04e5, 1.44e6, 3.45e5, //
        -1.04e5, -2.88e4, 3.45e5, 1.20e5,
    )
}

/// Table I as printed: `(p printed, nq, J1 KF, J2 KF, J1 EKF, J2 EKF)`.
pub const TABLE_I: [(f64, f64, f64, f64, f64, f64); 19] = [
    (-13.0, -6.79, 1.51, 0.00, 1.51, 0.00),
    (-12.0, -5.79, 1.51, 0.00, 1.51, 0.00),
    (-11.0, -4.79, 1.51, 0.00, 1.51, 0.00),
    (-10.0, -3.79, 1.50, 0.00, 1.51, 0.00),
    (-9.0, -2.79, 1.46, 0.00, 1.48, 0.00),
    (-8.0, -1.79, 1.35, 0.01, 1.39, 0.02),
    (-7.0, -0.79, 1.13, 0.07, 1.17, 0.08),
    (-6.0, 0.21, 0.78, 0.30, 0.81, 0.31),
    (-5.0, 1.21, 0.37, 0.80, 0.38, 0.81),
    (-4.0, 2.21, 0.10, 1.31, 0.11, 1.33),
    (-3.0, 3.21, 0.02, 1.59, 0.02, 1.60),
    (-1.0, 4.21, 0.00, 1.65, 0.00, 1.66),
    (0.0, 5.21, 0.00, 1.65, 0.00, 1.66),
    (1.0, 6.21, 0.00, 1.65, 0.00, 1.67),
    (2.0, 7.21, 0.00, 1.75, 0.00, 1.76),
    (3.0, 8.21, 0.00, 1.71, 0.00, 1.72),
    (4.0, 9.21, 0.00, 1.72, 0.00, 1.73),
    (5.0, 10.21, 0.00, 1.72, 0.00, 1.73),
    (6.0, 11.21, 0.00, 1.72, 0.00, 1.73),
];

/// The `p` of Table I's row `i`: `-13 + i` (the printed labels skip -2).
pub fn table_p(row: usize) -> f64 {
    -13.0 + row as f64
}

/// The paper's claim about the crossover: `nq` between 0.21 and 1.21 for both filters.
pub const CROSSOVER_NQ_RANGE: (f64, f64) = (0.21, 1.21);

/// How the filter is started and `P0` is used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum P0Use {
    /// Entry by entry as printed.
    AsPrinted,
    /// `(P0 + P0^T) / 2` (still indefinite).
    Symmetrised,
}

/// One way of reading the paper's set-up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Reading {
    /// Short name, used as the key in `results.json`.
    pub name: &'static str,
    /// What it assumes.
    pub description: &'static str,
    /// The filter starts at step `first_step` (2: after two-point differencing; 0: at once).
    pub first_step: usize,
    /// Divide J1, J2 by the horizon `N = 59` (true) or by the updates run (false).
    pub divide_by_horizon: bool,
    /// Factor applied to the printed `R`.
    pub r_scale: f64,
    /// How `P0` is used.
    pub p0: P0Use,
}

/// The readings the report shows; the first is the one that reproduces Table I.
pub const READINGS: [Reading; 4] = [
    Reading {
        name: "paper",
        description: "start at k = 2 (two-point differencing used y1, y2), divide by N = 59, R as printed / 10, P0 as printed",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 0.1,
        p0: P0Use::AsPrinted,
    },
    Reading {
        name: "paper-symmetric-p0",
        description: "as 'paper', with P0 symmetrised",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 0.1,
        p0: P0Use::Symmetrised,
    },
    Reading {
        name: "paper-r-as-printed",
        description: "as 'paper', with R as printed",
        first_step: 2,
        divide_by_horizon: true,
        r_scale: 1.0,
        p0: P0Use::AsPrinted,
    },
    Reading {
        name: "plain",
        description: "start at k = 0 with all 59 measurements, divide by the updates run, R as printed, P0 symmetrised",
        first_step: 0,
        divide_by_horizon: false,
        r_scale: 1.0,
        p0: P0Use::Symmetrised,
    },
];

/// The two filters of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum FilterKind {
    /// Linear KF on the drag-free model.
    Kf,
    /// EKF on the drag model.
    Ekf,
}

/// Size of the study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Step of the fine `p` grid used for the figure and the crossover.
    pub fine_step: f64,
    /// Threads for the sweep (0: all cores); results do not depend on it.
    pub threads: usize,
}

impl Config {
    /// The full study: fine grid step 0.05 in `p` over `[-13, 6]`.
    pub fn paper() -> Self {
        Self {
            fine_step: 0.05,
            threads: 0,
        }
    }

    /// The same study on a coarser fine grid (Table I itself is always complete).
    pub fn quick() -> Self {
        Self {
            fine_step: 0.25,
            threads: 0,
        }
    }
}

/// The fixed inputs of every filter run: noise-free measurements `y_1 .. y_59`.
struct Setup {
    measurements: Vec<Vector2<f64>>,
}

impl Setup {
    fn new() -> Result<Self, StudyError> {
        let truth = reentry::noise_free_truth()?;
        Ok(Self {
            measurements: truth[1..]
                .iter()
                .map(|x| Vector2::new(x[0], x[2]))
                .collect(),
        })
    }

    fn horizon(&self) -> usize {
        self.measurements.len()
    }
}

fn h() -> SMatrix<f64, 2, 4> {
    SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// The J metrics of one update in the paper's arithmetic (explicit LU solves, no checks).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayStep {
    /// `J1k = tr(S^-1 R)`.
    pub j1: f64,
    /// `J2k = tr((A + B)^-1 B)`.
    pub j2: f64,
    /// `tr(N_k) = tr((A + B)^-1 (A - C))`.
    pub tr_n: f64,
    /// `tr(B_k)`.
    pub tr_b: f64,
    /// Whether `S_k` and `A_k + B_k` (symmetrised) were both positive definite.
    pub definite: bool,
}

/// A KF/EKF run in the paper's arithmetic: `x- = f(x+)`, `F` the Jacobian at `x+`,
/// `P- = F P F^T + Q`, `S = H P- H^T + R`, `K = P- H^T S^-1` by LU, Joseph update, and the J
/// metrics of every update by LU solves. It exists because paper 000's printed `P0` is
/// indefinite (and asymmetric), which makes `S` indefinite at some steps: the library filters
/// refuse that with a typed error, as they should, while the published numbers come from
/// arithmetic that carries on. On valid inputs it equals the library's filters (a test checks
/// it to 1e-9), so it adds no other difference. `zs[i]` is the measurement at step
/// `first_step + 1 + i`.
///
/// # Errors
/// [`StudyError::Harness`] if `S` or `A + B` is singular.
pub fn replay<D: kalibra_models::Dynamics<U4>>(
    dynamics: &D,
    r: &Matrix2<f64>,
    x0: Vector4<f64>,
    p0: Matrix4<f64>,
    first_step: usize,
    zs: &[Vector2<f64>],
) -> Result<Vec<ReplayStep>, StudyError> {
    let h = h();
    let (mut x, mut p) = (x0, p0);
    let singular =
        |what: &str, k: usize| StudyError::Harness(format!("{what} singular at step {k}"));
    let mut out = Vec::with_capacity(zs.len());
    for (i, z) in zs.iter().enumerate() {
        let k = first_step + i + 1;
        let f = dynamics.jacobian(k - 1, &x);
        let q = dynamics.noise_cov(k - 1);
        x = dynamics.transition(k - 1, &x);
        let propagated = f * p * f.transpose();
        let prior = propagated + q;
        let a = h * propagated * h.transpose();
        let b = h * q * h.transpose();
        let s = h * prior * h.transpose() + r;
        let s_lu = s.lu();
        // K = P- H^T S^-1 exactly, also when P- (hence S) is asymmetric: K^T = S^-T H P-^T.
        let gain = s
            .transpose()
            .lu()
            .solve(&(h * prior.transpose()))
            .ok_or_else(|| singular("S", k))?
            .transpose();
        x += gain * (z - h * x);
        let ikh = Matrix4::identity() - gain * h;
        p = ikh * prior * ikh.transpose() + gain * r * gain.transpose();
        let c = h * p * h.transpose();
        let ab = a + b;
        let ab_lu = ab.lu();
        let trace_solve = |lu: &kalibra_linalg::nalgebra::LU<f64, U2, U2>, y: &Matrix2<f64>| {
            lu.solve(y).map(|m| m.trace())
        };
        let j1 = trace_solve(&s_lu, r).ok_or_else(|| singular("S", k))?;
        let j2 = trace_solve(&ab_lu, &b).ok_or_else(|| singular("A + B", k))?;
        let tr_n = trace_solve(&ab_lu, &(a - c)).ok_or_else(|| singular("A + B", k))?;
        let sym = |m: Matrix2<f64>| (m + m.transpose()) * 0.5;
        let definite = sym(s).cholesky().is_some() && sym(ab).cholesky().is_some();
        out.push(ReplayStep {
            j1,
            j2,
            tr_n,
            tr_b: b.trace(),
            definite,
        });
    }
    Ok(out)
}

/// J1, J2 and nq of one filter at one `p`.
fn point(
    setup: &Setup,
    reading: &Reading,
    kind: FilterKind,
    p: f64,
) -> Result<SweepRow, StudyError> {
    let q = reentry::scaled(&q_nom(), p);
    let r = r_printed() * reading.r_scale;
    let p0 = match reading.p0 {
        P0Use::AsPrinted => p0_printed(),
        P0Use::Symmetrised => (p0_printed() + p0_printed().transpose()) * 0.5,
    };
    // y_k is measurements[k - 1]; the filter processes y_{first_step + 1} onwards.
    let zs = &setup.measurements[reading.first_step..];
    let dynamics = reentry::dynamics(q)?;
    let steps = match kind {
        FilterKind::Kf => replay(
            &dynamics.drag_free(),
            &r,
            x0_printed(),
            p0,
            reading.first_step,
            zs,
        )?,
        FilterKind::Ekf => replay(&dynamics, &r, x0_printed(), p0, reading.first_step, zs)?,
    };
    let updates = steps.len();
    let divisor = if reading.divide_by_horizon {
        setup.horizon()
    } else {
        updates
    } as f64;
    Ok(SweepRow {
        p,
        nq: steps.iter().map(|s| s.tr_b.log10()).sum::<f64>() / updates as f64,
        j1: steps.iter().map(|s| s.j1).sum::<f64>() / divisor,
        j2: steps.iter().map(|s| s.j2).sum::<f64>() / divisor,
        indefinite_updates: steps.iter().filter(|s| !s.definite).count(),
        max_j2k: steps.iter().map(|s| s.j2).fold(f64::NEG_INFINITY, f64::max),
    })
}

/// One entry of our Table I beside the paper's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Entry {
    /// Printed value.
    pub paper: f64,
    /// Ours.
    pub ours: f64,
    /// `ours - paper`.
    pub gap: f64,
}

impl Entry {
    pub(crate) fn new(paper: f64, ours: f64) -> Self {
        Self {
            paper,
            ours,
            gap: ours - paper,
        }
    }
}

/// One row of Table I, ours beside the paper's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TableRow {
    /// The printed `p` label.
    pub p_printed: f64,
    /// The `p` we run (the printed labels skip -2).
    pub p: f64,
    /// `nq`.
    pub nq: Entry,
    /// J1 of the KF.
    pub j1_kf: Entry,
    /// J2 of the KF.
    pub j2_kf: Entry,
    /// J1 of the EKF.
    pub j1_ekf: Entry,
    /// J2 of the EKF.
    pub j2_ekf: Entry,
    /// Largest single-step J2k of the EKF at this `p` (a value above `m = 2` shows the
    /// indefinite `P0` at work).
    pub max_j2k_ekf: f64,
}

impl TableRow {
    /// The largest `|gap|` over the four J entries.
    pub fn max_j_gap(&self) -> f64 {
        [self.j1_kf, self.j2_kf, self.j1_ekf, self.j2_ekf]
            .iter()
            .map(|e| e.gap.abs())
            .fold(0.0, f64::max)
    }
}

/// Per-filter results of one reading.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PerFilter<T> {
    /// The KF.
    #[serde(rename = "KF")]
    pub kf: T,
    /// The EKF.
    #[serde(rename = "EKF")]
    pub ekf: T,
}

/// The results of one reading.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReadingReport {
    /// The reading.
    pub reading: Reading,
    /// Table I, ours beside the paper's.
    pub table: Vec<TableRow>,
    /// Largest `|gap|` over all J entries of the table.
    pub max_abs_gap: f64,
    /// The fine sweep per filter.
    pub sweep: PerFilter<Vec<SweepRow>>,
    /// The crossover per filter (None if J1 - J2 never changes sign).
    pub crossover: PerFilter<Option<CrossoverRow>>,
}

/// The results of the study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The configuration run.
    pub config: Config,
    /// Number of measurements in the horizon (59).
    pub horizon: usize,
    /// One report per reading, in the order of [`READINGS`].
    pub readings: Vec<ReadingReport>,
}

impl Report {
    /// The report of the reading named `name`.
    pub fn reading(&self, name: &str) -> Option<&ReadingReport> {
        self.readings.iter().find(|r| r.reading.name == name)
    }
}

/// Runs every reading: Table I (19 values of `p`) and a fine sweep for the crossover, for the
/// KF and the EKF.
///
/// # Errors
/// [`StudyError`] if a filter run fails or `config.fine_step` is not positive.
pub fn run(config: &Config) -> Result<Report, StudyError> {
    let setup = Setup::new()?;
    let fine = kalibra_sim::grid(-13.0..=6.0, config.fine_step)?;
    let mut readings = Vec::new();
    for reading in &READINGS {
        let sweep_of = |kind, grid: &[f64]| -> Result<Vec<SweepRow>, StudyError> {
            Ok(kalibra_sim::sweep(grid, config.threads, |p| {
                point(&setup, reading, kind, p)
            })?)
        };
        let table_ps: Vec<f64> = (0..TABLE_I.len()).map(table_p).collect();
        let (kf_t, ekf_t) = (
            sweep_of(FilterKind::Kf, &table_ps)?,
            sweep_of(FilterKind::Ekf, &table_ps)?,
        );
        let table: Vec<TableRow> = TABLE_I
            .iter()
            .zip(kf_t.iter().zip(&ekf_t))
            .map(|(&(pp, nq, j1k, j2k, j1e, j2e), (k, e))| TableRow {
                p_printed: pp,
                p: k.p,
                nq: Entry::new(nq, k.nq),
                j1_kf: Entry::new(j1k, k.j1),
                j2_kf: Entry::new(j2k, k.j2),
                j1_ekf: Entry::new(j1e, e.j1),
                j2_ekf: Entry::new(j2e, e.j2),
                max_j2k_ekf: e.max_j2k,
            })
            .collect();
        let max_abs_gap = table.iter().map(TableRow::max_j_gap).fold(0.0, f64::max);
        let sweep = PerFilter {
            kf: sweep_of(FilterKind::Kf, &fine)?,
            ekf: sweep_of(FilterKind::Ekf, &fine)?,
        };
        let crossover = PerFilter {
            kf: reentry::crossover_of(&sweep.kf)?,
            ekf: reentry::crossover_of(&sweep.ekf)?,
        };
        readings.push(ReadingReport {
            reading: *reading,
            table,
            max_abs_gap,
            sweep,
            crossover,
        });
    }
    Ok(Report {
        config: *config,
        horizon: setup.horizon(),
        readings,
    })
}

/// Largest `|gap|` between our J values and Table I's that counts as a reproduction (the
/// table prints two decimals).
pub const TABLE_TOLERANCE: f64 = 0.02;

/// The measurement dimension `m`: every `J1k` and `J2k` lies in `[0, m]` for valid covariances.
const M: f64 = 2.0;

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
fn largest_gap(table: &[TableRow]) -> Option<(&TableRow, &'static str, Entry)> {
    table
        .iter()
        .flat_map(|row| j_entries(row).map(|(name, e)| (row, name, e)))
        .max_by(|a, b| a.2.gap.abs().total_cmp(&b.2.gap.abs()))
}

/// The index of Table I's J2 spike: the row with the largest printed KF J2.
fn spike_row() -> usize {
    TABLE_I
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.3.total_cmp(&b.1.3))
        .map_or(0, |(i, _)| i)
}

/// Text safe inside a Markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
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

impl Report {
    /// The published claims beside ours (the `paper` reading, the one asserted): Table I's 76
    /// J entries within [`TABLE_TOLERANCE`], and the crossover `nq` of each filter inside
    /// [`CROSSOVER_NQ_RANGE`].
    pub fn claims(&self) -> Vec<crate::claims::Claim> {
        use crate::claims::{Claim, Verdict};
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

    /// The report as Markdown: set-up and readings, Table I of the `paper` reading beside the
    /// printed one, the largest gap of every reading, the crossover against the paper's claim,
    /// the J2 spike, the `nq` offset, the `results.json` keys and links to the figures
    /// (`j1j2_kf.svg`, `j1j2_ekf.svg`, `j1j2_readings.svg`, to be written beside the report).
    ///
    /// Every number shown comes from the report or from the published constants of this
    /// module ([`TABLE_I`], [`CROSSOVER_NQ_RANGE`], the printed matrices).
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let reproduces = |r: &ReadingReport| r.max_abs_gap <= TABLE_TOLERANCE;
        let paper = self.reading(READINGS[0].name);

        // Title and set-up.
        let _ = writeln!(
            s,
            "# Paper 000: J1/J2 for a KF and an EKF (Saha, Goswami, Ghosh 2012)\n"
        );
        let _ = writeln!(
            s,
            "**Truth**: the ballistic re-entry of Farina, Ristic and Benvenuti (2002), T = {} s, \
             beta = {} kg m^-1 s^-2, g = {} m/s^2, noise-free until ground impact: {} position \
             measurements y_1 .. y_{} (H = [[1,0,0,0],[0,0,1,0]]), also noise-free. \
             **Filters**: a linear KF on the drag-free model and an EKF on the drag model, both \
             from the printed x0, P0, R and Q_nom with a Joseph update, in the paper's arithmetic \
             (which carries on through the indefinite printed P0). \
             **Sweep**: Q = 10^p Q_nom at the 19 values of p of Table I, and on a fine grid \
             p = -13 .. 6 step {} for the crossover and the figures. J1 and J2 are horizon \
             averages of J1k = tr(S_k^-1 R) and J2k = tr((A_k + B_k)^-1 B_k); \
             nq = mean of log10 tr(B_k) over the updates.\n",
            reentry::T,
            reentry::BETA,
            reentry::G,
            self.horizon,
            self.horizon,
            self.config.fine_step
        );

        // Readings.
        let _ = writeln!(s, "## Readings\n");
        let _ = writeln!(
            s,
            "The paper leaves open, or prints inconsistently, where the filter starts, the \
             horizon divisor, R and P0. Each reading fixes them; a reading reproduces Table I \
             when every J entry is within {TABLE_TOLERANCE} of the printed value.\n"
        );
        let _ = writeln!(s, "| reading | description | reproduces Table I |");
        let _ = writeln!(s, "|---|---|---|");
        for r in &self.readings {
            let _ = writeln!(
                s,
                "| `{}` | {} | {} |",
                cell(r.reading.name),
                cell(r.reading.description),
                if reproduces(r) { "yes" } else { "no" }
            );
        }
        let winners: Vec<String> = self
            .readings
            .iter()
            .filter(|r| reproduces(r))
            .map(|r| format!("`{}`", r.reading.name))
            .collect();
        let _ = writeln!(
            s,
            "\nReading(s) that reproduce Table I: {}.\n",
            if winners.is_empty() {
                "none".to_string()
            } else {
                winners.join(", ")
            }
        );

        // Table I of the paper reading.
        if let Some(r) = paper {
            let _ = writeln!(s, "## Table I (reading `{}`)\n", r.reading.name);
            let _ = writeln!(
                s,
                "The printed p column skips -2: the rows printed -1 .. 6 are p = -2 .. 5. \
                 Paper values as printed (2 decimals), ours to 3 decimals, gap = ours - paper.\n"
            );
            let _ = writeln!(
                s,
                "| p (printed) | p (run) | nq paper / ours \
                 | KF J1 paper | KF J1 ours | KF J1 gap | KF J2 paper | KF J2 ours | KF J2 gap \
                 | EKF J1 paper | EKF J1 ours | EKF J1 gap | EKF J2 paper | EKF J2 ours | EKF J2 gap |"
            );
            let _ = writeln!(s, "|---|---|---{}|", "|---".repeat(12));
            for row in &r.table {
                let _ = write!(
                    s,
                    "| {:.0} | {:.0} | {:.2} / {:.3} |",
                    row.p_printed, row.p, row.nq.paper, row.nq.ours
                );
                for (_, e) in j_entries(row) {
                    let _ = write!(s, " {:.2} | {:.3} | {:+.3} |", e.paper, e.ours, e.gap);
                }
                let _ = writeln!(s);
            }
            let _ = write!(
                s,
                "\nlargest |gap| = {:.3} (tolerance {TABLE_TOLERANCE}): {}",
                r.max_abs_gap,
                if reproduces(r) {
                    "reproduced"
                } else {
                    "not reproduced"
                }
            );
            if let Some((row, name, _)) = largest_gap(&r.table) {
                let _ = write!(
                    s,
                    " (at {name}, p = {:.0}, printed {:.0})",
                    row.p, row.p_printed
                );
            }
            let _ = writeln!(s, ".\n");
        }

        // The gap of every reading.
        let _ = writeln!(s, "## Largest gap per reading\n");
        let _ = writeln!(
            s,
            "| reading | largest \\|gap\\| | where | within {TABLE_TOLERANCE} |"
        );
        let _ = writeln!(s, "|---|---|---|---|");
        for r in &self.readings {
            let place = largest_gap(&r.table).map_or_else(
                || "-".to_string(),
                |(row, name, e)| {
                    format!(
                        "{name} at p = {:.0} (printed {:.0}): {:.3} vs {:.2}",
                        row.p, row.p_printed, e.ours, e.paper
                    )
                },
            );
            let _ = writeln!(
                s,
                "| `{}` | {:.3} | {} | {} |",
                cell(r.reading.name),
                r.max_abs_gap,
                place,
                if reproduces(r) { "yes" } else { "no" }
            );
        }
        let _ = writeln!(s);

        // Crossover.
        let (lo, hi) = CROSSOVER_NQ_RANGE;
        let _ = writeln!(s, "## Crossover\n");
        let _ = writeln!(
            s,
            "The paper: at Q_comp the plots of J1 and J2 cross, at an nq between {lo} and {hi} \
             for both the KF and the EKF. Ours: the first sign change of J1 - J2 on the fine \
             grid, interpolated linearly in nq; p gives Q_comp = 10^p Q_nom.\n"
        );
        let _ = writeln!(
            s,
            "| reading | filter | nq | J1 = J2 | p | paper's nq range | verdict |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in &self.readings {
            for (filter, c) in [("KF", &r.crossover.kf), ("EKF", &r.crossover.ekf)] {
                let _ = match c {
                    Some(c) => writeln!(
                        s,
                        "| `{}` | {filter} | {:.3} | {:.3} | {:.3} | {lo} .. {hi} | {} |",
                        cell(r.reading.name),
                        c.nq,
                        c.j,
                        c.p,
                        if (lo..=hi).contains(&c.nq) {
                            "inside"
                        } else {
                            "outside"
                        }
                    ),
                    None => writeln!(
                        s,
                        "| `{}` | {filter} | none | - | - | {lo} .. {hi} | no crossover |",
                        cell(r.reading.name)
                    ),
                };
            }
        }
        let _ = writeln!(s);

        // The J2 spike.
        let i = spike_row();
        let (pp, nq_spike, _, j2k_paper, _, j2e_paper) = TABLE_I[i];
        let neighbour = |j: Option<usize>| j.and_then(|j| TABLE_I.get(j));
        let (before, after) = (neighbour(i.checked_sub(1)), neighbour(Some(i + 1)));
        let _ = writeln!(s, "## The J2 spike at nq = {nq_spike:.2}\n");
        let _ = write!(
            s,
            "Table I prints J2 = {j2k_paper:.2} (KF) and {j2e_paper:.2} (EKF) at the row printed \
             p = {pp:.0} (p = {:.0} in our run)",
            table_p(i)
        );
        if let (Some(b), Some(a)) = (before, after) {
            let _ = write!(
                s,
                ", above both neighbours ({:.2} / {:.2} one row before, {:.2} / {:.2} one row after)",
                b.3, b.5, a.3, a.5
            );
        }
        let p0 = p0_printed();
        let det13 = p0[(0, 0)] * p0[(2, 2)] - p0[(0, 2)] * p0[(2, 0)];
        let _ = writeln!(
            s,
            ". J2k = tr((A_k + B_k)^-1 B_k) stays in [0, m = {M}] when the covariances are \
             positive semi-definite, so a J2 that rises and falls again needs an update that \
             leaves the bound. The printed P0 provides it: it is asymmetric ((2,4) = {:.3e}, \
             (4,2) = {:.3e}) and indefinite (the (1,3) block has determinant {det13:.3e}), so \
             A_k = H F P F^T H^T is indefinite at the first update; where B_k = 10^p H Q_nom H^T \
             just offsets its negative direction, A_k + B_k is nearly singular and that single \
             J2k is far above m, which lifts the horizon average at this one row. \
             Symmetrising P0 keeps it indefinite, so the spike stays; what the asymmetry adds \
             is the difference between the readings below that differ only in P0. \
             max J2k is the largest single-step J2k of the EKF at this p.\n",
            p0[(1, 3)],
            p0[(3, 1)]
        );
        let _ = write!(
            s,
            "| reading | P0 | KF J2 (paper {j2k_paper:.2}) | EKF J2 (paper {j2e_paper:.2}) |"
        );
        if let (Some(b), Some(a)) = (before, after) {
            let _ = write!(
                s,
                " EKF J2 one row before / after (paper {:.2} / {:.2}) |",
                b.5, a.5
            );
        }
        let _ = writeln!(s, " max J2k EKF | above m |");
        let columns = if before.is_some() && after.is_some() {
            7
        } else {
            6
        };
        let _ = writeln!(s, "|{}", "---|".repeat(columns));
        for r in &self.readings {
            let Some(row) = r.table.get(i) else { continue };
            let _ = write!(
                s,
                "| `{}` | {} | {:.3} | {:.3} |",
                cell(r.reading.name),
                match r.reading.p0 {
                    P0Use::AsPrinted => "as printed",
                    P0Use::Symmetrised => "symmetrised",
                },
                row.j2_kf.ours,
                row.j2_ekf.ours
            );
            if before.is_some() && after.is_some() {
                let ekf = |j: usize| r.table.get(j).map(|t| t.j2_ekf.ours);
                match (ekf(i - 1), ekf(i + 1)) {
                    (Some(b), Some(a)) => {
                        let _ = write!(s, " {b:.3} / {a:.3} |");
                    }
                    _ => s.push_str(" - |"),
                }
            }
            let _ = writeln!(
                s,
                " {:.3} | {} |",
                row.max_j2k_ekf,
                if row.max_j2k_ekf > M { "yes" } else { "no" }
            );
        }
        let _ = writeln!(s);
        // Readings that differ only in how P0 is used: what the asymmetry adds.
        for printed in self
            .readings
            .iter()
            .filter(|r| r.reading.p0 == P0Use::AsPrinted)
        {
            let twin = self.readings.iter().find(|r| {
                r.reading.p0 == P0Use::Symmetrised
                    && r.reading.first_step == printed.reading.first_step
                    && r.reading.divide_by_horizon == printed.reading.divide_by_horizon
                    && r.reading.r_scale == printed.reading.r_scale
            });
            if let (Some(twin), Some(a), Some(b)) = (
                twin,
                printed.table.get(i),
                twin.and_then(|t| t.table.get(i)),
            ) {
                let _ = writeln!(
                    s,
                    "P0 as printed (`{}`) vs symmetrised (`{}`) at this row: EKF J2 {:.3} vs \
                     {:.3} ({:+.3}), KF J2 {:.3} vs {:.3} ({:+.3}), max J2k {:.3} vs {:.3}.\n",
                    printed.reading.name,
                    twin.reading.name,
                    a.j2_ekf.ours,
                    b.j2_ekf.ours,
                    b.j2_ekf.ours - a.j2_ekf.ours,
                    a.j2_kf.ours,
                    b.j2_kf.ours,
                    b.j2_kf.ours - a.j2_kf.ours,
                    a.max_j2k_ekf,
                    b.max_j2k_ekf
                );
            }
        }

        // The nq offset.
        if let Some(r) = paper {
            let ours = min_mean_max(r.table.iter().map(|t| t.nq.ours - t.p));
            let printed = min_mean_max(r.table.iter().map(|t| t.nq.paper - t.p));
            if let (Some((o_lo, o_mean, o_hi)), Some((_, p_mean, _))) = (ours, printed) {
                let b_nom = (h() * q_nom() * h().transpose()).trace();
                let _ = writeln!(s, "## nq offset\n");
                let _ = writeln!(
                    s,
                    "Ours: nq = p + {o_mean:.3} at every row of Table I (range {o_lo:.6} .. \
                     {o_hi:.6}); B_k = 10^p H Q_nom H^T at every update, so the offset is \
                     log10 tr(H Q_nom H^T) = {:.4}. The table prints nq = p + {p_mean:.2} (p as \
                     run). The difference, {:+.3}, is not explained in the paper; it moves the \
                     nq axis, not the J values.\n",
                    b_nom.log10(),
                    o_mean - p_mean
                );
            }
        }

        // results.json.
        let _ = writeln!(s, "## results.json schema\n");
        let _ = writeln!(
            s,
            "The report serialises (serde) to the `results` object of `results.json`:\n\n\
             * `config`: `fine_step` (step of the fine p grid), `threads`.\n\
             * `horizon`: number of measurements (the divisor N of the horizon averages).\n\
             * `readings[]`, in the order of the Readings table, each with\n\
             \x20 * `reading`: `name`, `description`, `first_step`, `divide_by_horizon`, \
             `r_scale`, `p0` (`\"AsPrinted\"` or `\"Symmetrised\"`);\n\
             \x20 * `table[]`: one object per Table I row: `p_printed`, `p`, and `nq`, `j1_kf`, \
             `j2_kf`, `j1_ekf`, `j2_ekf`, each `{{paper, ours, gap}}` (gap = ours - paper), and \
             `max_j2k_ekf`;\n\
             \x20 * `max_abs_gap`: the largest |gap| over the J entries of `table`;\n\
             \x20 * `sweep`: `KF` and `EKF`, each an array over the fine grid of \
             `{{p, nq, j1, j2, indefinite_updates, max_j2k}}` (`indefinite_updates`: updates at \
             which A_k + B_k was not positive definite; `max_j2k`: the largest single-step J2k);\n\
             \x20 * `crossover`: `KF` and `EKF`, each `{{nq, j, p}}` or `null` when J1 - J2 never \
             changes sign.\n"
        );

        // Figures.
        let _ = writeln!(s, "## Figures\n");
        let name = paper.map_or(READINGS[0].name, |r| r.reading.name);
        let _ = writeln!(
            s,
            "J1 and J2 against nq on the fine grid (reading `{name}`, lines) with Table I's \
             values (markers), the crossover circled and the paper's range {lo} .. {hi} dashed:\n\n\
             ![KF: J1 and J2 against nq](j1j2_kf.svg)\n\n\
             ![EKF: J1 and J2 against nq](j1j2_ekf.svg)\n\n\
             The EKF's J1 and J2 under every reading:\n\n\
             ![EKF: J1 and J2 against nq, every reading](j1j2_readings.svg)"
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_filters::{Ekf, Filter, FilterOptions, Kf, Start};
    use kalibra_linalg::{U2, Vector4};
    use kalibra_models::LinearObservation;

    /// The replay is the library's KF/EKF arithmetic: on a valid (positive definite) `P0`
    /// both give the same J values.
    #[test]
    fn replay_equals_the_library_filters_on_valid_inputs() {
        let setup = Setup::new().unwrap();
        let p0 = Matrix4::from_diagonal(&Vector4::new(2.48e6, 1.24e6, 1.47e7, 7.34e6));
        let r = r_printed();
        let meas = LinearObservation::<U4, U2>::new(h(), r).unwrap();
        let zs = &setup.measurements[2..];
        let options = FilterOptions {
            first_step: 2,
            ..FilterOptions::default()
        };
        for p in [-8.0, -4.0, 1.0] {
            let dynamics = reentry::dynamics(reentry::scaled(&q_nom(), p)).unwrap();
            let ours = replay(&dynamics, &r, x0_printed(), p0, 2, zs).unwrap();
            let ours_kf = replay(&dynamics.drag_free(), &r, x0_printed(), p0, 2, zs).unwrap();
            let mut ekf = Ekf::with_options(&dynamics, &meas, x0_printed(), p0, options).unwrap();
            let ekf_records = ekf
                .run_collect(zs.iter().map(Some), Start::PredictFirst)
                .unwrap();
            let mut kf =
                Kf::with_options(dynamics.drag_free(), &meas, x0_printed(), p0, options).unwrap();
            let kf_records = kf
                .run_collect(zs.iter().map(Some), Start::PredictFirst)
                .unwrap();
            for (replayed, records) in [(&ours, &ekf_records), (&ours_kf, &kf_records)] {
                assert_eq!(replayed.len(), records.len());
                for (a, rec) in replayed.iter().zip(records) {
                    let b = reentry::j_of(rec).unwrap();
                    for (x, y) in [
                        (a.j1, b.j1),
                        (a.j2, b.j2),
                        (a.tr_n, b.tr_n),
                        (a.tr_b, b.tr_b),
                    ] {
                        assert!(
                            (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                            "p {p}: {x} vs {y}"
                        );
                    }
                    assert!(a.definite && b.a_plus_b_definite);
                }
            }
        }
    }

    /// The Markdown report shows Table I's header and one row per printed row.
    #[test]
    fn markdown_has_table_i() {
        let report = run(&Config::quick()).unwrap();
        let md = report.to_markdown();
        assert!(md.starts_with("# Paper 000: J1/J2 for a KF and an EKF"));
        assert!(md.contains(
            "| p (printed) | p (run) | nq paper / ours | KF J1 paper | KF J1 ours | KF J1 gap |"
        ));
        let section = md
            .split("## Table I")
            .nth(1)
            .and_then(|t| t.split("\n## ").next())
            .unwrap();
        for (i, &(pp, nq, ..)) in TABLE_I.iter().enumerate() {
            let start = format!("| {pp:.0} | {:.0} | {nq:.2} / ", table_p(i));
            assert_eq!(
                section.lines().filter(|l| l.starts_with(&start)).count(),
                1,
                "row {start}"
            );
        }
        assert!(md.contains("largest |gap| = "));
        assert!(md.contains("(j1j2_kf.svg)") && md.contains("(j1j2_ekf.svg)"));
        assert!(!md.contains("NaN"));
    }
}

/// The study, as the registry lists it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Paper000;

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

    fn config(&self, options: &Options) -> Config {
        let mut config = match options.size {
            Size::Paper => Config::paper(),
            Size::Quick => Config::quick(),
        };
        config.threads = options.threads;
        config
    }

    fn seed(&self, _config: &Config) -> Option<u64> {
        None
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

    fn markdown(&self, _config: &Config, report: &Report) -> Result<String, StudyError> {
        Ok(report.to_markdown())
    }

    fn figures(&self, report: &Report) -> Vec<NamedFigure> {
        NamedFigure::from_pairs(figures::figures(report))
    }
}
