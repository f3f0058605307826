//! [`ResponseGrid`]: a frequency response sampled at many points.

use crate::C64;
use faer::Mat;

/// A frequency response sampled at `n` points: one `ny x nu` complex matrix per point,
/// stored column-major (`vec(G)`), the points one after another. Entry `(i, j)` of point
/// `k` is `values[k * ny * nu + j * ny + i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseGrid {
    /// Number of outputs.
    pub ny: usize,
    /// Number of inputs.
    pub nu: usize,
    /// The values, `n * ny * nu` of them.
    pub values: Vec<C64>,
}

impl ResponseGrid {
    /// A grid of zeros with `n` points.
    pub fn zeros(n: usize, ny: usize, nu: usize) -> Self {
        Self {
            ny,
            nu,
            values: vec![C64::new(0.0, 0.0); n * ny * nu],
        }
    }

    /// Number of frequency points.
    pub fn len(&self) -> usize {
        self.values
            .len()
            .checked_div(self.ny * self.nu)
            .unwrap_or(0)
    }

    /// True when the grid has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Entry `(i, j)` at point `k`.
    #[inline]
    pub fn get(&self, k: usize, i: usize, j: usize) -> C64 {
        self.values[k * self.ny * self.nu + j * self.ny + i]
    }

    /// `vec(G)` at point `k` (column-major, length `ny * nu`).
    #[inline]
    pub fn line(&self, k: usize) -> &[C64] {
        let m = self.ny * self.nu;
        &self.values[k * m..(k + 1) * m]
    }

    /// Mutable `vec(G)` at point `k`.
    #[inline]
    pub fn line_mut(&mut self, k: usize) -> &mut [C64] {
        let m = self.ny * self.nu;
        &mut self.values[k * m..(k + 1) * m]
    }

    /// Fills every point with `f(k, line)` (`line` is `vec(G)` at point `k`), in blocks of
    /// points on the rayon pool when the grid is large enough (`work_per_point` flops
    /// each) for threads to pay; in order of the points otherwise. `f` must not depend on
    /// the order in which the points are filled.
    pub fn fill_lines<F>(&mut self, work_per_point: usize, f: F)
    where
        F: Fn(usize, &mut [C64]) + Sync,
    {
        let m = self.ny * self.nu;
        let n = self.len();
        if m == 0 || n == 0 {
            return;
        }
        if work_per_point.saturating_mul(n) < PARALLEL_FILL_WORK || n < 2 * FILL_BLOCK {
            for (k, line) in self.values.chunks_mut(m).enumerate() {
                f(k, line);
            }
            return;
        }
        use rayon::prelude::*;
        self.values
            .par_chunks_mut(FILL_BLOCK * m)
            .enumerate()
            .for_each(|(b, block)| {
                for (i, line) in block.chunks_mut(m).enumerate() {
                    f(b * FILL_BLOCK + i, line);
                }
            });
    }

    /// The matrix at point `k` as a faer matrix.
    pub fn matrix(&self, k: usize) -> Mat<C64> {
        let l = self.line(k);
        Mat::from_fn(self.ny, self.nu, |i, j| l[j * self.ny + i])
    }
}

/// Below this many flops a [`ResponseGrid::fill_lines`] stays on one thread.
const PARALLEL_FILL_WORK: usize = 20_000_000;
/// Points per block of [`ResponseGrid::fill_lines`] on the rayon pool.
const FILL_BLOCK: usize = 64;
