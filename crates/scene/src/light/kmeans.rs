//! k-means on position and normal, the clustering step of the virtual area lights
//! (paper 004 Sec. 4.3, following Dong et al. \[9\]): samples of the direct light are
//! grouped by the distance |p - p'|^2 + w |n - n'|^2, with centres warm-started from the
//! previous frame so that lights keep their place (and index) under static or slowly
//! changing light.
//!
//! Deterministic: the assignment step is data-parallel with a fixed tie rule (the
//! smaller centre index wins), the update step accumulates in f64 in sample order, and
//! the k-means++ seeding and the re-seeding of empty clusters use counter-based hashes
//! or fixed rules, never a shared generator.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use relume_base::rng;

/// Samples per parallel task of the assignment step.
const CHUNK: usize = 256;

/// A point to cluster: a world position and a unit normal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Feature {
    pub position: Vec3,
    pub normal: Vec3,
}

/// The clustering distance |dp|^2 + w |dn|^2 (`normal_weight` w in m^2: a normal
/// difference of 90 degrees, |dn|^2 = 2, weighs like 2 w square metres of distance).
#[inline]
pub fn feature_distance(a: &Feature, b: &Feature, normal_weight: f32) -> f32 {
    a.position.distance_squared(b.position) + normal_weight * a.normal.distance_squared(b.normal)
}

/// The index of the centre nearest to `x` (the smaller index on ties) and its distance;
/// `(0, INFINITY)` with no centres.
#[inline]
pub fn nearest_centre(centres: &[Feature], x: &Feature, normal_weight: f32) -> (usize, f32) {
    let mut best = (0, f32::INFINITY);
    for (j, c) in centres.iter().enumerate() {
        let d = feature_distance(c, x, normal_weight);
        if d < best.1 {
            best = (j, d);
        }
    }
    best
}

/// What one run of [`kmeans`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KMeansReport {
    /// Lloyd iterations run (assignment + update).
    pub iterations: u32,
    /// The last update left every centre unchanged (a fixed point was reached).
    pub converged: bool,
    /// Centres re-seeded because their cluster was empty.
    pub reseeded: u32,
}

/// k-means++ seeding (Arthur and Vassilvitskii 2007) of up to `k` centres from
/// `samples`, drawing with counter-based hashes of (`seed`, centre index): the same
/// samples always give the same centres. Fewer than `k` centres when the samples have
/// fewer than `k` distinct features.
pub fn seed_centres(samples: &[Feature], k: usize, normal_weight: f32, seed: u64) -> Vec<Feature> {
    const SALT: u64 = 0x6b6d_6561_6e73_2b2b;
    let mut centres = Vec::with_capacity(k);
    if samples.is_empty() || k == 0 {
        return centres;
    }
    let first = (rng::unit_f64(rng::hash(&[seed, SALT, 0])) * samples.len() as f64) as usize;
    centres.push(samples[first.min(samples.len() - 1)]);
    let mut d2: Vec<f32> = samples
        .iter()
        .map(|s| feature_distance(s, &centres[0], normal_weight))
        .collect();
    while centres.len() < k {
        let total: f64 = d2.iter().map(|&d| d as f64).sum();
        if total <= 0.0 || !total.is_finite() {
            break;
        }
        let target = rng::unit_f64(rng::hash(&[seed, SALT, centres.len() as u64])) * total;
        let mut accumulated = 0.0;
        let mut pick = None;
        for (i, &d) in d2.iter().enumerate() {
            if d > 0.0 {
                accumulated += d as f64;
                pick = Some(i);
                if accumulated > target {
                    break;
                }
            }
        }
        let Some(pick) = pick else { break };
        let centre = samples[pick];
        centres.push(centre);
        for (d, s) in d2.iter_mut().zip(samples) {
            *d = d.min(feature_distance(s, &centre, normal_weight));
        }
    }
    centres
}

/// Lloyd's k-means of `samples` starting from `centres` (warm start; pass the previous
/// frame's centres), for at most `max_iterations` iterations or until an update leaves
/// every centre unchanged (bit for bit: a converged warm start is a fixed point and moves
/// nothing). `assignment` is a reusable buffer and holds each sample's centre
/// afterwards.
///
/// A centre left with no samples is re-seeded at the sample farthest from its own
/// centre (the worst-represented sample; ties to the smaller index), so no centre is
/// wasted while there are samples to separate; if every sample already coincides with
/// its centre, the empty centre stays where it is. New centre normals are the normalized
/// mean normal (the previous normal when the mean vanishes). Centres never become NaN.
pub fn kmeans(
    samples: &[Feature],
    centres: &mut [Feature],
    max_iterations: u32,
    normal_weight: f32,
    assignment: &mut Vec<u32>,
) -> KMeansReport {
    let mut report = KMeansReport {
        iterations: 0,
        converged: false,
        reseeded: 0,
    };
    assignment.clear();
    assignment.resize(samples.len(), u32::MAX);
    if samples.is_empty() || centres.is_empty() {
        report.converged = true;
        return report;
    }
    let mut distance = vec![0f32; samples.len()];
    let mut sums = vec![(DVec3::ZERO, DVec3::ZERO, 0u32); centres.len()];
    while report.iterations < max_iterations {
        report.iterations += 1;
        // Assignment (independent per sample).
        assignment
            .par_chunks_mut(CHUNK)
            .zip(distance.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(chunk, (assigned, dist))| {
                for (i, (a, d)) in assigned.iter_mut().zip(dist.iter_mut()).enumerate() {
                    let (j, dj) =
                        nearest_centre(centres, &samples[chunk * CHUNK + i], normal_weight);
                    *a = j as u32;
                    *d = dj;
                }
            });
        // Update, in sample order.
        sums.iter_mut()
            .for_each(|s| *s = (DVec3::ZERO, DVec3::ZERO, 0));
        for (s, &a) in samples.iter().zip(assignment.iter()) {
            let sum = &mut sums[a as usize];
            sum.0 += s.position.as_dvec3();
            sum.1 += s.normal.as_dvec3();
            sum.2 += 1;
        }
        let mut moved = false;
        let mut taken: Vec<usize> = Vec::new();
        for (centre, &(p, n, count)) in centres.iter_mut().zip(&sums) {
            let before = *centre;
            if count > 0 {
                centre.position = (p / count as f64).as_vec3();
                let mean = n.as_vec3();
                if mean.length_squared() > 1e-12 {
                    centre.normal = mean.normalize();
                }
            } else {
                // Empty: the worst-represented sample not taken by another empty centre.
                let mut worst: Option<(usize, f32)> = None;
                for (i, &d) in distance.iter().enumerate() {
                    if d > 0.0 && !taken.contains(&i) && worst.is_none_or(|w| d > w.1) {
                        worst = Some((i, d));
                    }
                }
                if let Some((i, _)) = worst {
                    *centre = samples[i];
                    taken.push(i);
                    report.reseeded += 1;
                }
            }
            moved |= *centre != before;
        }
        if !moved {
            report.converged = true;
            break;
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(centre: Vec3, normal: Vec3, count: usize, salt: u64) -> Vec<Feature> {
        let mut r = rng::Counter::new(&[salt]);
        (0..count)
            .map(|_| Feature {
                position: centre
                    + Vec3::new(r.next_f32() - 0.5, r.next_f32() - 0.5, r.next_f32() - 0.5) * 0.2,
                normal,
            })
            .collect()
    }

    #[test]
    fn separates_three_blobs_and_is_a_fixed_point_when_warm_started() {
        let mut samples = blob(Vec3::new(0.0, 2.5, 0.0), -Vec3::Y, 300, 1);
        samples.extend(blob(Vec3::new(2.5, 1.0, 0.0), -Vec3::X, 200, 2));
        samples.extend(blob(Vec3::new(0.0, 1.0, -2.5), Vec3::Z, 100, 3));
        let mut centres = seed_centres(&samples, 3, 1.0, 7);
        assert_eq!(centres.len(), 3);
        let mut assignment = Vec::new();
        let report = kmeans(&samples, &mut centres, 100, 1.0, &mut assignment);
        assert!(report.converged, "{report:?}");
        let mut found: Vec<Vec3> = centres.iter().map(|c| c.position).collect();
        found.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.z.total_cmp(&b.z)));
        let expected = [
            Vec3::new(0.0, 1.0, -2.5),
            Vec3::new(0.0, 2.5, 0.0),
            Vec3::new(2.5, 1.0, 0.0),
        ];
        for (f, e) in found.iter().zip(expected) {
            assert!(f.distance(e) < 0.03, "{f} vs {e}");
        }
        let before = centres.clone();
        let again = kmeans(&samples, &mut centres, 10, 1.0, &mut assignment);
        assert_eq!((again.iterations, again.converged), (1, true));
        assert_eq!(before, centres, "a converged warm start does not move");
    }

    #[test]
    fn empty_clusters_are_reseeded_and_coincident_samples_never_give_nan() {
        let samples = blob(Vec3::new(1.0, 1.0, 1.0), Vec3::Y, 50, 4);
        // Two centres far from every sample: one wins everything, the other is re-seeded.
        let far = Feature {
            position: Vec3::splat(100.0),
            normal: Vec3::X,
        };
        let mut centres = vec![far, far];
        let mut assignment = Vec::new();
        let report = kmeans(&samples, &mut centres, 50, 1.0, &mut assignment);
        assert!(report.reseeded >= 1, "{report:?}");
        assert!(assignment.contains(&1) && assignment.contains(&0));
        // All samples identical: seeding stops at one centre; extra centres stay finite.
        let same = vec![samples[0]; 20];
        assert_eq!(seed_centres(&same, 4, 1.0, 1).len(), 1);
        let mut centres = vec![samples[0], far];
        kmeans(&same, &mut centres, 10, 1.0, &mut assignment);
        assert!(
            centres
                .iter()
                .all(|c| c.position.is_finite() && c.normal.is_finite())
        );
    }
}
