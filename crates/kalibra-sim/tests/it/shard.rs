//! Shards of a Monte Carlo study merge into the one-process result to the bit, and
//! merging refuses partials that are not exactly the shards of one study.

use kalibra_metrics::{Credibility, SquaredErrors, StepMean};
use kalibra_sim::{
    ChaCha8Rng, MonteCarlo, PARTIAL_FORMAT_VERSION, Partial, Shard, ShardError, StudyId, merge,
};
use proptest::prelude::*;
use rand::RngExt;

const STEPS: usize = 5;
const DIM: usize = 2;

type Acc = (StepMean, SquaredErrors, Credibility);

fn make() -> Acc {
    (
        StepMean::new(STEPS),
        SquaredErrors::new(STEPS, DIM),
        Credibility::new(STEPS, DIM),
    )
}

/// A run with values of very different magnitudes, so that the order of additions shows in the
/// last bits (a merge in any other order than the one-process fold would not be bit-identical).
fn one(
    _run: usize,
    rng: &mut ChaCha8Rng,
    acc: &mut Acc,
) -> Result<(), kalibra_metrics::MetricsError> {
    for k in 0..STEPS {
        let scale = 10f64.powi(rng.random_range(-8..8));
        let e = [
            scale * (rng.random::<f64>() - 0.5),
            rng.random::<f64>() - 0.5,
        ];
        let nees = scale * rng.random::<f64>();
        acc.0.push(k, nees)?;
        acc.1.push_slice(k, &e)?;
        acc.2.push_nees(k, &e, nees)?;
    }
    Ok(())
}

fn id(mc: &MonteCarlo) -> StudyId {
    StudyId::new(mc, 0x5eed, "test")
}

/// Shard `i` of `count` run on `threads` threads, written to JSON and read back, as a shard
/// on another machine hands it over.
fn shard_through_json(mc: &MonteCarlo, i: usize, count: usize, threads: usize) -> Partial<Acc> {
    let part = mc
        .threads(threads)
        .accumulate_shard(Shard::new(i, count).unwrap(), &id(mc), make, one)
        .unwrap();
    let text = serde_json::to_string(&part).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn bits(acc: &Acc) -> String {
    serde_json::to_string(acc).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any number of shards, each on any thread count, in any order, through JSON: the merge
    /// is the one-process accumulator, every sum equal to the bit.
    #[test]
    fn merged_shards_equal_the_one_process_study_bit_for_bit(
        runs in 1usize..200,
        count in 1usize..9,
        threads in proptest::collection::vec(1usize..4, 9),
        seed in any::<u64>(),
        rotate in 0usize..9,
    ) {
        let mc = MonteCarlo::new(runs, seed);
        let whole = mc.threads(2).accumulate(make, one).unwrap();
        let mut parts: Vec<Partial<Acc>> = (0..count)
            .map(|i| shard_through_json(&mc, i, count, threads[i]))
            .collect();
        parts.rotate_left(rotate % count);
        let merged = merge(parts).unwrap();
        prop_assert_eq!(bits(&merged), bits(&whole));
        prop_assert_eq!(merged, whole);
    }
}

/// The test above can fail: merging shard totals (instead of laying their blocks end to end)
/// changes the last bits of a study whose blocks hold values of mixed magnitudes.
#[test]
fn merging_totals_instead_of_blocks_would_not_be_bit_identical() {
    use kalibra_metrics::Merge;
    let differs = (0..20u64).any(|seed| {
        let mc = MonteCarlo::new(128, seed);
        let whole = mc.accumulate(make, one).unwrap();
        // Each shard's blocks folded into a shard total first.
        let totals: Vec<Acc> = (0..4)
            .map(|i| {
                let mut blocks = shard_through_json(&mc, i, 4, 1).blocks.into_iter();
                let mut total = blocks.next().unwrap();
                for b in blocks {
                    total.merge(&b);
                }
                total
            })
            .collect();
        // ((b0..b15) + (b16..b31)) + ... instead of (((b0 + b1) + b2) + ...).
        let mut it = totals.into_iter();
        let mut total = it.next().unwrap();
        for t in it {
            total.merge(&t);
        }
        bits(&total) != bits(&whole)
    });
    assert!(
        differs,
        "re-associating the fold never changed a bit: the test proves nothing"
    );
}

fn parts(mc: &MonteCarlo, count: usize) -> Vec<Partial<Acc>> {
    (0..count)
        .map(|i| shard_through_json(mc, i, count, 1))
        .collect()
}

#[test]
fn merging_refuses_duplicates_gaps_and_other_studies() {
    let mc = MonteCarlo::new(100, 7);
    assert_eq!(merge::<Acc>(Vec::new()), Err(ShardError::Empty));

    let mut dup = parts(&mc, 3);
    dup[2] = dup[1].clone();
    assert_eq!(
        merge(dup),
        Err(ShardError::Duplicate { index: 1, count: 3 })
    );

    let mut gap = parts(&mc, 4);
    gap.remove(2);
    gap.remove(0);
    assert_eq!(
        merge(gap),
        Err(ShardError::Missing {
            missing: vec![0, 2],
            count: 4
        })
    );

    let mut other_seed = parts(&mc, 2);
    other_seed[1] = shard_through_json(&MonteCarlo::new(100, 8), 1, 2, 1);
    assert!(matches!(
        merge(other_seed),
        Err(ShardError::OtherStudy { index: 1, .. })
    ));

    let mut other_config = parts(&mc, 2);
    other_config[0].study.config_hash ^= 1;
    assert!(matches!(
        merge(other_config),
        Err(ShardError::OtherStudy { index: 1, .. })
    ));

    let mut other_count = parts(&mc, 2);
    other_count.push(shard_through_json(&mc, 2, 3, 1));
    assert!(matches!(
        merge(other_count),
        Err(ShardError::OtherCount {
            index: 2,
            found: 3,
            expected: 2
        })
    ));

    let mut version = parts(&mc, 2);
    version[1].format = PARTIAL_FORMAT_VERSION + 1;
    assert!(matches!(
        merge(version),
        Err(ShardError::Version { index: 1, .. })
    ));

    let mut blocks = parts(&mc, 2);
    blocks[1].blocks.pop();
    assert!(matches!(
        merge(blocks),
        Err(ShardError::Blocks { index: 1, .. })
    ));

    let mut shape = parts(&mc, 2);
    shape[1].blocks[0].0 = StepMean::new(STEPS + 1);
    assert_eq!(merge(shape), Err(ShardError::Shape { index: 1 }));
}

/// A partial edited by hand or truncated does not deserialise into an accumulator that would
/// panic when merged.
#[test]
fn a_tampered_partial_does_not_deserialise() {
    let mc = MonteCarlo::new(10, 1);
    let text = serde_json::to_string(&shard_through_json(&mc, 0, 1, 1)).unwrap();
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Drop one count of the first block's step mean: sums and counts no longer pair up.
    value["blocks"][0][0]["count"].as_array_mut().unwrap().pop();
    let err = serde_json::from_value::<Partial<Acc>>(value.clone()).unwrap_err();
    assert!(err.to_string().contains("5 sums and 4 counts"), "{err}");
    // An infinite sum cannot be written as JSON at all, and null is not a number.
    value["blocks"][0][0]["count"]
        .as_array_mut()
        .unwrap()
        .push(1.into());
    value["blocks"][0][1]["sum"][0] = serde_json::Value::Null;
    assert!(serde_json::from_value::<Partial<Acc>>(value).is_err());
}

/// A shard reports its lowest failing run whatever the thread count (its blocks are collected
/// in order before the errors are looked at).
#[test]
fn a_shard_reports_its_lowest_failing_run_for_any_thread_count() {
    let mc = MonteCarlo::new(200, 3);
    let id = id(&mc);
    for threads in [1, 2, 4, 8] {
        let err = mc
            .threads(threads)
            .accumulate_shard(
                Shard::new(1, 2).unwrap(),
                &id,
                || StepMean::new(1),
                |run, _, _| {
                    if run == 120 || run == 190 {
                        Err(kalibra_metrics::MetricsError::Empty {
                            what: "a failing run",
                        })
                    } else {
                        Ok(())
                    }
                },
            )
            .unwrap_err();
        assert!(
            matches!(err, kalibra_sim::SimError::Run { run: 120, .. }),
            "{threads} threads: {err:?}"
        );
    }
}
