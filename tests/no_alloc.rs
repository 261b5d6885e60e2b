//! Per-step work on the fixed-size path allocates nothing: a counting global allocator watches
//! a simulation step, a KF predict and update, and the NEES and NIS of the step.

// A global allocator can only be written with `unsafe`; it forwards to the system allocator.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use kalibra::filters::{Ekf, Filter, Kf};
use kalibra::linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra::metrics::nees;
use kalibra::models::{Kinematic, Simulator};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

struct Counting;

// Counted per thread, since the test harness runs tests in parallel. A `const` thread-local
// without a destructor needs no allocation itself.
thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn fixed_size_steps_do_not_allocate() {
    let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
    let f = cv.dynamics(U4).unwrap();
    let h = cv
        .position_measurement(U4, U2, Matrix2::identity() * 100.0)
        .unwrap();
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut truth = Simulator::new(&f, &h, x0, 0).unwrap();
    let mut kf = Kf::new(&f, &h, x0, Matrix4::identity() * 100.0).unwrap();
    let mut ekf = Ekf::new(&f, &h, x0, Matrix4::identity() * 100.0).unwrap();
    let mut total = 0.0;
    let before = allocations();
    for k in 0..1000 {
        let (x, z) = truth.step(&mut rng).unwrap();
        if k > 0 {
            kf.predict().unwrap();
            ekf.predict().unwrap();
        }
        let rec = kf.update(&z).unwrap();
        let e = x - rec.posterior().mean;
        total += rec.nis() + nees(&e, &rec.posterior().cov).unwrap() + rec.nees(&e).unwrap();
        total += rec.compute_a()[(0, 0)] + rec.compute_b()[(1, 1)];
        total += ekf.update(&z).unwrap().nis();
    }
    let allocations = allocations() - before;
    assert!(total.is_finite());
    assert_eq!(allocations, 0, "{allocations} allocations in 1000 steps");
}

/// The counter sees allocations when there are some: the same step on `Dyn` sizes allocates.
#[test]
fn the_counter_detects_dynamic_allocations() {
    use kalibra::linalg::{DMatrix, DVector};
    use kalibra::models::{LinearGaussian, LinearObservation};
    let f = LinearGaussian::new(DMatrix::<f64>::identity(2, 2), DMatrix::identity(2, 2)).unwrap();
    let h =
        LinearObservation::new(DMatrix::<f64>::identity(1, 2), DMatrix::identity(1, 1)).unwrap();
    let mut kf = Kf::new(&f, &h, DVector::zeros(2), DMatrix::identity(2, 2)).unwrap();
    let z = DVector::zeros(1);
    let before = allocations();
    kf.predict().unwrap();
    kf.update(&z).unwrap();
    assert!(allocations() > before);
}

/// On `Dyn` sizes from the faer threshold on, a step (predict, Joseph update, NEES) allocates
/// no more than on nalgebra's path: faer's operands are views of nalgebra's storage,
/// its Cholesky scratch is a per-thread buffer kept between calls, and its products write into
/// the result instead of into a temporary plus a transposed copy.
#[test]
fn faer_steps_allocate_no_more_than_nalgebra_steps() {
    use kalibra::linalg::{DMatrix, DVector, FAER_MIN_DIM, KernelPolicy, with_kernel_policy};
    use kalibra::models::{LinearGaussian, LinearObservation};
    for n in [FAER_MIN_DIM, 64] {
        let m = (n / 4).max(2);
        let wave = |i: usize, j: usize| ((i * 7 + j * 3) as f64).sin();
        let f = DMatrix::from_fn(n, n, |i, j| {
            0.01 * wave(i, j) + if i == j { 0.9 } else { 0.0 }
        });
        let h = DMatrix::from_fn(m, n, wave);
        let spd =
            |k: usize| DMatrix::from_fn(k, k, |i, j| if i == j { 2.0 } else { 0.5 / k as f64 });
        let dynamics = LinearGaussian::new(f, spd(n) * 0.1).unwrap();
        let measurement = LinearObservation::new(h, spd(m)).unwrap();
        let (z, x) = (DVector::from_element(m, 0.5), DVector::from_element(n, 0.1));
        let count = |policy| {
            with_kernel_policy(policy, || {
                let mut kf = Kf::new(&dynamics, &measurement, DVector::zeros(n), spd(n)).unwrap();
                let mut step = || {
                    kf.predict().unwrap();
                    let rec = kf.update(&z).unwrap();
                    rec.nees(&(&x - &rec.posterior().mean)).unwrap()
                };
                // The first steps size faer's per-thread buffers.
                let mut total = step() + step();
                let before = allocations();
                for _ in 0..10 {
                    total += step();
                }
                assert!(total.is_finite());
                allocations() - before
            })
        };
        let (faer, nalgebra) = (count(KernelPolicy::DEFAULT), count(KernelPolicy::NALGEBRA));
        assert!(
            faer <= nalgebra,
            "n = {n}: {faer} allocations in 10 faer steps, {nalgebra} in 10 nalgebra steps"
        );
    }
}
