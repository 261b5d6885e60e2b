//! The bit-for-bit checks of the fixed-size paths against the `Dyn` ones and the metrics
//! crate: [`Factor`](super::factor::Factor)'s NEES and NIS, and the `J1`/`J2` step; and of a
//! batch prepared apart ([`super::Evaluator::prepare_batch`]) against `push_batch`.

use kalibra_linalg::{DMatrix, DVector, LinalgError};
use kalibra_metrics::{MetricsError, j_step};
use proptest::prelude::*;

use super::cell::{MatrixCell, ModelCell};
use super::factor::Factor;
use super::j::{JModel, j_fixed};

/// `B B^T + I`, symmetric positive definite, from `k x k` values.
fn spd(v: &[f64], k: usize) -> DMatrix<f64> {
    let b = DMatrix::from_column_slice(k, k, &v[..k * k]);
    &b * b.transpose() + DMatrix::identity(k, k)
}

fn rows(a: &DMatrix<f64>) -> Vec<f64> {
    a.transpose().iter().copied().collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A cell's NEES and NIS are `kalibra_metrics::nees` and `nis` to the bit at every
    /// size, through the fixed-size factorisation (`nees_of`, `nis_of` up to 6) and the
    /// `Dyn` one (every size), for full cells (slightly asymmetric ones too, which NIS
    /// symmetrises), diagonal cells and indefinite ones (the same error).
    #[test]
    fn factor_equals_the_metrics_bit_for_bit(
        dim in 1usize..=8,
        v in proptest::collection::vec(-3.0f64..3.0, 64 + 8),
        skew in proptest::collection::vec(-1e-13f64..1e-13, 64),
        shift in prop_oneof![Just(0.0), -20.0f64..0.0],
    ) {
        let mut p = spd(&v, dim);
        // Below the symmetry tolerance, so a finding only for NEES's exact check if
        // ever; an indefinite matrix when shifted far enough.
        for i in 0..dim {
            p[(i, i)] += shift;
            for j in 0..i {
                p[(i, j)] += skew[i * 8 + j] * p[(i, j)].abs();
            }
        }
        let x = DVector::from_column_slice(&v[64..64 + dim]);
        let diagonal = DMatrix::from_diagonal(&p.diagonal());
        let (full, diag) = (rows(&p), p.diagonal().as_slice().to_vec());
        let s_full = kalibra_linalg::Covariance::new(p.clone());
        let s_diag = kalibra_linalg::Covariance::new(diagonal.clone());
        let cases = [
            (MatrixCell::Full(&full), &p, s_full),
            (MatrixCell::Diagonal(&diag), &diagonal, s_diag),
        ];
        for (cell, matrix, s) in cases {
            let mut fast = Factor::new(dim);
            let mut slow = Factor::new(dim);
            let want = kalibra_metrics::nees(&x, matrix).map(f64::to_bits);
            let got = fast.nees_of(cell, x.as_slice(), "P").map(f64::to_bits);
            slow.load(cell);
            let dynamic = slow.nees(x.as_slice(), "P").map(f64::to_bits);
            // Errors compare by kind (the metrics name the matrix differently).
            let kind = |e: LinalgError| std::mem::discriminant(&e);
            let want = want.map_err(|e| match e {
                MetricsError::Linalg(e) => Some(kind(e)),
                _ => None,
            });
            prop_assert_eq!(&got.map_err(|e| Some(kind(e))), &want);
            prop_assert_eq!(&dynamic.map_err(|e| Some(kind(e))), &want);
            let want = s
                .map_err(kalibra_metrics::MetricsError::from)
                .and_then(|s| kalibra_metrics::nis(&x, &s))
                .map(f64::to_bits);
            let got = fast.nis_of(cell, x.as_slice(), "S").map(f64::to_bits);
            slow.load(cell);
            let dynamic = slow.nis(x.as_slice(), "S").map(f64::to_bits);
            prop_assert_eq!(got.is_ok(), want.is_ok());
            prop_assert_eq!(dynamic.is_ok(), want.is_ok());
            if let (Ok(a), Ok(b), Ok(c)) = (got, dynamic, want) {
                prop_assert_eq!(a, c);
                prop_assert_eq!(b, c);
                // The normalised innovation, which whiteness takes, to the bit too.
                let wa: Vec<u64> = fast.w.iter().map(|v| v.to_bits()).collect();
                let wb: Vec<u64> = slow.w.iter().map(|v| v.to_bits()).collect();
                prop_assert_eq!(wa, wb);
            }
        }
    }

    /// The fixed-size `J1`/`J2` step gives the `Dyn` path's values to the bit, at every
    /// size it covers.
    #[test]
    fn fixed_size_j_equals_the_dyn_path_bit_for_bit(
        m in 1usize..=4,
        n in 1usize..=6,
        v in proptest::collection::vec(-2.0f64..2.0, 5 * 36 + 24),
    ) {
        let f = DMatrix::from_column_slice(n, n, &v[..n * n]);
        let h = DMatrix::from_column_slice(m, n, &v[36..36 + m * n]);
        let q = spd(&v[60..], n);
        let r = spd(&v[96..], m);
        let p0 = spd(&v[112..], n);
        let p1 = spd(&v[148..], n);
        let (fr, hr, qr, rr) = (rows(&f), rows(&h), rows(&q), rows(&r));
        let cell = ModelCell { f: &fr, h: &hr, q: &qr, r: &rr };
        let jm = JModel::new(&cell, (n, m));
        prop_assert!(jm.is(&cell));
        let fixed = j_fixed(&jm, &p0, &p1).expect("a covered size");
        let a: DMatrix<f64> = &jm.hf * &p0 * &jm.hft;
        let c: DMatrix<f64> = &jm.h * &p1 * &jm.ht;
        let dynamic = j_step(&a, &jm.b, &jm.r, &c);
        match (fixed, dynamic) {
            (Ok(x), Ok(y)) => {
                for (p, q) in [(x.j1, y.j1), (x.j2, y.j2), (x.tr_n, y.tr_n), (x.tr_b, y.tr_b)] {
                    prop_assert_eq!(p.to_bits(), q.to_bits());
                }
                prop_assert_eq!(x.a_plus_b_definite, y.a_plus_b_definite);
            }
            (Err(_), Err(_)) => {}
            (x, y) => prop_assert!(false, "fixed {x:?}, dyn {y:?}"),
        }
    }
}

/// Cells fed as prepared batches, prepared by a second evaluator, give `push_batch`'s report
/// to the bit, and its error with the same index; a batch prepared for other cells is set
/// aside.
#[test]
fn prepared_batches_give_the_same_report() {
    use super::cell::{Cell, Contents};
    use crate::Evaluation;
    let contents = Contents {
        truth: Some(2),
        estimate: Some(2),
        covariance: Some(2),
        innovation: Some(1),
        innovation_cov: Some(1),
        model: None,
    };
    let (runs, steps) = (3, 700);
    // Truth, estimate, covariance, innovation and its covariance of each cell.
    type Values = (Vec<f64>, Vec<f64>, Vec<f64>, [f64; 1], [f64; 1]);
    let values: Vec<Values> = (0..runs * steps)
        .map(|i| {
            let t = i as f64 * 0.37;
            // Every 97th covariance is indefinite: a finding, not an error.
            let d = if i % 97 == 5 {
                -1.0
            } else {
                1.0 + t.sin().abs()
            };
            (
                vec![t.cos(), t.sin()],
                vec![
                    t.cos() + 0.1 * (3.0 * t).sin(),
                    t.sin() - 0.2 * (5.0 * t).cos(),
                ],
                vec![d, 0.1, 0.1, 2.0],
                [(7.0 * t).sin()],
                [1.5],
            )
        })
        .collect();
    let cells: Vec<(usize, usize, Cell<'_>)> = values
        .iter()
        .enumerate()
        .map(|(i, (x, xhat, p, nu, s))| {
            let cell = Cell {
                truth: Some(x),
                estimate: Some(xhat),
                covariance: Some(MatrixCell::Full(p)),
                innovation: Some(nu),
                innovation_cov: Some(MatrixCell::Full(s)),
                model: None,
            };
            (i / steps, i % steps, cell)
        })
        .collect();
    let evaluation = Evaluation::new().window(10).unwrap();
    let report = |prepared: bool, cells: &[(usize, usize, Cell<'_>)]| {
        let mut evaluator = evaluation.evaluator(contents).unwrap();
        let preparer = evaluation.evaluator(contents).unwrap();
        for batch in cells.chunks(600) {
            let fed = if prepared {
                evaluator.push_prepared(batch, preparer.prepare_batch(batch))
            } else {
                evaluator.push_batch(batch)
            };
            if let Err((i, e)) = fed {
                return Err((i, e.to_string()));
            }
        }
        Ok(serde_json::to_string(&evaluator.finish(None).unwrap()).unwrap())
    };
    let batched = report(false, &cells).unwrap();
    assert_eq!(report(true, &cells).unwrap(), batched);
    // A cell of the wrong length: the same error at the same index.
    let mut bad = cells.clone();
    bad[1234].2.truth = Some(&values[0].3);
    let err = report(false, &bad).unwrap_err();
    assert_eq!(report(true, &bad).unwrap_err(), err);
    // A batch prepared for other cells is not used.
    let mut evaluator = evaluation.evaluator(contents).unwrap();
    evaluator
        .push_prepared(&cells[..600], evaluator.prepare_batch(&cells[600..1200]))
        .unwrap();
    for batch in cells[600..].chunks(600) {
        evaluator.push_batch(batch).unwrap();
    }
    assert_eq!(
        serde_json::to_string(&evaluator.finish(None).unwrap()).unwrap(),
        batched
    );
}
