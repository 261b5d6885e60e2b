//! The run: the metric sweeps of both readings, the initial tuning (`P_ad`, `Q_ad`), the
//! Monte Carlo at five settings, the posterior CRLB, observability, and the report they fill.

use kalibra_bounds::Pcrlb;
use kalibra_filters::batch::{BATCH, EkfBatch, Isa};
use kalibra_filters::{Ekf, Filter, Start};
use kalibra_linalg::{Matrix4, Vector3, Vector4};
use kalibra_metrics::{JHorizon, SquaredErrors, itse};
use kalibra_models::lanes::set_lane_vector;
use kalibra_models::{Dynamics, Measurement, Simulator};
use kalibra_sim::{MonteCarlo, RunFailure};
use serde::Serialize;

use super::scenario::{
    CROSSOVER_J, CROSSOVER_NQ, J1MAX, J2MAX, PLATEAU_EDGES, PLATEAU_TOLERANCE, READINGS, Reading,
    Setup, p0_table, q_nom, qt, x0_table,
};
use crate::StudyError;
use crate::paper000::Entry;
use crate::reentry::{self, CrossoverRow, SweepRow};

/// Size and seed of the study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Monte Carlo runs per setting.
    pub runs: usize,
    /// Seed; run `i` uses ChaCha8 stream `i`.
    pub seed: u64,
    /// Threads (0: all cores); results do not depend on it.
    pub threads: usize,
    /// Step of the fine `p` grid for the figure and the crossover.
    pub fine_step: f64,
    /// Instruction set of the batched Monte Carlo EKF (`None`: detected at run time). It
    /// changes the results only by rounding, and is not part of the report.
    #[serde(skip)]
    pub simd: Option<Isa>,
}

impl Config {
    /// The published size: 1000 runs per setting.
    pub fn paper() -> Self {
        Self {
            runs: 1000,
            seed: 2014,
            threads: 0,
            fine_step: 0.02,
            simd: None,
        }
    }

    /// Reduced size for tests: 100 runs, coarser grid.
    pub fn quick() -> Self {
        Self {
            runs: 100,
            fine_step: 0.1,
            ..Self::paper()
        }
    }
}

/// J1, J2, nq of the EKF at one `p`, for one divisor.
fn point(setup: &Setup, divisor: usize, p: f64) -> Result<SweepRow, StudyError> {
    let dynamics = reentry::dynamics(reentry::scaled(&q_nom(), p))?;
    let mut ekf = Ekf::new(&dynamics, &setup.radar, x0_table(), p0_table())?;
    let mut acc = JHorizon::new();
    let mut failure = None;
    ekf.run(
        setup.measurements.iter().map(Some),
        Start::PredictFirst,
        |rec| match reentry::j_of(rec) {
            Ok(j) => acc.push(&j),
            Err(e) => failure = failure.take().or(Some(e)),
        },
    )?;
    if let Some(e) = failure {
        return Err(e.into());
    }
    let s = acc.summary(divisor)?;
    // log10 of (sum tr B / divisor): the summary's mean is over the updates.
    let nq = s.nq_log10_mean + (s.updates as f64 / divisor as f64).log10();
    Ok(SweepRow {
        p,
        nq,
        j1: s.j1,
        j2: s.j2,
        indefinite_updates: s.indefinite_updates,
        max_j2k: s.max_j2k,
    })
}

/// Per-filter map (the paper has one filter), for the `results.json` schema.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EkfOnly<T> {
    /// The EKF.
    #[serde(rename = "EKF")]
    pub ekf: T,
}

/// The metric results of one reading.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReadingReport {
    /// The reading.
    pub reading: Reading,
    /// Integer `p` grid.
    pub table: Vec<SweepRow>,
    /// Fine `p` grid.
    pub sweep: EkfOnly<Vec<SweepRow>>,
    /// Crossover of the fine sweep.
    pub crossover: EkfOnly<Option<CrossoverRow>>,
    /// `J1max` (largest J1 of the sweep) against 2.72.
    pub j1max: Entry,
    /// `J2max` against 2.91.
    pub j2max: Entry,
    /// The J1 plateau edge (`nq`) against -2.18, and its `p`.
    pub j1_edge: (Entry, f64),
    /// The J2 plateau edge (`nq`) against 5.82, and its `p`.
    pub j2_edge: (Entry, f64),
    /// Crossover `nq` against 2.11.
    pub crossover_nq: Option<Entry>,
    /// Crossover `J` against 1.49.
    pub crossover_j: Option<Entry>,
}

/// One Monte Carlo setting.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct McSetting {
    /// `S3`, `S2`, `C`, `R2`, `R3`.
    pub name: &'static str,
    /// `Q = 10^p Q_nom`.
    pub p: f64,
    /// `nq` of the setting (paper reading).
    pub nq: f64,
    /// RMSE per step (`k = 0 .. 59`) and state.
    pub rmse: Vec<[f64; 4]>,
    /// ITSE per state, `integral t MSE(t) dt` over `t = 0 .. 118 s`.
    pub itse: [f64; 4],
}

/// The results of the study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The configuration run.
    pub config: Config,
    /// Measurements in the horizon (59).
    pub horizon: usize,
    /// The metric sweeps, per reading.
    pub readings: Vec<ReadingReport>,
    /// `P_ad` (eq 22), row-major.
    pub p_ad: [[f64; 4]; 4],
    /// Diagonal of `P_ad` against Table II's `P0`.
    pub p_ad_diagonal: Vec<Entry>,
    /// `Q_ad` (eq 23), row-major.
    pub q_ad: [[f64; 4]; 4],
    /// Every entry of `Q_ad` against Table III's `Q_nom` (row-major).
    pub q_ad_entries: Vec<Entry>,
    /// The five Monte Carlo settings.
    pub monte_carlo: Vec<McSetting>,
    /// The posterior CRLB (standard deviation) per step and state.
    pub crlb: Vec<[f64; 4]>,
    /// Time of each step (s).
    pub times: Vec<f64>,
    /// Singular values of the observability matrix along the noise-free truth, per step
    /// `k = 1 .. 56` (largest first).
    pub observability: Vec<[f64; 4]>,
    /// True altitude (m) and air density (kg/m^3) along the noise-free truth (Fig. 4).
    pub altitude_density: Vec<(f64, f64)>,
}

fn rows(m: &Matrix4<f64>) -> [[f64; 4]; 4] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

fn sweep_reading(
    setup: &Setup,
    reading: &Reading,
    config: &Config,
) -> Result<ReadingReport, StudyError> {
    let integer: Vec<f64> = (-10..=10).map(f64::from).collect();
    let fine = kalibra_tune::grid(-10.0..=10.0, config.fine_step)?;
    let run = |grid: &[f64]| -> Result<Vec<SweepRow>, StudyError> {
        Ok(kalibra_tune::sweep(grid, config.threads, |p| {
            point(setup, reading.divisor, p)
        })?)
    };
    let table = run(&integer)?;
    let sweep = run(&fine)?;
    let j1max = table.iter().map(|r| r.j1).fold(f64::NEG_INFINITY, f64::max);
    let j2max = table.iter().map(|r| r.j2).fold(f64::NEG_INFINITY, f64::max);
    let j1_edge = table
        .iter()
        .take_while(|r| r.j1 >= j1max - PLATEAU_TOLERANCE)
        .last()
        .ok_or_else(|| StudyError::Harness("no J1 plateau".into()))?;
    let j2_edge = table
        .iter()
        .find(|r| r.j2 >= j2max - PLATEAU_TOLERANCE)
        .ok_or_else(|| StudyError::Harness("no J2 plateau".into()))?;
    let crossover = reentry::crossover_of(&sweep)?;
    Ok(ReadingReport {
        reading: *reading,
        j1max: Entry::new(J1MAX, j1max),
        j2max: Entry::new(J2MAX, j2max),
        j1_edge: (Entry::new(PLATEAU_EDGES.0, j1_edge.nq), j1_edge.p),
        j2_edge: (Entry::new(PLATEAU_EDGES.1, j2_edge.nq), j2_edge.p),
        crossover_nq: crossover.map(|c| Entry::new(CROSSOVER_NQ, c.nq)),
        crossover_j: crossover.map(|c| Entry::new(CROSSOVER_J, c.j)),
        table,
        sweep: EkfOnly { ekf: sweep },
        crossover: EkfOnly { ekf: crossover },
    })
}

/// One Monte Carlo truth: states `x_0 .. x_59` and measurements `y_1 .. y_59`.
struct McTruth {
    states: Vec<Vector4<f64>>,
    measurements: Vec<Vector3<f64>>,
}

/// Runs the study.
///
/// # Errors
/// [`StudyError`] if a filter or model fails, the sweep has no crossover, or `config` asks for
/// zero runs.
pub fn run(config: &Config) -> Result<Report, StudyError> {
    if config.runs == 0 {
        return Err(StudyError::Harness("zero Monte Carlo runs".into()));
    }
    let setup = Setup::new()?;
    let horizon = setup.measurements.len();
    let readings = READINGS
        .iter()
        .map(|r| sweep_reading(&setup, r, config))
        .collect::<Result<Vec<_>, _>>()?;

    // Initial tuning along the noise-free truth.
    let truth_model = reentry::dynamics(qt())?;
    let p_ad = kalibra_tune::p_ad(&truth_model, &setup.radar, &setup.truth, 0)?;
    let table_p0 = p0_table();
    let p_ad_diagonal = (0..4)
        .map(|i| Entry::new(table_p0[(i, i)], p_ad[(i, i)]))
        .collect();
    let mut ekf = Ekf::new(&truth_model, &setup.radar, x0_table(), p_ad)?;
    let records = ekf.run_collect(setup.measurements.iter().map(Some), Start::PredictFirst)?;
    let q_ad = kalibra_tune::q_ad(
        &qt(),
        records.iter().map(|r| (&r.prior().cov, &r.posterior().cov)),
    )?;
    let qn = q_nom();
    let q_ad_entries = (0..16)
        .map(|i| Entry::new(qn[(i / 4, i % 4)], q_ad[(i / 4, i % 4)]))
        .collect();

    // Monte Carlo truths, shared by the five settings and the CRLB.
    let mc = MonteCarlo::new(config.runs, config.seed).threads(config.threads);
    let truths = mc.map(|_run, rng| {
        let mut sim = Simulator::new(&truth_model, &setup.radar, reentry::x0(), 0)?;
        let mut states = Vec::with_capacity(horizon + 1);
        let mut measurements = Vec::with_capacity(horizon);
        for k in 0..=horizon {
            let (x, z) = sim.step(rng)?;
            states.push(x);
            if k > 0 {
                measurements.push(z);
            }
        }
        Ok::<_, StudyError>(McTruth {
            states,
            measurements,
        })
    })?;

    // The five settings from the paper reading.
    let paper = &readings[0];
    let p_c = paper
        .crossover
        .ekf
        .ok_or_else(|| StudyError::Harness("no J1/J2 crossover".into()))?
        .p;
    let (p_s3, p_r3) = (paper.j1_edge.1, paper.j2_edge.1);
    let settings = [
        ("S3", p_s3),
        ("S2", 0.5 * (p_s3 + p_c)),
        ("C", p_c),
        ("R2", 0.5 * (p_c + p_r3)),
        ("R3", p_r3),
    ];
    let times: Vec<f64> = (0..=horizon).map(|k| k as f64 * reentry::T).collect();
    let isa = config.simd.unwrap_or_else(Isa::detect);
    let mut monte_carlo = Vec::new();
    for (name, p) in settings {
        let dynamics = reentry::dynamics(reentry::scaled(&q_nom(), p))?;
        // Eight runs per group through the batched EKF; each step's sums take the runs in run
        // order, as the one-run study added them.
        let acc = mc.accumulate_batched(
            || SquaredErrors::new(horizon + 1, 4),
            |runs, _rngs, acc| {
                let fail = |run: usize, source: StudyError| RunFailure { run, source };
                let group = &truths[runs.clone()];
                // The models' lane-wise implementations (the density's exponential and the
                // elevation's arctangent in SIMD, within 1 and 3 ulp of glibc's).
                let mut ekf = EkfBatch::new(isa, &dynamics, &setup.radar, x0_table(), p0_table())
                    .map_err(|e| fail(runs.start, e.into()))?;
                for (l, truth) in group.iter().enumerate() {
                    acc.push(0, &(truth.states[0] - x0_table()))
                        .map_err(|e| fail(runs.start + l, e.into()))?;
                }
                let mut z = [[0.0; BATCH]; 3];
                let mut x = [[0.0; BATCH]; 4];
                for k in 1..=horizon {
                    for (l, truth) in group.iter().enumerate() {
                        set_lane_vector(&mut z, l, &truth.measurements[k - 1]);
                        set_lane_vector(&mut x, l, &truth.states[k]);
                    }
                    let step = ekf.predict_update(&z, &x);
                    for l in 0..group.len() {
                        let run = runs.start + l;
                        step.nis(l).map_err(|e| fail(run, e.into()))?;
                        // The kernel's `x - x+` against the truth it was given.
                        acc.push(k, &Vector4::from(step.error(l)))
                            .map_err(|e| fail(run, e.into()))?;
                    }
                }
                Ok(())
            },
        )?;
        let rmse: Vec<[f64; 4]> = (0..=horizon)
            .map(|k| std::array::from_fn(|i| acc.rmse(k, i).unwrap_or(f64::NAN)))
            .collect();
        let itse_per_state = std::array::from_fn(|i| {
            let mse: Vec<f64> = rmse.iter().map(|r| r[i] * r[i]).collect();
            itse(&times, &mse).unwrap_or(f64::NAN)
        });
        let nq = point(&setup, READINGS[0].divisor, p)?.nq;
        monte_carlo.push(McSetting {
            name,
            p,
            nq,
            rmse,
            itse: itse_per_state,
        });
    }

    // Posterior CRLB over the Monte Carlo truths.
    let mut bound = Pcrlb::new(&p0_table())?;
    let sd = |b: &Pcrlb<kalibra_linalg::U4>| -> Result<[f64; 4], StudyError> {
        let m = b.bound()?;
        Ok(std::array::from_fn(|i| m[(i, i)].sqrt()))
    };
    let mut crlb = vec![sd(&bound)?];
    for k in 0..horizon {
        let f: Vec<Matrix4<f64>> = truths
            .iter()
            .map(|t| truth_model.jacobian(k, &t.states[k]))
            .collect();
        bound.predict(&f, &qt())?;
        let h: Vec<_> = truths
            .iter()
            .map(|t| {
                let x = &t.states[k + 1];
                (
                    setup.radar.jacobian(k + 1, x),
                    setup.radar.noise_cov(k + 1, x),
                )
            })
            .collect();
        bound.add_measurement(&h)?;
        crlb.push(sd(&bound)?);
    }

    // Observability along the noise-free truth.
    let fs: Vec<Matrix4<f64>> = setup
        .truth
        .iter()
        .enumerate()
        .map(|(k, x)| truth_model.jacobian(k, x))
        .collect();
    let hs: Vec<_> = setup
        .truth
        .iter()
        .enumerate()
        .map(|(k, x)| setup.radar.jacobian(k, x))
        .collect();
    let observability = (1..=horizon - 3)
        .map(|k| {
            kalibra_bounds::observability_singular_values(&fs, &hs, k, 4)
                .map(|sv| std::array::from_fn(|i| sv[i]))
                .map_err(StudyError::from)
        })
        .collect::<Result<Vec<[f64; 4]>, _>>()?;
    let altitude_density = setup
        .truth
        .iter()
        .map(|x| (x[2], truth_model.density().at(x[2])))
        .collect();

    Ok(Report {
        config: *config,
        horizon,
        readings,
        p_ad: rows(&p_ad),
        p_ad_diagonal,
        q_ad: rows(&q_ad),
        q_ad_entries,
        monte_carlo,
        crlb,
        times,
        observability,
        altitude_density,
    })
}

impl Report {
    /// The Monte Carlo setting named `name` (`S3`, `S2`, `C`, `R2`, `R3`).
    pub fn setting(&self, name: &str) -> Option<&McSetting> {
        self.monte_carlo.iter().find(|s| s.name == name)
    }
}
