//! The typed errors carry where the input is at fault (the file, the CSV row and column, the
//! array and index, the MODEL.toml key) and display as the command line's one-line messages.

use std::path::{Path, PathBuf};

use kalibra_eval::{EvalError, Evaluation};
use kalibra_io::Error;
use kalibra_io::input::{LogFormat, evaluate_bytes, log_from_arrays};
use kalibra_io::tune_input::{parse_model, parse_series};

fn eval_error(file: &str, format: LogFormat, bytes: &[u8]) -> Error {
    match evaluate_bytes(Path::new(file), format, bytes, &Evaluation::new()) {
        Ok(_) => panic!("{file} was accepted"),
        Err(e) => e,
    }
}

#[test]
fn a_csv_cell_names_its_row_and_column() {
    let csv = "run,step,truth_0,estimate_0,covariance_0_0\n0,0,1,1,1\n0,1,x,1,1\n";
    let e = eval_error("log.csv", LogFormat::Csv, csv.as_bytes());
    assert_eq!(
        e.to_string(),
        "log.csv: row 3, column 3 (truth_0): `x` is not a number"
    );
    let Error::Csv {
        file,
        row,
        column,
        column_name,
        ..
    } = e
    else {
        panic!("{e:?}")
    };
    assert_eq!(file, PathBuf::from("log.csv"));
    assert_eq!((row, column), (Some(3), Some(3)));
    assert_eq!(column_name.as_deref(), Some("truth_0"));
}

#[test]
fn a_json_value_names_its_array_and_index() {
    let json = r#"{"truth": [[[0.0], ["a"]]], "estimate": [[[0.0], [0.0]]],
                   "covariance": [[[[1.0]], [[1.0]]]]}"#;
    let e = eval_error("log.json", LogFormat::Json, json.as_bytes());
    assert_eq!(
        e.to_string(),
        "log.json: array truth[0][1][0]: expected a number, found a string"
    );
    let Error::Array {
        file, array, index, ..
    } = e
    else {
        panic!("{e:?}")
    };
    assert_eq!(file, Some(PathBuf::from("log.json")));
    assert_eq!((array.as_str(), index), ("truth", vec![0, 1, 0]));
}

#[test]
fn json_that_is_not_json_names_its_line_and_column() {
    let e = eval_error("log.json", LogFormat::Json, b"{\n  \"truth\": [1,");
    assert!(matches!(e, Error::Json { line: Some(2), .. }), "{e:?}");
    assert!(
        e.to_string().starts_with("log.json: line 2, column "),
        "{e}"
    );
}

#[test]
fn an_evaluation_error_keeps_the_evaluations_error() {
    let json = r#"{"truth": [[Infinity]], "estimate": [[0.0]], "covariance": [[[1.0]]]}"#;
    let e = eval_error("log.json", LogFormat::Json, json.as_bytes());
    assert_eq!(
        e.to_string(),
        "log.json: array truth holds a non-finite value at run 0, step 0"
    );
    assert!(
        matches!(
            e,
            Error::Refused {
                source: EvalError::NonFinite {
                    array: "truth",
                    run: 0,
                    step: 0
                },
                ..
            }
        ),
        "{e:?}"
    );
}

#[test]
fn arrays_in_memory_name_the_array_and_no_file() {
    let e = log_from_arrays(vec![("truth".to_string(), vec![2, 3], vec![0.0; 5])]).unwrap_err();
    assert_eq!(e.to_string(), "array truth holds 5 values for shape [2, 3]");
    assert!(e.file().is_none());
    assert!(
        matches!(&e, Error::Array { array, .. } if array == "truth"),
        "{e:?}"
    );
}

#[test]
fn model_toml_names_the_key() {
    let text = "F = [[1.0]]\nH = [[1.0]]\nQ = [[1.0]]\nR = [[1.0]]\nx0 = [0.0]\nP0 = [[1.0]]\n\
                bogus = 1\n";
    let Err(e) = parse_model(Path::new("model.toml"), text) else {
        panic!("accepted")
    };
    assert!(
        e.to_string()
            .starts_with("model.toml: key bogus, line 7, column 1: unknown field `bogus`"),
        "{e}"
    );
    assert!(
        matches!(&e, Error::Model { key: Some(k), line: Some(7), column: Some(1), .. } if k == "bogus"),
        "{e:?}"
    );
    let ragged = text
        .replace("F = [[1.0]]", "F = [[1.0, 2.0], [1.0]]")
        .replace("bogus = 1\n", "");
    let Err(e) = parse_model(Path::new("model.toml"), &ragged) else {
        panic!("accepted")
    };
    assert_eq!(
        e.to_string(),
        "model.toml: key F: matrix F row 1 holds 1 values, expected 2"
    );
    assert!(matches!(&e, Error::Model { key: Some(k), line: None, .. } if k == "F"));
}

#[test]
fn a_series_names_the_row() {
    let Err(e) = parse_series(
        Path::new("z.csv"),
        b"step,z_0\n0,1\n2,3\n",
        "z",
        1,
        "H has 1 row(s)",
    ) else {
        panic!("accepted")
    };
    assert!(
        matches!(
            e,
            Error::Csv {
                row: Some(3),
                column: Some(1),
                ..
            }
        ),
        "{e:?}"
    );
}

/// A model of `kalibra tune --method`: `R` 2x2 given inline as a full form with its
/// correlation fixed, `Q` as a table after the top-level keys.
const FORMS: &str = "F = [[1.0]]\nH = [[1.0], [1.0]]\nx0 = [0.0]\nP0 = [[1.0]]\n\
                     R = { form = \"full\", value = [[1.0, 0.0], [0.0, 2.0]], fixed = [[1, 0]] }\n\
                     \n[Q]\nform = \"diagonal\"\nvalue = [[0.5]]\n";

fn runs() -> Vec<kalibra_tune::Run> {
    vec![vec![Some(kalibra_tune::DVector::from_element(2, 0.5)); 4]]
}

#[test]
fn model_forms_give_the_parametrisation() {
    let path = Path::new("model.toml");
    let model = parse_model(path, FORMS).unwrap();
    assert!(!model.is_plain());
    let problem = model
        .noise_problem(path, Path::new("z.csv"), runs())
        .unwrap();
    let names: Vec<String> = problem
        .noise()
        .parameters()
        .into_iter()
        .map(|p| p.name)
        .collect();
    // R's correlation is fixed: its two variances are free, and Q's one.
    assert_eq!(names, ["Qw[0,0]", "R[0,0]", "R[1,1]"]);

    // Today's plain matrices: Q scaled (its multiplier q), R fixed.
    let plain = "F = [[1.0]]\nH = [[1.0]]\nQ = [[0.5]]\nR = [[1.0]]\nx0 = [0.0]\nP0 = [[1.0]]\n";
    let model = parse_model(path, plain).unwrap();
    assert!(model.is_plain());
    let runs = vec![vec![Some(kalibra_tune::DVector::from_element(1, 0.5)); 4]];
    let problem = model.noise_problem(path, Path::new("z.csv"), runs).unwrap();
    let names: Vec<String> = problem
        .noise()
        .parameters()
        .into_iter()
        .map(|p| p.name)
        .collect();
    assert_eq!(names, ["q"]);
}

#[test]
fn model_form_errors_name_the_key_and_line() {
    let path = Path::new("model.toml");
    let outside = FORMS.replace("fixed = [[1, 0]]", "fixed = [[2, 0]]");
    let Err(e) = parse_model(path, &outside) else {
        panic!("accepted")
    };
    assert_eq!(
        e.to_string(),
        "model.toml: key R, line 5, column 1: fixed entry [2, 0] is outside the 2x2 value \
         (entries count from 0)"
    );
    let late = format!("{FORMS}position = [0]\n");
    let Err(e) = parse_model(path, &late) else {
        panic!("accepted")
    };
    let message = e.to_string();
    assert!(message.contains("key Q.position"), "{message}");
    assert!(
        message.contains("write the top-level keys before the first table"),
        "{message}"
    );
    // A form's value the estimators refuse names its key and line.
    let indefinite = FORMS.replace("[[1.0, 0.0], [0.0, 2.0]]", "[[1.0, 0.0], [0.0, -2.0]]");
    let model = parse_model(path, &indefinite).unwrap();
    let Err(e) = model.noise_problem(path, Path::new("z.csv"), runs()) else {
        panic!("accepted")
    };
    assert!(
        matches!(&e, Error::Model { key: Some(k), line: Some(5), .. } if k == "R"),
        "{e:?}"
    );
}
