//! What the square-root filters' equality tests compare: every quantity of two runs' records
//! that a metric reads.

use kalibra_filters::StepRecord;
use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix};

/// Largest difference of `a` and `b` relative to `max(1, |a|)`.
pub fn rel<R: Dim, C: Dim>(a: &OMatrix<f64, R, C>, b: &OMatrix<f64, R, C>) -> f64
where
    DefaultAllocator: kalibra_linalg::nalgebra::allocator::Allocator<R, C>,
{
    (a - b).amax() / a.amax().max(1.0)
}

/// The largest relative difference between two runs' records: prior and posterior, `S`,
/// gain, `H`, innovation, the prior's split, NIS and log-likelihood.
pub fn worst_difference<N: Dim, M: Dim>(a: &[StepRecord<N, M>], b: &[StepRecord<N, M>]) -> f64
where
    DefaultAllocator: Alloc<N, M>,
{
    assert_eq!(a.len(), b.len());
    let mut worst = 0.0f64;
    for (a, b) in a.iter().zip(b) {
        assert_eq!(a.step(), b.step());
        for d in [
            rel(&a.prior().mean, &b.prior().mean),
            rel(&a.prior().cov, &b.prior().cov),
            rel(&a.posterior().mean, &b.posterior().mean),
            rel(&a.posterior().cov, &b.posterior().cov),
            rel(a.s_matrix(), b.s_matrix()),
            rel(a.gain(), b.gain()),
            rel(a.h(), b.h()),
            rel(a.innovation(), b.innovation()),
            rel(a.propagated(), b.propagated()),
            rel(a.process_noise(), b.process_noise()),
            (a.nis() - b.nis()).abs() / a.nis().max(1.0),
            (a.log_likelihood() - b.log_likelihood()).abs() / a.log_likelihood().abs().max(1.0),
        ] {
            worst = worst.max(d);
        }
    }
    worst
}
