//! End to end: the built `kalibra` binary on the committed fixtures and on bad inputs.

use kalibra_eval::{Evaluation, FilterLog, Matrices, Report, Vectors};
use serde::Deserialize;

use crate::common::{fixture, kalibra, scratch, text};

/// The JSON fixture read independently of the binary's reader (serde into typed arrays).
#[derive(Deserialize)]
struct Fixture {
    time: Vec<f64>,
    truth: Vec<Vec<Vec<f64>>>,
    estimate: Vec<Vec<Vec<f64>>>,
    covariance: Vec<Vec<Vec<Vec<f64>>>>,
    innovation: Vec<Vec<Option<Vec<f64>>>>,
    innovation_cov: Vec<Vec<Option<Vec<Vec<f64>>>>>,
    #[serde(rename = "F")]
    f: Vec<Vec<f64>>,
    #[serde(rename = "H")]
    h: Vec<Vec<f64>>,
    #[serde(rename = "Q")]
    q: Vec<Vec<f64>>,
    #[serde(rename = "R")]
    r: Vec<Vec<f64>>,
}

/// kf.json's arrays, one entry per cell in run-major order (`None` where null), read
/// independently of the binary's reader.
struct Arrays {
    runs: usize,
    steps: usize,
    time: Vec<f64>,
    truth: Vec<Option<Vec<f64>>>,
    estimate: Vec<Option<Vec<f64>>>,
    covariance: Vec<Option<Vec<f64>>>,
    innovation: Vec<Option<Vec<f64>>>,
    innovation_cov: Vec<Option<Vec<f64>>>,
    /// F, H, Q, R, row by row.
    model: [Vec<f64>; 4],
}

impl Arrays {
    /// The cell of `array` at `run` and `step`.
    fn cell_mut(&mut self, array: &str, run: usize, step: usize) -> &mut Option<Vec<f64>> {
        let cells = match array {
            "truth" => &mut self.truth,
            "estimate" => &mut self.estimate,
            "covariance" => &mut self.covariance,
            "innovation" => &mut self.innovation,
            "innovation_cov" => &mut self.innovation_cov,
            other => panic!("no per-cell array {other}"),
        };
        &mut cells[run * self.steps + step]
    }
}

fn fixture_arrays() -> Arrays {
    let text = std::fs::read_to_string(fixture("kf.json")).unwrap();
    let fx: Fixture = serde_json::from_str(&text).unwrap();
    let mat = |m: &Vec<Vec<f64>>| -> Vec<f64> { m.iter().flatten().copied().collect() };
    let vectors = |v: &Vec<Vec<Vec<f64>>>| -> Vec<Option<Vec<f64>>> {
        v.iter().flatten().map(|c| Some(c.clone())).collect()
    };
    Arrays {
        runs: fx.truth.len(),
        steps: fx.truth[0].len(),
        time: fx.time.clone(),
        truth: vectors(&fx.truth),
        estimate: vectors(&fx.estimate),
        covariance: fx
            .covariance
            .iter()
            .flatten()
            .map(|c| Some(mat(c)))
            .collect(),
        innovation: fx.innovation.iter().flatten().cloned().collect(),
        innovation_cov: fx
            .innovation_cov
            .iter()
            .flatten()
            .map(|c| c.as_ref().map(mat))
            .collect(),
        model: [mat(&fx.f), mat(&fx.h), mat(&fx.q), mat(&fx.r)],
    }
}

/// The evaluation of `a` in-process, with the options the tests pass.
fn evaluate_arrays(a: &Arrays, with_model: bool) -> Report {
    let mut log = FilterLog::new(a.runs, a.steps)
        .unwrap()
        .with_times(a.time.clone())
        .unwrap()
        .with_truth(Vectors::cells(4, a.truth.clone()))
        .unwrap()
        .with_estimate(Vectors::cells(4, a.estimate.clone()))
        .unwrap()
        .with_covariance(Matrices::cells(4, 4, a.covariance.clone()))
        .unwrap()
        .with_innovation(Vectors::cells(2, a.innovation.clone()))
        .unwrap()
        .with_innovation_cov(Matrices::cells(2, 2, a.innovation_cov.clone()))
        .unwrap();
    if with_model {
        let [f, h, q, r] = a.model.clone();
        log = log
            .with_model(
                Matrices::constant(4, 4, f),
                Matrices::constant(2, 4, h),
                Matrices::constant(4, 4, q),
                Matrices::constant(2, 2, r),
            )
            .unwrap();
    }
    Evaluation::new()
        .group("position", vec![0, 1])
        .unwrap()
        .evaluate(&log)
        .unwrap()
}

/// The evaluation of the fixture's arrays in-process.
fn in_process(with_model: bool) -> Report {
    evaluate_arrays(&fixture_arrays(), with_model)
}

/// As [`in_process`], for the fixture's runs repeated `copies` times (run `c R + r` is run
/// `r` of the fixture).
fn in_process_copies(with_model: bool, copies: usize) -> Report {
    let mut a = fixture_arrays();
    fn repeat<T: Clone>(v: &mut Vec<T>, copies: usize) {
        *v = (0..copies).flat_map(|_| v.iter().cloned()).collect();
    }
    repeat(&mut a.truth, copies);
    repeat(&mut a.estimate, copies);
    repeat(&mut a.covariance, copies);
    repeat(&mut a.innovation, copies);
    repeat(&mut a.innovation_cov, copies);
    a.runs *= copies;
    evaluate_arrays(&a, with_model)
}

fn good_log(test: &str, log: &str, with_model: bool) {
    let dir = scratch(test);
    let out = dir.join("report");
    let input = fixture(log);
    let run = kalibra(&[
        "eval",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--group",
        "position=0,1",
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout).contains("verdict: consistent"),
        "{}",
        text(&run.stdout)
    );
    let mut files = vec![
        "report.json",
        "report.md",
        "report.html",
        "anees.svg",
        "anis.svg",
        "nci.svg",
        "rmse.svg",
        "whiteness.svg",
    ];
    if with_model {
        files.push("j1j2.svg");
    }
    for f in &files {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let listed = std::fs::read_dir(&out).unwrap().count();
    assert_eq!(listed, files.len(), "unexpected files in the report");
    // Nothing left beside the report.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);

    let report: Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let expected = in_process(with_model);
    assert_eq!(report.summary, expected.summary);
    assert_eq!(report, expected);

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let mut lines = md.lines().filter(|l| !l.is_empty());
    assert!(lines.next().unwrap().starts_with("# kalibra report"));
    assert!(
        lines.next().unwrap().starts_with("**Verdict: consistent"),
        "{md}"
    );
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_eq!(html.matches("<svg").count(), files.len() - 3);
    // Inline figures clip to their own areas (ids are unique in a page).
    assert!(html.contains("kalibra-plot-area-0") && html.contains("kalibra-plot-area-4"));
    // Self-contained: no links, scripts or images from elsewhere.
    for banned in ["src=", "href=", "<link", "<script", "url(http", "@import"] {
        assert!(!html.contains(banned), "report.html contains {banned}");
    }
}

#[test]
fn json_log_gives_the_in_process_report() {
    good_log("good-json", "kf.json", true);
}

#[test]
fn csv_log_gives_the_in_process_report() {
    good_log("good-csv", "kf.csv", false);
}

/// A CSV log larger than the blocks the reader hands to its parsing threads (256 KiB): the
/// rows reach the evaluation in file order, so the report is the in-process one exactly, and
/// an error in a later block names its row of the file.
#[test]
fn csv_log_of_several_blocks() {
    let copies = 60;
    let fixture_csv = std::fs::read_to_string(fixture("kf.csv")).unwrap();
    let mut lines = fixture_csv.lines();
    let header = lines.next().unwrap();
    let rows: Vec<&str> = lines.collect();
    let runs = 4;
    let mut csv = format!("{header}\n");
    for c in 0..copies {
        for row in &rows {
            let (run, rest) = row.split_once(',').unwrap();
            let run: usize = run.parse().unwrap();
            csv += &format!("{},{rest}\n", c * runs + run);
        }
    }
    assert!(csv.len() > 2 << 20, "the log spans several blocks");
    let dir = scratch("several-blocks");
    let log = dir.join("big.csv");
    std::fs::write(&log, &csv).unwrap();
    let out = dir.join("report");
    let run = kalibra(&[
        "eval",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--group",
        "position=0,1",
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let report: Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report.runs, copies * runs);
    assert_eq!(report, in_process_copies(false, copies));

    // A bad cell far into the file: row 5001 (the header is row 1).
    let mut bad: Vec<String> = csv.lines().map(String::from).collect();
    let cells: Vec<&str> = bad[5000].split(',').collect();
    let mut cells: Vec<String> = cells.into_iter().map(String::from).collect();
    cells[4] = "oops".into();
    bad[5000] = cells.join(",");
    bad_input(
        "several-blocks-bad",
        "big.csv",
        (bad.join("\n") + "\n").as_bytes(),
        &["row 5001, column 5 (truth_1)", "`oops` is not a number"],
    );
}

/// `kf.npz` holds kf.json's arrays as numpy's `np.savez` wrote them (`make_npz.py`), NaN
/// cells where the JSON has null: the report is the same.
#[test]
fn npz_log_gives_the_in_process_report() {
    good_log("good-npz", "kf.npz", true);
}

/// `make_python_json.py`'s tables. Cells partly NaN or infinite (array, run, step, index in
/// the flat cell, value): findings, left out of the statistics they would poison.
const PYTHON_POISONED: [(&str, usize, usize, usize, f64); 4] = [
    ("covariance", 1, 4, 0, f64::NAN),
    ("covariance", 2, 9, 15, f64::INFINITY),
    ("estimate", 3, 12, 1, f64::NEG_INFINITY),
    ("innovation_cov", 2, 3, 3, f64::NAN),
];
/// Cells written as all NaN (array, run, step): not logged. So are the innovation cells that
/// kf.json has as null, which the script writes as all NaN.
const PYTHON_NOT_LOGGED: [(&str, usize, usize); 1] = [("truth", 0, 20)];

/// `kf_python.json` holds kf.json's arrays as Python's `json.dump` wrote them
/// (`make_python_json.py`), bare `NaN`, `Infinity` and `-Infinity` included: the report is
/// the library's on the same arrays, with the all-NaN cells as not logged and the partly
/// non-finite ones counted as findings.
#[test]
fn json_from_python_reads_nan_and_infinity() {
    let out = scratch("python-json").join("report");
    let run = kalibra(&[
        "eval",
        fixture("kf_python.json").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--group",
        "position=0,1",
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let report: Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();

    let mut arrays = fixture_arrays();
    for (array, run, step, index, value) in PYTHON_POISONED {
        arrays.cell_mut(array, run, step).as_mut().unwrap()[index] = value;
    }
    for (array, run, step) in PYTHON_NOT_LOGGED {
        *arrays.cell_mut(array, run, step) = None;
    }
    assert_eq!(report, evaluate_arrays(&arrays, true));

    // The findings are the poisoned cells, by family, and nothing else: an all-NaN cell read
    // as logged would be one more.
    let state: Vec<_> = PYTHON_POISONED
        .iter()
        .filter(|p| p.0 == "covariance" || p.0 == "estimate")
        .collect();
    let f = &report.findings;
    assert_eq!(f.state.cells, state.len());
    assert_eq!(
        f.state.non_finite_vector,
        state.iter().filter(|p| p.0 == "estimate").count()
    );
    assert_eq!(
        f.state.non_finite,
        f.state.cells - f.state.non_finite_vector
    );
    let first = state.iter().min_by_key(|p| (p.1, p.2)).unwrap();
    let found = f.state.first.as_ref().unwrap();
    assert_eq!(
        (found.array.as_str(), found.run, found.step),
        (first.0, first.1, first.2)
    );
    assert_eq!(f.innovation.cells, PYTHON_POISONED.len() - state.len());
    assert_eq!(f.innovation.non_finite, f.innovation.cells);
    // Every run has a NEES at a step but where the script poisoned or blanked a state cell.
    for (k, &runs) in report.nees_runs_per_step.iter().enumerate() {
        let lost = state.iter().filter(|p| p.2 == k).count()
            + PYTHON_NOT_LOGGED.iter().filter(|p| p.2 == k).count();
        assert_eq!(runs, report.runs - lost, "step {k}");
    }
}

/// A NaN inside a string, key or value, stays text: only a bare token is a number.
#[test]
fn json_nan_inside_strings_is_text() {
    let s = r#""innovation_cov": [[[1]], [[1]]]"#;
    let cases: [(&str, String, &[&str]); 3] = [
        (
            "nan-key",
            format!(r#"{{"NaN": [[0.5], [1.0]], {s}}}"#),
            &["unknown array `NaN`"],
        ),
        (
            "nan-value",
            format!(r#"{{"innovation": [[0.5], ["NaN"]], {s}}}"#),
            &[
                "array innovation[1][0]",
                "expected a number, found a string",
            ],
        ),
        // An escaped quote does not end the string: the NaN after it is still inside.
        (
            "nan-after-escaped-quote",
            format!(r#"{{"a\":NaN": [[0.5], [1.0]], {s}}}"#),
            &[r#"unknown array `a":NaN`"#],
        ),
    ];
    for (test, json, needles) in cases {
        bad_input(test, "strings.json", json.as_bytes(), needles);
    }
}

/// A string that serde_json would read like a bare token's stand-in is refused with its
/// place, rather than taken for a number.
#[test]
fn json_string_like_a_stand_in_is_refused() {
    let json = "{\"innovation\": [[0.5], [\"\\u0001\"]], \"innovation_cov\": [[[1]], [[1]]]}";
    let column = json.find("\"\\u0001").unwrap() + 1;
    bad_input(
        "stand-in",
        "forged.json",
        json.as_bytes(),
        &[&format!("line 1, column {column}"), "unexpected string"],
    );
}

/// Syntax errors after a bare token keep the line and column of the file as written, and a
/// bare token where a key belongs is a syntax error there.
#[test]
fn json_errors_after_python_tokens_keep_their_column() {
    let json = r#"{"innovation": [[NaN], [-Infinity], [Infinity], [x]], "innovation_cov": []}"#;
    let column = json.find('x').unwrap() + 1;
    bad_input(
        "token-column",
        "column.json",
        json.as_bytes(),
        &[&format!("line 1, column {column}:"), "not valid JSON"],
    );
    bad_input(
        "token-key",
        "key.json",
        br#"{NaN: [[1.0]]}"#,
        &["line 1, column 2:", "not valid JSON"],
    );
}

#[test]
fn npz_truncated_file() {
    let full = std::fs::read(fixture("kf.npz")).unwrap();
    bad_input(
        "truncated-npz",
        "cut.npz",
        &full[..full.len() / 2],
        &["not an NPZ archive"],
    );
}

#[test]
fn npz_not_an_archive() {
    bad_input(
        "not-npz",
        "log.npz",
        b"{\"truth\": []}",
        &["not an NPZ archive", "np.savez"],
    );
}

/// A small single-run CSV with diagonal covariances works, and a second run replaces the
/// first report.
#[test]
fn diagonal_single_run_csv_and_replacing_a_report() {
    let dir = scratch("diagonal");
    let log = dir.join("small.csv");
    std::fs::write(
        &log,
        "run,step,truth_0,truth_1,estimate_0,estimate_1,covariance_0_0,covariance_1_1\n\
         0,0,0,0,0.1,-0.2,1,1\n0,1,1,1,1.2,0.9,1,1\n0,2,2,2,,,,\n0,3,3,3,2.5,3.4,1,1\n",
    )
    .unwrap();
    let out = dir.join("report");
    for _ in 0..2 {
        let run = kalibra(&[
            "eval",
            log.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    }
    let report: Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report.runs, 1);
    assert_eq!(report.nees_runs_per_step, vec![1, 1, 0, 1]);
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        2,
        "leftovers beside the report"
    );
}

/// Runs `kalibra eval` on `content` saved as `name`; asserts exit code 1, a message naming
/// the file and every one of `needles`, and no report directory (nor temporary one) left.
fn bad_input(test: &str, name: &str, content: &[u8], needles: &[&str]) {
    let dir = scratch(test);
    let log = dir.join(name);
    std::fs::write(&log, content).unwrap();
    let out = dir.join("report");
    let run = kalibra(&[
        "eval",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(err.contains(name), "message does not name the file: {err}");
    for n in needles {
        assert!(err.contains(n), "message lacks `{n}`: {err}");
    }
    assert_eq!(err.trim_end().lines().count(), 1, "one message: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("backtrace"),
        "{err}"
    );
    assert!(!out.exists(), "a report was written");
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "leftovers");
}

const SMALL_CSV: &str = "run,step,truth_0,truth_1,estimate_0,estimate_1,covariance_0_0,covariance_1_1\n\
                         0,0,0,0,0.1,-0.2,1,1\n\
                         0,1,1,1,1.2,0.9,1,1\n";

#[test]
fn csv_missing_column() {
    // The column is gone from the header and from every row.
    let csv: String = SMALL_CSV
        .lines()
        .map(|l| {
            let mut cells: Vec<&str> = l.split(',').collect();
            cells.remove(5);
            cells.join(",") + "\n"
        })
        .collect();
    bad_input(
        "missing-column",
        "missing.csv",
        csv.as_bytes(),
        &["row 1", "missing column `estimate_1`"],
    );
}

#[test]
fn csv_misnamed_column() {
    let csv = SMALL_CSV.replacen("estimate_1", "estimat_1", 1);
    bad_input(
        "misnamed-column",
        "misnamed.csv",
        csv.as_bytes(),
        &["row 1, column 6", "unknown column `estimat_1`"],
    );
}

#[test]
fn csv_ragged_row() {
    let csv = SMALL_CSV.replacen("1.2,0.9,", "1.2,", 1);
    bad_input(
        "ragged",
        "ragged.csv",
        csv.as_bytes(),
        &["row 3", "7 fields, but the header has 8"],
    );
}

#[test]
fn csv_non_numeric_cell() {
    let csv = SMALL_CSV.replacen("-0.2", "abc", 1);
    bad_input(
        "non-numeric",
        "text.csv",
        csv.as_bytes(),
        &["row 2, column 6 (estimate_1)", "`abc` is not a number"],
    );
}

#[test]
fn csv_truncated_file() {
    let full = std::fs::read(fixture("kf.csv")).unwrap();
    // Cut inside a row: the last row is short.
    let cut = &full[..full.len() / 2];
    let cut = &cut[..cut.iter().rposition(|&b| b == b',').unwrap()];
    bad_input(
        "truncated-csv",
        "cut.csv",
        cut,
        &["row ", "is the file truncated?"],
    );
}

#[test]
fn csv_missing_rows() {
    let full = std::fs::read_to_string(fixture("kf.csv")).unwrap();
    // Cut at a row boundary inside run 3: its last steps have no row.
    let keep: Vec<&str> = full.lines().take(1 + 3 * 25 + 10).collect();
    bad_input(
        "missing-rows",
        "short.csv",
        (keep.join("\n") + "\n").as_bytes(),
        &["no row for run 3, step 10", "truncated"],
    );
}

#[test]
fn json_wrong_shape() {
    let json = r#"{"truth": [[0, 0], [1, 1], [2, 2]],
                   "estimate": [[0.1, 0.2], [1.1, 0.9, 3.0], [2.0, 2.1]],
                   "covariance": [[[1, 0], [0, 1]], [[1, 0], [0, 1]], [[1, 0], [0, 1]]]}"#;
    bad_input(
        "wrong-shape",
        "shape.json",
        json.as_bytes(),
        &["array estimate[1]", "expected 2 values, found 3"],
    );
}

#[test]
fn json_runs_disagree() {
    let json = r#"{"truth": [[[0], [1]], [[0], [1]]],
                   "estimate": [[[0.1], [1.1]]],
                   "covariance": [[[[1]], [[1]]], [[[1]], [[1]]]]}"#;
    bad_input(
        "runs-disagree",
        "runs.json",
        json.as_bytes(),
        &["array estimate has 1 runs of 2 steps, but array truth has 2 runs"],
    );
}

#[test]
fn json_non_numeric_value() {
    let json = r#"{"innovation": [[0.5], ["x"]], "innovation_cov": [[[1]], [[1]]]}"#;
    bad_input(
        "json-text",
        "text.json",
        json.as_bytes(),
        &[
            "array innovation[1][0]",
            "expected a number, found a string",
        ],
    );
}

#[test]
fn json_misnamed_array() {
    let json = r#"{"innovations": [[0.5], [1.0]], "innovation_cov": [[[1]], [[1]]]}"#;
    bad_input(
        "json-misnamed",
        "names.json",
        json.as_bytes(),
        &["unknown array `innovations`"],
    );
}

#[test]
fn json_truncated_file() {
    let full = std::fs::read(fixture("kf.json")).unwrap();
    bad_input(
        "truncated-json",
        "cut.json",
        &full[..full.len() / 2],
        &["line ", "column ", "ends early (truncated?)"],
    );
}

#[test]
fn unknown_extension() {
    bad_input(
        "extension",
        "log.npy",
        b"\x93NUMPY",
        &["unknown extension `.npy`"],
    );
}

#[test]
fn usage_errors_exit_2() {
    let log = fixture("kf.json");
    for args in [
        vec!["eval", log.to_str().unwrap(), "--confidence", "2"],
        vec!["eval", log.to_str().unwrap(), "--group", "position"],
        vec!["eval", log.to_str().unwrap(), "--window", "1"],
        vec!["eval"],
        vec!["judge"],
    ] {
        let run = kalibra(&args);
        assert_eq!(
            run.status.code(),
            Some(2),
            "{args:?}: {}",
            text(&run.stderr)
        );
    }
    let help = kalibra(&["eval", "--help"]);
    assert_eq!(help.status.code(), Some(0));
    assert!(text(&help.stdout).contains("LOG FORMATS"));
}

#[test]
fn an_existing_directory_that_is_no_report_is_left_alone() {
    let dir = scratch("foreign-dir");
    let out = dir.join("mine");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    let log = fixture("kf.json");
    let run = kalibra(&[
        "eval",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(1));
    assert!(text(&run.stderr).contains("holds no earlier report"));
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "keep me"
    );
}

/// The output is checked before the log is read: an `--out` under a plain file fails at once
/// (here the log does not even exist, and the message is about `--out`), for both commands.
#[test]
fn an_unwritable_out_fails_before_any_work() {
    let dir = scratch("unwritable-out");
    let blocker = dir.join("plain-file");
    std::fs::write(&blocker, "not a directory").unwrap();
    let out = blocker.join("report");
    for args in [
        vec!["eval", "missing-log.csv"],
        vec!["tune", "missing-model.toml", "missing-measurements.csv"],
    ] {
        let mut args = args.clone();
        args.extend(["--out", out.to_str().unwrap()]);
        let run = kalibra(&args);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{err}");
        assert!(err.contains("plain-file/report"), "{err}");
        assert!(err.contains("cannot create its parent directory"), "{err}");
        assert!(!err.contains("missing-"), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
}
