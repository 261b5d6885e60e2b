//! The simulated filter log of the fixtures: a seeded constant-velocity Kalman filter Monte
//! Carlo (4 runs of 25 steps, n = 4, m = 2), with no measurement at every sixth step so the
//! log has cells that were not logged.

#![allow(dead_code)]

use kalibra_filters::{Filter, Kf};
use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra_models::{Kinematic, Simulator, sample_with_factor};
use kalibra_sim::MonteCarlo;

pub const RUNS: usize = 4;
pub const STEPS: usize = 25;
pub const SEED: u64 = 15;

/// One run and step of the log.
pub struct Cell {
    pub truth: Vec<f64>,
    pub estimate: Vec<f64>,
    /// Row by row.
    pub covariance: Vec<f64>,
    /// `None` where there was no measurement.
    pub innovation: Option<(Vec<f64>, Vec<f64>)>,
}

/// The model matrices (constant): F, H, Q, R, each row by row, with their shapes.
pub struct Model {
    pub f: Vec<f64>,
    pub h: Vec<f64>,
    pub q: Vec<f64>,
    pub r: Vec<f64>,
}

fn row_major(rows: usize, cols: usize, at: impl Fn(usize, usize) -> f64) -> Vec<f64> {
    (0..rows)
        .flat_map(|i| (0..cols).map(move |j| (i, j)))
        .map(|(i, j)| at(i, j))
        .collect()
}

/// `[run][step]` cells and the model.
pub fn simulate() -> (Vec<Vec<Cell>>, Model) {
    let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
    let f = cv.dynamics(U4).unwrap();
    let h = cv
        .position_measurement(U4, U2, Matrix2::identity() * 25.0)
        .unwrap();
    let m0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0));
    let l0 = p0.map(f64::sqrt);
    let mut model = None;
    let runs = MonteCarlo::new(RUNS, SEED)
        .map(|_, rng| {
            let x0 = m0 + sample_with_factor(&l0, rng);
            let mut truth = Simulator::new(&f, &h, x0, 0).unwrap();
            let mut kf = Kf::new(&f, &h, m0, p0).unwrap();
            let mut cells = Vec::new();
            let mut matrices = None;
            for k in 0..STEPS {
                let (x, z) = truth.step(rng).unwrap();
                if k > 0 {
                    kf.predict().unwrap();
                }
                let innovation = if k % 6 == 5 {
                    None
                } else {
                    let rec = kf.update(&z).unwrap();
                    let s = rec.s_matrix();
                    if matrices.is_none() && k > 0 {
                        matrices = Some(Model {
                            f: row_major(4, 4, |i, j| rec.f()[(i, j)]),
                            h: row_major(2, 4, |i, j| rec.h()[(i, j)]),
                            q: row_major(4, 4, |i, j| rec.process_noise()[(i, j)]),
                            r: row_major(2, 2, |i, j| rec.r()[(i, j)]),
                        });
                    }
                    Some((
                        rec.innovation().iter().copied().collect(),
                        row_major(2, 2, |i, j| s[(i, j)]),
                    ))
                };
                let p = kf.covariance();
                cells.push(Cell {
                    truth: x.iter().copied().collect(),
                    estimate: kf.mean().iter().copied().collect(),
                    covariance: row_major(4, 4, |i, j| p[(i, j)]),
                    innovation,
                });
            }
            Ok::<_, std::fmt::Error>((cells, matrices))
        })
        .unwrap();
    let mut out = Vec::new();
    for (cells, m) in runs {
        if model.is_none() {
            model = m;
        }
        out.push(cells);
    }
    (out, model.unwrap())
}

fn json_list<T>(items: impl Iterator<Item = T>, f: impl Fn(T) -> String) -> String {
    format!("[{}]", items.map(f).collect::<Vec<_>>().join(", "))
}

fn json_numbers(v: &[f64]) -> String {
    json_list(v.iter(), |x| serde_json::to_string(x).unwrap())
}

fn json_matrix(v: &[f64], cols: usize) -> String {
    json_list(v.chunks(cols), json_numbers)
}

/// The JSON log: one array per line, each cell of a run on that line.
pub fn to_json(runs: &[Vec<Cell>], model: &Model) -> String {
    let per_cell = |name: &str, f: &dyn Fn(&Cell) -> String| {
        let runs = json_list(runs.iter(), |run| json_list(run.iter(), f));
        format!("  \"{name}\": {runs}")
    };
    let time = json_list(0..STEPS, |k| format!("{}.0", k));
    let lines = [
        format!("  \"time\": {time}"),
        per_cell("truth", &|c| json_numbers(&c.truth)),
        per_cell("estimate", &|c| json_numbers(&c.estimate)),
        per_cell("covariance", &|c| json_matrix(&c.covariance, 4)),
        per_cell("innovation", &|c| {
            c.innovation
                .as_ref()
                .map_or("null".into(), |(v, _)| json_numbers(v))
        }),
        per_cell("innovation_cov", &|c| {
            c.innovation
                .as_ref()
                .map_or("null".into(), |(_, s)| json_matrix(s, 2))
        }),
        format!("  \"F\": {}", json_matrix(&model.f, 4)),
        format!("  \"H\": {}", json_matrix(&model.h, 4)),
        format!("  \"Q\": {}", json_matrix(&model.q, 4)),
        format!("  \"R\": {}", json_matrix(&model.r, 2)),
    ];
    format!("{{\n{}\n}}\n", lines.join(",\n"))
}

/// The CSV log: full covariances, the innovation's cells empty where not logged.
pub fn to_csv(runs: &[Vec<Cell>]) -> String {
    let mut header = vec!["run".to_string(), "step".into(), "time".into()];
    for a in ["truth", "estimate"] {
        header.extend((0..4).map(|i| format!("{a}_{i}")));
    }
    header.extend((0..16).map(|i| format!("covariance_{}_{}", i / 4, i % 4)));
    header.extend((0..2).map(|i| format!("innovation_{i}")));
    header.extend((0..4).map(|i| format!("innovation_cov_{}_{}", i / 2, i % 2)));
    let mut out = header.join(",") + "\n";
    for (r, run) in runs.iter().enumerate() {
        for (k, c) in run.iter().enumerate() {
            let mut row = vec![r.to_string(), k.to_string(), format!("{k}")];
            let num = |x: &f64| format!("{x:?}");
            row.extend(c.truth.iter().map(num));
            row.extend(c.estimate.iter().map(num));
            row.extend(c.covariance.iter().map(num));
            match &c.innovation {
                Some((v, s)) => {
                    row.extend(v.iter().map(num));
                    row.extend(s.iter().map(num));
                }
                None => row.extend(std::iter::repeat_n(String::new(), 6)),
            }
            out.push_str(&row.join(","));
            out.push('\n');
        }
    }
    out
}

/// The tuning fixtures: a seeded scalar-axis constant-velocity target (n = 2, m = 1) whose
/// true process noise is a hundredth of the model's nominal `Q`, seen for `TUNE_STEPS` steps
/// with no measurement at every seventh step.
pub const TUNE_STEPS: usize = 60;
pub const TUNE_F: [[f64; 2]; 2] = [[1.0, 1.0], [0.0, 1.0]];
pub const TUNE_H: [[f64; 2]; 1] = [[1.0, 0.0]];
pub const TUNE_Q_NOM: [[f64; 2]; 2] = [[0.5, 0.5], [0.5, 1.0]];
/// The true `Q` is `TUNE_Q_TRUE_SCALE * Q_nom`.
pub const TUNE_Q_TRUE_SCALE: f64 = 0.01;
pub const TUNE_R: f64 = 4.0;
pub const TUNE_X0: [f64; 2] = [0.0, 1.0];
pub const TUNE_P0: [[f64; 2]; 2] = [[10.0, 0.0], [0.0, 1.0]];

/// `(measurements, truth)`: the true state at each step of the sequence and its measurement
/// (`None` at every seventh step). The truth starts one step after `TUNE_X0` (predict first).
pub fn simulate_tune() -> (Vec<Option<f64>>, Vec<[f64; 2]>) {
    use kalibra_linalg::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector2};
    use kalibra_models::{LinearGaussian, LinearObservation};
    let m2 = |a: [[f64; 2]; 2]| Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1]);
    let f = LinearGaussian::new(m2(TUNE_F), m2(TUNE_Q_NOM) * TUNE_Q_TRUE_SCALE).unwrap();
    let h = LinearObservation::new(
        Matrix1x2::new(TUNE_H[0][0], TUNE_H[0][1]),
        Matrix1::new(TUNE_R),
    )
    .unwrap();
    let l0 = m2(TUNE_P0).map(f64::sqrt);
    let runs = MonteCarlo::new(1, SEED)
        .map(|_, rng| {
            let x0 = Vector2::new(TUNE_X0[0], TUNE_X0[1]) + sample_with_factor(&l0, rng);
            let mut sim = Simulator::new(&f, &h, x0, 0).unwrap();
            // x0 is the state one step before the first measurement.
            sim.step(rng).unwrap();
            let mut zs = Vec::new();
            let mut xs = Vec::new();
            for k in 0..TUNE_STEPS {
                let (x, z) = sim.step(rng).unwrap();
                zs.push((k % 7 != 6).then_some(z[0]));
                xs.push([x[0], x[1]]);
            }
            Ok::<_, std::fmt::Error>((zs, xs))
        })
        .unwrap();
    runs.into_iter().next().unwrap()
}

fn toml_matrix<const C: usize>(rows: &[[f64; C]]) -> String {
    let rows: Vec<String> = rows
        .iter()
        .map(|r| {
            let cells: Vec<String> = r.iter().map(|v| format!("{v:?}")).collect();
            format!("[{}]", cells.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

/// `tune_model.toml`: the nominal model.
pub fn tune_model_toml() -> String {
    format!(
        "# The model of the tuning fixtures (tests/common/mod.rs writes it).\n\
         F = {}\nH = {}\nQ = {}\nR = [[{:?}]]\nx0 = [{:?}, {:?}]\nP0 = {}\nposition = [0]\n",
        toml_matrix(&TUNE_F),
        toml_matrix(&TUNE_H),
        toml_matrix(&TUNE_Q_NOM),
        TUNE_R,
        TUNE_X0[0],
        TUNE_X0[1],
        toml_matrix(&TUNE_P0)
    )
}

/// `tune_measurements.csv`: `step,z_0`, an empty cell where there is no measurement.
pub fn tune_measurements_csv(zs: &[Option<f64>]) -> String {
    let mut out = "step,z_0\n".to_string();
    for (k, z) in zs.iter().enumerate() {
        out.push_str(&format!(
            "{k},{}\n",
            z.map_or(String::new(), |z| format!("{z:?}"))
        ));
    }
    out
}

/// `tune_truth.csv`: `step,x_0,x_1`.
pub fn tune_truth_csv(xs: &[[f64; 2]]) -> String {
    let mut out = "step,x_0,x_1\n".to_string();
    for (k, x) in xs.iter().enumerate() {
        out.push_str(&format!("{k},{:?},{:?}\n", x[0], x[1]));
    }
    out
}

/// The noise-estimation fixtures (`kalibra tune --method`): a seeded constant-velocity
/// target (n = 2, m = 1) driven by one noise channel through `G` (a white acceleration),
/// every step measured, for `NOISE_STEPS` steps. MODEL.toml states `Qw` scaled from a nominal
/// ten times the truth and `R` diagonal from a start a quarter of the truth, so the estimate
/// must move both.
pub const NOISE_STEPS: usize = 200;
pub const NOISE_G: [[f64; 1]; 2] = [[0.5], [1.0]];
pub const NOISE_QW_TRUE: f64 = 0.04;
pub const NOISE_QW_NOM: f64 = 0.4;
pub const NOISE_R_TRUE: f64 = 4.0;
pub const NOISE_R_START: f64 = 1.0;
pub const NOISE_SEED: u64 = 31;

/// `(measurements, truth)` of the noise fixtures (predict first from `TUNE_X0`).
pub fn simulate_noise() -> (Vec<f64>, Vec<[f64; 2]>) {
    use kalibra_linalg::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector2};
    use kalibra_models::{LinearGaussian, LinearObservation};
    let m2 = |a: [[f64; 2]; 2]| Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1]);
    let g = Vector2::new(NOISE_G[0][0], NOISE_G[1][0]);
    let q = g * g.transpose() * NOISE_QW_TRUE;
    let f = LinearGaussian::new(m2(TUNE_F), q).unwrap();
    let h = LinearObservation::new(
        Matrix1x2::new(TUNE_H[0][0], TUNE_H[0][1]),
        Matrix1::new(NOISE_R_TRUE),
    )
    .unwrap();
    let l0 = m2(TUNE_P0).map(f64::sqrt);
    let runs = MonteCarlo::new(1, NOISE_SEED)
        .map(|_, rng| {
            let x0 = Vector2::new(TUNE_X0[0], TUNE_X0[1]) + sample_with_factor(&l0, rng);
            let mut sim = Simulator::new(&f, &h, x0, 0).unwrap();
            sim.step(rng).unwrap();
            let mut zs = Vec::new();
            let mut xs = Vec::new();
            for _ in 0..NOISE_STEPS {
                let (x, z) = sim.step(rng).unwrap();
                zs.push(z[0]);
                xs.push([x[0], x[1]]);
            }
            Ok::<_, std::fmt::Error>((zs, xs))
        })
        .unwrap();
    runs.into_iter().next().unwrap()
}

/// `noise_model.toml`: the model with `G` and the `[Q]` and `[R]` tables.
pub fn noise_model_toml() -> String {
    format!(
        "# The model of the noise-estimation fixtures (tests/common/mod.rs writes it).\n\
         F = {}\nH = {}\nG = {}\nx0 = [{:?}, {:?}]\nP0 = {}\n\n\
         [Q]\nform = \"scaled\"\nvalue = [[{:?}]]\n\n\
         [R]\nform = \"diagonal\"\nvalue = [[{:?}]]\n",
        toml_matrix(&TUNE_F),
        toml_matrix(&TUNE_H),
        toml_matrix(&NOISE_G),
        TUNE_X0[0],
        TUNE_X0[1],
        toml_matrix(&TUNE_P0),
        NOISE_QW_NOM,
        NOISE_R_START
    )
}

/// A committed fixture's path.
pub fn fixture(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A fresh, empty scratch directory for one test, named after the calling test file and the
/// test: the files share one test binary, so the binary's name would not keep them apart.
#[track_caller]
pub fn scratch(test: &str) -> std::path::PathBuf {
    let file = std::path::Path::new(std::panic::Location::caller().file());
    let module = file.file_stem().unwrap().to_string_lossy();
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kalibra-{module}-{test}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the built `kalibra` binary.
pub fn kalibra(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_kalibra"))
        .args(args)
        .output()
        .unwrap()
}

/// Process output as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}
