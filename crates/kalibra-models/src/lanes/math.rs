//! Elementary functions on SIMD vectors of f64 for models that evaluate their lanes together:
//! the arctangent, sine and cosine and exponential of [`kalibra_linalg::simd::math`]
//! (re-exported here), and [`wrap_angle_lanes`], the lane-wise [`wrap_angle`](crate::wrap_angle)
//! that needs this crate's scalar function. Each is `#[inline(always)]`, so it compiles inside
//! the caller's dispatched function for its instruction set.

use pulp::Simd;

pub use kalibra_linalg::simd::math::{
    EXP_LIMIT, SIN_COS_LIMIT, atan2, exp_lanes, sin_cos, sin_cos_lanes,
};

use super::{BATCH, Lanes, load, store};

/// [`wrap_angle`](crate::wrap_angle) of every lane of `a`, in place, to the bit: the lanes below
/// `2 pi` in size (every difference of two angles in `(-pi, pi]`, and every arctangent) take
/// its two selects across the lanes; the others (a large angle, NaN, an infinity) the scalar
/// function.
#[inline(always)]
pub fn wrap_angle_lanes<S: Simd>(simd: S, a: &mut Lanes) {
    use std::f64::consts::PI;
    let given = *a;
    let (two_pi, pi, zero) = (
        simd.splat_f64s(2.0 * PI),
        simd.splat_f64s(PI),
        simd.splat_f64s(0.0),
    );
    for c in 0..BATCH / S::F64_LANES {
        let v = load::<S>(a, c);
        let w = simd.select_f64s(simd.less_than_f64s(v, zero), simd.add_f64s(v, two_pi), v);
        let w = simd.select_f64s(simd.greater_than_f64s(w, pi), simd.sub_f64s(w, two_pi), w);
        store::<S>(a, c, w);
    }
    for (out, &v) in a.iter_mut().zip(&given) {
        if v.abs() >= 2.0 * PI || v.is_nan() {
            *out = crate::wrap_angle(v);
        }
    }
}
