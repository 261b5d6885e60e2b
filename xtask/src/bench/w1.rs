//! W1: a Kalman filter on a 2-D constant-velocity target (`[x, y, vx, vy]`, `T = 1`,
//! `R = 100 I2`), `--runs` x `--steps`, per-step NEES and NIS averaged over the runs, timed
//! four ways in one process: the scalar library (`w1::run_scalar`), a hand-written nalgebra
//! `SMatrix` loop on the same draws, and the batched study (`w1::run_batched`) on the detected
//! instruction set and with AVX2 and the scalar fallback forced, each with and without the
//! covariance schedule the runs share. Then the batched time's parts (the truth simulation and
//! its draws alone) and the thread checks: every path must give the results it gives on one
//! thread, to the bit, and the batched reports with and without the schedule must be equal.

use anyhow::{Result, bail};
use kalibra_filters::batch::{BATCH, Isa};
use kalibra_sim::{ChaCha8Lanes, LinearTruthBatch, MonteCarlo, RunFailure};
use kalibra_studies::w1;
use nalgebra::{Matrix2, Matrix4, SMatrix, Vector2, Vector4};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use super::{Args, Best, Figures, best_of};

/// Runs W1, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let total = (args.runs * args.steps) as f64;
    let title = format!(
        "KF on [x, y, vx, vy], T = 1, R = 100 I2, {} runs x {} steps, per-step NEES and NIS averaged over runs (best of {})",
        args.runs, args.steps, args.repeats
    );
    println!("W1: {title}");
    let mut figures = Figures::new("w1", title);
    let config = |threads| w1::Config {
        runs: args.runs,
        steps: args.steps,
        seed: 2012,
        threads,
        confidence: 0.95,
        simd: None,
    };
    // The batched path on the instruction set detected (or KALIBRA_SIMD's), then AVX2 and the
    // scalar fallback forced, where the CPU has them.
    let detected = super::isa()?;
    let mut isas = vec![detected];
    isas.extend(
        [Isa::Avx2, Isa::Scalar]
            .into_iter()
            .filter(|i| *i != detected && i.is_available()),
    );
    // Interleave them all so that machine noise hits each alike.
    let mut lib_best = Best::default();
    let mut hand_best = Best::default();
    let mut batched_best = vec![Best::default(); isas.len()];
    let mut batched_reports = vec![None; isas.len()];
    // The same batches computing every lane's covariances themselves (the dense kernel),
    // without the schedule the runs share.
    let mut per_lane_best = vec![Best::default(); isas.len()];
    let mut per_lane_reports = vec![None; isas.len()];
    let mut lib_report = None;
    let mut hand_out = None;
    for _ in 0..args.repeats {
        lib_report = Some(lib_best.time(|| w1::run_scalar(&config(1)))?);
        hand_out = Some(hand_best.time(|| hand_w1(args.runs, args.steps, 2012)));
        for (i, isa) in isas.iter().enumerate() {
            batched_reports[i] = Some(batched_best[i].time(|| w1::run_batched(&config(1), *isa))?);
            per_lane_reports[i] =
                Some(per_lane_best[i].time(|| w1::run_batched_per_lane(&config(1), *isa))?);
        }
    }
    let (lib_best, hand_best) = (lib_best.seconds(), hand_best.seconds());
    let (lib_report, hand_out) = (
        lib_report.expect("repeats > 0"),
        hand_out.expect("repeats > 0"),
    );
    let (t_par, mut par_report) =
        best_of(args.repeats, || Ok(w1::run_scalar(&config(args.threads))?))?;
    // The reports differ only in the thread count they record.
    par_report.config.threads = lib_report.config.threads;

    let lib_rate = total / lib_best;
    let hand_rate = total / hand_best;
    let par_rate = total / t_par;
    println!(
        "  library,      1 thread : {:>12.0} steps/s ({lib_best:.3} s)",
        lib_rate
    );
    println!(
        "  hand-written, 1 thread : {:>12.0} steps/s ({hand_best:.3} s)",
        hand_rate
    );
    println!(
        "  ratio library / hand-written (1 thread): {:.3}",
        lib_rate / hand_rate
    );
    figures.push("library, 1 thread", lib_rate, "steps/s");
    figures.push("hand-written nalgebra loop, 1 thread", hand_rate, "steps/s");
    figures.push("library / hand-written", lib_rate / hand_rate, "x");
    println!(
        "  library, {} threads   : {:>12.0} steps/s ({t_par:.3} s), speed-up {:.2}x over 1 thread",
        args.threads,
        par_rate,
        par_rate / lib_rate
    );
    figures.push(
        format!("library, {} threads", args.threads),
        par_rate,
        "steps/s",
    );
    // Largest relative difference over the per-step ANEES, ANIS and RMSE series.
    let rel_diff = |a: &w1::Report, b: &w1::Report| {
        [
            (&a.anees, &b.anees),
            (&a.anis, &b.anis),
            (&a.rmse_position, &b.rmse_position),
            (&a.rmse_velocity, &b.rmse_velocity),
        ]
        .into_iter()
        .flat_map(|(x, y)| x.iter().zip(y.iter()))
        .map(|(x, y)| (x - y).abs() / x.abs().max(y.abs()))
        .fold(0.0f64, f64::max)
    };
    for (i, isa) in isas.iter().enumerate() {
        let rate = total / batched_best[i].seconds();
        let report = batched_reports[i].as_ref().expect("repeats > 0");
        println!(
            "  batched ({:<6} {} lanes/vector), 1 thread: {:>12.0} steps/s ({:.3} s), {:.2}x hand-written, {:.2}x library; max rel. diff. to library {:.1e}{}",
            format!("{isa},"),
            isa.lanes(),
            rate,
            batched_best[i].seconds(),
            rate / hand_rate,
            rate / lib_rate,
            rel_diff(report, &lib_report),
            if i == 0 { " (detected)" } else { " (forced)" },
        );
        figures.push(format!("batched, {isa}, 1 thread"), rate, "steps/s");
        figures.push(
            format!("batched, {isa} / hand-written"),
            rate / hand_rate,
            "x",
        );
        figures.push(format!("batched, {isa} / library"), rate / lib_rate, "x");
    }
    for (i, isa) in isas.iter().enumerate() {
        let rate = total / per_lane_best[i].seconds();
        let same = per_lane_reports[i] == batched_reports[i];
        println!(
            "  batched ({:<6} per-lane covariances, no schedule), 1 thread: {:>12.0} steps/s ({:.3} s), {:.2}x hand-written, {:.2}x library; {}",
            format!("{isa},"),
            rate,
            per_lane_best[i].seconds(),
            rate / hand_rate,
            rate / lib_rate,
            if same {
                "bit-identical to the scheduled run"
            } else {
                "DIFFERENT from the scheduled run"
            },
        );
        if !same {
            bail!("the covariance schedule changes W1's results on {isa}");
        }
        figures.push(
            format!("batched without the schedule, {isa} / hand-written"),
            rate / hand_rate,
            "x",
        );
    }
    // Where the batched time goes: the truth alone (draws and truth arithmetic, accumulating
    // nothing), and the draws alone.
    let (t_truth, _) = best_of(args.repeats, || {
        w1_truth_only(args.runs, args.steps, true, detected)
    })?;
    let (t_draws, _) = best_of(args.repeats, || {
        w1_truth_only(args.runs, args.steps, false, detected)
    })?;
    // Lane-wise draws or each run's own generator, as `ChaCha8Lanes::for_batch` chooses.
    let draws = if ChaCha8Lanes::for_batch(detected, &[])?.isa() == Isa::Scalar {
        "per-run"
    } else {
        "lane-wise"
    };
    let batched0 = batched_best[0].seconds();
    println!(
        "  of the batched ({detected}) time: truth simulation {:.3} s ({:.0}%), of which the {draws} ChaCha8 normal draws {:.3} s ({:.0}%)",
        t_truth,
        100.0 * t_truth / batched0,
        t_draws,
        100.0 * t_draws / batched0,
    );
    figures.push(format!("batched, {detected}: study"), batched0, "s");
    figures.push(
        format!("batched, {detected}: its truth simulation"),
        t_truth,
        "s",
    );
    figures.push(
        format!("batched, {detected}: its {draws} normal draws"),
        t_draws,
        "s",
    );
    let (t_bpar, mut bpar_report) = best_of(args.repeats, || {
        Ok(w1::run_batched(&config(args.threads), detected)?)
    })?;
    bpar_report.config.threads = 1;
    println!(
        "  batched ({detected}), {} threads: {:>12.0} steps/s ({t_bpar:.3} s), {}",
        args.threads,
        total / t_bpar,
        if Some(&bpar_report) == batched_reports[0].as_ref() {
            "bit-identical to 1 thread"
        } else {
            "DIFFERENT from 1 thread"
        }
    );
    if Some(&bpar_report) != batched_reports[0].as_ref() {
        bail!("batched results depend on the thread count");
    }
    figures.push(
        format!("batched, {detected}, {} threads", args.threads),
        total / t_bpar,
        "steps/s",
    );
    let max_diff = lib_report
        .anees
        .iter()
        .zip(&hand_out.0)
        .chain(lib_report.anis.iter().zip(&hand_out.1))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    println!(
        "  same arithmetic check: max |library - hand-written| over per-step ANEES and NIS = {max_diff:.2e}"
    );
    println!(
        "  thread check: {} threads give {} results as 1 thread",
        args.threads,
        if par_report == lib_report {
            "bit-identical"
        } else {
            "DIFFERENT"
        }
    );
    if par_report != lib_report {
        bail!("results depend on the thread count");
    }
    Ok(figures)
}

/// W1's batched truth alone (`simulate`), or only its draws (the initial states' from the
/// runs' generators, the steps' through `ChaCha8Lanes::for_batch` as the batched study on
/// `isa` draws them), on one thread: the part of the batched time the filter kernel
/// cannot touch.
fn w1_truth_only(runs: usize, steps: usize, simulate: bool, isa: Isa) -> Result<f64> {
    let (f, h) = w1::models()?;
    let (m0, p0) = w1::prior();
    let l0 = *kalibra_linalg::PsdMatrix::new(p0)?.factor();
    let mc = MonteCarlo::new(runs, 2012).threads(1);
    let sum = mc.accumulate_batched(
        || kalibra_metrics::StepMean::new(1),
        |group, rngs, acc| {
            let fail = |message: String| RunFailure {
                run: group.start,
                source: std::io::Error::other(message),
            };
            let mut last = 0.0;
            if simulate {
                let mut truth = LinearTruthBatch::new(&f, &h, group.start, rngs, |rng| {
                    m0 + l0 * normals::<4>(rng)
                })
                .map_err(|e| fail(e.source.to_string()))?;
                let mut draws =
                    ChaCha8Lanes::for_batch(isa, rngs).map_err(|e| fail(e.to_string()))?;
                for _ in 0..steps {
                    truth
                        .step(&mut draws)
                        .map_err(|e| fail(e.source.to_string()))?;
                }
                last = truth.state()[0][0];
            } else {
                for rng in rngs.iter_mut() {
                    last += normals::<4>(rng)[0];
                }
                let mut draws =
                    ChaCha8Lanes::for_batch(isa, rngs).map_err(|e| fail(e.to_string()))?;
                let (mut nv, mut nw) = ([[0.0; BATCH]; 2], [[0.0; BATCH]; 4]);
                for _ in 0..steps {
                    draws.standard_normals(&mut nv);
                    draws.standard_normals(&mut nw);
                    last += nv[0][0] + nw[0][0];
                }
            }
            acc.push(0, last).map_err(|e| fail(e.to_string()))
        },
    );
    Ok(std::hint::black_box(sum)
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .mean(0)
        .unwrap_or(0.0))
}

fn normals<const D: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, D, 1> {
    SMatrix::<f64, D, 1>::from_fn(|_, _| StandardNormal.sample(rng))
}

fn sym4(m: &mut Matrix4<f64>) {
    *m = (*m + m.transpose()) * 0.5;
}

/// W1 written directly in nalgebra `SMatrix` code, as a user without kalibra would: the same
/// draws in the same order (initial state, then per step measurement noise and process noise),
/// the same Joseph update and symmetrisation, NEES and NIS through Cholesky, per-step sums.
/// Returns per-step ANEES and NIS / 2.
fn hand_w1(runs: usize, steps: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let f = Matrix4::new(
        1., 0., 1., 0., 0., 1., 0., 1., 0., 0., 1., 0., 0., 0., 0., 1.,
    );
    let g = SMatrix::<f64, 4, 2>::new(0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 1.0);
    let q = g * g.transpose();
    let h = SMatrix::<f64, 2, 4>::new(1., 0., 0., 0., 0., 1., 0., 0.);
    let r = Matrix2::identity() * 100.0;
    let (m0, p0) = w1::prior();
    // Factors as the library computes them (semi-definite Cholesky of the rank-2 Q).
    let lq = *kalibra_linalg::PsdMatrix::new(q).expect("valid Q").factor();
    let lr = *kalibra_linalg::PsdMatrix::new(r).expect("valid R").factor();
    let lp0 = *kalibra_linalg::PsdMatrix::new(p0)
        .expect("valid P0")
        .factor();
    let mut nees_sum = vec![0.0; steps];
    let mut nis_sum = vec![0.0; steps];
    let mut err_sum = vec![0.0; steps * 4];
    for run in 0..runs {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(run as u64);
        let mut x: Vector4<f64> = m0 + lp0 * normals::<4>(&mut rng);
        let (mut xh, mut p) = (m0, p0);
        for k in 0..steps {
            let z: Vector2<f64> = h * x + lr * normals::<2>(&mut rng);
            let x_k = x;
            x = f * x + lq * normals::<4>(&mut rng);
            if k > 0 {
                xh = f * xh;
                p = f * p * f.transpose() + q;
                sym4(&mut p);
            }
            let pht = p * h.transpose();
            let mut s = h * pht + r;
            s = (s + s.transpose()) * 0.5;
            let chol = s.cholesky().expect("S positive definite");
            let gain = chol.solve(&pht.transpose()).transpose();
            let nu = z - h * xh;
            xh += gain * nu;
            let ikh = Matrix4::identity() - gain * h;
            p = ikh * p * ikh.transpose() + gain * r * gain.transpose();
            sym4(&mut p);
            let e = x_k - xh;
            let lp = p.cholesky().expect("P positive definite");
            let w = lp.l().solve_lower_triangular(&e).expect("non-singular");
            nees_sum[k] += w.norm_squared() / 4.0;
            let v = chol.l().solve_lower_triangular(&nu).expect("non-singular");
            nis_sum[k] += v.norm_squared() / 2.0;
            for i in 0..4 {
                err_sum[k * 4 + i] += e[i] * e[i];
            }
        }
    }
    std::hint::black_box(&err_sum);
    let n = runs as f64;
    (
        nees_sum.iter().map(|s| s / n).collect(),
        nis_sum.iter().map(|s| s / n).collect(),
    )
}
