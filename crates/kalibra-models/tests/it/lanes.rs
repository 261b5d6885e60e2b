//! The lane-wise elementary functions of `kalibra_models::lanes::math` against glibc's, on
//! every instruction set this CPU has, and the lane-wise models against their scalar selves.

use kalibra_models::lanes::math;
use pulp::{Simd, WithSimd};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Distance in units in the last place between two doubles of the same sign (0 for equal
/// values, NaN and NaN included; `u64::MAX` for a NaN against a number).
fn ulps(a: f64, b: f64) -> u64 {
    if a.is_nan() || b.is_nan() {
        return if a.is_nan() && b.is_nan() {
            0
        } else {
            u64::MAX
        };
    }
    if a == b {
        return 0;
    }
    // Map the doubles to a monotonic integer line (negative values below positive ones).
    let key = |x: f64| {
        let bits = x.to_bits() as i64;
        if bits < 0 { i64::MIN - bits } else { bits }
    };
    key(a).abs_diff(key(b))
}

/// Runs `$body` with `$simd` the token and `$isa` the name of every instruction set this CPU
/// has (the scalar fallback always).
macro_rules! each_isa {
    ($simd:ident, $isa:ident => $body:expr) => {{
        {
            let ($simd, $isa) = (pulp::Scalar::new(), "scalar");
            $body;
        }
        #[cfg(target_arch = "x86_64")]
        {
            if let Some($simd) = pulp::x86::V3::try_new() {
                let $isa = "avx2";
                $body;
            }
            if let Some($simd) = pulp::x86::V4::try_new() {
                let $isa = "avx512";
                $body;
            }
        }
        #[cfg(target_arch = "aarch64")]
        if let Some($simd) = pulp::aarch64::Neon::try_new() {
            let $isa = "neon";
            $body;
        }
    }};
}

/// The largest distance in ulp between a lane-wise function and glibc's over `points`, taken
/// `BATCH` at a time: `ours` maps a batch of arguments to one or more batches of results,
/// `glibc` one argument to the same results. Beyond `limit` (or at NaN) the lane-wise
/// function hands the lane to libm, so it must be glibc's own there. `Some(failure)` when
/// the distance exceeds `bound` or a lane beyond the limit is not libm's.
fn against_glibc(
    isa: &str,
    points: &[f64],
    limit: f64,
    bound: u64,
    ours: impl Fn(&[f64; 8]) -> Vec<[f64; 8]>,
    glibc: impl Fn(f64) -> Vec<f64>,
) -> Option<String> {
    let mut worst = (0u64, 0.0);
    for chunk in points.chunks(8) {
        let mut x = [0.0; 8];
        x[..chunk.len()].copy_from_slice(chunk);
        let out = ours(&x);
        for (l, v) in chunk.iter().enumerate() {
            let d = glibc(*v)
                .iter()
                .zip(&out)
                .map(|(r, o)| ulps(o[l], *r))
                .max()
                .unwrap_or(0);
            if (v.abs() > limit || v.is_nan()) && d != 0 {
                return Some(format!("{isa}: libm's own beyond the limit, not at {v:e}"));
            }
            if d > worst.0 {
                worst = (d, *v);
            }
        }
    }
    (worst.0 > bound).then(|| format!("{isa}: {} ulp at {:e}", worst.0, worst.1))
}

/// `atan2` of 8 lanes on one instruction set.
struct Atan2<'a> {
    y: &'a [f64; 8],
    x: &'a [f64; 8],
    out: &'a mut [f64; 8],
}

impl WithSimd for Atan2<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let n = S::F64_LANES;
        for c in 0..8 / n {
            let y = S::as_simd_f64s(self.y).0[c];
            let x = S::as_simd_f64s(self.x).0[c];
            S::as_mut_simd_f64s(self.out).0[c] = math::atan2(simd, y, x);
        }
    }
}

/// Runs `op` on every instruction set this CPU has, by name.
fn on_every_isa(mut run: impl FnMut(&str, &dyn Fn(Atan2<'_>))) {
    run("scalar", &|op| Simd::vectorize(pulp::Scalar::new(), op));
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(simd) = pulp::x86::V3::try_new() {
            run("avx2", &move |op| Simd::vectorize(simd, op));
        }
        if let Some(simd) = pulp::x86::V4::try_new() {
            run("avx512", &move |op| Simd::vectorize(simd, op));
        }
    }
    #[cfg(target_arch = "aarch64")]
    if let Some(simd) = pulp::aarch64::Neon::try_new() {
        run("neon", &move |op| Simd::vectorize(simd, op));
    }
}

/// Log-uniform magnitudes from 1e-300 to 1e300 with random signs, and points near the axes,
/// the diagonals and the reduction boundary tan(pi/8).
fn samples(n: usize) -> Vec<(f64, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut out = Vec::with_capacity(n);
    let signed = |rng: &mut ChaCha8Rng, v: f64| if rng.random::<bool>() { v } else { -v };
    for i in 0..n {
        let (y, x) = match i % 3 {
            0 => {
                let y = 10f64.powf(rng.random_range(-300.0..300.0));
                let x = 10f64.powf(rng.random_range(-300.0..300.0));
                (y, x)
            }
            1 => {
                // Ratios near 1, tan(pi/8) and 1/tan(pi/8), at one scale.
                let s = 10f64.powf(rng.random_range(-20.0..20.0));
                let r = [1.0, 0.41421356237309503, 2.414213562373095][rng.random_range(0..3)];
                (s * r * (1.0 + rng.random_range(-1e-3..1e-3)), s)
            }
            _ => {
                // Ordinary bearings: a unit circle's worth of angles.
                let a: f64 = rng.random_range(-4.0..4.0);
                let r = 10f64.powf(rng.random_range(-3.0..6.0));
                (r * a.sin(), r * a.cos())
            }
        };
        out.push((signed(&mut rng, y), signed(&mut rng, x)));
    }
    out
}

const SPECIALS: [f64; 10] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NAN,
    f64::MIN_POSITIVE,
    5e-324,
    f64::MAX,
];

#[test]
fn atan2_is_within_3_ulp_of_glibc_over_the_whole_range_on_every_isa() {
    let mut points = samples(1_000_000);
    for y in SPECIALS {
        for x in SPECIALS {
            points.push((y, x));
        }
    }
    let mut failures = Vec::new();
    on_every_isa(|isa, run| {
        let mut worst = (0u64, 0.0, 0.0);
        for chunk in points.chunks(8) {
            let mut y = [0.0; 8];
            let mut x = [0.0; 8];
            for (i, (py, px)) in chunk.iter().enumerate() {
                y[i] = *py;
                x[i] = *px;
            }
            let mut out = [0.0; 8];
            run(Atan2 {
                y: &y,
                x: &x,
                out: &mut out,
            });
            for i in 0..chunk.len() {
                let d = ulps(out[i], y[i].atan2(x[i]));
                if d > worst.0 {
                    worst = (d, y[i], x[i]);
                }
            }
        }
        if worst.0 > 3 {
            failures.push(format!(
                "{isa}: {} ulp at atan2({:e}, {:e})",
                worst.0, worst.1, worst.2
            ));
        }
    });
    assert!(failures.is_empty(), "{failures:?}");
}

mod models {
    use super::*;
    use kalibra_linalg::{Matrix2, U2, Vector2};
    use kalibra_models::lanes::{BATCH, LaneDynamics, LaneMeasurement, Lanes, PerLane};
    use kalibra_models::{Bearing, BearingReference, Coordinate, LinearGaussian, Tabulated};

    /// Predicts `x`, and evaluates the measurement at `at` (the same for both models, so that
    /// `H` and `R` can be compared to the bit).
    struct Eval<'a, D, H> {
        dynamics: &'a D,
        measurement: &'a H,
        at: &'a [Lanes; 2],
        x: &'a mut [Lanes; 2],
        f: &'a mut [[Lanes; 2]; 2],
        q: &'a mut [[Lanes; 2]; 2],
        z: &'a [Lanes; 1],
        nu: &'a mut [Lanes; 1],
        h: &'a mut [[Lanes; 2]; 1],
        r: &'a mut [[Lanes; 1]; 1],
    }

    impl<D: LaneDynamics<2>, H: LaneMeasurement<2, 1>> WithSimd for Eval<'_, D, H> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            self.dynamics.predict_lanes(simd, 3, self.x, self.f, self.q);
            self.measurement
                .innovate_lanes(simd, 4, self.at, self.z, self.nu, self.h, self.r);
        }
    }

    type Out = (
        [Lanes; 2],
        [[Lanes; 2]; 2],
        [[Lanes; 2]; 2],
        [Lanes; 1],
        [[Lanes; 2]; 1],
        [[Lanes; 1]; 1],
    );

    fn eval<S: Simd, D: LaneDynamics<2>, H: LaneMeasurement<2, 1>>(
        simd: S,
        d: &D,
        m: &H,
        x0: &[Lanes; 2],
        z: &[Lanes; 1],
    ) -> Out {
        let mut out: Out = (
            *x0,
            [[[0.0; BATCH]; 2]; 2],
            [[[0.0; BATCH]; 2]; 2],
            [[0.0; BATCH]; 1],
            [[[0.0; BATCH]; 2]; 1],
            [[[0.0; BATCH]; 1]; 1],
        );
        Simd::vectorize(
            simd,
            Eval {
                dynamics: d,
                measurement: m,
                at: x0,
                x: &mut out.0,
                f: &mut out.1,
                q: &mut out.2,
                z,
                nu: &mut out.3,
                h: &mut out.4,
                r: &mut out.5,
            },
        );
        out
    }

    fn check<S: Simd>(simd: S, isa: &str) {
        let dynamics = LinearGaussian::new(
            Matrix2::new(0.9, 0.1, -0.2, 1.0),
            Matrix2::new(0.1, 0.01, 0.01, 0.1),
        )
        .unwrap();
        let platform = Tabulated::new(
            (0..10)
                .map(|k| Vector2::new((k as f64).cos(), (k as f64).sin()))
                .collect(),
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for (reference, translational) in [
            (BearingReference::XAxis, (0.0, 0.0)),
            (BearingReference::North, (0.3, 0.7)),
        ] {
            let bearing = Bearing::from_coordinates(
                U2,
                [Coordinate::State(0), Coordinate::State(1)],
                reference,
                0.025,
                platform.clone(),
            )
            .unwrap()
            .with_translational_noise(translational.0, translational.1)
            .unwrap();
            let line = Bearing::from_coordinates(
                U2,
                [Coordinate::State(0), Coordinate::Constant(-3.0)],
                reference,
                0.025,
                platform.clone(),
            )
            .unwrap();
            for sensor in [bearing, line] {
                let mut worst_x = 0.0f64;
                let mut worst_nu = 0u64;
                for _ in 0..2000 {
                    let mut x = [[0.0; BATCH]; 2];
                    let mut z = [[0.0; BATCH]; 1];
                    for l in 0..BATCH {
                        x[0][l] = rng.random_range(-30.0..30.0);
                        x[1][l] = rng.random_range(-30.0..30.0);
                        // Measurements anywhere in (-pi, pi], and a few far outside it.
                        z[0][l] = if rng.random_range(0..50) == 0 {
                            rng.random_range(-100.0..100.0)
                        } else {
                            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
                        };
                    }
                    let a = eval(simd, &dynamics, &sensor, &x, &z);
                    let b = eval(simd, &PerLane(&dynamics), &PerLane(&sensor), &x, &z);
                    // F and Q broadcast, H and R by the scalar operations: equal to the bit.
                    assert_eq!((a.1, a.2, a.4, a.5), (b.1, b.2, b.4, b.5), "{isa}");
                    for l in 0..BATCH {
                        // F x: relative to the input's size (a sum that cancels keeps the
                        // absolute error of its terms).
                        let size = x[0][l].abs().max(x[1][l].abs());
                        for i in 0..2 {
                            worst_x = worst_x.max((a.0[i][l] - b.0[i][l]).abs() / size);
                        }
                        // The innovation: atan2 within 3 ulp of glibc's, on an angle of pi at
                        // most, so within 3 ulp of pi of the scalar one
                        // (in ulp of the larger of pi and |z|: z - h(x) rounds at |z|'s scale).
                        let d = (a.3[0][l] - b.3[0][l]).abs();
                        let scale = z[0][l].abs().max(std::f64::consts::PI);
                        worst_nu = worst_nu.max((d / f64::EPSILON / scale).ceil() as u64);
                    }
                }
                assert!(worst_x <= 4.0 * f64::EPSILON, "{isa}: {worst_x:e}");
                assert!(worst_nu <= 3, "{isa}: {worst_nu}");
            }
        }
    }

    /// The linear observation: `z - H x` lane-wise against `PerLane`, `H` and `R` broadcast.
    fn check_linear<S: Simd>(simd: S, isa: &str) {
        use kalibra_linalg::nalgebra::SMatrix;
        use kalibra_models::LinearObservation;
        let sensor = LinearObservation::new(
            SMatrix::<f64, 1, 2>::new(0.7, -1.3),
            kalibra_linalg::Matrix1::new(0.04),
        )
        .unwrap();
        let dynamics = LinearGaussian::new(Matrix2::identity(), Matrix2::identity()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut worst = 0.0f64;
        for _ in 0..2000 {
            let mut x = [[0.0; BATCH]; 2];
            let mut z = [[0.0; BATCH]; 1];
            for l in 0..BATCH {
                x[0][l] = rng.random_range(-30.0..30.0);
                x[1][l] = rng.random_range(-30.0..30.0);
                z[0][l] = rng.random_range(-60.0..60.0);
            }
            let a = eval(simd, &dynamics, &sensor, &x, &z);
            let b = eval(simd, &dynamics, &PerLane(&sensor), &x, &z);
            assert_eq!((a.4, a.5), (b.4, b.5), "{isa}: H and R");
            for l in 0..BATCH {
                // A fused multiply-add is the one difference: within an ulp of the terms.
                let size = z[0][l].abs() + 0.7 * x[0][l].abs() + 1.3 * x[1][l].abs();
                worst = worst.max((a.3[0][l] - b.3[0][l]).abs() / size);
            }
        }
        assert!(worst <= 2.0 * f64::EPSILON, "{isa}: {worst:e}");
    }

    #[test]
    fn the_lane_wise_linear_observation_agrees_with_the_scalar_one_on_every_isa() {
        each_isa!(simd, isa => check_linear(simd, isa));
    }

    #[test]
    fn lane_wise_models_agree_with_their_scalar_selves_on_every_isa() {
        each_isa!(simd, isa => check(simd, isa));
    }
}

mod radar {
    use super::*;
    use kalibra_linalg::Matrix3;
    use kalibra_models::RadarRates;
    use kalibra_models::lanes::{BATCH, LaneMeasurement, Lanes, PerLane};

    type Out = ([Lanes; 3], [[Lanes; 4]; 3], [[Lanes; 3]; 3]);

    struct Innovate<'a, H> {
        m: &'a H,
        x: &'a [Lanes; 4],
        z: &'a [Lanes; 3],
        out: &'a mut Out,
    }

    impl<H: LaneMeasurement<4, 3>> WithSimd for Innovate<'_, H> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            let (nu, h, r) = self.out;
            self.m.innovate_lanes(simd, 0, self.x, self.z, nu, h, r);
        }
    }

    fn check<S: Simd>(simd: S, isa: &str) {
        let radar = RadarRates::new(Matrix3::from_diagonal(&[225.0, 3e-6, 3e-8].into())).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut worst = 0u64;
        for _ in 0..5000 {
            let mut x = [[0.0; BATCH]; 4];
            let mut z = [[0.0; BATCH]; 3];
            for l in 0..BATCH {
                // Re-entry scales: positions to 3e5 m either side, velocities to 3e3 m/s.
                for (i, xi) in x.iter_mut().enumerate() {
                    let scale = if i % 2 == 0 { 3e5 } else { 3e3 };
                    xi[l] = rng.random_range(-scale..scale);
                }
                z[0][l] = rng.random_range(-3e3..3e3);
                z[1][l] = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
                z[2][l] = rng.random_range(-0.1..0.1);
            }
            let mut a: Out = (
                [[0.0; BATCH]; 3],
                [[[0.0; BATCH]; 4]; 3],
                [[[0.0; BATCH]; 3]; 3],
            );
            let mut b = a;
            Simd::vectorize(
                simd,
                Innovate {
                    m: &radar,
                    x: &x,
                    z: &z,
                    out: &mut a,
                },
            );
            Simd::vectorize(
                simd,
                Innovate {
                    m: &PerLane(&radar),
                    x: &x,
                    z: &z,
                    out: &mut b,
                },
            );
            // Range rate, sightline rate, H and R: the scalar operations, to the bit.
            assert_eq!(
                (a.0[0], a.0[2], a.1, a.2),
                (b.0[0], b.0[2], b.1, b.2),
                "{isa}"
            );
            for l in 0..BATCH {
                let d = (a.0[1][l] - b.0[1][l]).abs();
                worst = worst.max((d / f64::EPSILON / std::f64::consts::PI).ceil() as u64);
            }
        }
        // The elevation innovation: atan2 within 3 ulp of glibc's, on an angle of pi at most.
        assert!(worst <= 3, "{isa}: {worst}");
    }

    #[test]
    fn the_lane_wise_radar_agrees_with_the_scalar_one_on_every_isa() {
        each_isa!(simd, isa => check(simd, isa));
    }
}

mod trig {
    use super::*;
    use kalibra_models::lanes::math::{SIN_COS_LIMIT, sin_cos_lanes};
    use kalibra_models::lanes::{BATCH, Lanes};

    struct SinCos<'a> {
        x: &'a Lanes,
        out: &'a mut (Lanes, Lanes),
    }

    impl WithSimd for SinCos<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            *self.out = sin_cos_lanes(simd, self.x);
        }
    }

    /// Log-uniform magnitudes up to 1e6 (beyond the SIMD range too), ordinary angles, the
    /// doubles nearest to multiples of pi/2, points next to multiples of pi/4, and the special
    /// values.
    fn samples() -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let mut out = Vec::new();
        for i in 0..1_000_000 {
            let v: f64 = match i % 4 {
                0 => 10f64.powf(rng.random_range(-300.0..6.0)),
                1 => rng.random_range(-20.0..20.0),
                // The doubles nearest to multiples of pi/2: the hardest reductions.
                2 => rng.random_range(-70_000i64..70_000) as f64 * std::f64::consts::FRAC_PI_2,
                _ => {
                    let k = rng.random_range(-200_000i64..200_000) as f64;
                    k * std::f64::consts::FRAC_PI_4 * (1.0 + rng.random_range(-1e-12..1e-12))
                }
            };
            out.push(if rng.random::<bool>() { v } else { -v });
        }
        out.extend([
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            5e-324,
            f64::MAX,
        ]);
        out.extend([
            SIN_COS_LIMIT,
            -SIN_COS_LIMIT,
            SIN_COS_LIMIT * (1.0 + f64::EPSILON),
        ]);
        out
    }

    fn check<S: Simd>(simd: S, isa: &str, points: &[f64]) -> Option<String> {
        let ours = |x: &Lanes| {
            let mut out = ([0.0; BATCH], [0.0; BATCH]);
            Simd::vectorize(simd, SinCos { x, out: &mut out });
            vec![out.0, out.1]
        };
        against_glibc(isa, points, SIN_COS_LIMIT, 2, ours, |v| {
            vec![v.sin(), v.cos()]
        })
    }

    #[test]
    fn sin_cos_is_within_2_ulp_of_glibc_on_every_isa() {
        let points = samples();
        let mut failures = Vec::new();
        each_isa!(simd, isa => failures.extend(check(simd, isa, &points)));
        assert!(failures.is_empty(), "{failures:?}");
    }
}

mod accel_axis {
    use super::*;
    use kalibra_models::lanes::{BATCH, LaneDynamics, Lanes, PerLane};
    use kalibra_models::{AccelAxis, Target3dParams};

    type Out = ([Lanes; 3], [[Lanes; 3]; 3], [[Lanes; 3]; 3]);

    struct Predict<'a, D> {
        d: &'a D,
        out: &'a mut Out,
    }

    impl<D: LaneDynamics<3>> WithSimd for Predict<'_, D> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            let (x, f, q) = self.out;
            self.d.predict_lanes(simd, 5, x, f, q);
        }
    }

    fn check<S: Simd>(simd: S, isa: &str) {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        for axis in 0..3 {
            let model = AccelAxis::new(Target3dParams::default(), axis).unwrap();
            let mut worst = 0.0f64;
            for _ in 0..5000 {
                let mut x = [[0.0; BATCH]; 3];
                for xi in x.iter_mut() {
                    for v in xi.iter_mut() {
                        *v = rng.random_range(-50.0..50.0);
                    }
                }
                let mut a: Out = (x, [[[0.0; BATCH]; 3]; 3], [[[0.0; BATCH]; 3]; 3]);
                let mut b = a;
                Simd::vectorize(
                    simd,
                    Predict {
                        d: &model,
                        out: &mut a,
                    },
                );
                Simd::vectorize(
                    simd,
                    Predict {
                        d: &PerLane(&model),
                        out: &mut b,
                    },
                );
                assert_eq!(a.2, b.2, "{isa}: Q");
                // The separate lane-wise transition and Jacobian are the prediction's parts,
                // to the bit.
                let mut t = x;
                model.transition_lanes(simd, 5, &mut t);
                assert_eq!(t, a.0, "{isa}: transition_lanes");
                let mut f = [[[0.0; BATCH]; 3]; 3];
                model.jacobian_lanes(simd, &x, &mut f);
                assert_eq!(f, a.1, "{isa}: jacobian_lanes");
                for l in 0..BATCH {
                    // Relative to the state's size: sin and cos within 2 ulp of glibc's enter
                    // a sum with the other terms.
                    let size = x.iter().map(|xi| xi[l].abs()).fold(1.0, f64::max);
                    for i in 0..3 {
                        worst = worst.max((a.0[i][l] - b.0[i][l]).abs() / size);
                        for j in 0..3 {
                            worst = worst.max((a.1[i][j][l] - b.1[i][j][l]).abs());
                        }
                    }
                }
            }
            assert!(worst <= 2.0 * f64::EPSILON, "{isa}, axis {axis}: {worst:e}");
        }
    }

    #[test]
    fn the_lane_wise_axis_agrees_with_the_scalar_one_on_every_isa() {
        each_isa!(simd, isa => check(simd, isa));
    }
}

mod exp {
    use super::*;
    use kalibra_models::lanes::math::{EXP_LIMIT, exp_lanes};
    use kalibra_models::lanes::{BATCH, Lanes};

    struct Exp<'a> {
        x: &'a Lanes,
        out: &'a mut Lanes,
    }

    impl WithSimd for Exp<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            *self.out = exp_lanes(simd, self.x);
        }
    }

    /// Uniform over the SIMD range, ordinary arguments, the neighbourhoods of the reduction's
    /// switch points (odd multiples of ln2 / 2), beyond the limit, and the special values.
    fn samples() -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(29);
        let mut out = Vec::new();
        for i in 0..1_000_000 {
            out.push(match i % 4 {
                0 => rng.random_range(-EXP_LIMIT..EXP_LIMIT),
                1 => rng.random_range(-20.0..20.0),
                2 => {
                    let k = rng.random_range(-1021i64..1021) as f64 + 0.5;
                    k * std::f64::consts::LN_2 * (1.0 + rng.random_range(-1e-14..1e-14))
                }
                _ => {
                    let v = 10f64.powf(rng.random_range(-300.0..3.2));
                    if rng.random::<bool>() { v } else { -v }
                }
            });
        }
        out.extend([
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            5e-324,
            f64::MAX,
            -f64::MAX,
            EXP_LIMIT,
            -EXP_LIMIT,
            709.7,
            -745.0,
            -746.0,
        ]);
        out
    }

    fn check<S: Simd>(simd: S, isa: &str, points: &[f64]) -> Option<String> {
        let ours = |x: &Lanes| {
            let mut out = [0.0; BATCH];
            Simd::vectorize(simd, Exp { x, out: &mut out });
            vec![out]
        };
        against_glibc(isa, points, EXP_LIMIT, 1, ours, |v| vec![v.exp()])
    }

    #[test]
    fn exp_is_within_1_ulp_of_glibc_on_every_isa() {
        let points = samples();
        let mut failures = Vec::new();
        each_isa!(simd, isa => failures.extend(check(simd, isa, &points)));
        assert!(failures.is_empty(), "{failures:?}");
    }
}

mod ballistic {
    use super::*;
    use kalibra_linalg::Matrix4;
    use kalibra_models::lanes::{BATCH, LaneDynamics, Lanes, PerLane};
    use kalibra_models::{Ballistic, BallisticParams, ballistic_f1};

    type Out = ([Lanes; 4], [[Lanes; 4]; 4], [[Lanes; 4]; 4]);

    struct Predict<'a, D> {
        d: &'a D,
        out: &'a mut Out,
    }

    impl<D: LaneDynamics<4>> WithSimd for Predict<'_, D> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            let (x, f, q) = self.out;
            self.d.predict_lanes(simd, 2, x, f, q);
        }
    }

    fn check<S: Simd>(simd: S, isa: &str) {
        let params = BallisticParams {
            period: 2.0,
            beta: 40_000.0,
            gravity: 9.81,
        };
        let q = Matrix4::new(
            2.0, 0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.5, 0.0, 0.0, 0.5, 1.0,
        );
        let model = Ballistic::new(params, q).unwrap();
        let f1 = ballistic_f1(params.period);
        let mut rng = ChaCha8Rng::seed_from_u64(37);
        let mut worst = 0.0f64;
        for round in 0..5000 {
            let mut x = [[0.0; BATCH]; 4];
            for l in 0..BATCH {
                // Altitudes either side of the density's switch at 9144 m, and on it.
                let h = match l {
                    0 => 9144.0,
                    1 => rng.random_range(9000.0..9300.0),
                    _ => rng.random_range(-100.0..1.2e5),
                };
                let state = [
                    rng.random_range(0.0..3e5),
                    rng.random_range(-3000.0..3000.0),
                    h,
                    rng.random_range(-3000.0..3000.0),
                ];
                for (xi, v) in x.iter_mut().zip(state) {
                    xi[l] = v;
                }
            }
            if round % 7 == 0 {
                // At rest: the Jacobian's limit without the outer-product term.
                x[1][3] = 0.0;
                x[3][3] = 0.0;
            }
            let mut a: Out = (x, [[[0.0; BATCH]; 4]; 4], [[[0.0; BATCH]; 4]; 4]);
            let mut b = a;
            Simd::vectorize(
                simd,
                Predict {
                    d: &model,
                    out: &mut a,
                },
            );
            Simd::vectorize(
                simd,
                Predict {
                    d: &PerLane(&model),
                    out: &mut b,
                },
            );
            assert_eq!(a.2, b.2, "{isa}: Q");
            for l in 0..BATCH {
                // The exponential within 1 ulp of glibc's enters the drag, a small part of
                // each entry: the state relative to its size (a sum that cancels keeps the
                // absolute error of its terms), the Jacobian relative to each entry.
                let size = x.iter().map(|xi| xi[l].abs()).fold(1.0, f64::max);
                for i in 0..4 {
                    worst = worst.max((a.0[i][l] - b.0[i][l]).abs() / size);
                    for j in 0..4 {
                        // F = F1 + G dfkk/dx: relative to the size of its two terms.
                        let scale = b.1[i][j][l].abs() + f1[(i, j)].abs() + 1e-300;
                        worst = worst.max((a.1[i][j][l] - b.1[i][j][l]).abs() / scale);
                    }
                }
            }
        }
        assert!(worst <= 4.0 * f64::EPSILON, "{isa}: {worst:e}");
    }

    #[test]
    fn the_lane_wise_ballistic_model_agrees_with_the_scalar_one_on_every_isa() {
        each_isa!(simd, isa => check(simd, isa));
    }
}

/// `wrap_angle_lanes` of 8 lanes on one instruction set.
struct Wrap<'a>(&'a mut [f64; 8]);

impl WithSimd for Wrap<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        math::wrap_angle_lanes(simd, self.0);
    }
}

#[test]
fn wrap_angle_lanes_is_wrap_angle_to_the_bit_on_every_instruction_set() {
    use std::f64::consts::PI;
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    // The boundaries (+-pi, +-2 pi and their neighbours, signed zeros), the specials, then
    // differences of angles and larger angles.
    let mut values = vec![
        0.0,
        -0.0,
        PI,
        -PI,
        2.0 * PI,
        -2.0 * PI,
        PI.next_up(),
        PI.next_down(),
        (-PI).next_up(),
        (-PI).next_down(),
        (2.0 * PI).next_down(),
        (-2.0 * PI).next_up(),
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e-300,
    ];
    values.extend((0..20_000).map(|i| {
        let scale = if i % 4 == 0 { 40.0 } else { 2.0 * PI };
        (rng.random::<f64>() * 2.0 - 1.0) * scale
    }));
    while values.len() % 8 != 0 {
        values.push(0.5);
    }
    on_every_isa(|name, _| {
        let mut checked = 0;
        for chunk in values.chunks(8) {
            let mut lanes: [f64; 8] = chunk.try_into().unwrap();
            match name {
                "scalar" => Simd::vectorize(pulp::Scalar::new(), Wrap(&mut lanes)),
                #[cfg(target_arch = "x86_64")]
                "avx2" => Simd::vectorize(pulp::x86::V3::try_new().unwrap(), Wrap(&mut lanes)),
                #[cfg(target_arch = "x86_64")]
                "avx512" => Simd::vectorize(pulp::x86::V4::try_new().unwrap(), Wrap(&mut lanes)),
                #[cfg(target_arch = "aarch64")]
                "neon" => {
                    Simd::vectorize(pulp::aarch64::Neon::try_new().unwrap(), Wrap(&mut lanes))
                }
                _ => unreachable!(),
            }
            for (&v, &w) in chunk.iter().zip(&lanes) {
                let want = kalibra_models::wrap_angle(v);
                assert!(
                    want.to_bits() == w.to_bits() || (want.is_nan() && w.is_nan()),
                    "{name}: wrap_angle({v:e}) = {want:e}, lanes {w:e}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, values.len());
    });
}
