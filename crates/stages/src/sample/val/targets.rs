//! Where a light's shadow maps go: its slice of the renderer's map buffer, split into
//! the targets of the virtual and the real map builders (area lights and spots alike).

use super::real_splat::RealTarget;
use super::shadow::ShadowFrustum;
use super::virtual_maps::VirtualTarget;

/// One light's slice of [`super::ValRenderer`]'s maps (its virtual map, real map and the
/// real map's scratch, size^2 each) as the targets of the map builders.
pub(super) fn light_targets<'a>(
    frustum: &'a ShadowFrustum,
    maps: &'a mut [f32],
) -> (VirtualTarget<'a>, RealTarget<'a>) {
    let texels = frustum.size * frustum.size;
    let (virtual_map, rest) = maps.split_at_mut(texels);
    let (map, scratch) = rest.split_at_mut(texels);
    let virtual_target = VirtualTarget {
        frustum,
        map: virtual_map,
    };
    (
        virtual_target,
        RealTarget {
            frustum,
            map,
            scratch,
        },
    )
}
