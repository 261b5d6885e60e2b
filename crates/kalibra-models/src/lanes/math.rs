//! Elementary functions on SIMD vectors of f64, generic over [`pulp::Simd`], for models that
//! evaluate their lanes together. Each is `#[inline(always)]`, so it compiles inside the
//! caller's dispatched function for its instruction set.

use pulp::Simd;

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
