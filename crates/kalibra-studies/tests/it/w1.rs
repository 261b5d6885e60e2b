//! The W1 consistency study at reduced size, as `cargo xtask reproduce` runs it at full size.

use kalibra_studies::study::Study;
use kalibra_studies::w1;

#[test]
fn w1_quick_study_is_consistent() {
    let report = w1::run(&w1::Config::quick()).unwrap();
    assert_eq!(report.anees.len(), 200);
    // Per step, a consistent filter's ANEES is inside its 95% band with probability 0.95;
    // steps are correlated in time, so the fraction over 200 steps varies more than a binomial
    // (sd 1.5%) would. 85% is far below what a consistent filter shows (the full study gives
    // about 95%) and far above what a mistuned one does (tests/consistency.rs).
    assert!(
        report.anees_inside >= 0.85,
        "ANEES inside its band at only {:.1}% of steps",
        100.0 * report.anees_inside
    );
    assert!(
        report.anis_inside >= 0.85,
        "NIS inside its band at only {:.1}% of steps",
        100.0 * report.anis_inside
    );
    // Time averages of 200 x 200 NEES values: within 5% of 1.
    assert!(
        (report.anees_time_average - 1.0).abs() < 0.05,
        "{}",
        report.anees_time_average
    );
    assert!(
        (report.anis_time_average - 1.0).abs() < 0.05,
        "{}",
        report.anis_time_average
    );
    // RMSE settles: the steady-state position RMSE is below the measurement noise (10 per axis).
    let late = report.rmse_position[150..].iter().sum::<f64>() / 50.0;
    assert!(late < 10.0 * 2f64.sqrt(), "{late}");
    // The report's template renders from this report: the template is strict, so a field it
    // names that the report lacks is an error.
    w1::W1.markdown(&w1::Config::quick(), &report).unwrap();
}

/// The batched W1 (`run`, through `run_batched`) against the scalar reference (`run_scalar`) on
/// every instruction set this CPU has, forced in turn: every per-step series agrees to 1e-12
/// relative, and the batched path is bit-identical for 1 and 3 threads on each.
#[test]
fn w1_batched_agrees_with_scalar_on_every_instruction_set() {
    use kalibra_filters::batch::Isa;
    let config = w1::Config {
        runs: 203,
        steps: 120,
        threads: 2,
        ..w1::Config::quick()
    };
    let scalar = w1::run_scalar(&config).unwrap();
    for isa in Isa::available() {
        let batched = w1::run_batched(&config, isa).unwrap();
        let series = [
            (&batched.anees, &scalar.anees),
            (&batched.anis, &scalar.anis),
            (&batched.rmse_position, &scalar.rmse_position),
            (&batched.rmse_velocity, &scalar.rmse_velocity),
        ];
        for (b, s) in series {
            assert_eq!(b.len(), s.len());
            for (k, (x, y)) in b.iter().zip(s.iter()).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
                    "{isa}: step {k}: {x} against {y}"
                );
            }
        }
        // `run` with the instruction set forced is the batched path.
        let mut forced = w1::run(&w1::Config {
            simd: Some(isa),
            ..config
        })
        .unwrap();
        // The report records the configuration, instruction set included.
        forced.config.simd = None;
        assert_eq!(forced, batched);
        let one = w1::run_batched(
            &w1::Config {
                threads: 1,
                ..config
            },
            isa,
        )
        .unwrap();
        let three = w1::run_batched(
            &w1::Config {
                threads: 3,
                ..config
            },
            isa,
        )
        .unwrap();
        assert_eq!(one.anees, three.anees, "{isa}");
        assert_eq!(one.anis, three.anis, "{isa}");
        assert_eq!(one.rmse_position, three.rmse_position, "{isa}");
        assert_eq!(one.rmse_velocity, three.rmse_velocity, "{isa}");
    }
}

/// AVX2 and AVX-512 both fuse multiply-adds and group the runs the same way, so the batched
/// path's results agree to the bit (the scalar fallback rounds each product and sum apart:
/// shards record which arithmetic they used, `w1::run_shard`).
#[test]
fn w1_batched_is_bit_identical_on_avx2_and_avx512() {
    use kalibra_filters::batch::Isa;
    let config = w1::Config {
        runs: 40,
        steps: 60,
        ..w1::Config::quick()
    };
    let bits = |isa| serde_json::to_string(&w1::run_batched(&config, isa).unwrap()).unwrap();
    let available = Isa::available();
    if available.contains(&Isa::Avx512) && available.contains(&Isa::Avx2) {
        assert_eq!(bits(Isa::Avx512), bits(Isa::Avx2));
    }
}

/// Shards of the batched W1 merge into `run`'s report to the bit, and shards of different
/// instruction sets refuse to merge.
#[test]
fn w1_shards_merge_into_the_batched_report() {
    use kalibra_filters::batch::Isa;
    use kalibra_sim::Shard;
    let config = w1::Config {
        runs: 70,
        steps: 30,
        ..w1::Config::quick()
    };
    let whole = serde_json::to_string(&w1::run(&config).unwrap()).unwrap();
    let parts: Vec<_> = (0..3)
        .map(|i| w1::run_shard(&config, Shard::new(i, 3).unwrap()).unwrap())
        .collect();
    let merged = w1::merge(&config, parts.clone()).unwrap();
    assert_eq!(serde_json::to_string(&merged).unwrap(), whole);

    let scalar = w1::Config {
        simd: Some(Isa::Scalar),
        ..config
    };
    let mut mixed = parts;
    mixed[1] = w1::run_shard(&scalar, Shard::new(1, 3).unwrap()).unwrap();
    if Isa::detect() != Isa::Scalar {
        let err = w1::merge(&config, mixed).unwrap_err().to_string();
        assert!(err.contains("another study"), "{err}");
    }
}
