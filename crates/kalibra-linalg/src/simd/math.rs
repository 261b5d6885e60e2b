//! Elementary functions on SIMD vectors of f64, generic over [`pulp::Simd`], for models that
//! evaluate their lanes together. Each is `#[inline(always)]`, so it compiles inside the
//! caller's dispatched function for its instruction set.
//!
//! Their accuracy against glibc is measured by kalibra-models' `tests/lanes.rs` (through the
//! re-export `kalibra_models::lanes::math`), on every instruction set the CPU has.

use pulp::Simd;

use super::{BATCH, Lanes, load, store};

/// `pi`, `pi/2` and `pi/4` as a double plus the double nearest to the remainder, so that
/// `hi - a + lo` keeps the bits a single constant would lose.
const PI: (f64, f64) = (std::f64::consts::PI, 1.2246467991473532e-16);
const FRAC_PI_2: (f64, f64) = (std::f64::consts::FRAC_PI_2, 6.123233995736766e-17);
const FRAC_PI_4: (f64, f64) = (std::f64::consts::FRAC_PI_4, 3.061616997868383e-17);
/// `tan(pi/8)`: above it, `atan t = pi/4 + atan((t - 1)/(t + 1))`.
const TAN_PI_8: f64 = 0.41421356237309503;
/// `q(z)` with `atan(u) = u + u z q(z)`, `z = u^2`, for `|u| <= tan(pi/8)`: the Chebyshev
/// interpolant of degree 11 in `z` of `atan(sqrt z)/sqrt z` (mpmath, 60 digits), highest
/// degree first and without its constant 1. Its own error is 1.3e-18 relative, far below the
/// rounding of its evaluation.
const ATAN_Q: [f64; 11] = [
    -0.017805397205419446,
    0.03796525745386593,
    -0.05035102456601552,
    0.05846878297330872,
    -0.06662951813629191,
    0.07692045330902225,
    -0.09090896809064027,
    0.11111110744919658,
    -0.14285714279250245,
    0.19999999999940893,
    -0.3333333333333312,
];

/// Lanes whose sign bit is set (`-0.0` included, unlike `x < 0`).
#[inline(always)]
fn sign_bit<S: Simd>(simd: S, x: S::f64s) -> S::m64s {
    let zero = simd.splat_f64s(0.0);
    // 1/x keeps x's sign and turns -0 into -inf, which compares below 0.
    simd.or_m64s(
        simd.less_than_f64s(x, zero),
        simd.less_than_f64s(simd.div_f64s(simd.splat_f64s(1.0), x), zero),
    )
}

/// The four-quadrant arctangent `atan2(y, x)` of every lane, in `[-pi, pi]`, with the special
/// values of IEEE 754 / C's `atan2` (signed zeros, infinities, NaN in, NaN out).
///
/// Accuracy: within 3 ulp of glibc's `atan2` over the whole range of finite and infinite
/// inputs (`tests/lanes.rs` measures the largest distance on 10^6 samples, log-uniform from
/// 1e-300 to 1e300, near the reduction boundaries and along ordinary bearings, and at the
/// special values, on every instruction set the CPU has: 3 ulp on each). Fused
/// multiply-adds where the instruction set has them (`mul_add_e`), so the scalar fallback
/// rounds apart from the vector paths, which agree with each other to the bit.
#[inline(always)]
pub fn atan2<S: Simd>(simd: S, y: S::f64s, x: S::f64s) -> S::f64s {
    let zero = simd.splat_f64s(0.0);
    let one = simd.splat_f64s(1.0);
    let (ax, ay) = (simd.abs_f64s(x), simd.abs_f64s(y));
    // The angle of (max, min) in [0, pi/4], then reflected.
    let swap = simd.greater_than_f64s(ay, ax);
    let big = simd.select_f64s(swap, ay, ax);
    let small = simd.select_f64s(swap, ax, ay);
    let mut t = simd.div_f64s(small, big);
    // 0/0 and inf/inf: the angle of two zeros is 0, of two infinities pi/4.
    let same = simd.equal_f64s(ax, ay);
    t = simd.select_f64s(simd.and_m64s(same, simd.equal_f64s(ax, zero)), zero, t);
    t = simd.select_f64s(
        simd.and_m64s(same, simd.equal_f64s(ax, simd.splat_f64s(f64::INFINITY))),
        one,
        t,
    );
    let reduce = simd.greater_than_f64s(t, simd.splat_f64s(TAN_PI_8));
    let u = simd.select_f64s(
        reduce,
        simd.div_f64s(simd.sub_f64s(t, one), simd.add_f64s(t, one)),
        t,
    );
    let z = simd.mul_f64s(u, u);
    let mut q = simd.splat_f64s(ATAN_Q[0]);
    for c in &ATAN_Q[1..] {
        q = simd.mul_add_e_f64s(q, z, simd.splat_f64s(*c));
    }
    // u + (u z) q: the correction is added to u last, so u's bits survive.
    let mut a = simd.mul_add_e_f64s(simd.mul_f64s(u, z), q, u);
    a = simd.select_f64s(
        reduce,
        simd.add_f64s(
            simd.add_f64s(a, simd.splat_f64s(FRAC_PI_4.1)),
            simd.splat_f64s(FRAC_PI_4.0),
        ),
        a,
    );
    a = simd.select_f64s(
        swap,
        simd.add_f64s(
            simd.sub_f64s(simd.splat_f64s(FRAC_PI_2.0), a),
            simd.splat_f64s(FRAC_PI_2.1),
        ),
        a,
    );
    a = simd.select_f64s(
        sign_bit(simd, x),
        simd.add_f64s(
            simd.sub_f64s(simd.splat_f64s(PI.0), a),
            simd.splat_f64s(PI.1),
        ),
        a,
    );
    // a >= 0 here: give it y's sign bit.
    simd.xor_f64s(a, simd.and_f64s(y, simd.splat_f64s(-0.0)))
}

/// `pi/2` in three parts of 33 significant bits each (fdlibm's `pio2_1`, `pio2_2`, `pio2_3`),
/// so that `n * part` is exact for `|n| < 2^20` (Cody and Waite's reduction), and the rest
/// (`pio2_3t`): without it, `x` next to a multiple of `pi/2` (`r` near 1e-13 at `x` near
/// 7e4) kept an error of `n * 8.5e-32`, hundreds of ulp of `r`.
const PIO2: [f64; 4] = [
    1.5707963267341256,
    6.077100506303966e-11,
    2.0222662487111665e-21,
    8.4784276603689e-32,
];
/// Above this magnitude [`sin_cos`] leaves the lane to libm (the three-part reduction is
/// exact while `|x| 2/pi < 2^20`; this keeps a wide margin).
pub const SIN_COS_LIMIT: f64 = 1e5;
/// `1.5 * 2^52`: adding and subtracting it rounds a double below `2^51` to an integer.
const ROUND: f64 = 6755399441055744.0;
/// `sin r = r + r z S(z)` and `cos r = 1 - z/2 + z^2 C(z)`, `z = r^2`, `|r| <= pi/4`: Chebyshev
/// interpolants of degree 6 in `z` (mpmath, 60 digits), highest degree first; their own errors
/// are 1.2e-20 and 6.4e-22 relative.
const SIN_S: [f64; 7] = [
    -7.586697117706918e-13,
    1.6058531618986147e-10,
    -2.5052106232447578e-08,
    2.7557319219339167e-06,
    -0.00019841269841265065,
    0.008333333333333331,
    -0.16666666666666666,
];
const COS_C: [f64; 7] = [
    4.7458719020432915e-14,
    -1.1470460887609959e-11,
    2.087675579108042e-09,
    -2.7557319221402824e-07,
    2.4801587301584645e-05,
    -0.0013888888888888887,
    0.041666666666666664,
];

/// `v` rounded to the nearest integer (ties to even) for `|v| < 2^51`, by adding and
/// subtracting [`ROUND`].
#[inline(always)]
fn nearest_integer<S: Simd>(simd: S, v: S::f64s) -> S::f64s {
    let round = simd.splat_f64s(ROUND);
    simd.sub_f64s(simd.add_f64s(v, round), round)
}

#[inline(always)]
fn horner<S: Simd>(simd: S, c: &[f64], z: S::f64s) -> S::f64s {
    let mut p = simd.splat_f64s(c[0]);
    for v in &c[1..] {
        p = simd.mul_add_e_f64s(p, z, simd.splat_f64s(*v));
    }
    p
}

/// `sin x` and `cos x` of every lane with `|x| <= SIN_COS_LIMIT`: `x = n pi/2 + r` by a
/// four-part Cody-Waite reduction, the polynomials on `|r| <= pi/4`, the quadrant from `n`.
/// Lanes beyond the limit, infinite or NaN come back unspecified: [`sin_cos_lanes`] gives them
/// to libm.
#[inline(always)]
pub fn sin_cos<S: Simd>(simd: S, x: S::f64s) -> (S::f64s, S::f64s) {
    let n = nearest_integer(
        simd,
        simd.mul_f64s(x, simd.splat_f64s(std::f64::consts::FRAC_2_PI)),
    );
    let mut r = x;
    for part in PIO2 {
        r = simd.sub_f64s(r, simd.mul_f64s(n, simd.splat_f64s(part)));
    }
    let z = simd.mul_f64s(r, r);
    // sin r = r + (r z) S(z); cos r = (1 - z/2) + z^2 C(z).
    let sin_r = simd.mul_add_e_f64s(simd.mul_f64s(r, z), horner(simd, &SIN_S, z), r);
    let one_minus = simd.sub_f64s(simd.splat_f64s(1.0), simd.mul_f64s(simd.splat_f64s(0.5), z));
    let cos_r = simd.mul_add_e_f64s(simd.mul_f64s(z, z), horner(simd, &COS_C, z), one_minus);
    // n mod 4 (n is an integer in a double): n - 4 floor(n/4), the floor by rounding
    // n/4 - 3/8, whose fraction is never a half.
    let quarter = nearest_integer(
        simd,
        simd.sub_f64s(
            simd.mul_f64s(n, simd.splat_f64s(0.25)),
            simd.splat_f64s(0.375),
        ),
    );
    let q = simd.sub_f64s(n, simd.mul_f64s(quarter, simd.splat_f64s(4.0)));
    let is = |v: f64| simd.equal_f64s(q, simd.splat_f64s(v));
    // Quadrants 1 and 3 swap sine and cosine; the sine is negative in 2 and 3, the cosine in
    // 1 and 2.
    let odd = simd.or_m64s(is(1.0), is(3.0));
    let s = simd.select_f64s(odd, cos_r, sin_r);
    let c = simd.select_f64s(odd, sin_r, cos_r);
    let s = simd.select_f64s(simd.or_m64s(is(2.0), is(3.0)), simd.neg_f64s(s), s);
    let c = simd.select_f64s(simd.or_m64s(is(1.0), is(2.0)), simd.neg_f64s(c), c);
    (s, c)
}

/// `sin` and `cos` of every lane of `x`: [`sin_cos`] on the instruction set of `simd`, and
/// libm's for the lanes beyond [`SIN_COS_LIMIT`] (or not finite). Within 2 ulp of glibc's for
/// `|x| <= SIN_COS_LIMIT` on every instruction set, and glibc's own beyond (`tests/lanes.rs`).
#[inline(always)]
pub fn sin_cos_lanes<S: Simd>(simd: S, x: &Lanes) -> (Lanes, Lanes) {
    let mut s = [0.0; BATCH];
    let mut c = [0.0; BATCH];
    for chunk in 0..BATCH / S::F64_LANES {
        let (sv, cv) = sin_cos(simd, load::<S>(x, chunk));
        store::<S>(&mut s, chunk, sv);
        store::<S>(&mut c, chunk, cv);
    }
    for l in 0..BATCH {
        // Beyond the limit, infinite or NaN.
        if x[l].abs() > SIN_COS_LIMIT || x[l].is_nan() {
            (s[l], c[l]) = x[l].sin_cos();
        }
    }
    (s, c)
}

/// `ln 2` as a double with 21 trailing zero bits, so that `n * hi` is exact for `|n| < 2^21`,
/// and the double nearest to the rest (Cody and Waite's reduction for `exp`).
const LN2: (f64, f64) = (0.6931471803691238, 1.9082149292705877e-10);
/// Below this magnitude [`exp_lanes`] computes the lane itself: `exp(x)` is a normal double
/// (above `2.2e-308`, below `1.8e308`) and `2^n` for the reduction's `n` too.
pub const EXP_LIMIT: f64 = 708.0;
/// `E(r)` with `exp(r) = 1 + r + r^2 E(r)` for `|r| <= ln2 / 2`: the Chebyshev interpolant of
/// degree 10 of `(exp(r) - 1 - r) / r^2` (mpmath, 60 digits), highest degree first. Its own
/// error is 2.3e-19 relative to `exp(r)`, far below the rounding of its evaluation.
const EXP_E: [f64; 11] = [
    2.0914679376583935e-09,
    2.510520637395701e-08,
    2.7557273661348637e-07,
    2.7557255425746435e-06,
    2.4801587325533363e-05,
    0.00019841269874800493,
    0.0013888888888883752,
    0.008333333333326141,
    0.04166666666666667,
    0.1666666666666667,
    0.5,
];

/// `exp(r)` and `n` with `exp(x) = exp(r) 2^n`, `x = n ln2 + r`, `|r| <= ln2 / 2` (about),
/// for every lane with `|x| <= EXP_LIMIT`; the power of two is applied by [`exp_lanes`].
#[inline(always)]
fn exp_reduced<S: Simd>(simd: S, x: S::f64s) -> (S::f64s, S::f64s) {
    let n = nearest_integer(
        simd,
        simd.mul_f64s(x, simd.splat_f64s(std::f64::consts::LOG2_E)),
    );
    let r = simd.sub_f64s(
        simd.sub_f64s(x, simd.mul_f64s(n, simd.splat_f64s(LN2.0))),
        simd.mul_f64s(n, simd.splat_f64s(LN2.1)),
    );
    let r2 = simd.mul_f64s(r, r);
    // 1 + (r + r^2 E(r)): the small part first, so its rounding is relative to it.
    let small = simd.mul_add_e_f64s(r2, horner(simd, &EXP_E, r), r);
    (simd.add_f64s(simd.splat_f64s(1.0), small), n)
}

/// `exp` of every lane of `x`: a Cody-Waite reduction to `|r| <= ln2 / 2`, a polynomial, and
/// an exact scaling by `2^n`, on the instruction set of `simd`; libm's for the lanes beyond
/// [`EXP_LIMIT`] (or NaN), where the result leaves the normal range. Within 1 ulp of glibc's
/// for `|x| <= EXP_LIMIT` on every instruction set, and glibc's own beyond (`tests/lanes.rs`).
#[inline(always)]
pub fn exp_lanes<S: Simd>(simd: S, x: &Lanes) -> Lanes {
    let mut mantissa = [0.0; BATCH];
    let mut power = [0.0; BATCH];
    for chunk in 0..BATCH / S::F64_LANES {
        let (m, n) = exp_reduced(simd, load::<S>(x, chunk));
        store::<S>(&mut mantissa, chunk, m);
        store::<S>(&mut power, chunk, n);
    }
    let mut out = [0.0; BATCH];
    for l in 0..BATCH {
        out[l] = if x[l].abs() <= EXP_LIMIT {
            // 2^n from its bits: n is an integer in [-1022, 1022] here, so n + 1023 is a
            // biased exponent of a normal double (the cast is exact).
            let biased = (power[l] as i64 + 1023) as u64;
            mantissa[l] * f64::from_bits(biased << 52)
        } else {
            x[l].exp()
        };
    }
    out
}
