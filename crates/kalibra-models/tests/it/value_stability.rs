//! Value stability: the seeded output of [`simulate`] is pinned to literal values.
//!
//! Every published reproduction number of kalibra (the six `results.json` of `cargo xtask
//! reproduce`) flows from truths drawn this way: the seed fixes the generator, the generator
//! fixes `v_k` then `w_k` at every step, and the models turn the draws into states and
//! measurements. If this test fails, a change in the draws (the order of `v_k` and `w_k`, the
//! normal sampler, the noise factor, a dependency's value stability) has changed every
//! published reproduction number: either undo it, or re-run the reproduction, record the new
//! numbers, say why in the changelog, and only then update the literals here. The literals were
//! printed once with `{:?}` (shortest round-trip form, so they are the exact `f64`s) and are
//! compared bit for bit, as rand_distr's `value_stability.rs` pins its distributions.

use kalibra_linalg::nalgebra::Matrix1x2;
use kalibra_linalg::{Matrix1, Matrix2, U1, U2, Vector2};
use kalibra_models::{LinearGaussian, LinearObservation, simulate};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

/// Exact equality of bit patterns, with the values in the message.
fn assert_bits(got: &[f64], want: &[f64], what: &str) {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(got), bits(want), "{what}: got {got:?}, want {want:?}");
}

#[test]
fn simulate_draws_are_pinned() {
    // A constant-velocity target with rank-one process noise G G^T (G = [1/2, 1]) and a noisy
    // position: the semi-definite factor and both noise draws enter every step.
    let dynamics = LinearGaussian::new(
        Matrix2::new(1.0, 1.0, 0.0, 1.0),
        Matrix2::new(0.25, 0.5, 0.5, 1.0),
    )
    .unwrap();
    let sensor =
        LinearObservation::<U2, U1>::new(Matrix1x2::new(1.0, 0.0), Matrix1::new(4.0)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let truth = simulate(&dynamics, &sensor, Vector2::new(0.0, 1.0), 4, &mut rng).unwrap();
    let states: Vec<f64> = truth.states.iter().flat_map(|x| [x[0], x[1]]).collect();
    let measurements: Vec<f64> = truth.measurements.iter().map(|z| z[0]).collect();
    assert_bits(&states, &STATES, "states");
    assert_bits(&measurements, &MEASUREMENTS, "measurements");
}

/// `[x_k, xdot_k]` for `k = 0..4` (`x_0` given, then three steps of drawn noise).
const STATES: [f64; 8] = [
    0.0,
    1.0,
    1.6921154678097263,
    2.3842309356194527,
    4.262299073205311,
    2.7561362751717158,
    6.590224932905303,
    1.8997154442282689,
];
/// `z_k` for `k = 0..4`.
const MEASUREMENTS: [f64; 4] = [
    -1.3889887231267104,
    4.716839409999393,
    1.1942560301070935,
    10.724515913039756,
];
