//! End to end: `kalibra tune` on the committed tuning fixtures and on bad inputs.

use crate::common;

use std::path::{Path, PathBuf};

use kalibra_linalg::{DMatrix, DVector};
use kalibra_tune::{InitialCovariance, TuneError, TuneProblem, TuneReport, Tuning};

use crate::common::{fixture, kalibra, scratch, text};

fn m2(a: [[f64; 2]; 2]) -> DMatrix<f64> {
    DMatrix::from_fn(2, 2, |i, j| a[i][j])
}

/// A constructor of [`TuneProblem`]: [`TuneProblem::new`] or [`TuneProblem::as_given`].
type Build = fn(
    DMatrix<f64>,
    DMatrix<f64>,
    DMatrix<f64>,
    DMatrix<f64>,
    DVector<f64>,
    DMatrix<f64>,
    Vec<Option<DVector<f64>>>,
) -> Result<TuneProblem, TuneError>;

/// The problem of the fixtures built in-process from the generator's constants and its
/// seeded simulation (not from the files the binary reads), with the initial covariance `p0`
/// taken by `build`.
fn in_process_with(build: Build, p0: [[f64; 2]; 2], with_truth: bool) -> TuneReport {
    let (zs, xs) = common::simulate_tune();
    let problem = build(
        m2(common::TUNE_F),
        DMatrix::from_fn(1, 2, |i, j| common::TUNE_H[i][j]),
        m2(common::TUNE_Q_NOM),
        DMatrix::from_element(1, 1, common::TUNE_R),
        DVector::from_column_slice(&common::TUNE_X0),
        m2(p0),
        zs.iter()
            .map(|z| z.map(|z| DVector::from_element(1, z)))
            .collect(),
    )
    .unwrap();
    let problem = if with_truth {
        problem
            .with_truth(
                xs.iter()
                    .map(|x| Some(DVector::from_column_slice(x)))
                    .collect(),
            )
            .unwrap()
    } else {
        problem
    };
    Tuning::new()
        .exponents(-4.0, 2.0, 0.25)
        .unwrap()
        .position(vec![0])
        .tune(&problem)
        .unwrap()
}

/// The fixtures' problem in-process, `P0` checked.
fn in_process(with_truth: bool) -> TuneReport {
    in_process_with(TuneProblem::new, common::TUNE_P0, with_truth)
}

/// Runs `kalibra tune` on `model` and the fixtures' measurements (and truth) on the tests'
/// grid; returns the report directory and `report.json`.
fn run_good(test: &str, model: &Path, with_truth: bool) -> (PathBuf, TuneReport) {
    let out = scratch(test).join("report");
    let (meas, truth) = (fixture("tune_measurements.csv"), fixture("tune_truth.csv"));
    let mut args = vec![
        "tune",
        model.to_str().unwrap(),
        meas.to_str().unwrap(),
        "--p",
        "-4:2:0.25",
        "--threads",
        "2",
        "--out",
        out.to_str().unwrap(),
    ];
    if with_truth {
        args.extend(["--truth", truth.to_str().unwrap()]);
    }
    let run = kalibra(&args);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout).starts_with("recommendation: use Q = 10^"),
        "{}",
        text(&run.stdout)
    );
    let json = std::fs::read_to_string(out.join("report.json")).unwrap();
    let report: TuneReport = serde_json::from_str(&json).unwrap();
    (out, report)
}

#[test]
fn tune_with_truth_equals_the_library_sweep() {
    let (out, report) = run_good("truth", &fixture("tune_model.toml"), true);
    // The "results match the library's own sweep exactly": every field, bit for bit.
    assert_eq!(report, in_process(true));
    for name in [
        "report.json",
        "report.md",
        "report.html",
        "j1j2.svg",
        "rmse.svg",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let second = md.lines().nth(2).unwrap();
    assert!(
        second.starts_with("**Recommendation: use Q = 10^"),
        "{second}"
    );
    assert!(md.contains("p\\_c"), "{md}");
    assert!(md.contains("nq\\_c"), "{md}");
    assert!(md.contains("Recommended Q:"), "{md}");
    assert!(md.contains("smallest state RMSE"), "{md}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(html.matches("<svg").count(), 2);
    assert!(!html.contains("src=\"http"));
    let svg = std::fs::read_to_string(out.join("j1j2.svg")).unwrap();
    assert!(svg.contains("p_c = "), "the crossover is marked");
}

#[test]
fn tune_without_truth_equals_the_library_sweep() {
    let (out, report) = run_good("no-truth", &fixture("tune_model.toml"), false);
    assert_eq!(report, in_process(false));
    assert!(report.crossover.is_some());
    assert!(out.join("j1j2.svg").is_file());
    assert!(!out.join("rmse.svg").exists());
}

/// `p0_as_given = true` takes a `P0` that the checked path refuses (asymmetric, as the 2012
/// paper's printed one, or indefinite) and sweeps it as `TuneProblem::as_given` does, field
/// for field; without the key the same model is refused, naming `P0`.
#[test]
fn p0_as_given_equals_the_library_sweep_as_given() {
    let asymmetric = [[10.0, 0.5], [0.0, 1.0]];
    let indefinite = [[-12.0, 0.0], [0.0, 1.0]];
    let fixture_p0 = "P0 = [[10.0, 0.0], [0.0, 1.0]]";
    assert!(model_text().contains(fixture_p0));
    for (name, p0) in [("asymmetric", asymmetric), ("indefinite", indefinite)] {
        let dir = scratch(&format!("as-given-{name}"));
        let checked = model_text().replace(
            fixture_p0,
            &format!(
                "P0 = [[{:?}, {:?}], [{:?}, {:?}]]",
                p0[0][0], p0[0][1], p0[1][0], p0[1][1]
            ),
        );
        let refused = dir.join("checked.toml");
        std::fs::write(&refused, &checked).unwrap();
        let run = kalibra(&[
            "tune",
            refused.to_str().unwrap(),
            fixture("tune_measurements.csv").to_str().unwrap(),
            "--out",
            dir.join("refused").to_str().unwrap(),
        ]);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains("checked.toml") && err.contains("P0"), "{err}");

        let model = dir.join("as_given.toml");
        std::fs::write(&model, checked + "p0_as_given = true\n").unwrap();
        let (_, report) = run_good(&format!("as-given-{name}-run"), &model, true);
        assert_eq!(report.initial_covariance, InitialCovariance::AsGiven);
        assert_eq!(
            report,
            in_process_with(TuneProblem::as_given, p0, true),
            "{name}"
        );
    }
}

#[test]
fn a_grid_without_crossover_says_which_way_to_move() {
    let out = scratch("no-crossover").join("report");
    let run = kalibra(&[
        "tune",
        fixture("tune_model.toml").to_str().unwrap(),
        fixture("tune_measurements.csv").to_str().unwrap(),
        "--p",
        "2:4:0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("no crossover"), "{md}");
    assert!(md.contains("lower the grid's lower end"), "{md}");
}

/// Runs `kalibra tune` with `file` (a model, measurements or truth) replaced by `content`,
/// expects exit 1 with one message holding every needle, and no report.
fn bad_input(test: &str, which: &str, content: &str, needles: &[&str]) {
    let dir = scratch(test);
    let out = dir.join("report");
    let name = match which {
        "model" => "model.toml",
        "measurements" => "measurements.csv",
        _ => "truth.csv",
    };
    let bad = dir.join(name);
    std::fs::write(&bad, content).unwrap();
    let pick = |w: &str, f: &str| {
        if w == which { bad.clone() } else { fixture(f) }
    };
    let model = pick("model", "tune_model.toml");
    let meas = pick("measurements", "tune_measurements.csv");
    let truth = pick("truth", "tune_truth.csv");
    let run = kalibra(&[
        "tune",
        model.to_str().unwrap(),
        meas.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(name), "names the file: {err}");
    for needle in needles {
        assert!(err.contains(needle), "`{needle}` not in: {err}");
    }
    assert!(!out.exists(), "no report after a failed run");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

fn model_text() -> String {
    std::fs::read_to_string(fixture("tune_model.toml")).unwrap()
}

fn measurements_text() -> String {
    std::fs::read_to_string(fixture("tune_measurements.csv")).unwrap()
}

#[test]
fn model_unknown_key() {
    let model = model_text() + "Qnom = [[1.0]]\n";
    bad_input("unknown-key", "model", &model, &["unknown field `Qnom`"]);
}

#[test]
fn model_missing_key() {
    let model = model_text().replace("R = [[4.0]]\n", "");
    bad_input("missing-key", "model", &model, &["missing field `R`"]);
}

#[test]
fn model_ragged_matrix() {
    let model = model_text().replace("F = [[1.0, 1.0], [0.0, 1.0]]", "F = [[1.0, 1.0], [0.0]]");
    bad_input("ragged", "model", &model, &["key F", "row 1"]);
}

#[test]
fn model_non_numeric_value() {
    let model = model_text().replace("R = [[4.0]]", "R = [[\"four\"]]");
    bad_input(
        "model-non-numeric",
        "model",
        &model,
        &["key R", "line 5", "column"],
    );
}

#[test]
fn model_wrong_shape() {
    let model = model_text().replace("R = [[4.0]]", "R = [[4.0, 0.0], [0.0, 4.0]]");
    bad_input("model-shape", "model", &model, &["R", "2x2", "1x1"]);
}

#[test]
fn model_bad_start() {
    let model = model_text() + "start = \"sideways\"\n";
    bad_input("bad-start", "model", &model, &["sideways", "predict_first"]);
}

#[test]
fn measurements_non_numeric_cell() {
    let csv = measurements_text().replacen("\n3,", "\n3,abc", 1);
    bad_input(
        "non-numeric",
        "measurements",
        &csv,
        &["row 5", "column 2 (z_0)", "not a number"],
    );
}

#[test]
fn measurements_partly_empty_row() {
    let csv = "step,z_0,z_1\n0,1.0,2.0\n1,,3.0\n";
    let model = model_text().replace("H = [[1.0, 0.0]]", "H = [[1.0, 0.0], [0.0, 1.0]]");
    let model = model.replace("R = [[4.0]]", "R = [[4.0, 0.0], [0.0, 4.0]]");
    // Two files are bad here: write the model beside the measurements.
    let dir = scratch("partly-empty");
    let (m, z) = (dir.join("model.toml"), dir.join("measurements.csv"));
    std::fs::write(&m, model).unwrap();
    std::fs::write(&z, csv).unwrap();
    let out = dir.join("report");
    let run = kalibra(&[
        "tune",
        m.to_str().unwrap(),
        z.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    for needle in [
        "measurements.csv",
        "row 3",
        "column 2 (z_0)",
        "column 3 (z_1)",
    ] {
        assert!(err.contains(needle), "`{needle}` not in: {err}");
    }
    assert!(!out.exists());
}

#[test]
fn measurements_wrong_column_count() {
    let csv = "step,z_0,z_1\n0,1.0,2.0\n";
    bad_input(
        "column-count",
        "measurements",
        csv,
        &["row 1", "2 value column(s)", "H has 1 row(s)"],
    );
}

#[test]
fn measurements_counted_from_one() {
    let csv = measurements_text().replacen("step,z_0", "step,z_1", 1);
    bad_input(
        "from-one",
        "measurements",
        &csv,
        &["row 1, column 2", "`z_1`", "count from 0"],
    );
}

#[test]
fn measurements_step_gap() {
    let csv = measurements_text().replacen("\n4,", "\n5,", 1);
    bad_input(
        "gap",
        "measurements",
        &csv,
        &[
            "row 6",
            "column 1 (step)",
            "step 5 where step 4 is expected",
        ],
    );
}

#[test]
fn measurements_ragged_row() {
    let csv = measurements_text().replacen("\n3,", "\n3,1.0,", 1);
    bad_input("ragged-row", "measurements", &csv, &["row 5", "ragged"]);
}

#[test]
fn truth_wrong_length() {
    let truth = std::fs::read_to_string(fixture("tune_truth.csv")).unwrap();
    let short: String = truth.lines().take(11).map(|l| format!("{l}\n")).collect();
    bad_input("truth-short", "truth", &short, &["10"]);
}

#[test]
fn bad_grid_is_usage() {
    let dir = scratch("bad-grid");
    let out = dir.join("report");
    for grid in ["1:0:0.5", "0:1:0", "0:1", "a:1:0.5"] {
        let run = kalibra(&[
            "tune",
            fixture("tune_model.toml").to_str().unwrap(),
            fixture("tune_measurements.csv").to_str().unwrap(),
            "--p",
            grid,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(run.status.code(), Some(2), "{grid}: {}", text(&run.stderr));
        assert!(text(&run.stderr).contains("--p"), "{}", text(&run.stderr));
        assert!(!out.exists());
    }
    let help = kalibra(&["tune", "--help"]);
    assert_eq!(help.status.code(), Some(0));
    assert!(text(&help.stdout).contains("z_0, ..., z_{m-1}"));
}
