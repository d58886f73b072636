//! The projection of [`super::ism::splat`], eight points at a time: where each point
//! falls in a map and how many texels its splat reaches, one point per lane, operation
//! for operation as the scalar `Projection::project`, `texel_size` and reach (the same
//! bits). The squares are then written one point at a time: the nearest depth a texel
//! keeps does not depend on the order of the points.

use super::gather_lanes::{Projected, project};
use super::ism::{MAX_SPLAT_RADIUS, Projection, Texel};
use crate::simd::{Kernel, LANES, Lanes, Portable};
use glam::Vec3;

/// Where each of eight points (position, patch radius) falls in a `size`-texel map of
/// `projection`, and its splat's reach in texels; `None` outside the map.
pub(super) fn project_points(
    kernel: Kernel,
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
) -> [Option<(Texel, i32)>; LANES] {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { project_points_avx2(projection, size, points) },
        _ => project_points_with::<Portable>(projection, size, points),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn project_points_avx2(
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
) -> [Option<(Texel, i32)>; LANES] {
    project_points_with::<crate::simd::Avx2>(projection, size, points)
}

#[inline(always)]
fn project_points_with<V: Lanes>(
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
) -> [Option<(Texel, i32)>; LANES] {
    let p = [
        V::from_array(points.map(|(p, _)| p.x)),
        V::from_array(points.map(|(p, _)| p.y)),
        V::from_array(points.map(|(p, _)| p.z)),
    ];
    let radius = V::from_array(points.map(|(_, r)| r));
    let Projected {
        inside,
        x,
        y,
        depth,
    } = project(projection, p, size);
    let s = size as f32;
    let texel = match *projection {
        Projection::Paraboloid { .. } => depth.mul(V::splat(4.0)).div(V::splat(s)),
        Projection::Orthographic { radius, .. } => V::splat(2.0 * radius / s),
    };
    // ceil(radius / texel - 0.5), at most MAX_SPLAT_RADIUS, where it is positive (the
    // ceiling of a positive value below it: its truncation, plus one unless whole).
    let over = radius.div(texel).sub(V::splat(0.5));
    let capped = over.min(V::splat(MAX_SPLAT_RADIUS as f32));
    let whole = capped.trunc();
    let up = V::select(capped.gt(whole), V::splat(1.0), V::splat(0.0));
    let reach = V::select(over.gt(V::splat(0.0)), whole.add(up), V::splat(0.0));
    let (inside, x, y) = (inside.to_array(), x.to_array(), y.to_array());
    let (depth, reach) = (depth.to_array(), reach.to_array());
    std::array::from_fn(|l| {
        (inside[l].to_bits() != 0).then(|| {
            let texel = Texel {
                x: x[l] as u32,
                y: y[l] as u32,
                depth: depth[l],
            };
            (texel, reach[l] as i32)
        })
    })
}
