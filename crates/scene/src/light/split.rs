//! Splitting captured radiance into a direct and an indirect part (paper 004 Sec. 4.2).
//!
//! Per color channel, texels are ranked by radiance L, brightest first, and their radiant
//! intensities I_k = L_k dA_k are accumulated until `ratio` of the channel's total is
//! reached. The radiance of the texel where that happens is the channel's threshold:
//! texels whose radiance is at or above it are *direct* in that channel, the rest
//! *indirect* ("texels in the atlas with a radiance larger than the threshold are
//! assigned to the direct radiance atlas"). Ranking by radiance, not by L dA, keeps a
//! small bright lamp direct wherever it lies in the map: a texel near a pole of a
//! latitude-longitude map spans a fraction of an equator texel's solid angle, and a far
//! wall's texels span d^2 times more area than a near lamp's. The split is per channel
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

/// Radiance and radiant intensity of channel `channel` of texel `index`, or `None` for a
/// texel that cannot emit (see [`channel_intensity`]).
#[inline]
fn emitting(map: &EnvMap, index: usize, channel: usize, area: f32) -> Option<(f64, f64)> {
    let intensity = channel_intensity(map, index, channel, area);
    (intensity > 0.0).then(|| (map.radiance[index][channel] as f64, intensity))
}

/// The per-channel radiance thresholds of the split (Sec. 4.2): the largest texel
/// radiance L such that the texels of that radiance or more hold at least `ratio` of the
/// channel's total radiant intensity (the brightest texels that reach the ratio).
/// `f64::INFINITY` where nothing is direct (`ratio <= 0` or a black channel).
pub fn split_thresholds(map: &EnvMap, ratio: f64) -> [f64; 3] {
    let areas: Vec<f32> = (0..map.radiance.len())
        .map(|i| texel_area(map, i))
        .collect();
    let mut out = [f64::INFINITY; 3];
    out.par_iter_mut().enumerate().for_each(|(channel, t)| {
        let mut texels: Vec<(f64, f64)> = areas
            .iter()
            .enumerate()
            .filter_map(|(i, &a)| emitting(map, i, channel, a))
            .collect();
        // Brightest first. Ties in radiance are ordered by intensity, so that the sort
        // is total and the running sum the same on every run.
        texels.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(b.1.total_cmp(&a.1)));
        *t = threshold_of_sorted(&texels, ratio);
    });
    out
}

/// The threshold of `(radiance, intensity)` pairs sorted by radiance from the largest
/// down (all positive): the radiance of the pair whose intensity brings the running sum
/// to `ratio` of the total.
fn threshold_of_sorted(descending: &[(f64, f64)], ratio: f64) -> f64 {
    // The total in the same order as the running sum, so ratio 1 ends exactly on the
    // last texel.
    let total: f64 = descending.iter().map(|&(_, i)| i).sum();
    if ratio.is_nan() || ratio <= 0.0 || total <= 0.0 {
        return f64::INFINITY;
    }
    let target = ratio.min(1.0) * total;
    let mut accumulated = 0.0;
    for &(radiance, intensity) in descending {
        accumulated += intensity;
        if accumulated >= target {
            return radiance;
        }
    }
    descending
        .last()
        .map_or(f64::INFINITY, |&(radiance, _)| radiance)
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
                    let radiance = emitting(map, index, channel, area).map(|(l, _)| l);
                    if radiance.is_some_and(|l| l >= threshold) {
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
                    .filter_map(|i| emitting(&map, i, c, texel_area(&map, i)))
                    .filter(|&(l, _)| l > thresholds[c])
                    .map(|(_, intensity)| intensity)
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
    fn threshold_is_the_radiance_where_the_ratio_is_reached() {
        // Radiances 8, 4, 2, 1 with intensities 1, 8, 4, 2 (total 15): 0.05 -> 8 alone
        // (1/15); 0.5 -> down to 4 (9/15); 0.7 -> down to 2 (13/15); 1 -> all; 0 -> none.
        let v = [(8.0, 1.0), (4.0, 8.0), (2.0, 4.0), (1.0, 2.0)];
        assert_eq!(threshold_of_sorted(&v, 0.05), 8.0);
        assert_eq!(threshold_of_sorted(&v, 0.5), 4.0);
        assert_eq!(threshold_of_sorted(&v, 0.7), 2.0);
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
    fn intensity_decides_how_far_the_split_goes_radiance_decides_the_order() {
        // Two texels of equal radiance, one twice as far: four times the intensity. The
        // far one alone holds 4 / 5 of the total, but both have the threshold's radiance.
        let mut map = EnvMap::constant(4, 2, Vec3::ZERO);
        map.radiance[1] = Vec3::ONE;
        map.radiance[2] = Vec3::ONE;
        map.distance = vec![1.0; 8];
        map.distance[2] = 2.0;
        let (direct, indirect) = split_direct_indirect(&map, 0.75);
        assert_eq!(
            (direct.radiance[1], direct.radiance[2]),
            (Vec3::ONE, Vec3::ONE)
        );
        assert_eq!(indirect.radiance, vec![Vec3::ZERO; 8]);
    }

    #[test]
    fn a_small_bright_lamp_near_the_pole_is_direct_before_a_large_dim_wall() {
        // A lamp of radiance 100 at 2 m in the top row, where a texel spans about 1/20 of
        // an equator texel's solid angle, and a wall of radiance 1 at 5 m on the equator.
        // The wall's intensity is the larger (25 dOmega against about 20 dOmega), so
        // ranking by L dA would make the wall direct and leave the lamp indirect.
        let mut map = EnvMap::constant(64, 32, Vec3::ZERO);
        let lamp = 3;
        let wall = 16 * 64 + 5;
        map.radiance[lamp] = Vec3::splat(100.0);
        map.radiance[wall] = Vec3::ONE;
        map.distance = vec![3.0; 64 * 32];
        map.distance[lamp] = 2.0;
        map.distance[wall] = 5.0;
        let (lamp_intensity, wall_intensity) = (
            channel_intensity(&map, lamp, 0, texel_area(&map, lamp)),
            channel_intensity(&map, wall, 0, texel_area(&map, wall)),
        );
        assert!(
            wall_intensity > lamp_intensity,
            "the case the test is about"
        );
        let lamp_share = lamp_intensity / (lamp_intensity + wall_intensity);
        let (direct, indirect) = split_direct_indirect(&map, lamp_share * 0.99);
        assert_eq!(direct.radiance[lamp], Vec3::splat(100.0));
        assert_eq!(indirect.radiance[wall], Vec3::ONE);
        assert_eq!(direct.radiance[wall], Vec3::ZERO);
    }
}
