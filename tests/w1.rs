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
