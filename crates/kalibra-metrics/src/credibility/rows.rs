//! [`CredibilityRows`]: runs pushed run after run into one buffer, and their transposition
//! into a [`Credibility`]'s per-step storage in blocks of steps.

use super::Credibility;
use crate::MetricsError;

/// Steps per block of [`Credibility::settle`]: each block's per-step vectors stay in cache
/// while every row copies its cells of the block.
const SETTLE_STEPS: usize = 32;

/// Runs' errors and NEES for a [`Credibility`], pushed in one buffer in push order and moved
/// into it by [`Credibility::settle`].
///
/// [`Credibility`] keeps each step's runs in a vector of its own, so pushing run after run
/// stores to a place per step, far apart, cell after cell; here a run after run appends to
/// one buffer, and the settling moves it in blocks of steps (`cargo xtask bench eval`, NPZ,
/// times it). Each step then holds its runs in push order, as pushing them to the
/// [`Credibility`] directly gives, so every statistic is the same to the bit (the test
/// `settled_rows_equal_direct_pushes_to_the_bit`).
#[derive(Clone, Debug, Default)]
pub struct CredibilityRows {
    /// Rows of consecutive steps, in push order: (first step, number of steps).
    rows: Vec<(usize, usize)>,
    /// The rows' errors, one cell after the other.
    errors: Vec<f64>,
    /// The rows' NEES, one per cell.
    nees: Vec<f64>,
}

impl CredibilityRows {
    /// An empty buffer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of cells held.
    pub fn len(&self) -> usize {
        self.nees.len()
    }

    /// Whether no cell is held.
    pub fn is_empty(&self) -> bool {
        self.nees.is_empty()
    }

    /// Adds one run's error and NEES at `step`, to be settled into `cred`, checked as
    /// [`Credibility::push_nees`] checks them. Nothing is stored on failure.
    ///
    /// # Errors
    /// As [`Credibility::push_nees`].
    #[inline]
    pub fn push_nees(
        &mut self,
        cred: &Credibility,
        step: usize,
        error: &[f64],
        nees: f64,
    ) -> Result<(), MetricsError> {
        cred.check(step, error)?;
        Credibility::check_nees(nees)?;
        match self.rows.last_mut() {
            Some((first, len)) if *first + *len == step => *len += 1,
            _ => self.rows.push((step, 1)),
        }
        self.errors.extend_from_slice(error);
        self.nees.push(nees);
        Ok(())
    }
}

impl Credibility {
    /// Moves the cells of `rows` into this accumulator, each step taking its cells in the
    /// order they were pushed to `rows`, after those it holds; `rows` is left empty, its
    /// buffers kept for reuse.
    ///
    /// # Panics
    /// If `rows` holds a cell beyond the horizon or of another dimension: it was pushed
    /// against another accumulator.
    pub fn settle(&mut self, rows: &mut CredibilityRows) {
        let dim = self.dim;
        assert_eq!(
            rows.errors.len(),
            rows.nees.len() * dim,
            "Credibility::settle: rows of another dimension"
        );
        let end = rows.rows.iter().map(|&(f, l)| f + l).max().unwrap_or(0);
        assert!(
            end <= self.steps(),
            "Credibility::settle: rows beyond the horizon"
        );
        let start = rows.rows.iter().map(|&(f, _)| f).min().unwrap_or(0);
        // A step occurs at most once per row, so taking the rows in order within a block of
        // steps keeps each step's cells in push order.
        for block in (start..end).step_by(SETTLE_STEPS) {
            let block_end = (block + SETTLE_STEPS).min(end);
            let mut offset = 0;
            for &(first, len) in &rows.rows {
                let lo = first.max(block);
                let hi = (first + len).min(block_end);
                for k in lo..hi {
                    let cell = offset + k - first;
                    self.errors[k].extend_from_slice(&rows.errors[cell * dim..(cell + 1) * dim]);
                    self.nees[k].push(rows.nees[cell]);
                }
                offset += len;
            }
        }
        rows.rows.clear();
        rows.errors.clear();
        rows.nees.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settled_rows_equal_direct_pushes_to_the_bit() {
        // Rows of every shape: whole runs, partial runs, single cells, a step out of order,
        // more than one block of steps, settled part way and into a non-empty accumulator.
        let (steps, dim) = (70, 3);
        let mut cells = Vec::new();
        for run in 0..9usize {
            let range = match run % 3 {
                0 => 0..steps,
                1 => 5..40,
                _ => 33..34,
            };
            for k in range {
                cells.push((k, run));
            }
            if run == 4 {
                cells.push((2, run));
            }
        }
        let value = |k: usize, run: usize, i: usize| {
            ((k * 31 + run * 7 + i) as f64 * 0.618_033_988_75).sin() + 1e-3 * i as f64
        };
        let mut direct = Credibility::new(steps, dim);
        let mut settled = Credibility::new(steps, dim);
        let mut rows = CredibilityRows::new();
        for (i, &(k, run)) in cells.iter().enumerate() {
            let e: Vec<f64> = (0..dim).map(|c| value(k, run, c)).collect();
            let nees = 1.0 + value(k, run, 9).abs();
            direct.push_nees(k, &e, nees).unwrap();
            rows.push_nees(&settled, k, &e, nees).unwrap();
            if i == 100 {
                settled.settle(&mut rows);
                assert!(rows.is_empty());
            }
        }
        settled.settle(&mut rows);
        assert_eq!(direct, settled);
        for k in 0..steps {
            assert_eq!(
                direct.step_nci(k).unwrap().to_bits(),
                settled.step_nci(k).unwrap().to_bits()
            );
        }
    }

    #[test]
    fn rows_check_as_push_nees() {
        let cred = Credibility::new(2, 2);
        let mut rows = CredibilityRows::new();
        assert!(rows.push_nees(&cred, 2, &[0.0, 0.0], 1.0).is_err());
        assert!(rows.push_nees(&cred, 0, &[0.0], 1.0).is_err());
        assert!(rows.push_nees(&cred, 0, &[f64::NAN, 0.0], 1.0).is_err());
        assert!(rows.push_nees(&cred, 0, &[0.0, 0.0], -1.0).is_err());
        assert!(
            rows.push_nees(&cred, 0, &[0.0, 0.0], f64::INFINITY)
                .is_err()
        );
        assert!(rows.is_empty());
    }
}
