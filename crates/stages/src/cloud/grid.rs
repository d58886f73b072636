//! The probabilistic hash grid of environment samples (paper 000 Sec. 5, after
//! Hachisuka and Jensen's stochastic spatial hashing): `capacity` slots addressed by the
//! hash of a virtual cell (cell size 0.05 m in the paper), each with a collision counter
//! and at most one sample, kept by reservoir sampling with k = 1: the n-th sample that
//! lands in a slot replaces the occupant with probability 1/n.
//!
//! Samples live in a dense structure of arrays (positions, colors, normals and the slot
//! each one occupies), so a snapshot copies only the live samples, never the slots; a
//! slot holds the index of its sample plus one (0 = empty). Removal swaps the last sample
//! into the hole and fixes its slot through the back-pointer.

use crate::OpError;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng;
use relume_scene::light::EnvCloud;

/// The largest number of slots: sample indices plus one must fit a `u32`, and 2^28
/// slots are already 2 GiB of slot table.
pub const MAX_CAPACITY: usize = 1 << 28;

/// One environment sample: world position (metres), compensated linear color and unit
/// world normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub position: Vec3,
    pub color: Vec3,
    pub normal: Vec3,
}

/// What [`HashGrid::insert`] did with a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Insertion {
    /// The slot was empty; the sample now occupies it.
    Added,
    /// The sample replaced the slot's occupant (probability 1/n).
    Replaced,
    /// The occupant stayed; only the collision counter grew.
    Rejected,
}

/// A slot: how many samples have landed in it since it was last emptied, and its
/// occupant's index plus one (0 = empty).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Slot {
    collisions: u32,
    occupant: u32,
}

/// The probabilistic hash grid; see the module documentation.
#[derive(Clone, Debug)]
pub struct HashGrid {
    inv_cell_size: f32,
    slots: Vec<Slot>,
    positions: Vec<Vec3>,
    colors: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// The slot each sample occupies (back-pointer for swap-removal).
    slot_of: Vec<u32>,
}

impl HashGrid {
    /// An empty grid with `capacity` slots (at most that many samples) and cubic cells of
    /// `cell_size` metres.
    pub fn new(capacity: usize, cell_size: f32) -> Result<HashGrid, OpError> {
        if capacity == 0 || capacity > MAX_CAPACITY {
            return Err(OpError::BadParameter(format!(
                "hash grid capacity {capacity} is outside 1..={MAX_CAPACITY}"
            )));
        }
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return Err(OpError::BadParameter(format!(
                "hash grid cell size {cell_size} is not a positive length"
            )));
        }
        Ok(HashGrid {
            inv_cell_size: 1.0 / cell_size,
            slots: vec![Slot::default(); capacity],
            positions: Vec::new(),
            colors: Vec::new(),
            normals: Vec::new(),
            slot_of: Vec::new(),
        })
    }

    /// The number of slots, which bounds the number of samples.
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// The number of live samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Live sample positions, in storage order.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The slot of the cell holding `position`: hash(ix, iy, iz) reduced to
    /// [0, capacity) by a multiply-high (an unbiased stand-in for `mod`).
    #[inline]
    pub fn slot_for(&self, position: Vec3) -> u32 {
        let cell = (position * self.inv_cell_size).floor();
        // Saturating float-to-int casts: far or non-finite positions still hash.
        let h = rng::hash(&[
            cell.x as i64 as u64,
            cell.y as i64 as u64,
            cell.z as i64 as u64,
        ]);
        ((h as u128 * self.slots.len() as u128) >> 64) as u32
    }

    /// The collision counter of `slot` (samples that landed there since it was emptied).
    pub fn collisions(&self, slot: u32) -> u32 {
        self.slots[slot as usize].collisions
    }

    /// Inserts `sample` into its cell's slot; `draw` is a uniform 64-bit random value
    /// (counter-based, e.g. `rng::hash(&[seed, frame, salt, pixel])`) that decides the
    /// replacement.
    pub fn insert(&mut self, sample: Sample, draw: u64) -> Insertion {
        let slot = self.slot_for(sample.position);
        self.insert_at(slot, sample, draw)
    }

    /// [`HashGrid::insert`] with the slot already computed by [`HashGrid::slot_for`]
    /// (so that callers can hash in parallel and insert in order). Counts the collision,
    /// then replaces the occupant of a slot that has seen n samples with probability
    /// 1/n: exactly when floor(draw * n / 2^64) = 0.
    pub fn insert_at(&mut self, slot: u32, sample: Sample, draw: u64) -> Insertion {
        let entry = &mut self.slots[slot as usize];
        entry.collisions = entry.collisions.saturating_add(1);
        if entry.occupant == 0 {
            // At most one sample per slot: the sample count never exceeds the capacity.
            self.positions.push(sample.position);
            self.colors.push(sample.color);
            self.normals.push(sample.normal);
            self.slot_of.push(slot);
            entry.occupant = self.positions.len() as u32;
            return Insertion::Added;
        }
        let n = entry.collisions as u128;
        if (draw as u128 * n) >> 64 != 0 {
            return Insertion::Rejected;
        }
        let i = entry.occupant as usize - 1;
        self.positions[i] = sample.position;
        self.colors[i] = sample.color;
        self.normals[i] = sample.normal;
        Insertion::Replaced
    }

    /// Removes every sample whose position satisfies `remove` (evaluated in parallel)
    /// and empties its slot (collision counter reset). Returns how many were removed.
    /// The result does not depend on the thread count: removals are applied from the
    /// highest index down, each swapping the current last sample into the hole.
    pub fn remove_where(&mut self, remove: impl Fn(Vec3) -> bool + Sync) -> usize {
        let positions = &self.positions;
        let doomed: Vec<u32> = (0..positions.len() as u32)
            .into_par_iter()
            .with_min_len(4096)
            .filter(|&i| remove(positions[i as usize]))
            .collect();
        for &i in doomed.iter().rev() {
            self.swap_remove(i as usize);
        }
        doomed.len()
    }

    /// Removes sample `i`, moving the last sample into its place.
    fn swap_remove(&mut self, i: usize) {
        let slot = self.slot_of[i] as usize;
        self.slots[slot] = Slot::default();
        self.positions.swap_remove(i);
        self.colors.swap_remove(i);
        self.normals.swap_remove(i);
        self.slot_of.swap_remove(i);
        if let Some(&moved_slot) = self.slot_of.get(i) {
            self.slots[moved_slot as usize].occupant = i as u32 + 1;
        }
    }

    /// A copy of the live samples in storage order (three slice copies; the slot table
    /// is not touched).
    pub fn snapshot(&self) -> EnvCloud {
        EnvCloud {
            positions: self.positions.clone(),
            colors: self.colors.clone(),
            normals: self.normals.clone(),
        }
    }

    /// Checks the slot/sample cross references (for tests).
    #[cfg(test)]
    pub(crate) fn check_invariants(&self) {
        let n = self.len();
        assert!(n <= self.capacity());
        assert_eq!(self.colors.len(), n);
        assert_eq!(self.normals.len(), n);
        assert_eq!(self.slot_of.len(), n);
        for (i, &s) in self.slot_of.iter().enumerate() {
            assert_eq!(self.slots[s as usize].occupant as usize, i + 1);
            assert!(self.slots[s as usize].collisions >= 1);
        }
        let occupied = self.slots.iter().filter(|s| s.occupant != 0).count();
        assert_eq!(occupied, n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(x: f32, tag: f32) -> Sample {
        Sample {
            position: Vec3::new(x, 0.5, 2.0),
            color: Vec3::splat(tag),
            normal: Vec3::Z,
        }
    }

    #[test]
    fn rejects_bad_construction() {
        assert!(HashGrid::new(0, 0.05).is_err());
        assert!(HashGrid::new(MAX_CAPACITY + 1, 0.05).is_err());
        assert!(HashGrid::new(16, 0.0).is_err());
        assert!(HashGrid::new(16, f32::NAN).is_err());
    }

    #[test]
    fn never_exceeds_capacity() {
        let mut grid = HashGrid::new(7, 0.05).unwrap();
        for i in 0..10_000u64 {
            let x = (i as f32) * 0.013 - 40.0;
            grid.insert(sample(x, i as f32), rng::hash(&[1, i]));
            assert!(grid.len() <= 7);
        }
        assert_eq!(
            grid.len(),
            7,
            "10k samples over 1.3 km of cells fill all 7 slots"
        );
        grid.check_invariants();
        let total: u64 = (0..7).map(|s| grid.collisions(s) as u64).sum();
        assert_eq!(
            total, 10_000,
            "every insertion is counted in exactly one slot"
        );
    }

    #[test]
    fn same_cell_shares_a_slot_and_counts_collisions() {
        let mut grid = HashGrid::new(1 << 16, 0.05).unwrap();
        // 0.101 and 0.149 lie in cell 2 along x; 0.151 in cell 3.
        assert_eq!(
            grid.slot_for(Vec3::new(0.101, 0.5, 2.0)),
            grid.slot_for(Vec3::new(0.149, 0.52, 2.04))
        );
        assert_eq!(grid.insert(sample(0.101, 1.0), u64::MAX), Insertion::Added);
        // n = 2: floor(draw * 2 / 2^64) = 0 exactly when draw < 2^63.
        assert_eq!(
            grid.insert(sample(0.149, 2.0), 1 << 63),
            Insertion::Rejected
        );
        // n = 3 (then 4): replaced exactly when draw < 2^64 / n.
        assert_eq!(
            grid.insert(sample(0.13, 4.0), u64::MAX / 3 + 1),
            Insertion::Rejected
        );
        assert_eq!(
            grid.insert(sample(0.12, 3.0), u64::MAX / 4),
            Insertion::Replaced
        );
        assert_eq!(grid.len(), 1);
        assert_eq!(grid.snapshot().colors, vec![Vec3::splat(3.0)]);
        let slot = grid.slot_for(Vec3::new(0.12, 0.5, 2.0));
        assert_eq!(grid.collisions(slot), 4);
    }

    /// n samples into one cell, over many seeds: each survives with frequency 1/n
    /// (chi-square over the n outcomes).
    #[test]
    fn replacement_keeps_each_sample_with_probability_one_over_n() {
        let n = 5usize;
        let trials = 20_000u64;
        let mut survivors = vec![0u64; n];
        let mut grid = HashGrid::new(4, 0.05).unwrap();
        for seed in 0..trials {
            grid.remove_where(|_| true);
            for k in 0..n {
                let draw = rng::hash(&[seed, 0, 99, k as u64]);
                grid.insert(sample(0.01 + 0.001 * k as f32, k as f32), draw);
            }
            let kept = grid.snapshot().colors[0].x as usize;
            survivors[kept] += 1;
        }
        let expected = trials as f64 / n as f64;
        let chi2: f64 = survivors
            .iter()
            .map(|&o| (o as f64 - expected).powi(2) / expected)
            .sum();
        // 4 degrees of freedom: P(chi2 > 18.47) = 0.001.
        assert!(chi2 < 18.47, "survivor counts {survivors:?}, chi2 {chi2}");
    }

    #[test]
    fn removal_swaps_in_the_last_sample_and_empties_the_slot() {
        let mut grid = HashGrid::new(1 << 12, 0.05).unwrap();
        for i in 0..6 {
            grid.insert(sample(i as f32, i as f32), 0);
        }
        let removed = grid.remove_where(|p| p.x == 1.0 || p.x == 4.0);
        assert_eq!(removed, 2);
        grid.check_invariants();
        // Descending: 4 takes 5, then 1 takes the new last (5 again, now at 4).
        let xs: Vec<f32> = grid.positions().iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![0.0, 5.0, 2.0, 3.0]);
        let slot = grid.slot_for(Vec3::new(1.0, 0.5, 2.0));
        assert_eq!(grid.collisions(slot), 0, "counter reset");
        assert_eq!(grid.insert(sample(1.0, 7.0), u64::MAX), Insertion::Added);
        assert_eq!(grid.remove_where(|_| true), 5);
        assert!(grid.is_empty());
        grid.check_invariants();
    }
}
