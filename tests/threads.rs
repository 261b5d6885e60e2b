//! A Monte Carlo study gives bit-identical results whatever the thread count.

use kalibra_studies::w1;

#[test]
fn w1_is_bit_identical_for_1_2_and_8_threads() {
    let base = w1::Config {
        runs: 150,
        steps: 60,
        ..w1::Config::quick()
    };
    let run = |threads| {
        let mut r = w1::run(&w1::Config { threads, ..base }).unwrap();
        // The report records the thread count; everything else must match bit for bit.
        r.config.threads = 0;
        r
    };
    let one = run(1);
    let two = run(2);
    let eight = run(8);
    assert_eq!(one, two);
    assert_eq!(one, eight);
    // And the study is not trivially constant: another seed gives other numbers.
    let other = w1::run(&w1::Config {
        seed: base.seed + 1,
        threads: 2,
        ..base
    })
    .unwrap();
    assert_ne!(one.anees, other.anees);
}
