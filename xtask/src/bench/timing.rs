//! Wall-clock timing, the one place the benchmarks read the clock.
//!
//! Every figure of `cargo xtask bench` is a best time (the minimum over repeats or blocks):
//! machine noise only ever adds time, so the minimum is the least noisy estimate of the cost.
//! Paths compared with each other are timed alternately (interleaved in one loop), so that a
//! burst of noise hits them alike.

use std::time::Instant;

use anyhow::Result;

/// The wall time of one call of `f`, in seconds, with its result.
pub(crate) fn timed<T>(f: impl FnOnce() -> T) -> (f64, T) {
    let start = Instant::now();
    let out = f();
    (start.elapsed().as_secs_f64(), out)
}

/// The shortest wall time of `repeats` calls of `f` (at least one), and the last call's result.
pub(crate) fn best_of<T>(repeats: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let (mut best, first) = timed(&mut f);
    let mut out = first?;
    for _ in 1..repeats {
        let (t, r) = timed(&mut f);
        out = r?;
        best = best.min(t);
    }
    Ok((best, out))
}

/// A running minimum of wall times: `Best::default()`, then [`Best::time`] per repeat.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Best(f64);

impl Default for Best {
    fn default() -> Self {
        Self(f64::INFINITY)
    }
}

impl Best {
    /// Times one call of `f`, keeps the shorter time, and returns the call's result.
    pub(crate) fn time<T>(&mut self, f: impl FnOnce() -> T) -> T {
        let (t, out) = timed(f);
        self.0 = self.0.min(t);
        out
    }

    /// Keeps `seconds` if it is shorter than the best so far.
    pub(crate) fn add(&mut self, seconds: f64) {
        self.0 = self.0.min(seconds);
    }

    /// The shortest time seen, in seconds (infinite before any).
    pub(crate) fn seconds(self) -> f64 {
        self.0
    }
}

/// A time budget for blocks of work: keep going until at least a minimum of blocks has run
/// and the budget has passed.
pub(crate) struct Budget {
    start: Instant,
    seconds: f64,
}

impl Budget {
    /// A budget of `seconds`, starting now.
    pub(crate) fn new(seconds: f64) -> Self {
        Self {
            start: Instant::now(),
            seconds,
        }
    }

    /// Whether to run another block, after `blocks` of at least `min_blocks`.
    pub(crate) fn more(&self, blocks: usize, min_blocks: usize) -> bool {
        blocks < min_blocks || self.start.elapsed().as_secs_f64() < self.seconds
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_of_keeps_the_last_result_and_a_time() {
        let mut calls = 0;
        let (t, last) = best_of(3, || {
            calls += 1;
            Ok(calls)
        })
        .unwrap();
        assert_eq!((calls, last), (3, 3));
        assert!(t.is_finite() && t >= 0.0);
    }

    #[test]
    fn best_of_stops_at_the_first_error() {
        let mut calls = 0;
        let result = best_of(3, || -> Result<()> {
            calls += 1;
            anyhow::bail!("fails")
        });
        assert!(result.is_err());
        assert_eq!(calls, 1);
    }

    #[test]
    fn best_keeps_the_minimum() {
        let mut best = Best::default();
        assert!(best.seconds().is_infinite());
        best.add(2.0);
        best.add(1.0);
        best.add(3.0);
        assert_eq!(best.seconds(), 1.0);
        assert_eq!(best.time(|| 7), 7);
        assert!(best.seconds() <= 1.0);
    }

    #[test]
    fn a_budget_runs_at_least_its_blocks() {
        let budget = Budget::new(0.0);
        let mut blocks = 0;
        while budget.more(blocks, 3) {
            blocks += 1;
        }
        assert_eq!(blocks, 3);
        assert!(Budget::new(3600.0).more(5, 3));
    }
}
