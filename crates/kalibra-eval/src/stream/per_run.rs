//! Per run, the sums of a normalised statistic over its steps ([`PerRun`]), kept per block of
//! [`RUN_SUM_STEPS`] steps for the t-test of the runs' time averages.

/// Steps per block of the per-run sums ([`PerRun`]).
pub(crate) const RUN_SUM_STEPS: usize = 128;

/// Per run, the sum and count of a normalised statistic (NEES / n, NIS / m) over its steps,
/// for the runs' time averages that the t-test takes. Kept per block of [`RUN_SUM_STEPS`]
/// steps (`step / RUN_SUM_STEPS`) and added block after block by [`PerRun::totals`]: the sums
/// then do not depend on how the steps were cut between evaluators, as long as each block of
/// steps of a run went to one of them, so [`Evaluation::evaluate`](crate::Evaluation::evaluate) can evaluate blocks of
/// steps in parallel and give the bits of one pass (and of `kalibra eval`'s streaming
/// readers, which make one pass). Memory: one sum and count per run and block, an eighth of
/// a byte per cell.
#[derive(Default)]
pub(super) struct PerRun {
    /// `[run][block]`: sum and count.
    pub(super) blocks: Vec<Vec<(f64, usize)>>,
}

impl PerRun {
    #[inline(always)]
    pub(super) fn add(&mut self, run: usize, step: usize, value: f64) {
        if run >= self.blocks.len() {
            self.blocks.resize_with(run + 1, Vec::new);
        }
        let blocks = &mut self.blocks[run];
        let b = step / RUN_SUM_STEPS;
        if b >= blocks.len() {
            blocks.resize(b + 1, (0.0, 0));
        }
        blocks[b].0 += value;
        blocks[b].1 += 1;
    }

    /// Adds `other`'s sums (each run and block from whichever evaluator saw it).
    pub(super) fn merge(&mut self, other: PerRun) {
        if other.blocks.len() > self.blocks.len() {
            self.blocks.resize_with(other.blocks.len(), Vec::new);
        }
        for (mine, theirs) in self.blocks.iter_mut().zip(other.blocks) {
            if mine.is_empty() {
                *mine = theirs;
                continue;
            }
            if theirs.len() > mine.len() {
                mine.resize(theirs.len(), (0.0, 0));
            }
            for (a, b) in mine.iter_mut().zip(theirs) {
                a.0 += b.0;
                a.1 += b.1;
            }
        }
    }

    /// Each of `runs` runs' sum and count over its blocks, in block order.
    pub(super) fn totals(&self, runs: usize) -> Vec<(f64, usize)> {
        let mut totals: Vec<(f64, usize)> = self
            .blocks
            .iter()
            .map(|b| b.iter().fold((0.0, 0), |(s, c), (bs, bc)| (s + bs, c + bc)))
            .collect();
        totals.resize(runs, (0.0, 0));
        totals
    }
}
