//! The lanes' estimates: the initial checks and the writes of one lane, as the scalar filters
//! check an initial estimate.

use kalibra_linalg::{SMatrix, SVector, check_finite};

use super::{BATCH, Lanes};
use crate::FilterError;

/// An initial covariance checked as the scalar filters check one, and symmetrised as they keep
/// it.
pub(super) fn initial_cov<const N: usize>(
    p: SMatrix<f64, N, N>,
) -> Result<SMatrix<f64, N, N>, FilterError> {
    Ok(kalibra_linalg::PsdMatrix::named(p, "initial covariance")
        .map_err(FilterError::Initial)?
        .matrix()
        .clone_owned())
}

/// The lanes of a batch that all start from `(x0, P0)`, checked as the scalar filters check an
/// initial estimate (and `P0` symmetrised as they keep it).
pub(super) fn initial_lanes<const N: usize>(
    x0: &SVector<f64, N>,
    p0: SMatrix<f64, N, N>,
) -> Result<([Lanes; N], [[Lanes; N]; N]), FilterError> {
    check_finite(x0, "initial mean").map_err(FilterError::Initial)?;
    let p0 = initial_cov(p0)?;
    Ok((
        std::array::from_fn(|i| [x0[i]; BATCH]),
        std::array::from_fn(|i| std::array::from_fn(|j| [p0[(i, j)]; BATCH])),
    ))
}

/// Sets lane `lane` to the estimate `(x, P)` (`x` already checked), after the initial check
/// of `P`; the lane is unchanged if it fails.
pub(super) fn set_lane_estimate<const N: usize>(
    xs: &mut [Lanes; N],
    ps: &mut [[Lanes; N]; N],
    lane: usize,
    x: &SVector<f64, N>,
    p: SMatrix<f64, N, N>,
) -> Result<(), FilterError> {
    write_lane(xs, ps, lane, x, &initial_cov(p)?);
    Ok(())
}

/// Writes the estimate `(x, P)`, both already checked, into lane `lane`.
pub(super) fn write_lane<const N: usize>(
    xs: &mut [Lanes; N],
    ps: &mut [[Lanes; N]; N],
    lane: usize,
    x: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
) {
    for i in 0..N {
        xs[i][lane] = x[i];
        for j in 0..N {
            ps[i][j][lane] = p[(i, j)];
        }
    }
}
