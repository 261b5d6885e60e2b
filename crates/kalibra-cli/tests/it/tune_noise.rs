//! End to end: `kalibra tune --method ml|em|als|j1j2` on the committed noise-estimation
//! fixtures (a model with `G` and `[Q]`, `[R]` tables), today's sweep files unchanged byte for
//! byte, and bad inputs.

use std::path::{Path, PathBuf};

use kalibra_io::noise_report::NoiseReportFile;
use kalibra_linalg::{DMatrix, DVector};
use kalibra_tune::{
    Als, CovarianceForm, Em, MaximumLikelihood, Method, MethodKind, NoiseProblem, NoiseReport,
    ParameterSweep, Parametrisation, ReportOptions, Start,
};

use crate::common;
use crate::common::{fixture, kalibra, scratch, text};

/// The fixtures' problem built in-process from the generator's constants and its seeded
/// simulation (not from the files the binary reads).
fn problem() -> NoiseProblem {
    let (zs, _) = common::simulate_noise();
    let g = DMatrix::from_column_slice(2, 1, &[common::NOISE_G[0][0], common::NOISE_G[1][0]]);
    let noise = Parametrisation::new(
        Some(g),
        CovarianceForm::scaled(DMatrix::from_element(1, 1, common::NOISE_QW_NOM)),
        CovarianceForm::diagonal(DMatrix::from_element(1, 1, common::NOISE_R_START)),
    )
    .unwrap();
    let m2 = |a: [[f64; 2]; 2]| DMatrix::from_fn(2, 2, |i, j| a[i][j]);
    NoiseProblem::new(
        m2(common::TUNE_F),
        DMatrix::from_fn(1, 2, |i, j| common::TUNE_H[i][j]),
        DVector::from_column_slice(&common::TUNE_X0),
        m2(common::TUNE_P0),
        Start::PredictFirst,
        noise,
        vec![
            zs.iter()
                .map(|&z| Some(DVector::from_element(1, z)))
                .collect(),
        ],
    )
    .unwrap()
}

/// Runs `kalibra tune` on the noise fixtures with `extra` arguments; returns the report
/// directory and `report.json`.
fn run_method(test: &str, extra: &[&str]) -> (PathBuf, NoiseReportFile) {
    let out = scratch(test).join("report");
    let (model, meas, truth) = (
        fixture("noise_model.toml"),
        fixture("noise_measurements.csv"),
        fixture("noise_truth.csv"),
    );
    let mut args = vec![
        "tune",
        model.to_str().unwrap(),
        meas.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    let run = kalibra(&args);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout).starts_with("recommendation: use Q = [["),
        "{}",
        text(&run.stdout)
    );
    let json = std::fs::read_to_string(out.join("report.json")).unwrap();
    let report: NoiseReportFile = serde_json::from_str(&json).unwrap();
    (out, report)
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// The human-readable files: the recommendation first, no script, no external resource.
fn check_documents(out: &Path, method: &str) {
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.starts_with(&format!("# kalibra tune --method {method}")),
        "{md}"
    );
    let second = md.lines().nth(2).unwrap();
    assert!(second.starts_with("**Recommendation: use Q = "), "{second}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<strong>Recommendation: use Q = "), "{html}");
    assert!(!html.contains("<script"));
    assert!(!html.contains("src=\"http") && !html.contains("href=\"http"));
}

/// `report.json` of the library's report on the fixtures' problem and truth, in-process.
fn in_process(method: &Method) -> NoiseReportFile {
    let problem = problem();
    let (_, xs) = common::simulate_noise();
    let truth = vec![
        xs.iter()
            .map(|x| Some(DVector::from_column_slice(x)))
            .collect(),
    ];
    let report =
        NoiseReport::estimate(&problem, method, ReportOptions::new(), Some(&truth)).unwrap();
    NoiseReportFile::new(&problem, &report)
}

#[test]
fn ml_equals_the_library_report_at_full_precision() {
    let (out, report) = run_method("ml", &["--method", "ml"]);
    // Every field, bit for bit: serde_json writes the shortest text that reads back to the
    // same f64.
    assert_eq!(
        report,
        in_process(&Method::MaximumLikelihood(MaximumLikelihood::new()))
    );
    assert_eq!(report.method, MethodKind::Ml);
    let names: Vec<_> = report.parameters.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["q", "R[0,0]"]);
    // The fixture's truth: q = 0.04 / 0.4 of the nominal, R = 4; both inside their intervals.
    let truth = [
        common::NOISE_QW_TRUE / common::NOISE_QW_NOM,
        common::NOISE_R_TRUE,
    ];
    for (row, t) in report.parameters.iter().zip(truth) {
        let [lo, hi] = row.ci95.unwrap();
        assert!(lo.unwrap() < t && t < hi.unwrap(), "{row:?} misses {t}");
        assert!(row.stderr.is_some() && row.profile.is_some(), "{row:?}");
    }
    assert_eq!(report.identifiable.identifiable, Some(true));
    assert_eq!(report.identifiable.rank, Some(2));
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    // The tuned filter is consistent on the data; the starting guess (R a quarter of the
    // truth) is not.
    let tuned = report.consistency.tuned.as_ref().unwrap();
    let start = report.consistency.start.as_ref().unwrap();
    assert_eq!(tuned.anis_consistent, Some(true));
    assert_eq!(start.anis_consistent, Some(false));
    assert!(tuned.anees.is_some() && tuned.rmse.is_some());
    check_documents(&out, "ml");
    // One profile figure per parameter, inline in the HTML.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(html.matches("<svg").count(), 2);
    assert!(html.contains("Profile log-likelihood of q"));
    assert!(out.join("profile_q.svg").is_file() && out.join("profile_R_0_0.svg").is_file());
}

#[test]
fn em_runs_exactly_the_iterations_asked_for() {
    let (out, report) = run_method("em", &["--method", "em", "--iterations", "10"]);
    assert_eq!(
        report,
        in_process(&Method::Em(Em::new().exact_iterations(10)))
    );
    let est = Em::new().exact_iterations(10).estimate(&problem()).unwrap();
    assert_eq!(report.method, MethodKind::Em);
    assert_eq!(report.iterations, 10);
    assert_eq!(report.q, rows(&est.matrices.q));
    assert_eq!(report.r, rows(&est.matrices.r));
    check_documents(&out, "em");
}

#[test]
fn als_equals_the_library_report() {
    let (out, report) = run_method("als", &["--method", "als"]);
    assert_eq!(report, in_process(&Method::Als(Als::new())));
    let est = Als::new().estimate(&problem()).unwrap();
    assert_eq!(report.method, MethodKind::Als);
    assert_eq!(report.q, rows(&est.matrices.q));
    assert_eq!(report.r, rows(&est.matrices.r));
    assert_eq!(report.identifiable.rank, Some(est.rank));
    check_documents(&out, "als");
}

#[test]
fn j1j2_sweeps_every_parameter_around_the_start() {
    let (out, report) = run_method("j1j2", &["--method", "j1j2", "--p", "-3:3:0.5"]);
    let grid: Vec<f64> = (0..=12).map(|i| -3.0 + 0.5 * f64::from(i)).collect();
    let sweep = ParameterSweep::new().grid(grid).unwrap();
    assert_eq!(report, in_process(&Method::J1J2(sweep)));
    assert_eq!(report.method, MethodKind::J1j2);
    assert_eq!(report.curves.len(), 2);
    for c in &report.curves {
        assert!(
            c.crossover.is_some(),
            "{} crosses on the grid",
            c.parameter.name
        );
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(
        html.matches("<svg").count(),
        2,
        "one J1/J2 figure per parameter"
    );
    check_documents(&out, "j1j2");
}

/// Today's files (plain `Q` and `R`, no `G`) give the report they gave before the estimators
/// came, byte for byte: `tests/fixtures/tune_report` is the output of the previous release's
/// `kalibra tune tune_model.toml tune_measurements.csv --truth tune_truth.csv` (default
/// grid), and `--method j1j2` on such a file is the same sweep.
#[test]
fn plain_files_give_the_sweep_report_unchanged() {
    for (test, extra) in [
        ("plain", &[][..]),
        ("plain-j1j2", &["--method", "j1j2"][..]),
    ] {
        let out = scratch(test).join("report");
        let mut args = vec![
            "tune".to_string(),
            fixture("tune_model.toml").display().to_string(),
            fixture("tune_measurements.csv").display().to_string(),
            "--truth".to_string(),
            fixture("tune_truth.csv").display().to_string(),
            "--out".to_string(),
            out.display().to_string(),
        ];
        args.extend(extra.iter().map(|s| (*s).to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let run = kalibra(&args);
        assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
        let golden = fixture("tune_report");
        let mut names: Vec<_> = std::fs::read_dir(&golden)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        names.sort();
        let mut written: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        written.sort();
        assert_eq!(names, written, "{test}");
        for name in names {
            let before = std::fs::read(golden.join(&name)).unwrap();
            let now = std::fs::read(out.join(&name)).unwrap();
            assert!(before == now, "{test}: {} differs", name.to_string_lossy());
        }
    }
}

/// Runs `kalibra tune --method ml` with the model text `model` (and the measurements
/// `measurements`, if given); expects exit 1, one line on stderr holding every needle, and no
/// report.
fn refused(test: &str, model: &str, measurements: Option<&str>, needles: &[&str]) {
    let dir = scratch(test);
    let out = dir.join("report");
    let model_path = dir.join("model.toml");
    std::fs::write(&model_path, model).unwrap();
    let meas = match measurements {
        Some(text) => {
            let p = dir.join("measurements.csv");
            std::fs::write(&p, text).unwrap();
            p
        }
        None => fixture("noise_measurements.csv"),
    };
    let run = kalibra(&[
        "tune",
        model_path.to_str().unwrap(),
        meas.to_str().unwrap(),
        "--method",
        "ml",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    for needle in needles {
        assert!(err.contains(needle), "`{needle}` not in: {err}");
    }
    assert!(!out.exists(), "no report after a failed run");
}

fn noise_model() -> String {
    std::fs::read_to_string(fixture("noise_model.toml")).unwrap()
}

#[test]
fn a_bad_form_name_is_named_with_its_line() {
    let model = noise_model().replace("form = \"diagonal\"", "form = \"diag\"");
    refused(
        "bad-form",
        &model,
        None,
        &[
            "model.toml",
            "key R.form",
            "line 13",
            "unknown variant `diag`",
            "`diagonal`",
        ],
    );
}

#[test]
fn g_of_the_wrong_shape_is_named() {
    let model = noise_model().replace("G = [[0.5], [1.0]]", "G = [[0.5, 0.0], [1.0, 0.0]]");
    refused(
        "g-shape",
        &model,
        None,
        &["model.toml", "key G", "line 4, column 1", "2x2", "1"],
    );
}

#[test]
fn a_nan_measurement_is_named_by_its_row() {
    // Step 3 (row 5, the header being row 1) holds NaN.
    let csv: String = std::fs::read_to_string(fixture("noise_measurements.csv"))
        .unwrap()
        .lines()
        .map(|l| {
            if l.starts_with("3,") {
                "3,NaN\n".to_string()
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    refused(
        "nan",
        &noise_model(),
        Some(&csv),
        &["measurements.csv", "row 5", "non-finite"],
    );
}

#[test]
fn too_many_free_parameters_are_refused_with_the_reason() {
    // Without G, a full 2x2 Q (3 entries) and R (1) ask for 4 > n m + m (m + 1) / 2 = 3.
    let model = noise_model().replace("G = [[0.5], [1.0]]\n", "").replace(
        "form = \"scaled\"\nvalue = [[0.4]]",
        "form = \"full\"\nvalue = [[0.1, 0.0], [0.0, 0.4]]",
    );
    refused(
        "too-many",
        &model,
        None,
        &["model.toml", "4 free noise parameters", "at most", "= 3"],
    );
}

#[test]
fn iterations_without_em_is_usage() {
    let out = scratch("iterations-usage").join("report");
    let run = kalibra(&[
        "tune",
        fixture("noise_model.toml").to_str().unwrap(),
        fixture("noise_measurements.csv").to_str().unwrap(),
        "--method",
        "ml",
        "--iterations",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2), "{}", text(&run.stderr));
    assert!(text(&run.stderr).contains("--iterations"));
    assert!(!out.exists());
}
