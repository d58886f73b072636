//! Splitting captured radiance into a direct and an indirect part (paper 004 Sec. 4.2).
//!
//! Per color channel, every texel's radiant intensity I_k = L_k dA_k is ranked; from the
//! brightest down, intensities are accumulated until `ratio` of the channel's total is
//! reached. The intensity where that happens is the channel's threshold: texels at or
//! above it are *direct* in that channel, the rest *indirect*. The split is per channel
//! (paper 004 Fig. 5) so that a saturated colored source is direct even when its gray
//! brightness is low. Each channel of each texel goes wholly to one part, so
//! direct + indirect equals the original exactly.

use super::EnvMap;
use glam::Vec3;
use rayon::prelude::*;

/// The area dA of texel `index` as the paper's radiance atlas stores it: the texel's solid
/// angle times distance^2 for a finite distance (a distance impostor), the solid angle
/// alone for a distant texel (`distance` infinite or not a positive number).
#[inline]
pub fn texel_area(map: &EnvMap, index: usize) -> f32 {
    let row = (index / map.width.max(1) as usize) as u32;
    let d_omega = map.texel_solid_angle(row);
    let d = map.distance[index];
    if d.is_finite() && d > 0.0 {
        d_omega * d * d
    } else {
        d_omega
    }
}

/// True when the map's buffers hold `width * height` texels each (stages check this
/// before handing a map from another stage to the functions of this module, which
/// assume it).
pub fn map_is_consistent(map: &EnvMap) -> bool {
    let n = map.width as usize * map.height as usize;
    map.radiance.len() == n && map.distance.len() == n
}

/// The radiant intensity L dA of channel `channel` of texel `index` in f64, or 0 for a
/// texel that cannot emit (negative or non-finite radiance, degenerate area).
#[inline]
fn channel_intensity(map: &EnvMap, index: usize, channel: usize, area: f32) -> f64 {
    let l = map.radiance[index][channel];
    if l.is_finite() && l > 0.0 && area.is_finite() && area > 0.0 {
        l as f64 * area as f64
    } else {
        0.0
    }
}

/// The per-channel intensity thresholds of the split (Sec. 4.2): the smallest texel
/// intensity L dA such that the texels at or above it hold at least `ratio` of the
/// channel's total. `f64::INFINITY` where nothing is direct (`ratio <= 0` or a black
/// channel).
pub fn split_thresholds(map: &EnvMap, ratio: f64) -> [f64; 3] {
    let areas: Vec<f32> = (0..map.radiance.len())
        .map(|i| texel_area(map, i))
        .collect();
    let mut out = [f64::INFINITY; 3];
    out.par_iter_mut().enumerate().for_each(|(channel, t)| {
        let mut values: Vec<f64> = areas
            .iter()
            .enumerate()
            .map(|(i, &a)| channel_intensity(map, i, channel, a))
            .filter(|&v| v > 0.0)
            .collect();
        // Equal values are indistinguishable, so an unstable sort gives one result.
        values.par_sort_unstable_by(|a, b| b.total_cmp(a));
        *t = threshold_of_sorted(&values, ratio);
    });
    out
}

/// The threshold of intensities sorted from the largest down (all positive).
fn threshold_of_sorted(descending: &[f64], ratio: f64) -> f64 {
    // The total in the same order as the running sum, so ratio 1 ends exactly on the
    // last texel.
    let total: f64 = descending.iter().sum();
    if ratio.is_nan() || ratio <= 0.0 || total <= 0.0 {
        return f64::INFINITY;
    }
    let target = ratio.min(1.0) * total;
    let mut accumulated = 0.0;
    for &v in descending {
        accumulated += v;
        if accumulated >= target {
            return v;
        }
    }
    descending.last().copied().unwrap_or(f64::INFINITY)
}

/// Splits `map` into its direct and indirect parts (paper 004 Sec. 4.2) with the
/// thresholds of [`split_thresholds`]. Both parts have the map's size, distances and
/// centre; per texel and channel one part holds the original value and the other 0.
/// Assumes [`map_is_consistent`].
pub fn split_direct_indirect(map: &EnvMap, ratio: f64) -> (EnvMap, EnvMap) {
    let thresholds = split_thresholds(map, ratio);
    let mut direct = map.clone();
    let mut indirect = map.clone();
    let width = map.width.max(1) as usize;
    direct
        .radiance
        .par_chunks_mut(width)
        .zip(indirect.radiance.par_chunks_mut(width))
        .enumerate()
        .for_each(|(row, (d_row, i_row))| {
            for (column, (d, i)) in d_row.iter_mut().zip(i_row.iter_mut()).enumerate() {
                let index = row * width + column;
                let area = texel_area(map, index);
                for (channel, &threshold) in thresholds.iter().enumerate() {
                    if channel_intensity(map, index, channel, area) >= threshold {
                        i[channel] = 0.0;
                    } else {
                        d[channel] = 0.0;
                    }
                }
            }
        });
    (direct, indirect)
}

/// The total radiant intensity sum L dA of a map per channel (f64, row-major order),
/// over texels that can emit.
pub fn total_intensity(map: &EnvMap) -> [f64; 3] {
    let mut total = [0.0; 3];
    for i in 0..map.radiance.len() {
        let area = texel_area(map, i);
        for (c, t) in total.iter_mut().enumerate() {
            *t += channel_intensity(map, i, c, area);
        }
    }
    total
}

/// Luminance (Rec. 709 weights) of linear RGB.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dim sky with two bright spots of different colors, and a finite-distance copy.
    fn spotty(distance: Option<f32>) -> EnvMap {
        let mut map = EnvMap::from_fn(64, 32, |d| {
            let red = (d - Vec3::new(0.0, 1.0, 0.0)).length() < 0.3;
            let blue = (d - Vec3::new(1.0, 0.0, 0.0)).length() < 0.25;
            Vec3::splat(0.2 + 0.1 * d.y)
                + if red {
                    Vec3::new(40.0, 1.0, 1.0)
                } else {
                    Vec3::ZERO
                }
                + if blue {
                    Vec3::new(0.0, 0.0, 30.0)
                } else {
                    Vec3::ZERO
                }
        });
        if let Some(d) = distance {
            for (i, t) in map.distance.iter_mut().enumerate() {
                *t = d * (1.0 + (i % 7) as f32 * 0.1);
            }
            map.center = Vec3::new(0.0, 0.3, 0.0);
        }
        map
    }

    #[test]
    fn parts_add_up_exactly_and_direct_holds_the_ratio_per_channel() {
        for distance in [None, Some(2.0)] {
            let map = spotty(distance);
            let (direct, indirect) = split_direct_indirect(&map, 0.9);
            assert_eq!(direct.distance, map.distance);
            assert_eq!(indirect.center, map.center);
            for i in 0..map.radiance.len() {
                assert_eq!(direct.radiance[i] + indirect.radiance[i], map.radiance[i]);
                for c in 0..3 {
                    assert!(direct.radiance[i][c] == 0.0 || indirect.radiance[i][c] == 0.0);
                }
            }
            let (all, part) = (total_intensity(&map), total_intensity(&direct));
            let thresholds = split_thresholds(&map, 0.9);
            for c in 0..3 {
                let share = part[c] / all[c];
                assert!(share >= 0.9, "channel {c}: {share}");
                // Without the texels at the threshold itself the ratio is not reached.
                let above: f64 = (0..map.radiance.len())
                    .map(|i| channel_intensity(&map, i, c, texel_area(&map, i)))
                    .filter(|&v| v > thresholds[c])
                    .sum();
                assert!(above < 0.9 * all[c], "channel {c}: {above}");
            }
        }
    }

    #[test]
    fn per_channel_split_keeps_a_blue_source_direct_in_blue_only() {
        let map = spotty(None);
        let (direct, _) = split_direct_indirect(&map, 0.8);
        let blue = map.texel_of(Vec3::X);
        let red = map.texel_of(Vec3::Y);
        assert_eq!(direct.radiance[blue].z, map.radiance[blue].z);
        assert_eq!(
            direct.radiance[blue].x, 0.0,
            "dim red of the blue spot is indirect"
        );
        assert_eq!(direct.radiance[red].x, map.radiance[red].x);
        let sky = map.texel_of(Vec3::new(0.0, -1.0, 0.3).normalize());
        assert_eq!(direct.radiance[sky], Vec3::ZERO);
    }

    #[test]
    fn threshold_is_the_texel_where_the_ratio_is_reached() {
        // Intensities 8, 4, 2, 1 (total 15): 0.5 -> 8 alone (8/15 >= 0.5); 0.6 -> 8 + 4;
        // 1 -> all; 0 -> none.
        let v = [8.0, 4.0, 2.0, 1.0];
        assert_eq!(threshold_of_sorted(&v, 0.5), 8.0);
        assert_eq!(threshold_of_sorted(&v, 0.6), 4.0);
        assert_eq!(threshold_of_sorted(&v, 1.0), 1.0);
        assert_eq!(threshold_of_sorted(&v, 0.0), f64::INFINITY);
        assert_eq!(threshold_of_sorted(&[], 0.9), f64::INFINITY);
    }

    #[test]
    fn black_and_empty_maps_are_all_indirect() {
        let black = EnvMap::constant(8, 4, Vec3::ZERO);
        let (d, i) = split_direct_indirect(&black, 0.9);
        assert_eq!((d.radiance, i), (black.radiance.clone(), black));
        let empty = EnvMap::distant(0, 0, Vec::new());
        let (d, i) = split_direct_indirect(&empty, 0.9);
        assert!(d.radiance.is_empty() && i.radiance.is_empty());
    }

    #[test]
    fn finite_distances_weight_texels_by_area() {
        // Two texels of equal radiance, one twice as far: four times the intensity.
        let mut map = EnvMap::constant(4, 2, Vec3::ZERO);
        map.radiance[1] = Vec3::ONE;
        map.radiance[2] = Vec3::ONE;
        map.distance = vec![1.0; 8];
        map.distance[2] = 2.0;
        let (direct, _) = split_direct_indirect(&map, 0.75);
        assert_eq!(direct.radiance[2], Vec3::ONE);
        assert_eq!(
            direct.radiance[1],
            Vec3::ZERO,
            "4 / 5 of the total is enough"
        );
    }
}
