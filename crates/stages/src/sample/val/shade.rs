//! Per-point shading from the virtual area lights with two visibilities (paper 004
//! Sec. 5, eqs. 6, 12 and 13 in irradiance form).

use super::shadow::ShadowFrustum;
use glam::{Vec3, Vec3A};
use relume_scene::light::AreaLight;

/// One light prepared for shading: its data in SIMD-friendly form and its shadow maps.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PreparedLight {
    pub position: Vec3A,
    pub normal: Vec3A,
    pub intensity: Vec3A,
    /// A / pi: the least r^2 of eq. 6 (see `light_irradiance`).
    pub min_r2: f32,
    pub frustum: Option<ShadowFrustum>,
}

impl PreparedLight {
    /// This light's (the `j`-th's) frustum, if it has one and bit j of `lookup` does not
    /// say the point lies outside it (lights from 64 on are always looked up).
    #[inline]
    pub fn frustum_to_look_up(&self, j: usize, lookup: u64) -> Option<&ShadowFrustum> {
        self.frustum
            .as_ref()
            .filter(|_| j >= 64 || (lookup >> j) & 1 == 1)
    }

    pub fn new(light: &AreaLight, frustum: Option<ShadowFrustum>) -> PreparedLight {
        PreparedLight {
            position: light.position.into(),
            normal: light.normal.normalize_or_zero().into(),
            intensity: light.intensity.into(),
            min_r2: (light.area / std::f32::consts::PI).max(0.0),
            frustum,
        }
    }
}

/// Biases of the shadow-map tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Biases {
    pub virtual_bias: f32,
    pub real_bias: f32,
    /// Times tan(angle of incidence) times the texel footprint (virtual map) or the
    /// larger of the texel footprint and the receiver's real patch (real map, whose
    /// points are splatted over their patch), added to the biases.
    pub slope: f32,
}

/// The shadow maps of all lights: `size^2` virtual texels then `size^2` real texels
/// (then scratch) per light, `stride` floats apart.
#[derive(Clone, Copy)]
pub(crate) struct Maps<'a> {
    pub data: &'a [f32],
    pub stride: usize,
    pub texels: usize,
}

/// What one shading point receives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Shaded {
    /// sum_j V_j E_j
    pub e_r: Vec3,
    /// sum_j V_j V^_j E_j, summed in the same order as `e_r`: bit-identical to it when
    /// every V^_j is 1.
    pub e_rv: Vec3,
    /// The distance to the nearest occluder (real or virtual) of a light that would
    /// otherwise reach the point over the cosine of the light's direction at the point
    /// (the z / cos^2(theta_occ) of paper 001 eq. 17, as `sample.path` records it);
    /// INFINITY when none.
    pub min_occluder: f32,
}

/// What a light's two shadow maps say of a receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MapVisibility {
    /// V_j: no real occluder in the real map.
    pub real: bool,
    /// V^_j: no virtual occluder in the virtual map.
    pub virtual_: bool,
    /// The distance to the nearer occluder along the ray to the light over the cosine
    /// at the receiver (see [`Shaded::min_occluder`]), where one occludes.
    pub occluder_over_cos: Option<f32>,
}

/// V_j and V^_j of the receiver `x` (unit normal `n`, `v` = light position - x, `r2` =
/// |v|^2, real-map splat size `patch`) from one light's maps (`light_maps`: its
/// virtual map then its real map, `f.size^2` texels each) over frustum `f`: both 1
/// outside the frustum.
#[allow(clippy::too_many_arguments)]
pub(crate) fn map_visibility(
    f: &ShadowFrustum,
    light_maps: &[f32],
    x: Vec3A,
    n: Vec3A,
    v: Vec3A,
    r2: f32,
    patch: f32,
    biases: Biases,
) -> MapVisibility {
    let visible = MapVisibility {
        real: true,
        virtual_: true,
        occluder_over_cos: None,
    };
    let l = f.light_space(x);
    let Some(t) = f.texel(l) else {
        return visible;
    };
    let texels = f.size * f.size;
    let z_virtual = light_maps[t];
    let z_real = light_maps[texels + t];
    // The slope terms below are never negative, so a texel that passes both tests
    // without them passes them with them (the same comparisons, so the same bits): most
    // receivers skip the sqrt and divisions.
    let virtual_may_occlude = z_virtual < l.z - biases.virtual_bias;
    let real_may_occlude = z_real < l.z - biases.real_bias;
    if biases.slope >= 0.0 && !virtual_may_occlude && !real_may_occlude {
        return visible;
    }
    // tan of the angle of incidence, with cos clamped at 0.1.
    let cos = (n.dot(v) / r2.sqrt()).clamp(0.1, 1.0);
    let tan = (1.0 - cos * cos).sqrt() / cos;
    let texel = f.footprint(l.z);
    let slope = biases.slope * tan;
    let virtual_occludes = z_virtual < l.z - (biases.virtual_bias + slope * texel);
    let real_occludes = z_real < l.z - (biases.real_bias + slope * texel.max(patch));
    let mut occluder = f32::INFINITY;
    if virtual_occludes {
        occluder = z_virtual;
    }
    if real_occludes {
        occluder = occluder.min(z_real);
    }
    // Along the ray to the light, distance scales with light-space depth; over the
    // cosine at the receiver, as `sample.path` records it.
    let occluder_over_cos = occluder.is_finite().then(|| {
        let r = r2.sqrt();
        let d = r * (1.0 - occluder / l.z);
        let cos_receiver = n.dot(v) / r;
        d.max(0.0) / cos_receiver
    });
    MapVisibility {
        real: !real_occludes,
        virtual_: !virtual_occludes,
        occluder_over_cos,
    }
}

/// Eq. 6 as irradiance: E_j = I_j cos(theta_j)+ cos(theta)+ / r^2 for the receiver at
/// `x` with unit normal `n`, where `v` = light position - x. r^2 is clamped below at
/// A_j / pi: a Lambertian disk of area A and radiance L gives at most pi L = I / (A / pi)
/// (the irradiance of a whole hemisphere of that radiance), so a receiver next to an
/// area light does not see 1/r^2 blow up. Returns 0 when either cosine is not positive.
/// (The scalar reference: the stage shades through `shade_lanes::shade_points`.)
#[cfg(test)]
pub(crate) fn light_irradiance(light: &PreparedLight, n: Vec3A, v: Vec3A) -> Option<(Vec3A, f32)> {
    let cos_receiver = n.dot(v);
    let cos_light = -light.normal.dot(v);
    if !(cos_receiver > 0.0 && cos_light > 0.0) {
        return None;
    }
    let r2 = v.length_squared();
    let e = light.intensity * (cos_receiver * cos_light / (r2 * r2.max(light.min_r2)));
    Some((e, r2))
}

/// Shades a point `x` with unit normal `n` (world) by every light: E_R and E_RV of eqs.
/// 12-13 in irradiance form. V_j and V^_j come from the light's shadow maps for points
/// inside its frustum and are 1 outside it (and for lights without maps). `patch` is
/// the world size of the real-map splat at the receiver (see [`Biases::slope`]). Bit j
/// of `lookup` clear says the point is known to lie outside light j's frustum (lights
/// from 64 on are always looked up). The scalar reference of
/// [`super::shade_lanes::shade_points`], which shades every point of the stage with its
/// bits (tested).
#[cfg(test)]
pub(crate) fn shade_point(
    x: Vec3A,
    n: Vec3A,
    patch: f32,
    lookup: u64,
    lights: &[PreparedLight],
    maps: Maps,
    biases: Biases,
) -> Shaded {
    let mut out = Shaded {
        e_r: Vec3::ZERO,
        e_rv: Vec3::ZERO,
        min_occluder: f32::INFINITY,
    };
    let (mut e_r, mut e_rv) = (Vec3A::ZERO, Vec3A::ZERO);
    for (j, light) in lights.iter().enumerate() {
        let v = light.position - x;
        let Some((e, r2)) = light_irradiance(light, n, v) else {
            continue;
        };
        let (mut real_visible, mut virtual_visible) = (true, true);
        if let Some(f) = light.frustum_to_look_up(j, lookup) {
            let base = j * maps.stride;
            let light_maps = &maps.data[base..base + 2 * maps.texels];
            let seen = map_visibility(f, light_maps, x, n, v, r2, patch, biases);
            (real_visible, virtual_visible) = (seen.real, seen.virtual_);
            if let Some(d) = seen.occluder_over_cos {
                out.min_occluder = out.min_occluder.min(d);
            }
        }
        if real_visible {
            e_r += e;
            if virtual_visible {
                e_rv += e;
            }
        }
    }
    out.e_r = e_r.into();
    out.e_rv = e_rv.into();
    out
}

/// SH9 irradiance with the cosine-lobe factors folded into the coefficients once per
/// frame, evaluated in f32 (the formula of [`relume_scene::light::sh::sh9_irradiance`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sh9Irradiance {
    weighted: [Vec3A; 9],
}

impl Sh9Irradiance {
    pub fn new(coeffs: &[Vec3; 9]) -> Sh9Irradiance {
        let mut weighted = [Vec3A::ZERO; 9];
        for k in 0..9 {
            weighted[k] =
                Vec3A::from(coeffs[k]) * relume_scene::light::sh::SH9_COSINE_LOBE[k] as f32;
        }
        Sh9Irradiance { weighted }
    }

    #[inline]
    pub fn at(&self, n: Vec3A) -> Vec3 {
        let (x, y, z) = (n.x, n.y, n.z);
        let w = &self.weighted;
        let e = w[0] * 0.282095
            + w[1] * (0.488603 * y)
            + w[2] * (0.488603 * z)
            + w[3] * (0.488603 * x)
            + w[4] * (1.092548 * x * y)
            + w[5] * (1.092548 * y * z)
            + w[6] * (0.315392 * (3.0 * z * z - 1.0))
            + w[7] * (1.092548 * x * z)
            + w[8] * (0.546274 * (x * x - y * y));
        e.into()
    }
}
