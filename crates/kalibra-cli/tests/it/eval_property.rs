//! The report-equals-metrics property through the binary: random small logs written as CSV
//! and as JSON give a `report.json` equal to the library's `Evaluation::evaluate` of the same
//! arrays, compared as JSON values, so every number to the last bit: the logs are written
//! with shortest round-trip float printing and read with correctly rounded parsing, and the
//! report's numbers are printed and read back the same way. Few cases, as each spawns the
//! binary twice; `kalibra-eval`'s own property test covers the metrics with many more.

use kalibra_eval::{Evaluation, FilterLog, Matrices, Vectors};
use proptest::prelude::*;

use crate::common::{kalibra, scratch, text};

/// A random positive definite matrix, row by row: variances in [0.5, 4) and correlations
/// below 1 / 2 in magnitude, which for at most three components keeps the correlation
/// matrix diagonally dominant.
fn covariance(dim: usize) -> impl Strategy<Value = Vec<f64>> + Clone {
    (
        prop::collection::vec(0.5..4.0f64, dim),
        prop::collection::vec(-0.45..0.45f64, dim * dim),
    )
        .prop_map(move |(var, rho)| {
            let mut p = vec![0.0; dim * dim];
            for i in 0..dim {
                for j in 0..dim {
                    // The lower triangle mirrors the upper: exactly symmetric.
                    let r = if i == j {
                        1.0
                    } else {
                        rho[i.min(j) * dim + i.max(j)]
                    };
                    p[i * dim + j] = r * (var[i] * var[j]).sqrt();
                }
            }
            p
        })
}

/// `count` cells, each missing with probability 0.25, but the first: a JSON array with no
/// logged cell cannot say its cells' size.
fn cells(
    count: usize,
    cell: impl Strategy<Value = Vec<f64>> + Clone,
) -> impl Strategy<Value = Vec<Option<Vec<f64>>>> {
    (
        cell.clone(),
        prop::collection::vec(prop::option::weighted(0.75, cell), count - 1),
    )
        .prop_map(|(first, rest)| std::iter::once(Some(first)).chain(rest).collect())
}

#[derive(Debug, Clone)]
struct Case {
    runs: usize,
    steps: usize,
    n: usize,
    m: usize,
    /// truth, estimate, covariance, innovation, innovation_cov: one entry per cell, run-major.
    arrays: [Vec<Option<Vec<f64>>>; 5],
    confidence: f64,
    window: Option<usize>,
    /// Whether the JSON writes a cell not logged as Python writes a NaN-filled numpy cell
    /// (`[NaN, NaN]`) rather than as `null`.
    missing_as_nan: bool,
}

const NAMES: [&str; 5] = [
    "truth",
    "estimate",
    "covariance",
    "innovation",
    "innovation_cov",
];

fn cases() -> impl Strategy<Value = Case> {
    (1usize..=4, 1usize..=12, 1usize..=3, 1usize..=2).prop_flat_map(|(runs, steps, n, m)| {
        let c = runs * steps;
        let vectors = |dim| cells(c, prop::collection::vec(-5.0..5.0f64, dim));
        (
            (vectors(n), vectors(n), cells(c, covariance(n))),
            (vectors(m), cells(c, covariance(m))),
            0.5..0.999f64,
            prop::option::of(2usize..6),
            any::<bool>(),
        )
            .prop_map(
                move |((truth, estimate, cov), (nu, s), confidence, window, missing_as_nan)| Case {
                    runs,
                    steps,
                    n,
                    m,
                    arrays: [truth, estimate, cov, nu, s],
                    confidence,
                    window,
                    missing_as_nan,
                },
            )
    })
}

impl Case {
    /// The size of one cell of array `a` (rows; a matrix is square).
    fn dim(&self, a: usize) -> usize {
        if a < 3 { self.n } else { self.m }
    }

    fn is_matrix(a: usize) -> bool {
        matches!(NAMES[a], "covariance" | "innovation_cov")
    }

    fn csv(&self) -> String {
        let mut header = vec!["run".to_string(), "step".to_string()];
        for (a, name) in NAMES.iter().enumerate() {
            let d = self.dim(a);
            if Self::is_matrix(a) {
                header.extend((0..d * d).map(|v| format!("{name}_{}_{}", v / d, v % d)));
            } else {
                header.extend((0..d).map(|i| format!("{name}_{i}")));
            }
        }
        let mut out = header.join(",") + "\n";
        for cell in 0..self.runs * self.steps {
            let mut row = vec![
                (cell / self.steps).to_string(),
                (cell % self.steps).to_string(),
            ];
            for (a, array) in self.arrays.iter().enumerate() {
                let width = if Self::is_matrix(a) {
                    self.dim(a) * self.dim(a)
                } else {
                    self.dim(a)
                };
                match &array[cell] {
                    // `{:?}` prints the shortest text that reads back as the same f64.
                    Some(values) => row.extend(values.iter().map(|v| format!("{v:?}"))),
                    None => row.extend(std::iter::repeat_n(String::new(), width)),
                }
            }
            out.push_str(&row.join(","));
            out.push('\n');
        }
        out
    }

    fn json(&self) -> String {
        let list = |items: Vec<String>| format!("[{}]", items.join(", "));
        let mut fields = Vec::new();
        for (a, array) in self.arrays.iter().enumerate() {
            let d = self.dim(a);
            let cell_text = |values: Vec<String>| {
                if Self::is_matrix(a) {
                    list(values.chunks(d).map(|row| list(row.to_vec())).collect())
                } else {
                    list(values)
                }
            };
            let width = if Self::is_matrix(a) { d * d } else { d };
            let runs = (0..self.runs)
                .map(|r| {
                    list(
                        (0..self.steps)
                            .map(|k| match &array[r * self.steps + k] {
                                Some(values) => cell_text(
                                    values
                                        .iter()
                                        .map(|v| serde_json::to_string(v).unwrap())
                                        .collect(),
                                ),
                                None if self.missing_as_nan => {
                                    cell_text(vec!["NaN".to_string(); width])
                                }
                                None => "null".to_string(),
                            })
                            .collect(),
                    )
                })
                .collect();
            fields.push(format!("\"{}\": {}", NAMES[a], list(runs)));
        }
        format!("{{{}}}", fields.join(", "))
    }

    /// The library's report of the same arrays, as JSON.
    fn library_report(&self) -> serde_json::Value {
        let [truth, estimate, cov, nu, s] = self.arrays.clone();
        let log = FilterLog::new(self.runs, self.steps)
            .unwrap()
            .with_truth(Vectors::cells(self.n, truth))
            .unwrap()
            .with_estimate(Vectors::cells(self.n, estimate))
            .unwrap()
            .with_covariance(Matrices::cells(self.n, self.n, cov))
            .unwrap()
            .with_innovation(Vectors::cells(self.m, nu))
            .unwrap()
            .with_innovation_cov(Matrices::cells(self.m, self.m, s))
            .unwrap();
        let mut evaluation = Evaluation::new().confidence(self.confidence).unwrap();
        if let Some(w) = self.window {
            evaluation = evaluation.window(w).unwrap();
        }
        serde_json::to_value(evaluation.evaluate(&log).unwrap()).unwrap()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn csv_and_json_reports_equal_the_library_report(c in cases()) {
        let dir = scratch("property");
        let expected = c.library_report();
        for (name, content) in [("log.csv", c.csv()), ("log.json", c.json())] {
            let log = dir.join(name);
            std::fs::write(&log, content).unwrap();
            let out = dir.join(format!("report-{name}"));
            let confidence = format!("{:?}", c.confidence);
            let window = c.window.map(|w| w.to_string());
            let mut args = vec![
                "eval",
                log.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--confidence",
                &confidence,
            ];
            if let Some(w) = &window {
                args.extend(["--window", w]);
            }
            let run = kalibra(&args);
            prop_assert_eq!(run.status.code(), Some(0), "{}: {}", name, text(&run.stderr));
            let written: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                    .unwrap();
            prop_assert_eq!(&written, &expected, "{}", name);
        }
    }
}
