//! Paper 004's radiance atlas (Secs. 4.1-4.2) on relume's reconstruction: every sample
//! of the environment-sample cloud is a texel of the room's surface with its captured
//! radiance, world position, normal and area, and the brightest texels, those that
//! carry a given share of the room's radiant intensity, are its direct part.
//!
//! Where it departs: the paper projects HDR camera images onto a modelled mesh; relume's
//! texels are the cloud's grid samples, whose colour the 8-bit camera captured (clipped
//! where the room is brightest), and a sample's area is estimated from the grid (a
//! plane of unit normal n crosses (|n_x| + |n_y| + |n_z|) / c^2 cells of side c per
//! square metre). The split is on luminance, not per channel.

use crate::light::cloud::EnvCloud;
use crate::light::split::luminance;
use glam::Vec3;

/// One texel of the radiance atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtlasTexel {
    pub position: Vec3,
    /// Unit normal of the surface, on the side the radiance leaves.
    pub normal: Vec3,
    /// Radiance leaving the surface (linear RGB).
    pub radiance: Vec3,
    /// Square metres of surface the texel stands for.
    pub area: f32,
}

impl AtlasTexel {
    /// Luminance of its radiant intensity along the normal, L dA: its share of the light.
    pub fn weight(&self) -> f64 {
        luminance(self.radiance) as f64 * self.area as f64
    }
}

/// The cloud's samples as atlas texels, a grid of `cell_size` metres: samples without a
/// unit normal or with a non-finite value are left out.
pub fn atlas_of_cloud(cloud: &EnvCloud, cell_size: f32) -> Vec<AtlasTexel> {
    let cell_area = cell_size * cell_size;
    cloud
        .positions
        .iter()
        .zip(&cloud.colors)
        .zip(&cloud.normals)
        .filter_map(|((&position, &radiance), &normal)| {
            let crossings = normal.abs().element_sum();
            let ok = position.is_finite()
                && radiance.is_finite()
                && (normal.length_squared() - 1.0).abs() < 1e-3
                && crossings > 0.0;
            ok.then(|| AtlasTexel {
                position,
                normal,
                radiance: radiance.max(Vec3::ZERO),
                area: cell_area / crossings,
            })
        })
        .collect()
}

/// The direct part of `atlas` (paper 004 Sec. 4.2): its brightest texels by radiance
/// luminance, taken from the top until they hold `share` of the total L dA (ties at the
/// threshold all go in; at least one texel when any emits).
pub fn direct_part(atlas: &[AtlasTexel], share: f32) -> Vec<AtlasTexel> {
    let total: f64 = atlas.iter().map(AtlasTexel::weight).sum();
    if !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..atlas.len()).collect();
    // Brightest first; the index breaks ties, so the split does not depend on the sort.
    order.sort_by(|&a, &b| {
        let (la, lb) = (luminance(atlas[a].radiance), luminance(atlas[b].radiance));
        lb.total_cmp(&la).then(a.cmp(&b))
    });
    let goal = total * share.clamp(0.0, 1.0) as f64;
    let mut held = 0.0;
    let mut threshold = f32::INFINITY;
    for &i in &order {
        if held >= goal && luminance(atlas[i].radiance) < threshold {
            break;
        }
        held += atlas[i].weight();
        threshold = luminance(atlas[i].radiance);
    }
    atlas
        .iter()
        .filter(|t| luminance(t.radiance) >= threshold && t.weight() > 0.0)
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texel(x: f32, radiance: f32) -> AtlasTexel {
        AtlasTexel {
            position: Vec3::new(x, 0.0, 0.0),
            normal: Vec3::Y,
            radiance: Vec3::splat(radiance),
            area: 1.0,
        }
    }

    #[test]
    fn the_direct_part_is_the_brightest_texels_holding_the_share() {
        let atlas = [
            texel(0.0, 1.0),
            texel(1.0, 8.0),
            texel(2.0, 1.0),
            texel(3.0, 2.0),
        ];
        // Total 12: 8 alone holds two thirds, 8 + 2 = 10 holds 5/6.
        let xs = |share| {
            direct_part(&atlas, share)
                .iter()
                .map(|t| t.position.x)
                .collect::<Vec<_>>()
        };
        assert_eq!(xs(0.5), [1.0]);
        assert_eq!(xs(0.8), [1.0, 3.0]);
        // The two texels of radiance 1 tie at the threshold: both go in.
        assert_eq!(xs(0.9), [0.0, 1.0, 2.0, 3.0]);
        assert!(direct_part(&[texel(0.0, 0.0)], 0.9).is_empty());
    }

    #[test]
    fn a_cloud_sample_stands_for_the_surface_its_grid_cell_holds() {
        let cloud = EnvCloud {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            colors: vec![Vec3::ONE, Vec3::ONE, Vec3::splat(f32::NAN)],
            normals: vec![Vec3::Y, Vec3::new(1.0, 1.0, 0.0).normalize(), Vec3::Y],
        };
        let atlas = atlas_of_cloud(&cloud, 0.02);
        assert_eq!(atlas.len(), 2, "the NaN colour is left out");
        // A floor sample: one cell per 4 cm^2; a 45-degree plane crosses sqrt(2) as many.
        assert!((atlas[0].area - 4e-4).abs() < 1e-9);
        assert!((atlas[1].area - 4e-4 / 2f32.sqrt()).abs() < 1e-9);
    }
}
