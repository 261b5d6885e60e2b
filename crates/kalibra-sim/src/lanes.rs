//! Lane-wise random draws: the ChaCha8 streams of up to [`BATCH`] runs generated together with
//! SIMD, and standard normals drawn from them, each lane giving exactly what its run's own
//! [`ChaCha8Rng`] and rand_distr's [`StandardNormal`] give.
//!
//! # Why
//! A batched study steps [`BATCH`] runs together, but each run draws from its own generator
//! ([`MonteCarlo::rng`](crate::MonteCarlo::rng): one key from the seed, the run's number as
//! the ChaCha stream). Drawing lane by lane through [`ChaCha8Rng`] computes each generator's
//! blocks alone (4 at a time); for W1 the draws were a third of the batched time.
//! [`ChaCha8Lanes`] computes the ChaCha8 blocks of all its lanes at once, one SIMD lane per
//! (stream, block): the 16 state words of 16 blocks (AVX-512), 8 (AVX2) or 4 (NEON) at a time,
//! with no shuffles since every vector holds one state word of several blocks. A refill
//! computes 4 blocks (a chunk) per lane into the lane's next slot of a ring of 4, as the kernel
//! leaves them (word `w` of every block in one row); every lane has its own columns in every
//! slot, so its chunks follow one another and it reads them in order with its own count of
//! words read. With [`Isa::Scalar`] every draw goes through the lanes' own generators (one
//! lane at a time, as the batched filters' scalar fallback).
//!
//! # Cost
//! Lane-wise draws make the batched study faster than each run's own generator on AVX-512,
//! and not on AVX2 (example `lane_normals` times the draws on every instruction set the CPU
//! has, `cargo xtask bench w1` the batched study). On AVX-512 the ziggurat's fast path runs across
//! the 8 lanes with gathers (`lanes/gather.rs`, the crate's one `unsafe` code: pulp offers
//! gathers only as `unsafe`); on AVX2 the same pass over two halves is slower than lane by
//! lane (example `lane_normals`), so AVX2 draws lane by lane.
//!
//! # Exactness
//! A ChaCha8 stream is a fixed sequence of 32-bit words (block `b` of stream `s` under key
//! `k`); [`ChaCha8Rng::next_u64`](rand_chacha::rand_core::Rng::next_u64) returns the next two
//! words, low word first, whatever the word position's parity, and `next_u32` the next word.
//! A lane reads its words in the same order, so its values depend only on its key, stream and
//! position, never on the instruction set or on when the lanes' buffers are refilled; the
//! integer arithmetic is exact on every instruction set. [`ChaCha8Lanes::write_back`] sets
//! each scalar generator to its lane's position, so drawing from it afterwards continues where
//! it would have had every draw been scalar.
//!
//! [`ChaCha8Lanes::standard_normals`] is rand_distr 0.6's ziggurat (Doornik's ZIGNOR, 256
//! boxes, its tables copied verbatim): the fast path (one `u64`: 8 bits choose the box, the top
//! 52 a value in `[-1, 1)`; about 99% of draws) across the lanes on AVX-512, inline per lane
//! otherwise, from the lane's words, and the rare rest per lane: the wedge test's uniform as
//! rand's `StandardUniform` computes it and a fresh try through the lane's own fast path, the
//! base strip's tail through [`LaneRng`] with rand's own `Open01`, each consuming the lane's
//! words exactly as rand_distr consumes the scalar generator's. The tests
//! compare 10^5 and more normals per lane, tails and wedges included, to the bit, on every
//! instruction set the CPU has.

#[cfg(target_arch = "x86_64")]
mod gather;

use std::convert::Infallible;

use kalibra_linalg::LinalgError;
use kalibra_linalg::simd::{BATCH, Isa, Lanes};
use pulp::{Simd, WithSimd};
use rand_chacha::rand_core::{Rng, TryRng};
use rand_distr::{Distribution, Open01, StandardNormal};

use crate::ChaCha8Rng;
use crate::ziggurat_tables::{ZIG_NORM_F, ZIG_NORM_R, ZIG_NORM_X};

/// 32-bit words per ChaCha block.
const BLOCK_WORDS: usize = 16;
/// Blocks each lane receives per refill: rand_chacha's 4-block buffer, so a lane refills as
/// often as its scalar generator would.
const CHUNK_BLOCKS: usize = 4;
/// Words each lane receives per refill (a chunk).
const CHUNK: usize = CHUNK_BLOCKS * BLOCK_WORDS;
/// Words of each lane's ring: a lane that has drawn less than the others (lanes drift apart
/// through the ziggurat's rare extra draws) keeps up to this many words unread (4 chunks).
const RING: usize = 4 * CHUNK;
/// Blocks per refill, over all lanes: a multiple of every instruction set's u32 lane count
/// (16, 8, 4, 1), so the kernel has no remainder. Column `lane * CHUNK_BLOCKS + b` is block
/// `b` of the chunk of lane `lane`.
const GEN: usize = CHUNK_BLOCKS * BATCH;
/// One chunk slot: word `w` of every column (the kernel's output as it is).
type Slot = [[u32; GEN]; BLOCK_WORDS];
/// Chunk slots in the ring: lane `l`'s `k`-th chunk is in slot `k % SLOTS`, its columns.
const SLOTS: usize = RING / CHUNK;
/// Words in the ring.
const RING_WORDS: usize = SLOTS * BLOCK_WORDS * GEN;
/// ChaCha8: four double rounds.
const DOUBLE_ROUNDS: usize = 4;
/// "expand 32-byte k", ChaCha's first four state words.
const SIGMA: [u32; 4] = [0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574];
/// Word positions are 68-bit (a 64-bit block counter of 16-word blocks); [`ChaCha8Rng`]'s
/// `set_word_pos` ignores the bits above.
const WORD_POS_MOD: u128 = 1 << 68;

/// Why lane-wise draws could not be set up or handed back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LanesError {
    /// More generators than lanes.
    #[error("{given} generators for at most {BATCH} lanes")]
    TooManyLanes {
        /// Generators given.
        given: usize,
    },
    /// [`ChaCha8Lanes::write_back`] was given a different number of generators than lanes.
    #[error("{given} generators to write back {lanes} lanes into")]
    LaneCount {
        /// Generators given.
        given: usize,
        /// Lanes of the batch.
        lanes: usize,
    },
    /// [`ChaCha8Lanes::write_back`] was given a generator of another key or stream than its lane.
    #[error("generator {lane} has another key or stream than lane {lane}")]
    OtherStream {
        /// The lane.
        lane: usize,
    },
    /// The instruction set is not available on this CPU.
    #[error(transparent)]
    Isa(#[from] LinalgError),
}

/// The ChaCha8 streams of up to [`BATCH`] generators, drawn lane by lane with their blocks
/// computed together.
///
/// Each lane reads its own stream's words in order, exactly as its [`ChaCha8Rng`] would
/// (`next_u64` takes two words, low first, at any word position), from buffers that SIMD
/// refills for all lanes at once: one ChaCha8 block per SIMD lane, one state word per vector,
/// so the rounds need no shuffles ([`Isa::Scalar`]: the lanes' own generators, one lane at a
/// time). A lane's values depend only on its key, stream and position, not on the instruction
/// set nor on when buffers are refilled. [`ChaCha8Lanes::standard_normals`]
/// is rand_distr 0.6's ziggurat over these words, [`ChaCha8Lanes::lane`] any other
/// distribution, and [`ChaCha8Lanes::write_back`] hands the positions back to the scalar
/// generators.
///
/// ```
/// use kalibra_linalg::simd::{BATCH, Isa};
/// use kalibra_sim::{ChaCha8Lanes, MonteCarlo};
/// use rand_distr::{Distribution, StandardNormal};
///
/// let mc = MonteCarlo::new(3, 42);
/// let mut rngs: Vec<_> = (0..3).map(|run| mc.rng(run)).collect();
/// let mut scalar = rngs.clone();
/// let mut lanes = ChaCha8Lanes::new(Isa::detect(), &rngs)?;
/// let mut rows = [[0.0; BATCH]; 2];
/// lanes.standard_normals(&mut rows);
/// lanes.write_back(&mut rngs)?;
/// for (lane, rng) in scalar.iter_mut().enumerate() {
///     for row in &rows {
///         let x: f64 = StandardNormal.sample(rng);
///         assert_eq!(row[lane].to_bits(), x.to_bits());
///     }
///     assert_eq!(rngs[lane].get_word_pos(), rng.get_word_pos());
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone)]
pub struct ChaCha8Lanes {
    isa: Isa,
    lanes: usize,
    /// Lane `l`'s key words (its seed, little-endian).
    key: [[u32; 8]; BATCH],
    stream: [u64; BATCH],
    /// The next block each lane's refill computes.
    block: [u64; BATCH],
    /// State words 4..16 of every column (key, counter, stream): only the counters change.
    input: [[u32; GEN]; 12],
    /// The ring the kernel writes into: lane `l`'s `v`-th word (counted from word 0 of the
    /// block its first refill computed) at [`word_index`]`(l, v)` of the flattened ring, in
    /// slot `v / CHUNK % SLOTS`, the lane's own columns. A lane's chunks follow one another
    /// in its slots whatever the other lanes have read.
    ring: [Slot; SLOTS],
    /// The words each lane has read (it starts at the generator's offset in its block) and
    /// has received, counted as `v` above: words `read..end` are unread.
    read: [u64; BATCH],
    end: [u64; BATCH],
    /// With [`Isa::Scalar`], the lanes' own generators, which every draw goes through (the
    /// ring is unused); empty otherwise.
    scalar: Vec<ChaCha8Rng>,
}

impl std::fmt::Debug for ChaCha8Lanes {
    /// The instruction set, lane count and positions; never the key or the buffered words.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChaCha8Lanes")
            .field("isa", &self.isa)
            .field("stream", &&self.stream[..self.lanes])
            .field(
                "word_pos",
                &(0..self.lanes)
                    .filter_map(|l| self.word_pos(l))
                    .collect::<Vec<_>>(),
            )
            .finish_non_exhaustive()
    }
}

impl ChaCha8Lanes {
    /// One lane per generator (at most [`BATCH`]), each continuing from its generator's
    /// current position (key, stream and word position are read, the generators left as they
    /// are), computing blocks on instruction set `isa`.
    ///
    /// # Errors
    /// [`LanesError::TooManyLanes`] for more than [`BATCH`] generators, [`LanesError::Isa`]
    /// if the CPU does not run `isa`.
    pub fn new(isa: Isa, rngs: &[ChaCha8Rng]) -> Result<Self, LanesError> {
        let isa = isa.checked()?;
        if rngs.len() > BATCH {
            return Err(LanesError::TooManyLanes { given: rngs.len() });
        }
        let mut out = Self {
            isa,
            lanes: rngs.len(),
            key: [[0; 8]; BATCH],
            stream: [0; BATCH],
            block: [0; BATCH],
            input: [[0; GEN]; 12],
            ring: [[[0; GEN]; BLOCK_WORDS]; SLOTS],
            read: [0; BATCH],
            end: [0; BATCH],
            scalar: Vec::new(),
        };
        for (lane, rng) in rngs.iter().enumerate() {
            let seed = rng.get_seed();
            for (word, bytes) in out.key[lane].iter_mut().zip(seed.chunks_exact(4)) {
                *word = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
            }
            out.stream[lane] = rng.get_stream();
            let pos = rng.get_word_pos() % WORD_POS_MOD;
            // pos < 2^68, so the block index fits the 64-bit counter.
            out.block[lane] = (pos / BLOCK_WORDS as u128) as u64;
            // A generator taken mid-block starts inside its first block.
            out.read[lane] = (pos % BLOCK_WORDS as u128) as u64;
            for b in 0..CHUNK_BLOCKS {
                let col = lane * CHUNK_BLOCKS + b;
                for (k, key) in out.key[lane].iter().enumerate() {
                    out.input[k][col] = *key;
                }
                out.input[10][col] = out.stream[lane] as u32;
                out.input[11][col] = (out.stream[lane] >> 32) as u32;
            }
            if isa == Isa::Scalar {
                out.scalar.push(rng.clone());
            }
        }
        Ok(out)
    }

    /// Number of lanes.
    pub fn len(&self) -> usize {
        self.lanes
    }

    /// Whether there are no lanes.
    pub fn is_empty(&self) -> bool {
        self.lanes == 0
    }

    /// The generators of a batch stepped on `isa`, drawing the way that is faster there:
    /// lane-wise on AVX-512, through the runs' own generators ([`Isa::Scalar`]) on every other
    /// instruction set, where lane-wise draws do not make the batched study faster
    /// (`cargo xtask bench w1` times both; example `lane_normals` the draws alone). The
    /// numbers drawn are the same either way; only the time differs, so a study passes its
    /// batch's instruction set and this chooses.
    ///
    /// # Errors
    /// As [`ChaCha8Lanes::new`].
    pub fn for_batch(isa: Isa, rngs: &[ChaCha8Rng]) -> Result<Self, LanesError> {
        let draws = if isa == Isa::Avx512 { isa } else { Isa::Scalar };
        Self::new(draws, rngs)
    }

    /// The instruction set the blocks are computed on ([`Isa::Scalar`]: the lanes' own
    /// generators).
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// Lane `lane`'s position in its stream, in 32-bit words (modulo 2^68, as
    /// [`ChaCha8Rng::set_word_pos`] takes it); `None` past the lanes.
    pub fn word_pos(&self, lane: usize) -> Option<u128> {
        if let Some(rng) = self.scalar.get(lane) {
            return Some(rng.get_word_pos() % WORD_POS_MOD);
        }
        (lane < self.lanes).then(|| {
            // Word `end` is word 0 of block `block`; a wrapped block counter is below the
            // words received: add the period first.
            let next = u128::from(self.block[lane]) * BLOCK_WORDS as u128;
            let (read, end) = (u128::from(self.read[lane]), u128::from(self.end[lane]));
            (next + WORD_POS_MOD - end + read) % WORD_POS_MOD
        })
    }

    /// Sets each generator to its lane's position, so that drawing from it continues exactly
    /// where the lane stopped.
    ///
    /// # Errors
    /// [`LanesError::LaneCount`] unless there is one generator per lane,
    /// [`LanesError::OtherStream`] for a generator whose key or stream is not its lane's; no
    /// generator is changed then.
    pub fn write_back(&self, rngs: &mut [ChaCha8Rng]) -> Result<(), LanesError> {
        if rngs.len() != self.lanes {
            return Err(LanesError::LaneCount {
                given: rngs.len(),
                lanes: self.lanes,
            });
        }
        if let Some(lane) = rngs.iter().enumerate().position(|(lane, rng)| {
            let key: Vec<u32> = rng
                .get_seed()
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            key != self.key[lane] || rng.get_stream() != self.stream[lane]
        }) {
            return Err(LanesError::OtherStream { lane });
        }
        for (lane, rng) in rngs.iter_mut().enumerate() {
            let pos = self.word_pos(lane).unwrap_or_default();
            // Setting a position mid-block computes a block; skip it when nothing changed.
            if rng.get_word_pos() % WORD_POS_MOD != pos {
                rng.set_word_pos(pos);
            }
        }
        Ok(())
    }

    /// Lane `lane` as a generator of its own (`None` past the lanes): any rand distribution
    /// sampled from it draws what it would draw from the lane's [`ChaCha8Rng`].
    pub fn lane(&mut self, lane: usize) -> Option<LaneRng<'_>> {
        (lane < self.lanes).then_some(LaneRng { lanes: self, lane })
    }

    /// Fills `rows` with standard normals: `rows[r][l]` is the `r`-th draw of lane `l` in this
    /// call, bit for bit the value [`StandardNormal`] draws from the lane's [`ChaCha8Rng`] in
    /// its place. Entries of lanes past [`ChaCha8Lanes::len`] are left as they are.
    #[inline(always)]
    pub fn standard_normals(&mut self, rows: &mut [Lanes]) {
        // Inlined into the caller, where the number of rows is often a constant: the scalar
        // mode's loops then unroll as the one-run code's do.
        if self.scalar.is_empty() {
            self.lane_normals(rows);
        } else {
            self.scalar_normals(rows);
        }
    }

    /// [`ChaCha8Lanes::standard_normals`] with [`Isa::Scalar`]: one generator at a time
    /// through its rows, as the one-run study draws.
    #[inline(always)]
    fn scalar_normals(&mut self, rows: &mut [Lanes]) {
        for (lane, rng) in self.scalar.iter_mut().enumerate() {
            for row in rows.iter_mut() {
                row[lane] = StandardNormal.sample(rng);
            }
        }
    }

    /// [`ChaCha8Lanes::standard_normals`] from the lane-wise blocks: the fast path across
    /// lanes with gathers on AVX-512 (`gather.rs`), per lane otherwise.
    fn lane_normals(&mut self, rows: &mut [Lanes]) {
        // AVX-512 only: AVX2's gathers (two ymm halves) make it slower than per lane (example
        // `lane_normals`).
        #[cfg(target_arch = "x86_64")]
        if self.isa == Isa::Avx512
            && let Some(simd) = pulp::x86::V4::try_new()
        {
            return self.normals_v4(simd, rows);
        }
        // Row by row: consecutive draws are from different lanes, so their dependency chains
        // (each lane's read position) overlap.
        for row in rows.iter_mut() {
            for (lane, value) in row.iter_mut().enumerate().take(self.lanes) {
                *value = self.standard_normal(lane);
            }
        }
    }

    /// One standard normal from lane `lane`: the ziggurat's fast path inline.
    #[inline(always)]
    fn standard_normal(&mut self, lane: usize) -> f64 {
        match ziggurat_fast(self.next_u64(lane)) {
            Ok(x) => x,
            Err((i, u, x)) => self.standard_normal_slow(lane, i, u, x),
        }
    }

    /// The rest of rand_distr's ziggurat loop after a rejected fast try `x` in box `i`: the
    /// tail of the base strip, the wedge test, or a fresh try (the loop keeps no state between
    /// tries, so a fresh try is a fresh [`StandardNormal`] sample).
    #[cold]
    #[inline(never)]
    fn standard_normal_slow(&mut self, lane: usize, i: usize, u: f64, x: f64) -> f64 {
        if i == 0 {
            return normal_tail(&mut LaneRng { lanes: self, lane }, u);
        }
        // rand's `StandardUniform` for f64 (the top 53 bits of the next `u64`, scaled by
        // 2^-53) and a fresh try through this lane's own fast path, rather than rand's generic
        // code through `LaneRng`, whose calls cost the batched study time (`cargo xtask bench
        // w1`): the same words in the same order, so the same numbers, which the tests check
        // against rand's `StandardNormal` on the scalar generators, slow draws included.
        let draw = (self.next_u64(lane) >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
        if ZIG_NORM_F[i + 1] + (ZIG_NORM_F[i] - ZIG_NORM_F[i + 1]) * draw < (-x * x / 2.0).exp() {
            return x;
        }
        self.standard_normal(lane)
    }

    /// Word `v` of lane `lane` (received and not overwritten).
    #[inline(always)]
    fn word(&self, lane: usize, v: u64) -> u32 {
        self.ring.as_flattened().as_flattened()[word_index(lane, v)]
    }

    /// Lane `lane`'s next two words, low first, as `ChaCha8Rng::next_u64` reads them.
    #[inline(always)]
    fn next_u64(&mut self, lane: usize) -> u64 {
        let v = self.read[lane];
        if v + 2 <= self.end[lane] {
            self.read[lane] = v + 2;
            return (u64::from(self.word(lane, v + 1)) << 32) | u64::from(self.word(lane, v));
        }
        self.next_u64_across(lane)
    }

    /// [`ChaCha8Lanes::next_u64`] when the lane has fewer than two words: word by word,
    /// refilling between them as needed.
    #[inline(never)]
    fn next_u64_across(&mut self, lane: usize) -> u64 {
        let lo = self.next_u32(lane);
        let hi = self.next_u32(lane);
        (u64::from(hi) << 32) | u64::from(lo)
    }

    /// Lane `lane`'s next word.
    #[inline(always)]
    fn next_u32(&mut self, lane: usize) -> u32 {
        if self.read[lane] >= self.end[lane] {
            self.refill();
        }
        let v = self.read[lane];
        self.read[lane] = v + 1;
        self.word(lane, v)
    }

    /// Computes the next [`CHUNK_BLOCKS`] blocks of every lane that has room for them in its
    /// ring and appends them there. A lane with more than `RING - CHUNK` words unread (it has
    /// drawn 3 chunks fewer than the lane asking) keeps its counter, so it computes these
    /// blocks at a later refill. Called when a lane has too few words left, so that lane takes.
    #[inline(never)]
    fn refill(&mut self) {
        let mut take = [0u32; GEN];
        let mut takes = [false; BATCH];
        // The slots asked for, as bits.
        let mut slots = 0u32;
        for (lane, takes) in takes.iter_mut().enumerate().take(self.lanes) {
            let unread = self.end[lane].saturating_sub(self.read[lane]) as usize;
            if unread + CHUNK > RING {
                continue;
            }
            *takes = true;
            slots |= 1 << (self.end[lane] / CHUNK as u64 % SLOTS as u64);
            for b in 0..CHUNK_BLOCKS {
                let col = lane * CHUNK_BLOCKS + b;
                let counter = self.block[lane].wrapping_add(b as u64);
                self.input[8][col] = counter as u32;
                self.input[9][col] = (counter >> 32) as u32;
                take[col] = 1;
            }
        }
        // Each lane's chunk goes to its next slot: one kernel call per slot asked for. The
        // usual case, one slot (no lane has skipped a refill), needs no mask per slot, which
        // keeps `refill` off the batched study's profile (`cargo xtask bench w1`).
        if slots.count_ones() == 1 {
            self.isa.dispatch(Blocks {
                input: &self.input,
                take: &take,
                out: &mut self.ring[slots.trailing_zeros() as usize],
            });
            self.received(takes);
            return;
        }
        for slot in 0..SLOTS {
            let mut in_slot = take;
            let mut any = false;
            for lane in 0..self.lanes {
                let here =
                    takes[lane] && self.end[lane] / CHUNK as u64 % SLOTS as u64 == slot as u64;
                any |= here;
                if !here {
                    in_slot[lane * CHUNK_BLOCKS..(lane + 1) * CHUNK_BLOCKS].fill(0);
                }
            }
            if any {
                self.isa.dispatch(Blocks {
                    input: &self.input,
                    take: &in_slot,
                    out: &mut self.ring[slot],
                });
            }
        }
        self.received(takes);
    }

    /// The lanes in `takes` have received a chunk.
    #[inline(always)]
    fn received(&mut self, takes: [bool; BATCH]) {
        for lane in (0..self.lanes).filter(|l| takes[*l]) {
            self.end[lane] += CHUNK as u64;
            self.block[lane] = self.block[lane].wrapping_add(CHUNK_BLOCKS as u64);
        }
    }
}

/// Where word `v` of lane `lane` is in [`ChaCha8Lanes`]' flattened ring: slot
/// `v / CHUNK % SLOTS`, row `v % 16` (the word in its block), column of block
/// `v % CHUNK / 16` of the lane's chunk.
#[inline(always)]
fn word_index(lane: usize, v: u64) -> usize {
    let v = v as usize;
    let slot = v / CHUNK % SLOTS;
    let block = v / BLOCK_WORDS % CHUNK_BLOCKS;
    let word = v % BLOCK_WORDS;
    (slot * BLOCK_WORDS + word) * GEN + lane * CHUNK_BLOCKS + block
}

/// rand_distr's ziggurat fast try from one `u64`: the low 8 bits choose the box `i`, the top
/// 52 a value `u` in [2, 4) (exponent 1), shifted to [-1, 1); `x = u X[i]` is accepted inside
/// the box's rectangle. A rejection returns `(i, u, x)` for the slow path.
#[inline(always)]
fn ziggurat_fast(bits: u64) -> Result<f64, (usize, f64, f64)> {
    let i = (bits & 0xff) as usize;
    let u = f64::from_bits((bits >> 12) | (1024 << 52)) - 3.0;
    let x = u * ZIG_NORM_X[i];
    if x.abs() < ZIG_NORM_X[i + 1] {
        Ok(x)
    } else {
        Err((i, u, x))
    }
}

/// rand_distr's tail of the base strip (Marsaglia's method beyond `R`), drawing what it draws.
fn normal_tail(rng: &mut LaneRng<'_>, u: f64) -> f64 {
    // rand_distr's loop starts from values that enter it once.
    let mut x = 1.0f64;
    let mut y = 0.0f64;
    while -2.0 * y < x * x {
        let x_: f64 = Open01.sample(rng);
        let y_: f64 = Open01.sample(rng);
        x = x_.ln() / ZIG_NORM_R;
        y = y_.ln();
    }
    if u < 0.0 {
        x - ZIG_NORM_R
    } else {
        ZIG_NORM_R - x
    }
}

/// One lane of a [`ChaCha8Lanes`] as a generator ([`ChaCha8Lanes::lane`]): `next_u32`,
/// `next_u64` and `fill_bytes` consume the lane's words as [`ChaCha8Rng`]'s consume its
/// stream (a partly used word at the end of a byte fill is used up).
#[derive(Debug)]
pub struct LaneRng<'a> {
    lanes: &'a mut ChaCha8Lanes,
    lane: usize,
}

impl TryRng for LaneRng<'_> {
    type Error = Infallible;

    #[inline]
    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        Ok(match self.lanes.scalar.get_mut(self.lane) {
            Some(rng) => rng.next_u32(),
            None => self.lanes.next_u32(self.lane),
        })
    }

    #[inline]
    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        Ok(match self.lanes.scalar.get_mut(self.lane) {
            Some(rng) => rng.next_u64(),
            None => self.lanes.next_u64(self.lane),
        })
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Infallible> {
        if let Some(rng) = self.lanes.scalar.get_mut(self.lane) {
            rng.fill_bytes(dst);
            return Ok(());
        }
        for chunk in dst.chunks_mut(4) {
            let word = self.lanes.next_u32(self.lane).to_le_bytes();
            chunk.copy_from_slice(&word[..chunk.len()]);
        }
        Ok(())
    }
}

/// [`GEN`] ChaCha8 blocks, column by column: `input` holds state words 4..16 of every block,
/// `out` receives the 16 output words in the columns where `take` is not 0 and keeps its
/// values elsewhere.
struct Blocks<'a> {
    input: &'a [[u32; GEN]; 12],
    take: &'a [u32; GEN],
    out: &'a mut Slot,
}

impl WithSimd for Blocks<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let vectors = S::as_simd_u32s(&self.input[0]).0.len();
        for v in 0..vectors {
            let mut init = [simd.splat_u32s(0); BLOCK_WORDS];
            for (w, sigma) in SIGMA.iter().enumerate() {
                init[w] = simd.splat_u32s(*sigma);
            }
            for (w, row) in self.input.iter().enumerate() {
                init[4 + w] = S::as_simd_u32s(row).0[v];
            }
            let mut x = init;
            for _ in 0..DOUBLE_ROUNDS {
                quarter(simd, &mut x, 0, 4, 8, 12);
                quarter(simd, &mut x, 1, 5, 9, 13);
                quarter(simd, &mut x, 2, 6, 10, 14);
                quarter(simd, &mut x, 3, 7, 11, 15);
                quarter(simd, &mut x, 0, 5, 10, 15);
                quarter(simd, &mut x, 1, 6, 11, 12);
                quarter(simd, &mut x, 2, 7, 8, 13);
                quarter(simd, &mut x, 3, 4, 9, 14);
            }
            let take = simd.greater_than_u32s(S::as_simd_u32s(self.take).0[v], simd.splat_u32s(0));
            for (w, row) in self.out.iter_mut().enumerate() {
                let out = &mut S::as_mut_simd_u32s(row).0[v];
                *out = simd.select_u32s(take, simd.add_u32s(x[w], init[w]), *out);
            }
        }
    }
}

/// ChaCha's quarter round on state words `a, b, c, d` of every block in the vectors.
#[inline(always)]
fn quarter<S: Simd>(simd: S, x: &mut [S::u32s; 16], a: usize, b: usize, c: usize, d: usize) {
    x[a] = simd.add_u32s(x[a], x[b]);
    x[d] = rotl(simd, simd.xor_u32s(x[d], x[a]), 16);
    x[c] = simd.add_u32s(x[c], x[d]);
    x[b] = rotl(simd, simd.xor_u32s(x[b], x[c]), 12);
    x[a] = simd.add_u32s(x[a], x[b]);
    x[d] = rotl(simd, simd.xor_u32s(x[d], x[a]), 8);
    x[c] = simd.add_u32s(x[c], x[d]);
    x[b] = rotl(simd, simd.xor_u32s(x[b], x[c]), 7);
}

/// Each word rotated left by `k` bits (pulp's `rotate_*_u32s` rotate lanes, not bits).
#[inline(always)]
fn rotl<S: Simd>(simd: S, x: S::u32s, k: u32) -> S::u32s {
    simd.or_u32s(
        simd.wrapping_dyn_shl_u32s(x, simd.splat_u32s(k)),
        simd.wrapping_dyn_shr_u32s(x, simd.splat_u32s(32 - k)),
    )
}
