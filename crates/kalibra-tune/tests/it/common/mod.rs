//! Seeded simulation of linear-Gaussian systems for the report and coverage tests.

#![allow(dead_code)]

use kalibra_tune::{DMatrix, DVector, Run};
use rand::RngExt;
use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
use rand_distr::StandardNormal;

/// A system `x_k = F x_{k-1} + G w_k`, `z_k = H x_k + v_k`, `w ~ N(0, Qw)`, `v ~ N(0, R)`,
/// from a known `x_0`.
pub struct System {
    pub f: DMatrix<f64>,
    pub g: DMatrix<f64>,
    pub qw: DMatrix<f64>,
    pub h: DMatrix<f64>,
    pub r: DMatrix<f64>,
    pub x0: DVector<f64>,
}

/// A lower Cholesky factor of a positive semi-definite matrix (a zero matrix gives zero).
fn factor(m: &DMatrix<f64>) -> DMatrix<f64> {
    if m.iter().all(|&v| v == 0.0) {
        return m.clone();
    }
    m.clone().cholesky().expect("positive definite noise").l()
}

impl System {
    /// One run of `steps` measurements (predict first: the first is of `x_1`) and the true
    /// states at those steps.
    pub fn simulate(&self, steps: usize, seed: u64) -> (Run, Run) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (lq, lr) = (factor(&self.qw), factor(&self.r));
        let mut normal = |k: usize| {
            DVector::from_iterator(k, (0..k).map(|_| rng.sample::<f64, _>(StandardNormal)))
        };
        let mut x = self.x0.clone();
        let mut zs = Vec::with_capacity(steps);
        let mut xs = Vec::with_capacity(steps);
        for _ in 0..steps {
            let w = &lq * normal(lq.nrows());
            x = &self.f * &x + &self.g * w;
            let v = &lr * normal(lr.nrows());
            zs.push(Some(&self.h * &x + v));
            xs.push(Some(x.clone()));
        }
        (zs, xs)
    }
}

/// A scalar matrix.
pub fn one(v: f64) -> DMatrix<f64> {
    DMatrix::from_element(1, 1, v)
}
