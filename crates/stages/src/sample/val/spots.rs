//! The pipeline's spot lights (`[[light]]`, paper 002 Sec. 3.7) in `sample.val`: each
//! gets the two shadow maps an area light gets (paper 004 Sec. 5: the virtual objects
//! and the real points over one frustum fitted to the objects, the same builders and
//! tests), and its direct light is added after the area lights' with paper 002's
//! flags (eqs. 4-5): a real spot adds V_j E_j to E_R and V_j V^_j E_j to E_RV; a
//! virtual one adds V_j V^_j E_j to E_RV only, real points included. Its E_j is the
//! spot's own (`SpotLight::arrival`: intensity, cone and 1 / d^2), not eq. 6's.
//!
//! A pixel showing an object takes E_RV at the object's point (both worlds' spots light
//! it) and keeps E_R at the real point behind it (real spots). Two maps, one per world,
//! cannot double a shadow: a real occluder behind a virtual one as the spot sees it is
//! still in the real map (paper 002 Fig. 5).
//!
//! The maps' frustum: a real spot's is fitted to the objects, as an area light's (its
//! E_R has no real shadows outside it, but the ratio E_RV / E_R is exact there: 1); a
//! virtual spot's light is new wherever it reaches, so its maps cover its cone (up to
//! [`MAX_CONE_DEG`]), at the map's resolution over the whole cone. Where it departs:
//! beyond 75 degrees a virtual spot lights the real surfaces without their real
//! shadows; the maps are built every frame (`shadow_updates` applies to the area
//! lights).

use super::real_splat::{RealSurface, real_shadow_maps};
use super::shade::{Biases, map_visibility};
use super::shadow::ShadowFrustum;
use super::targets::light_targets;
use super::virtual_maps::virtual_shadow_maps;
use super::{ValInputs, ValShadingParams};
use crate::sample::layers::{IrradianceLayers, shade_rows};
use glam::{Vec3, Vec3A};
use relume_base::simd::Kernel;
use relume_scene::light::{LightWorld, SpotLight};

/// The widest half-angle a virtual spot's maps cover, degrees: beyond it a texel would
/// stretch over too much of the room (a spot of a wider cone lights its rim unshadowed).
pub(super) const MAX_CONE_DEG: f32 = 75.0;

/// Every spot's frustum (`None`: no map) and its two maps.
#[derive(Default)]
pub(super) struct SpotMaps {
    pub(super) frusta: Vec<Option<ShadowFrustum>>,
    /// Per spot, `3 size^2` floats: its virtual map, its real map and the real map's
    /// scratch (as the area lights' maps).
    pub(super) maps: Vec<f32>,
    pub(super) size: usize,
}

impl SpotMaps {
    /// Fits each spot's frustum to the objects and builds its maps from the objects'
    /// triangles and the real `surface`.
    pub(super) fn build(
        &mut self,
        inputs: &ValInputs,
        params: &ValShadingParams,
        surface: &RealSurface,
        kernel: Kernel,
    ) {
        let size = params.shadow_map_size;
        let bounds = inputs.objects.bounds();
        self.frusta = inputs
            .spots
            .iter()
            .map(|spot| match spot.world {
                // Its real shadows matter where the objects change nothing (the
                // ratio is exact, 1, outside their frustum): the objects' frustum.
                LightWorld::Real if inputs.objects.is_empty() => None,
                LightWorld::Real => {
                    let reach = params.real_occluder_reach;
                    ShadowFrustum::fit(spot.position, spot.direction, &bounds, size, reach)
                }
                // Its light is new everywhere it reaches: its cone, up to 75 degrees.
                LightWorld::Virtual => {
                    let tan_half = spot.cutoff.min(MAX_CONE_DEG.to_radians()).tan();
                    ShadowFrustum::cone(spot.position, spot.direction, tan_half, size)
                }
            })
            .collect();
        let stride = 3 * size * size;
        self.size = size;
        self.maps.clear();
        self.maps.resize(stride * self.frusta.len(), f32::INFINITY);
        for (maps, frustum) in self.maps.chunks_mut(stride).zip(&self.frusta) {
            let Some(frustum) = frustum else { continue };
            let (virtual_target, real_target) = light_targets(frustum, maps);
            virtual_shadow_maps(kernel, &mut [virtual_target], inputs.objects);
            real_shadow_maps(kernel, &mut [real_target], surface);
        }
    }

    /// The light of every spot at the point `x` (unit normal `n`, real-map splat size
    /// `patch`): its shares of E_R (for a real point) and E_RV, and the nearest
    /// occluder over the cosine where one occludes.
    pub(super) fn light_at(
        &self,
        spots: &[SpotLight],
        x: Vec3,
        n: Vec3,
        patch: f32,
        biases: Biases,
    ) -> (Vec3, Vec3, Option<f32>) {
        let (mut e_r, mut e_rv, mut nearest) = (Vec3::ZERO, Vec3::ZERO, None::<f32>);
        let texels = self.size * self.size;
        for (j, spot) in spots.iter().enumerate() {
            let Some(arrival) = spot.arrival(x, n) else {
                continue;
            };
            let (mut real, mut virtual_) = (true, true);
            if let Some(f) = &self.frusta[j] {
                let maps = &self.maps[3 * texels * j..3 * texels * j + 2 * texels];
                let v = Vec3A::from(spot.position) - Vec3A::from(x);
                let r2 = v.length_squared();
                let seen = map_visibility(f, maps, x.into(), n.into(), v, r2, patch, biases);
                (real, virtual_) = (seen.real, seen.virtual_);
                if let Some(d) = seen.occluder_over_cos {
                    nearest = Some(nearest.map_or(d, |m| m.min(d)));
                }
            }
            if !real {
                continue;
            }
            if spot.world == LightWorld::Real {
                e_r += arrival.irradiance;
            }
            if virtual_ {
                e_rv += arrival.irradiance;
            }
        }
        (e_r, e_rv, nearest)
    }
}

/// Adds the spots' direct light to every pixel the area lights shaded: at the real
/// point of a real pixel, at the object's point of an object pixel (E_RV) with E_R
/// at the real point behind it.
pub(super) fn add_spots(
    inputs: &ValInputs,
    spot_maps: &SpotMaps,
    real: (&[Vec3A], &[Vec3A], &[f32]),
    patch_of: impl Fn(Vec3) -> f32 + Sync,
    biases: Biases,
    out: &mut IrradianceLayers,
) {
    let (points, normals, patches) = real;
    let w = inputs.depth.width as usize;
    let spots = inputs.spots;
    shade_rows(
        out,
        w,
        1,
        || (),
        |_, y, row| {
            for x in 0..w {
                let i = y * w + x;
                let (p, n) = (points[i], normals[i]);
                let at_real = (p.is_finite() && n != Vec3A::ZERO)
                    .then(|| spot_maps.light_at(spots, p.into(), n.into(), patches[i], biases));
                let at_object = (row.mask[x] == 0.0).then(|| {
                    let (position, normal) = (row.world_position[x], row.world_normal[x]);
                    let patch = patch_of(position);
                    spot_maps.light_at(spots, position, normal, patch, biases)
                });
                if let Some((e_r, _, _)) = at_real {
                    row.e_r_dir[x] += e_r;
                }
                let shown = at_object.or(at_real);
                if let Some((_, e_rv, nearest)) = shown {
                    row.e_rv_dir[x] += e_rv;
                    if let Some(d) = nearest {
                        row.direct_min_distance[x] = row.direct_min_distance[x].min(d);
                    }
                }
            }
        },
    );
}
