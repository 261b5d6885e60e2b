//! The run: the configuration, the as-given filter runs and their J metrics ([`replay`]), Table I and the
//! fine sweeps of every reading, and the report they fill.

use kalibra_filters::{Ekf, Filter, FilterOptions, Kf, Start, StepRecord};
use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
use kalibra_models::{Ballistic, LinearObservation};
use serde::Serialize;

use super::scenario::{
    FilterKind, P0Use, READINGS, Reading, Setup, TABLE_I, h, p0_printed, q_nom, r_printed, table_p,
    x0_printed,
};
use crate::StudyError;
use crate::reentry::{self, CrossoverRow, SweepRow};

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

/// A KF (drag-free, [`Ballistic::drag_free`]) or EKF run from `p0` as given, with the J metrics of every update in the paper's
/// arithmetic. The filter is the library's, through its explicit opt-in
/// ([`Kf::as_given`], [`Ekf::as_given`]): paper 000's printed `P0` is asymmetric and
/// indefinite, which makes `S` indefinite at some steps, and the as-given filter carries on
/// with LU solves where a checked filter would (rightly) stop with a typed error. The J
/// metrics are computed here by LU too, since the library's `j_step` refuses the asymmetric
/// `A_k` such a run produces. `zs[i]` is the measurement at step `first_step + 1 + i`.
///
/// # Errors
/// [`StudyError::Filter`] if the filter fails (a singular `S`), [`StudyError::Harness`] if
/// `S` or `A + B` is singular in the J metrics.
pub fn replay(
    dynamics: &Ballistic,
    r: &Matrix2<f64>,
    x0: Vector4<f64>,
    p0: Matrix4<f64>,
    first_step: usize,
    kind: FilterKind,
    zs: &[Vector2<f64>],
) -> Result<Vec<ReplayStep>, StudyError> {
    let meas = LinearObservation::<U4, U2>::new(h(), *r)?;
    let options = FilterOptions {
        first_step,
        ..FilterOptions::default()
    };
    let measurements = zs.iter().map(Some);
    let records = match kind {
        FilterKind::Kf => Kf::as_given(dynamics.drag_free(), &meas, x0, p0, options)?
            .run_collect(measurements, Start::PredictFirst)?,
        FilterKind::Ekf => Ekf::as_given(dynamics, &meas, x0, p0, options)?
            .run_collect(measurements, Start::PredictFirst)?,
    };
    records.iter().map(j_lu).collect()
}

/// The J metrics of one as-given update by LU solves, and whether `S` and `A + B`
/// (symmetrised) were positive definite.
fn j_lu(rec: &StepRecord<U4, U2>) -> Result<ReplayStep, StudyError> {
    let k = rec.step();
    let singular = |what: &str| StudyError::Harness(format!("{what} singular at step {k}"));
    let (s, r) = (*rec.s_matrix(), *rec.r());
    let (a, b, c) = (rec.compute_a(), rec.compute_b(), rec.compute_c());
    let ab = a + b;
    let (s_lu, ab_lu) = (s.lu(), ab.lu());
    let trace_solve = |lu: &kalibra_linalg::nalgebra::LU<f64, U2, U2>, y: &Matrix2<f64>| {
        lu.solve(y).map(|m| m.trace())
    };
    let sym = |m: Matrix2<f64>| (m + m.transpose()) * 0.5;
    Ok(ReplayStep {
        j1: trace_solve(&s_lu, &r).ok_or_else(|| singular("S"))?,
        j2: trace_solve(&ab_lu, &b).ok_or_else(|| singular("A + B"))?,
        tr_n: trace_solve(&ab_lu, &(a - c)).ok_or_else(|| singular("A + B"))?,
        tr_b: b.trace(),
        definite: sym(s).cholesky().is_some() && sym(ab).cholesky().is_some(),
    })
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
    let steps = replay(
        &dynamics,
        &r,
        x0_printed(),
        p0,
        reading.first_step,
        kind,
        zs,
    )?;
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
    let fine = kalibra_tune::grid(-13.0..=6.0, config.fine_step)?;
    let mut readings = Vec::new();
    for reading in &READINGS {
        let sweep_of = |kind, grid: &[f64]| -> Result<Vec<SweepRow>, StudyError> {
            Ok(kalibra_tune::sweep(grid, config.threads, |p| {
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

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::Vector4;

    /// On a valid (positive definite) `P0` the as-given runs and their LU J metrics equal the
    /// checked filters and the library's `j_step`: the opt-in changes nothing where it is not
    /// needed.
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
            let ours = replay(&dynamics, &r, x0_printed(), p0, 2, FilterKind::Ekf, zs).unwrap();
            let ours_kf = replay(&dynamics, &r, x0_printed(), p0, 2, FilterKind::Kf, zs).unwrap();
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
}
