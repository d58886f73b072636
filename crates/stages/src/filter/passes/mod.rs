//! The separable filter's passes (paper 001 Sec. 7): the X pass (eq. 21, [`x_pass`])
//! from the input planes into the X set, and the Y pass (eq. 22, [`y_pass`]) with the
//! temporal taps of the previous frame (eq. 26) from the X set into the output images.
//! The stage runs the X pass fused with the preparation of its input planes, a row at
//! a time ([`prepare_x_pass`]); [`x_pass`] over a whole input set is the reference.
//!
//! Both sets are lane-interleaved ([`super::lane_planes`]), and both passes work on
//! groups of eight targets, one per lane: the X pass on pixels (l S + j, y) of the input
//! set (segments order), whose taps are slots j + i of the same row; the Y pass on
//! pixels (8 n + l, y) of the X set (blocks order), whose taps are block n of rows
//! y + i. Either way a tap of the eight targets is one aligned vector per plane, and
//! every tap of a lane is a pixel of the same image row (X) or column (Y). The X pass
//! transposes each eight groups of a row into eight blocks of the X set.
//!
//! Eq. 23's weight is symmetric in target and source: the squared distance and the
//! summed squared bandwidths do not change, bit for bit, when the two swap (each
//! difference only changes sign). So each pass walks its direction group by group and
//! weighs each pair of groups (j, j + k), k = 0..=R, once, when the walk reaches j
//! (`PairRing`): that weight is tap +k of group j and tap -k of group j + k, both in
//! the same lanes. A pass costs R + 1 `exp` per pixel and kind instead of 2 R + 1. The
//! temporal taps pair the current frame with the previous one and are weighed per tap.
//!
//! The kernel (AVX2 + FMA or portable, [`Kernel`](relume_base::simd::Kernel)) is chosen per task; both give the
//! same bits. The lane operations are never called from closures: closures do not
//! inherit `#[target_feature]`, and their lane operations would not be inlined.

mod blended;
mod sets;
mod taps;
mod x;
mod y;

pub use sets::{FullWindows, Previous, XSet};
pub use x::{prepare_x_pass, x_pass};
pub use y::y_pass;

#[cfg(test)]
mod tests;
