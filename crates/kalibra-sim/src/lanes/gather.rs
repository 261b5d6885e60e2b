//! The ziggurat's fast path across the 8 lanes of one zmm on AVX-512. Each call makes one
//! vector pass over its rows: in row `r`, every lane whose next `u64` is two received words
//! at an even position (the common case: both in one block) gathers them, forms the `u64`,
//! chooses its box `i`, gathers `X[i]` and `X[i + 1]` and tries the box, all lanes at once.
//! A lane whose row is not the common case, or whose try is rejected, draws that row through
//! the per-lane code of `lanes.rs` at once (a rejected try through
//! [`ChaCha8Lanes::standard_normal_slow`] with the same box, value and try, its position past
//! the `u64`, as the per-lane code leaves it), and the pass goes on from the positions it
//! leaves. So each lane draws the same words in the same order, with the same IEEE operations
//! (one subtraction, one multiplication, a comparison of magnitudes): every value is the
//! per-lane one to the bit, which the tests check on every instruction set the CPU has.
//!
//! The positions advance as if every try were accepted, and the branch to a row's leaving
//! lanes is seldom taken (the fast path accepts about 99% of tries), so a row's words need
//! not wait for the previous row's table look-ups: the gathers' latency overlaps. A lane that
//! leaves is resolved in its row rather than after the pass, which keeps the other lanes'
//! pass going (example `lane_normals`; `cargo xtask bench w1`).
//!
//! # Why `unsafe`
//! The gathers: pulp 0.22 exposes them only as `unsafe` functions of raw pointers (the rest of
//! the arithmetic goes through pulp's safe wrappers, whose target features the `V4` token
//! proves), and they make the draws faster than the per-lane code (example `lane_normals`;
//! `cargo xtask bench w1`). With AVX2 (two ymm halves of 4 lanes, 8 gathers a row) the same
//! pass is slower than per lane, so AVX2 draws per lane and this module has no AVX2 code.
//! Every index is masked into its array just before the gather (see the `SAFETY` comments),
//! so no lane, whatever its state, reads outside.
#![allow(unsafe_code)]

use std::arch::x86_64::__m512i;

use kalibra_linalg::simd::{BATCH, Lanes};
use pulp::x86::V4;
use pulp::{NullaryFnOnce, cast};

use super::{BLOCK_WORDS, CHUNK, CHUNK_BLOCKS, ChaCha8Lanes, GEN, RING_WORDS, SLOTS};
use crate::ziggurat_tables::ZIG_NORM_X;

/// Indices into the ring are masked with this: `RING_WORDS` is a power of two.
const INDEX_MASK: u64 = RING_WORDS as u64 - 1;
/// `word_index` as shifts and masks: the slot, the word in its block (the row) and the block
/// of word `v`; the index is rows of GEN words and the lane's column of the block.
const ROW_MASK: u64 = BLOCK_WORDS as u64 - 1;
const ROW_STRIDE: u32 = GEN.trailing_zeros();
const BLOCK_SHIFT: u32 = BLOCK_WORDS.trailing_zeros();
const BLOCK_MASK: u64 = CHUNK_BLOCKS as u64 - 1;
const SLOT_SHIFT: u32 = CHUNK.trailing_zeros();
const SLOT_MASK: u64 = SLOTS as u64 - 1;
const SLOT_ROWS: u32 = BLOCK_WORDS.trailing_zeros();
const _: () = assert!(
    RING_WORDS.is_power_of_two()
        && CHUNK.is_power_of_two()
        && SLOTS.is_power_of_two()
        && GEN.is_power_of_two()
        && BLOCK_WORDS.is_power_of_two()
        && CHUNK_BLOCKS.is_power_of_two()
);
/// The ziggurat's boxes: `i = bits & BOX_MASK`, and `X` has an entry at `i + 1`.
const BOX_MASK: u64 = 0xff;
const _: () = assert!(ZIG_NORM_X.len() > BOX_MASK as usize + 1);
/// Bits of a `u64` that place a value's 52 fraction bits in `[2, 4)` (exponent 1).
const EXP_ONE: u64 = 1024 << 52;

impl ChaCha8Lanes {
    /// [`ChaCha8Lanes::standard_normals`] with AVX-512 gathers (`simd` proves the CPU has it).
    pub(super) fn normals_v4(&mut self, simd: V4, rows: &mut [Lanes]) {
        simd.vectorize(RowsV4 {
            simd,
            lanes: self,
            rows,
        });
    }

    /// The live lanes (below [`ChaCha8Lanes::len`]) as bits.
    #[inline(always)]
    fn live(&self) -> u8 {
        ((1u16 << self.lanes) - 1) as u8
    }

    /// The lanes of `bad` in one row of the vector pass: those in `tried` were rejected in
    /// box `i[lane]` with `u[lane]`, `x[lane]` (their positions past that `u64`), the others
    /// not tried (at an odd word or short of words, their positions at the row's draw); each
    /// draws its value per lane, as the per-lane code would.
    #[cold]
    #[inline(never)]
    fn resolve_row(&mut self, row: &mut Lanes, bad: u8, tried: u8, tries: Tries) {
        for lane in bits(bad) {
            row[lane] = if tried & (1 << lane) != 0 {
                let (i, u, x) = (tries.i[lane] as usize, tries.u[lane], tries.x[lane]);
                self.standard_normal_slow(lane, i, u, x)
            } else {
                self.standard_normal(lane)
            };
        }
    }
}

/// A row's tries, lane by lane.
struct Tries {
    i: [u64; BATCH],
    u: [f64; BATCH],
    x: [f64; BATCH],
}

/// The set bits of `mask`, lowest first.
#[inline(always)]
fn bits(mut mask: u8) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            lane
        })
    })
}

/// The rows of one call on AVX-512, inside the token's target features.
struct RowsV4<'a> {
    simd: V4,
    lanes: &'a mut ChaCha8Lanes,
    rows: &'a mut [Lanes],
}

impl NullaryFnOnce for RowsV4<'_> {
    type Output = ();

    #[inline(always)]
    fn call(self) {
        let Self { simd, lanes, rows } = self;
        let f = simd.avx512f;
        let live = lanes.live();
        let full = lanes.lanes == BATCH;
        let splat = |v: u64| f._mm512_set1_epi64(v as i64);
        let (one, two, index_mask) = (splat(1), splat(2), splat(INDEX_MASK));
        let (slot_mask, row_mask, block_mask) =
            (splat(SLOT_MASK), splat(ROW_MASK), splat(BLOCK_MASK));
        let gen_words = splat(GEN as u64);
        let box_mask = splat(BOX_MASK);
        let exp_one = splat(EXP_ONE);
        let three = f._mm512_set1_pd(3.0);
        let c = CHUNK_BLOCKS as i64;
        let starts = f._mm512_setr_epi64(0, c, 2 * c, 3 * c, 4 * c, 5 * c, 6 * c, 7 * c);
        let mut end: __m512i = cast(lanes.end);
        let mut read: __m512i = cast(lanes.read);
        // A lane with fewer words than the rows' fast tries take: a refill now (the lane
        // would ask for it a few draws later; the words do not depend on when they are
        // computed), so that the pass can go on.
        let needed = f._mm512_add_epi64(read, splat(2 * rows.len() as u64));
        if live & f._mm512_cmpgt_epu64_mask(needed, end) != 0 {
            lanes.refill();
            end = cast(lanes.end);
        }
        for row in rows.iter_mut() {
            // Two words received, at an even word (both in one block).
            let take = live
                & f._mm512_testn_epi64_mask(read, one)
                & f._mm512_cmple_epu64_mask(f._mm512_add_epi64(read, two), end);
            // `word_index`: slot, row and block of the word, and the lane's first column; the
            // high word (an even word: the same block) is a row further.
            let slot = f._mm512_and_si512(f._mm512_srli_epi64::<SLOT_SHIFT>(read), slot_mask);
            let row_of = f._mm512_add_epi64(
                f._mm512_slli_epi64::<SLOT_ROWS>(slot),
                f._mm512_and_si512(read, row_mask),
            );
            let block = f._mm512_and_si512(f._mm512_srli_epi64::<BLOCK_SHIFT>(read), block_mask);
            let at = f._mm512_add_epi64(
                f._mm512_slli_epi64::<ROW_STRIDE>(row_of),
                f._mm512_add_epi64(starts, block),
            );
            let lo_at = f._mm512_and_si512(at, index_mask);
            let hi_at = f._mm512_and_si512(f._mm512_add_epi64(at, gen_words), index_mask);
            let ring = lanes.ring.as_flattened().as_flattened();
            // SAFETY: every index is masked to below RING_WORDS, the length of `ring`
            // (asserted at compile time to be a power of two), read as 4-byte elements (scale
            // 4) of a `[u32]`; AVX-512F is present since `simd` is a V4 token, which exists
            // only on a CPU that has it, and this runs inside its `vectorize`.
            let (lo, hi) = unsafe {
                (
                    f._mm512_i64gather_epi32::<4>(lo_at, ring.as_ptr().cast()),
                    f._mm512_i64gather_epi32::<4>(hi_at, ring.as_ptr().cast()),
                )
            };
            let word = f._mm512_or_si512(
                f._mm512_cvtepu32_epi64(lo),
                f._mm512_slli_epi64::<32>(f._mm512_cvtepu32_epi64(hi)),
            );
            let i = f._mm512_and_si512(word, box_mask);
            let u = f._mm512_sub_pd(
                f._mm512_castsi512_pd(f._mm512_or_si512(f._mm512_srli_epi64::<12>(word), exp_one)),
                three,
            );
            // SAFETY: `i` is masked to at most BOX_MASK, and `ZIG_NORM_X` has entries at
            // BOX_MASK and BOX_MASK + 1 (asserted at compile time): `X[1..]` read at `i` is
            // `X[i + 1]`. 8-byte elements (scale 8) of `[f64]`; AVX-512F as above.
            let (xi, xi1) = unsafe {
                (
                    f._mm512_i64gather_pd::<8>(i, ZIG_NORM_X.as_ptr()),
                    f._mm512_i64gather_pd::<8>(i, ZIG_NORM_X[1..].as_ptr()),
                )
            };
            let x = f._mm512_mul_pd(u, xi);
            let accept = f._mm512_mask_cmplt_pd_mask(take, f._mm512_abs_pd(x), xi1);
            // A full batch stores the whole row (the lanes that were not accepted are written
            // again below); a partial one must leave the lanes past it.
            *row = cast(if full {
                x
            } else {
                f._mm512_mask_blend_pd(accept, cast(*row), x)
            });
            read = f._mm512_mask_add_epi64(read, take, read, two);
            // The lanes not taken or rejected (a minority of rows): each draws this row
            // per lane from its position (past the rejected `u64`, or at the row's draw), and
            // the pass goes on from where they leave the positions. The branch is rarely
            // taken, so the next row's words need not wait for this row's table look-ups.
            let bad = live & !accept;
            if bad != 0 {
                lanes.read = cast(read);
                let tries = Tries {
                    i: cast(i),
                    u: cast(u),
                    x: cast(x),
                };
                lanes.resolve_row(row, bad, take & !accept, tries);
                read = cast(lanes.read);
                end = cast(lanes.end);
            }
        }
        lanes.read = cast(read);
    }
}
