//! The hot-path kernels' documented panic: mismatched `Dyn` sizes panic
//! at once, on nalgebra's path and on faer's (from `FAER_MIN_DIM`), and never return a
//! result computed from the wrong entries (faer's `innovation_covariance` did, for an `R`
//! larger than `H`'s rows). The filters check sizes before calling them
//! (`kalibra-filters/tests/model_sizes.rs`).

use std::panic::{AssertUnwindSafe, catch_unwind};

use kalibra_linalg::{
    DMatrix, FAER_MIN_DIM, innovation_covariance, joseph_update, product, propagate,
    standard_update,
};

fn panics(what: &str, f: impl FnOnce()) {
    let result = catch_unwind(AssertUnwindSafe(f));
    assert!(result.is_err(), "{what}: returned instead of panicking");
}

#[test]
fn mismatched_dyn_sizes_panic_on_both_paths() {
    for n in [3, FAER_MIN_DIM + 4] {
        let m = 2;
        let p = DMatrix::<f64>::identity(n, n);
        let wide = DMatrix::<f64>::identity(m, n + 1);
        let h = DMatrix::<f64>::identity(m, n);
        let r = DMatrix::<f64>::identity(m, m);
        let k = DMatrix::<f64>::zeros(n, m);
        let at = |what: &str| format!("{what}, n = {n}");
        panics(&at("propagate"), || drop(propagate(&wide, &p)));
        panics(&at("product"), || drop(product(&p, &wide)));
        panics(&at("innovation_covariance H"), || {
            drop(innovation_covariance(&p, &wide, &r))
        });
        panics(&at("innovation_covariance R"), || {
            drop(innovation_covariance(
                &p,
                &h,
                &DMatrix::identity(m + 1, m + 1),
            ))
        });
        panics(&at("joseph_update"), || {
            drop(joseph_update(&p, &k, &wide, &r))
        });
        panics(&at("standard_update"), || {
            drop(standard_update(&p, &k, &wide))
        });
        // The same calls with fitting sizes return, so the panics above are the sizes'.
        drop(propagate(&h, &p));
        drop(innovation_covariance(&p, &h, &r));
        drop(joseph_update(&p, &k, &h, &r));
        drop(standard_update(&p, &k, &h));
    }
}
