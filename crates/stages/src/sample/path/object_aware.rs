//! H_a of object-aware sampling (paper 000 Sec. 7): the candidates that meet the
//! objects' bounding box are offered to a [`Reservoir`], which keeps a uniform random
//! subset of at most `cache_size` of them; the estimator (`Kernel::object_aware` and
//! `Kernel::object_aware_direct` in `kernel.rs`) traces those and scales their sum.

use super::params::MAX_CANDIDATES;
use super::sampling::{Stream, below};

/// H_a: the candidates kept from H by reservoir sampling (a uniform random subset of
/// at most `size`).
pub(super) struct Reservoir<'s> {
    kept: [u16; MAX_CANDIDATES],
    size: usize,
    /// |H|: candidates offered so far.
    offered: usize,
    choices: &'s Stream,
}

impl<'s> Reservoir<'s> {
    pub(super) fn new(size: usize, choices: &'s Stream) -> Reservoir<'s> {
        Reservoir {
            kept: [0; MAX_CANDIDATES],
            size: size.clamp(1, MAX_CANDIDATES),
            offered: 0,
            choices,
        }
    }

    /// Offers candidate `i` (a member of H).
    #[inline]
    pub(super) fn offer(&mut self, i: usize) {
        if self.offered < self.size {
            self.kept[self.offered] = i as u16;
        } else {
            let r = below(self.choices.bits(i as u64), self.offered as u32 + 1) as usize;
            if r < self.size {
                self.kept[r] = i as u16;
            }
        }
        self.offered += 1;
    }

    /// H_a, in the order kept.
    pub(super) fn kept(&self) -> &[u16] {
        &self.kept[..self.offered.min(self.size)]
    }

    /// `factor` |H| / (|H_a| N): the weight of each traced candidate's difference.
    pub(super) fn scale(&self, candidates: usize, factor: f32) -> f32 {
        factor * self.offered as f32 / (self.kept().len() as f32 * candidates as f32)
    }
}
