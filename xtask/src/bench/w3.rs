//! W3: paper 003's re-entry EKF with the J1/J2 terms at every step, swept over 41
//! values of `Q = 10^p Q_nom` (`p = -10, -9.5, ..., 10`), [`RUNS`] Monte Carlo runs of 59
//! steps at each, three ways in one process:
//!
//! * the scalar library: [`Ekf`] and `reentry::j_of` on its step records, as paper 003's
//!   study computes them;
//! * a hand-written loop: the same EKF (Joseph update, symmetrised covariances) and the same
//!   J terms written out in fixed-size nalgebra, calling the models only for the physics
//!   (`f`, `F`, `h`, `H`), as a user without kalibra would write it;
//! * the batched EKF ([`EkfBatch::predict_update_j`]), eight runs per group, the ballistic
//!   dynamics and the radar evaluated for the lanes together (their lane-wise
//!   implementations: the density's exponential and the elevation's arctangent in SIMD), and
//!   again with both evaluated lane by lane ([`PerLane`]).
//!
//! The truths (the study's, seed 2003) are simulated once outside the timed region. The paths
//! must agree on every `p`'s horizon J1 and J2 to [`TOLERANCE`]; the bench fails otherwise.

use anyhow::{Context, Result, bail};
use kalibra_filters::batch::{BATCH, EkfBatch, Isa, LaneDynamics, LaneMeasurement, PerLane};
use kalibra_filters::{Ekf, Filter};
use kalibra_metrics::j_step;
use kalibra_models::lanes::set_lane_vector;
use kalibra_models::{Ballistic, Dynamics, Measurement, RadarRates, Simulator, wrap_angle};
use kalibra_sim::MonteCarlo;
use kalibra_studies::paper003::{p0_table, q_nom, qt, r, x0_table};
use kalibra_studies::reentry;
use nalgebra::{Matrix3, Matrix4, SMatrix, Vector3, Vector4};

use super::{Args, Best, Figures};

/// Monte Carlo runs per value of `p`.
const RUNS: usize = 100;
/// Seed of the truths (paper 003's study seed).
const SEED: u64 = 2003;
/// Largest relative difference of a horizon J accepted as the same arithmetic.
const TOLERANCE: f64 = 1e-9;

/// One Monte Carlo truth: states `x_1 ..` and measurements `y_1 ..` (59 each).
struct Truth {
    states: Vec<Vector4<f64>>,
    measurements: Vec<Vector3<f64>>,
}

/// Horizon sums of J1k and J2k per value of `p`, and the updates behind them.
type Sums = Vec<(f64, f64)>;

/// Runs W3, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let radar = RadarRates::new(r())?;
    let truth_model = reentry::dynamics(qt())?;
    let horizon = reentry::noise_free_truth()?.len() - 1;
    let grid = kalibra_tune::grid(-10.0..=10.0, 0.5)?;
    let models = grid
        .iter()
        .map(|&p| reentry::dynamics(reentry::scaled(&q_nom(), p)))
        .collect::<Result<Vec<_>, _>>()?;
    let mc = MonteCarlo::new(RUNS, SEED);
    let truths = (0..RUNS)
        .map(|run| {
            let mut rng = mc.rng(run);
            let mut sim = Simulator::new(&truth_model, &radar, reentry::x0(), 0)?;
            let mut t = Truth {
                states: Vec::with_capacity(horizon),
                measurements: Vec::with_capacity(horizon),
            };
            for k in 0..=horizon {
                let (x, z) = sim.step(&mut rng)?;
                if k > 0 {
                    t.states.push(x);
                    t.measurements.push(z);
                }
            }
            Ok(t)
        })
        .collect::<Result<Vec<_>, kalibra_models::ModelError>>()?;
    let isa = super::isa()?;
    let steps = (grid.len() * RUNS * horizon) as f64;
    let title = format!(
        "paper 003's re-entry EKF with J1/J2 at every step, {} values of Q = 10^p Q_nom x {RUNS} runs x {horizon} steps (best of {})",
        grid.len(),
        args.repeats
    );
    println!("W3: {title}");
    let mut figures = Figures::new("w3", title);

    // Warm up each path once, then interleave them so that machine noise hits all alike.
    let mut best = [Best::default(); 4];
    let mut sums: [Sums; 4] = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
    for repeat in 0..=args.repeats {
        for (i, best) in best.iter_mut().enumerate() {
            let (t, s) = super::timed(|| match i {
                0 => library(&models, &radar, &truths),
                1 => hand(&models, &radar, &truths),
                2 => batched(&models, &radar, &truths, isa, true),
                _ => batched(&models, &radar, &truths, isa, false),
            });
            if repeat > 0 {
                best.add(t);
            }
            sums[i] = s?;
        }
    }
    let [lib, hand_t, batch_t, per_lane_t] = best.map(Best::seconds);
    println!(
        "  library (scalar Ekf), 1 thread: {:>12.0} steps/s ({lib:.4} s)",
        steps / lib
    );
    println!(
        "  hand-written nalgebra, 1 thread: {:>12.0} steps/s ({hand_t:.4} s)",
        steps / hand_t
    );
    println!(
        "  batched ({isa}, {} lanes per vector, lane-wise models), 1 thread: {:>12.0} steps/s ({batch_t:.4} s)",
        isa.lanes(),
        steps / batch_t
    );
    println!(
        "  batched ({isa}, models per lane), 1 thread: {:>12.0} steps/s ({per_lane_t:.4} s)",
        steps / per_lane_t
    );
    println!(
        "  ratios to the hand-written loop: library {:.2}x, batched {:.2}x (goal 3x), batched with the models per lane {:.2}x",
        hand_t / lib,
        hand_t / batch_t,
        hand_t / per_lane_t
    );
    figures.push("library (scalar Ekf), 1 thread", steps / lib, "steps/s");
    figures.push("hand-written loop, 1 thread", steps / hand_t, "steps/s");
    figures.push(
        format!("batched, {isa}, lane-wise models, 1 thread"),
        steps / batch_t,
        "steps/s",
    );
    figures.push(
        format!("batched, {isa}, models per lane, 1 thread"),
        steps / per_lane_t,
        "steps/s",
    );
    figures.push("library / hand-written", hand_t / lib, "x");
    figures.push(
        format!("batched, {isa}, lane-wise models / hand-written"),
        hand_t / batch_t,
        "x",
    );
    figures.push(
        format!("batched, {isa}, models per lane / hand-written"),
        hand_t / per_lane_t,
        "x",
    );
    let mut worst = 0.0f64;
    for other in &sums[1..] {
        for ((a1, a2), (b1, b2)) in sums[0].iter().zip(other) {
            worst = worst
                .max((a1 - b1).abs() / a1.abs().max(b1.abs()))
                .max((a2 - b2).abs() / a2.abs().max(b2.abs()));
        }
    }
    println!(
        "  same arithmetic check: max relative difference of the horizon J1, J2 over the sweep = {worst:.2e}"
    );
    if worst.is_nan() || worst > TOLERANCE {
        bail!("W3: the three paths disagree on J1/J2 ({worst:.2e} > {TOLERANCE:.0e})");
    }
    Ok(figures)
}

/// The scalar library, as paper 003's study runs it.
fn library(models: &[Ballistic], radar: &RadarRates, truths: &[Truth]) -> Result<Sums> {
    let mut out = Vec::with_capacity(models.len());
    for model in models {
        let (mut j1, mut j2) = (0.0, 0.0);
        for t in truths {
            let mut ekf = Ekf::new(model, radar, x0_table(), p0_table())?;
            for z in &t.measurements {
                ekf.predict()?;
                let j = reentry::j_of(ekf.update(z)?)?;
                j1 += j.j1;
                j2 += j.j2;
            }
        }
        out.push((j1, j2));
    }
    Ok(out)
}

/// The batched EKF: [`BATCH`] runs per group, the models evaluated for the lanes together
/// (`lane_wise`: their lane-wise implementations) or lane by lane ([`PerLane`]); a lane whose
/// `A + B` was not positive definite (never here) would take the scalar `j_step`.
fn batched(
    models: &[Ballistic],
    radar: &RadarRates,
    truths: &[Truth],
    isa: Isa,
    lane_wise: bool,
) -> Result<Sums> {
    if lane_wise {
        batched_on(models, |m| m, radar, truths, isa)
    } else {
        batched_on(models, PerLane, PerLane(radar), truths, isa)
    }
}

fn batched_on<'a, D: LaneDynamics<4>, H: LaneMeasurement<4, 3> + Copy>(
    models: &'a [Ballistic],
    lanes: impl Fn(&'a Ballistic) -> D,
    radar: H,
    truths: &[Truth],
    isa: Isa,
) -> Result<Sums> {
    let mut out = Vec::with_capacity(models.len());
    for model in models {
        let (mut j1, mut j2) = (0.0, 0.0);
        for group in truths.chunks(BATCH) {
            let mut ekf = EkfBatch::new(isa, lanes(model), radar, x0_table(), p0_table())?;
            let mut z = [[0.0; BATCH]; 3];
            let mut x = [[0.0; BATCH]; 4];
            for k in 0..group[0].measurements.len() {
                for (l, t) in group.iter().enumerate() {
                    set_lane_vector(&mut z, l, &t.measurements[k]);
                    set_lane_vector(&mut x, l, &t.states[k]);
                }
                let (step, terms) = ekf.predict_update_j(&z, &x);
                for l in 0..group.len() {
                    step.nis(l)?;
                    let (a, b) = (terms.j1(l), terms.j2(l));
                    if a.is_finite() && b.is_finite() && terms.tr_n(l).is_finite() {
                        j1 += a;
                        j2 += b;
                    } else {
                        let j = j_step(&terms.a(l), &terms.b(l), &terms.r(l), &terms.c(l))?;
                        j1 += j.j1;
                        j2 += j.j2;
                    }
                }
            }
        }
        out.push((j1, j2));
    }
    Ok(out)
}

#[inline(always)]
fn sym<const D: usize>(m: &mut SMatrix<f64, D, D>) {
    *m = (*m + m.transpose()) * 0.5;
}

/// `tr(M^-1 X)` through the Cholesky factor of `M`.
#[inline(always)]
fn trace_solve(m: Matrix3<f64>, x: &Matrix3<f64>) -> Result<f64> {
    Ok(m.cholesky()
        .context("not positive definite")?
        .solve(x)
        .trace())
}

/// The EKF and the J terms written out in fixed-size nalgebra.
fn hand(models: &[Ballistic], radar: &RadarRates, truths: &[Truth]) -> Result<Sums> {
    let rm = r();
    let mut out = Vec::with_capacity(models.len());
    for model in models {
        let q = model.noise_cov(0);
        let (mut j1, mut j2) = (0.0, 0.0);
        for t in truths {
            let (mut x, mut p) = (x0_table(), p0_table());
            for (k, z) in t.measurements.iter().enumerate() {
                // Prediction: f(x), F at x; P- = F P F^T + Q.
                let f = model.jacobian(k, &x);
                x = model.transition(k, &x);
                let fpf: Matrix4<f64> = f * p * f.transpose();
                p = fpf + q;
                sym(&mut p);
                // Update: h, H at x-; S = H P- H^T + R; K = P- H^T S^-1; Joseph.
                let h = radar.jacobian(k + 1, &x);
                let mut nu = z - radar.measure(k + 1, &x);
                nu[RadarRates::ELEVATION] = wrap_angle(nu[RadarRates::ELEVATION]);
                let pht = p * h.transpose();
                let mut s = h * pht + rm;
                sym(&mut s);
                let gain = s
                    .cholesky()
                    .context("S not positive definite")?
                    .solve(&pht.transpose())
                    .transpose();
                x += gain * nu;
                let ikh = Matrix4::identity() - gain * h;
                let mut post = ikh * p * ikh.transpose() + gain * rm * gain.transpose();
                sym(&mut post);
                // J terms: A = H F P F^T H^T, B = H Q H^T, C = H P+ H^T.
                let mut a = h * fpf * h.transpose();
                sym(&mut a);
                let mut b = h * q * h.transpose();
                sym(&mut b);
                let mut c = h * post * h.transpose();
                sym(&mut c);
                let mut ab = a + b;
                sym(&mut ab);
                let mut s2 = ab + rm;
                sym(&mut s2);
                j1 += trace_solve(s2, &rm)?;
                j2 += trace_solve(ab, &b)?;
                // tr(N_k) is part of the study's step terms: computed here too, so that the
                // hand loop does the same work.
                std::hint::black_box(trace_solve(ab, &(a - c))?);
                p = post;
            }
        }
        out.push((j1, j2));
    }
    Ok(out)
}
