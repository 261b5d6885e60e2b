//! The ballistic re-entry scenario shared by papers 000 ([`crate::paper000`]) and 003
//! ([`crate::paper003`]), and the J1/J2 bookkeeping both use.
//!
//! # Truth
//! Farina, Ristic and Benvenuti (2002) as both papers use it: `T = 2 s` (003 states it; 000's
//! `Qt` and `P0` imply it), `beta = 40 000 kg m^-1 s^-2`, `g = 9.81 m/s^2`,
//! `x0 = [232 km, 2290 cos 190 deg m/s, 88 km, 2290 sin 190 deg m/s]`. The truth runs until
//! ground impact: the last state above ground is `x_59`, so there are 59 measurements
//! `y_1 .. y_59`. The metric sweeps evaluate the filters on the noise-free truth with
//! noise-free measurements (the papers call the metrics an offline computation; the KF's J
//! values do not depend on the measurements at all, the EKF's only through its linearisation
//! point).
//!
//! # Readings of the papers
//! * Paper 003 prints `G` as `[[T^2/2, 0], [0, T^2/2], [0, 0], [0, 0]]`, a layout typo (it
//!   would leave the velocities without gravity); [`Ballistic`] uses the `G` of the source
//!   paper (Farina et al.) that both papers cite.
//! * The air density switches at 9144 m; at exactly 9144 m the upper piece applies, which is
//!   003's reading of the boundary (000 leaves `x2 = 9144` open).

use kalibra_filters::StepRecord;
use kalibra_linalg::{Alloc, DefaultAllocator, Dim, Matrix4, Vector4};
use kalibra_metrics::{JStep, MetricsError, j_step};
use kalibra_models::{Ballistic, BallisticParams, Dynamics, ModelError};
use serde::Serialize;

/// Sampling period (s).
pub const T: f64 = 2.0;
/// Ballistic coefficient (kg m^-1 s^-2).
pub const BETA: f64 = 40_000.0;
/// Gravity (m/s^2).
pub const G: f64 = 9.81;
/// Longest truth the scenario allows before it must have hit the ground.
const MAX_STEPS: usize = 1000;

/// The true initial state.
pub fn x0() -> Vector4<f64> {
    let a = 190f64.to_radians();
    Vector4::new(232e3, 2290.0 * a.cos(), 88e3, 2290.0 * a.sin())
}

/// The truth dynamics with process-noise covariance `q`.
///
/// # Errors
/// [`ModelError`] if `q` is not positive semi-definite.
pub fn dynamics(q: Matrix4<f64>) -> Result<Ballistic, ModelError> {
    let params = BallisticParams {
        period: T,
        beta: BETA,
        gravity: G,
    };
    Ballistic::new(params, q)
}

/// The noise-free truth `x_0, x_1, ..., x_N`, `x_N` the last state above ground.
///
/// # Errors
/// [`ModelError::NonFinite`] if the state becomes non-finite or never reaches the ground.
pub fn noise_free_truth() -> Result<Vec<Vector4<f64>>, ModelError> {
    let model = dynamics(Matrix4::zeros())?;
    let mut states = vec![x0()];
    for k in 0..MAX_STEPS {
        let next = model.transition(k, &states[k]);
        if !next.iter().all(|v| v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "ballistic truth",
                step: k + 1,
            });
        }
        if next[2] < 0.0 {
            return Ok(states);
        }
        states.push(next);
    }
    Err(ModelError::NonFinite {
        what: "ballistic truth (no ground impact)",
        step: MAX_STEPS,
    })
}

/// The J1/J2 step metrics of one filter update, from its step record:
/// `A = H F P+ F^T H^T`, `B = H Q H^T`, `R`, and `C = H P+_k H^T` ([`StepRecord::compute_a`],
/// [`StepRecord::compute_b`], [`StepRecord::compute_c`]).
///
/// # Errors
/// [`MetricsError`] if `S` is not positive definite or `A + B` is singular.
pub fn j_of<N: Dim, M: Dim>(rec: &StepRecord<N, M>) -> Result<JStep, MetricsError>
where
    DefaultAllocator: Alloc<N, M>,
{
    j_step(
        &rec.compute_a(),
        &rec.compute_b(),
        rec.r(),
        &rec.compute_c(),
    )
}

/// One point of a `Q = 10^p Q_nom` sweep, serialised in `results.json`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SweepRow {
    /// The exponent `p`.
    pub p: f64,
    /// `nq` in the paper's definition.
    pub nq: f64,
    /// Horizon J1.
    pub j1: f64,
    /// Horizon J2.
    pub j2: f64,
    /// Updates at which `A_k + B_k` was not positive definite (an indefinite `P0`).
    pub indefinite_updates: usize,
    /// Largest single-step `J2k` (above `m` only with an indefinite covariance).
    pub max_j2k: f64,
}

/// A crossover of J1 and J2, serialised in `results.json`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CrossoverRow {
    /// `nq` at the crossover.
    pub nq: f64,
    /// `J1 = J2` at the crossover.
    pub j: f64,
    /// `p` at the crossover (`Q_comp = 10^p Q_nom`).
    pub p: f64,
}

/// The crossover of a sweep, if J1 - J2 changes sign.
///
/// # Errors
/// [`MetricsError`] for a non-finite sweep value.
pub fn crossover_of(rows: &[SweepRow]) -> Result<Option<CrossoverRow>, MetricsError> {
    let points: Vec<kalibra_metrics::SweepPoint> = rows
        .iter()
        .map(|r| kalibra_metrics::SweepPoint {
            p: r.p,
            nq: r.nq,
            j1: r.j1,
            j2: r.j2,
        })
        .collect();
    Ok(kalibra_metrics::crossover(&points)?.map(|c| CrossoverRow {
        nq: c.nq,
        j: c.j,
        p: c.p,
    }))
}

/// `Q = 10^p Q_nom`.
pub fn scaled(q_nom: &Matrix4<f64>, p: f64) -> Matrix4<f64> {
    q_nom * 10f64.powf(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_noise_free_truth_lands_after_59_steps() {
        let truth = noise_free_truth().unwrap();
        assert_eq!(truth.len(), 60, "x_0 .. x_59");
        assert!(truth[59][2] > 0.0);
        let next = dynamics(Matrix4::zeros())
            .unwrap()
            .transition(59, &truth[59]);
        assert!(next[2] < 0.0);
    }
}
