//! [`ChaCha8Lanes`] against the scalar [`ChaCha8Rng`] it stands in for, on every instruction
//! set this CPU has: the same words, the same standard normals to the bit (over enough draws
//! that the ziggurat's tail and wedge paths are taken many times), and the same positions
//! afterwards, for full and partial groups of lanes, any key, stream and word position.

use kalibra_linalg::simd::{BATCH, Isa};
use kalibra_sim::{ChaCha8Lanes, ChaCha8Rng, LanesError, MonteCarlo};
use rand::{Rng, RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

/// ZIGNOR's base-strip edge: a normal beyond it came from the tail path.
const ZIG_NORM_R: f64 = 3.654_152_885_361_009;

/// Draws `per_lane` normals per lane lane-wise (in calls of 1 to 7 rows) and from the scalar
/// generators, checks every pair to the bit, then the positions after a write-back and the
/// next value each generator draws. Returns (tail draws, draws that used more than one `u64`).
fn check_normals(isa: Isa, rngs: &[ChaCha8Rng], per_lane: usize) -> (usize, usize) {
    let mut scalar = rngs.to_vec();
    let mut written = rngs.to_vec();
    let mut lanes = ChaCha8Lanes::new(isa, rngs).unwrap();
    assert_eq!(lanes.len(), rngs.len());
    let (mut tails, mut slow) = (0, 0);
    let mut done = 0;
    let mut call = 0;
    while done < per_lane {
        let rows = (1 + call % 7).min(per_lane - done);
        call += 1;
        // Lanes past the generators must be left alone.
        let mut out = vec![[f64::NAN; BATCH]; rows];
        lanes.standard_normals(&mut out);
        for (lane, rng) in scalar.iter_mut().enumerate() {
            for (r, row) in out.iter().enumerate() {
                let before = rng.get_word_pos();
                let x: f64 = StandardNormal.sample(rng);
                assert_eq!(
                    row[lane].to_bits(),
                    x.to_bits(),
                    "{isa}: lane {lane}, draw {}: {} against {x}",
                    done + r,
                    row[lane]
                );
                tails += usize::from(x.abs() > ZIG_NORM_R);
                slow += usize::from(rng.get_word_pos() - before > 2);
            }
        }
        for row in &out {
            assert!(row[rngs.len()..].iter().all(|v| v.is_nan()), "{isa}");
        }
        done += rows;
    }
    lanes.write_back(&mut written).unwrap();
    for (lane, (w, s)) in written.iter_mut().zip(&mut scalar).enumerate() {
        assert_eq!(w.get_word_pos(), s.get_word_pos(), "{isa}: lane {lane}");
        assert_eq!(
            lanes.word_pos(lane),
            Some(s.get_word_pos()),
            "{isa}: lane {lane}"
        );
        assert_eq!(w.next_u64(), s.next_u64(), "{isa}: lane {lane}");
    }
    assert_eq!(lanes.word_pos(rngs.len()), None);
    (tails, slow)
}

fn study_rngs(seed: u64, runs: std::ops::Range<usize>) -> Vec<ChaCha8Rng> {
    let mc = MonteCarlo::new(runs.end, seed);
    runs.map(|run| mc.rng(run)).collect()
}

#[test]
fn normals_equal_the_scalar_generators_to_the_bit_on_every_instruction_set() {
    let isas = Isa::available();
    assert!(isas.contains(&Isa::Scalar));
    for isa in isas {
        let (mut tails, mut slow) = (0, 0);
        // A full group of 8 runs at 10^5 normals per lane, then shorter runs of other seeds
        // and a partial group (the last 3 runs of a study).
        for (seed, runs, per_lane) in [
            (2012, 0..BATCH, 100_000),
            (7, 40..48, 20_000),
            (u64::MAX, 1000..1003, 100_000),
        ] {
            let (t, s) = check_normals(isa, &study_rngs(seed, runs), per_lane);
            tails += t;
            slow += s;
        }
        // Expected about 300 tail draws and 13000 slow ones: the paths are exercised.
        assert!(tails >= 100, "{isa}: {tails} tail draws");
        assert!(slow >= 5000, "{isa}: {slow} slow draws");
    }
}

#[test]
fn any_key_stream_and_word_position_including_odd_ones() {
    for isa in Isa::available() {
        let rngs: Vec<ChaCha8Rng> = (0..5u64)
            .map(|lane| {
                // Different keys per lane, streams near the top, and positions inside a block,
                // odd, and one word before the end of rand_chacha's 64-word buffer.
                let mut rng = ChaCha8Rng::seed_from_u64(lane * 1000 + 3);
                rng.set_stream(u64::MAX - lane);
                match lane {
                    0 => {}
                    1 => {
                        rng.next_u32();
                    }
                    2 => rng.set_word_pos(63),
                    3 => rng.set_word_pos(16 * 1_000_003 + 5),
                    _ => {
                        for _ in 0..7 {
                            rng.next_u32();
                        }
                    }
                }
                rng
            })
            .collect();
        check_normals(isa, &rngs, 3_000);
    }
}

#[test]
fn a_lane_is_a_generator_that_draws_what_its_stream_draws() {
    for isa in Isa::available() {
        let rngs = study_rngs(11, 0..4);
        let mut scalar = rngs.clone();
        let mut lanes = ChaCha8Lanes::new(isa, &rngs).unwrap();
        assert!(lanes.lane(4).is_none());
        // Lane 0 draws far ahead while the others wait: their buffers fill up and they skip
        // refills, then they catch up.
        for _ in 0..1000 {
            let a: u64 = lanes.lane(0).unwrap().next_u64();
            assert_eq!(a, scalar[0].next_u64(), "{isa}");
        }
        for (lane, rng) in scalar.iter_mut().enumerate() {
            let mut mine = lanes.lane(lane).unwrap();
            // Mixed widths, so the position is odd part of the time.
            for i in 0..700 {
                match i % 5 {
                    0 => assert_eq!(mine.next_u32(), rng.next_u32(), "{isa}"),
                    1 => assert_eq!(mine.next_u64(), rng.next_u64(), "{isa}"),
                    2 => {
                        let (mut a, mut b) = ([0u8; 7], [0u8; 7]);
                        mine.fill_bytes(&mut a);
                        rng.fill_bytes(&mut b);
                        assert_eq!(a, b, "{isa}");
                    }
                    3 => assert_eq!(
                        mine.random::<f64>().to_bits(),
                        rng.random::<f64>().to_bits(),
                        "{isa}"
                    ),
                    _ => {
                        let (x, y): (f64, f64) =
                            (StandardNormal.sample(&mut mine), StandardNormal.sample(rng));
                        assert_eq!(x.to_bits(), y.to_bits(), "{isa}");
                    }
                }
            }
        }
        let mut written = rngs.clone();
        lanes.write_back(&mut written).unwrap();
        for (w, s) in written.iter_mut().zip(&mut scalar) {
            assert_eq!(w.get_word_pos(), s.get_word_pos(), "{isa}");
            assert_eq!(w.next_u32(), s.next_u32(), "{isa}");
        }
    }
}

#[test]
fn misuse_is_a_typed_error() {
    let nine = study_rngs(1, 0..9);
    assert_eq!(
        ChaCha8Lanes::new(Isa::Scalar, &nine).unwrap_err(),
        LanesError::TooManyLanes { given: 9 }
    );
    let lanes = ChaCha8Lanes::new(Isa::Scalar, &nine[..3]).unwrap();
    let mut two = nine[..2].to_vec();
    assert_eq!(
        lanes.write_back(&mut two).unwrap_err(),
        LanesError::LaneCount { given: 2, lanes: 3 }
    );
    // Runs 0, 1 and 3: the third generator is another stream; nothing is written.
    let mut other = vec![nine[0].clone(), nine[1].clone(), nine[3].clone()];
    other[0].next_u64();
    let before = other[0].get_word_pos();
    assert_eq!(
        lanes.write_back(&mut other).unwrap_err(),
        LanesError::OtherStream { lane: 2 }
    );
    assert_eq!(other[0].get_word_pos(), before);
    let mut keyed = nine[..3].to_vec();
    keyed[1] = ChaCha8Rng::seed_from_u64(2);
    keyed[1].set_stream(1);
    assert_eq!(
        lanes.write_back(&mut keyed).unwrap_err(),
        LanesError::OtherStream { lane: 1 }
    );
    for isa in Isa::ALL.into_iter().filter(|i| !i.is_available()) {
        assert!(matches!(
            ChaCha8Lanes::new(isa, &nine[..1]),
            Err(LanesError::Isa(_))
        ));
    }
}

/// A generator of `seed` (stream `stream`) at the first even word position from `from` on
/// whose next standard normal takes the ziggurat's slow path (more than one `u64`).
fn before_a_slow_draw(seed: u64, stream: u64, from: u128) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let mut pos = from + from % 2;
    loop {
        rng.set_word_pos(pos);
        let mut probe = rng.clone();
        let _: f64 = StandardNormal.sample(&mut probe);
        if probe.get_word_pos() - pos > 2 {
            return rng;
        }
        pos += 2;
    }
}

/// Lanes in every state at once, in the same calls: at odd word positions, one `u64` before
/// the end of a 64-word chunk or of the ring, one word before it, about to take the slow path
/// in the first row or a few rows in, fresh; calls of 1, 2, 4 and 6 rows, with single words
/// drawn from some lanes between calls (so positions turn odd and even again mid-stream).
/// Every value and every position against the scalar generators, on every instruction set the
/// CPU has, for a full group of 8 lanes and a partial one of 5.
#[test]
fn mixed_rows_lanes_in_different_states_in_the_same_call() {
    let starts: Vec<ChaCha8Rng> = (0..BATCH as u64)
        .map(|lane| {
            let (seed, stream) = (lane * 7919 + 1, 3 * lane + 1);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(stream);
            match lane {
                // Fresh.
                0 => rng,
                // Odd.
                1 => {
                    rng.set_word_pos(5);
                    rng
                }
                // One u64 before the end of the first chunk.
                2 => {
                    rng.set_word_pos(62);
                    rng
                }
                // One word before the end of a chunk, far into the stream.
                3 => {
                    rng.set_word_pos(64 * 1001 - 1);
                    rng
                }
                // Slow path on the first draw.
                4 => before_a_slow_draw(seed, stream, 0),
                // A slow draw two draws in (unless an earlier one is slow), near the end of the
                // ring's 4 chunks.
                5 => {
                    let slow = before_a_slow_draw(seed, stream, 256 - 2);
                    let mut rng = slow.clone();
                    rng.set_word_pos(slow.get_word_pos() - 4);
                    rng
                }
                // A slow draw one draw in, after a single word drawn (`next_u32`) to get there.
                6 => {
                    let slow = before_a_slow_draw(seed, stream, 1001);
                    let mut rng = slow.clone();
                    rng.set_word_pos(slow.get_word_pos() - 3);
                    rng.next_u32();
                    rng
                }
                _ => {
                    rng.set_word_pos(16 * 1234 + 14);
                    rng
                }
            }
        })
        .collect();
    for isa in Isa::available() {
        for group in [&starts[..], &starts[..5]] {
            let mut scalar = group.to_vec();
            let mut lanes = ChaCha8Lanes::new(isa, group).unwrap();
            for call in 0..3000 {
                let rows = [1, 2, 4, 6][call % 4];
                let mut out = vec![[f64::NAN; BATCH]; rows];
                lanes.standard_normals(&mut out);
                for (lane, rng) in scalar.iter_mut().enumerate() {
                    for (r, row) in out.iter().enumerate() {
                        let x: f64 = StandardNormal.sample(rng);
                        assert_eq!(
                            row[lane].to_bits(),
                            x.to_bits(),
                            "{isa}, {} lanes: call {call}, lane {lane}, row {r} of {rows}",
                            group.len()
                        );
                    }
                    assert_eq!(
                        lanes.word_pos(lane),
                        Some(rng.get_word_pos()),
                        "{isa}, {} lanes: call {call}, lane {lane}",
                        group.len()
                    );
                }
                for row in &out {
                    assert!(row[group.len()..].iter().all(|v| v.is_nan()), "{isa}");
                }
                // A single word from one lane in three calls: its parity flips.
                if call % 3 == 0 {
                    let lane = call / 3 % group.len();
                    let word = lanes.lane(lane).unwrap().next_u32();
                    assert_eq!(word, scalar[lane].next_u32(), "{isa}: call {call}");
                }
            }
            let mut written = group.to_vec();
            lanes.write_back(&mut written).unwrap();
            for (w, s) in written.iter_mut().zip(&mut scalar) {
                assert_eq!(w.get_word_pos(), s.get_word_pos(), "{isa}");
                assert_eq!(w.next_u64(), s.next_u64(), "{isa}");
            }
        }
    }
}
