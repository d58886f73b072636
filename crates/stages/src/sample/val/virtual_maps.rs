//! The virtual shadow maps (paper 004 Sec. 5; see [`super::shadow`]): the virtual
//! triangles rasterized into each light's frustum, nearest depth per texel.
//!
//! Each triangle is moved into the light spaces of a group of up to eight lights at
//! once, one light per lane ([`Lanes`]), and projected there; each light's map then
//! rasterizes it alone with [`raster_screen_triangle`]. The lanes do the one-light
//! code's operations in its order, so every kernel and grouping gives the maps of
//! `virtual_shadow_map_reference`, one light at a time (tested). A triangle that crosses a
//! light's near plane (which a frustum fitted to the objects keeps them in front of)
//! takes that one-light path for that light: clipped, then rasterized.

use super::raster::{DepthTarget, raster_screen_triangle, raster_view_triangle};
use super::shadow::{FrustumLanes, ShadowFrustum};
use glam::{Vec2, Vec3};
use relume_base::simd::{Kernel, LANES, Lanes, Portable};
use relume_scene::objects::VirtualScene;

/// The near plane of the virtual maps (light-space z).
const NEAR: f32 = 1e-6;

/// One light's virtual map to build: its frustum and the map (size^2).
pub(crate) struct VirtualTarget<'a> {
    pub frustum: &'a ShadowFrustum,
    pub map: &'a mut [f32],
}

/// Rasterizes the virtual triangles into the maps of `targets` (at most [`LANES`],
/// reset here) with `kernel` (any kernel gives the same maps).
pub(crate) fn virtual_shadow_maps(
    kernel: Kernel,
    targets: &mut [VirtualTarget],
    scene: &VirtualScene,
) {
    assert!(targets.len() <= LANES, "at most {LANES} lights per pass");
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the kernel came from `Kernel::available`: the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { raster_avx2(targets, scene) },
        _ => raster_lanes::<Portable>(targets, scene),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn raster_avx2(targets: &mut [VirtualTarget], scene: &VirtualScene) {
    raster_lanes::<relume_base::simd::Avx2>(targets, scene)
}

/// The pass of [`virtual_shadow_maps`] with lanes `V`.
#[inline(always)]
fn raster_lanes<V: Lanes>(targets: &mut [VirtualTarget], scene: &VirtualScene) {
    let frames = FrustumLanes::<V>::new(targets.iter().map(|t| t.frustum));
    // `ShadowFrustum::project`: raster coordinates, texel centres at integers.
    let raster_half = frames.half.sub(V::splat(0.5));
    let (near, one) = (V::splat(NEAR), V::splat(1.0));
    let mut maps: Vec<(&ShadowFrustum, DepthTarget)> = targets
        .iter_mut()
        .map(|t| {
            t.map.fill(f32::INFINITY);
            let target = DepthTarget {
                width: t.frustum.size,
                height: t.frustum.size,
                first_row: 0,
                depth: &mut *t.map,
                ids: None,
            };
            (t.frustum, target)
        })
        .collect();
    for (i, tri) in scene.triangles.iter().enumerate() {
        let mut in_front = V::from_array([f32::from_bits(u32::MAX); LANES]);
        let mut screen = [[[0.0f32; LANES]; 3]; 3];
        for (k, v) in tri.vertices.iter().enumerate() {
            let d = frames.offset((*v).into());
            let (lx, ly, lz) = (frames.x(d), frames.y(d), frames.z(d));
            in_front = in_front.and(lz.ge(near));
            screen[k] = [
                lx.div(lz).mul(frames.scale).add(raster_half).to_array(),
                ly.div(lz).mul(frames.scale).add(raster_half).to_array(),
                one.div(lz).to_array(),
            ];
        }
        let in_front = in_front.to_array();
        for (l, (frustum, target)) in maps.iter_mut().enumerate() {
            if in_front[l].to_bits() != 0 {
                let vertex =
                    |k: usize| (Vec2::new(screen[k][0][l], screen[k][1][l]), screen[k][2][l]);
                raster_screen_triangle(target, [vertex(0), vertex(1), vertex(2)], i as u32);
            } else {
                let view = tri
                    .vertices
                    .map(|v| Vec3::from(frustum.light_space(v.into())));
                raster_view_triangle(target, &view, NEAR, |l| frustum.project(l), i as u32);
            }
        }
    }
}

/// One light's virtual map, one triangle at a time: clipped at the near plane,
/// projected and rasterized (the reference the lanes are tested against).
#[cfg(test)]
pub(crate) fn virtual_shadow_map_reference(
    frustum: &ShadowFrustum,
    scene: &VirtualScene,
    map: &mut [f32],
) {
    map.fill(f32::INFINITY);
    let mut target = DepthTarget {
        width: frustum.size,
        height: frustum.size,
        first_row: 0,
        depth: map,
        ids: None,
    };
    for (i, tri) in scene.triangles.iter().enumerate() {
        let view = tri
            .vertices
            .map(|v| Vec3::from(frustum.light_space(v.into())));
        raster_view_triangle(&mut target, &view, NEAR, |l| frustum.project(l), i as u32);
    }
}

#[cfg(test)]
mod tests {
    use super::super::shadow::test_support::{assert_groups_match, eight_lights, unit_box};
    use super::*;
    use glam::{Affine3A, Vec3A};
    use relume_base::rng::{hash, unit_f32};
    use relume_scene::objects::{Material, Triangle, shapes};

    #[test]
    fn virtual_map_holds_the_depth_of_a_square_seen_from_above() {
        let b = unit_box();
        let f = ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &b, 64, 1.0).unwrap();
        let (y, h) = (1.0, 0.25);
        let v = [
            Vec3::new(-h, y, -h),
            Vec3::new(h, y, -h),
            Vec3::new(h, y, h),
            Vec3::new(-h, y, h),
        ];
        let tri = |a, b, c| Triangle {
            vertices: [a, b, c],
            normals: [Vec3::Y; 3],
            material: 0,
        };
        let scene = VirtualScene::new(
            vec![tri(v[0], v[1], v[2]), tri(v[0], v[2], v[3])],
            vec![Material::DIFFUSE_GRAY],
        );
        let mut map = vec![0.0; 64 * 64];
        virtual_shadow_map_reference(&f, &scene, &mut map);
        let centre = f.texel(f.light_space(Vec3A::new(0.0, 0.0, 0.0))).unwrap();
        assert!((map[centre] - 4.0).abs() < 1e-4, "{}", map[centre]);
        let outside = f.texel(f.light_space(Vec3A::new(0.45, 0.0, 0.0))).unwrap();
        assert_eq!(map[outside], f32::INFINITY);
        // Covered texels: the square's share of the map, (0.5 / 4) / (2 tan) squared.
        let covered = map.iter().filter(|z| z.is_finite()).count() as f32;
        let expected = (0.5 / 4.0 / (2.0 * f.tan_half) * 64.0).powi(2);
        assert!(
            (covered - expected).abs() < 0.1 * expected,
            "{covered} vs {expected}"
        );
    }

    /// A group pass gives each light the one-light map bit for bit: a torus, a sphere
    /// and random triangles around the objects' box, some reaching behind the lights
    /// (clipped at their near planes), seen by eight lights from many directions, in
    /// groups of 1, 3 and 8.
    #[test]
    fn a_group_pass_gives_each_light_its_one_light_map() {
        let place = |triangles: Vec<Triangle>, at: Vec3| -> Vec<Triangle> {
            let to = Affine3A::from_translation(at);
            triangles
                .into_iter()
                .map(|t| Triangle {
                    vertices: t.vertices.map(|v| to.transform_point3(v)),
                    ..t
                })
                .collect()
        };
        let mut triangles = place(shapes::torus(0.3, 0.1, 32, 12), Vec3::new(0.0, 0.1, 0.0));
        triangles.extend(place(shapes::sphere(0.15, 16), Vec3::new(0.3, 0.5, -0.2)));
        let random = |i: u64, k: u64| unit_f32(hash(&[9, i, k])) - 0.5;
        for i in 0..200 {
            let centre = Vec3::new(random(i, 0), 0.5 + random(i, 1), random(i, 2));
            // Every tenth one long enough to reach behind the lights.
            let reach = if i % 10 == 0 { 12.0 } else { 0.3 };
            let vertex = |k: u64| {
                centre
                    + Vec3::new(
                        random(i, 3 * k + 3),
                        random(i, 3 * k + 4),
                        random(i, 3 * k + 5),
                    ) * reach
            };
            triangles.push(Triangle {
                vertices: [vertex(0), vertex(1), vertex(2)],
                normals: [Vec3::Y; 3],
                material: 0,
            });
        }
        let scene = VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY]);
        let frusta = eight_lights(64);
        let reference: Vec<Vec<f32>> = frusta
            .iter()
            .map(|f| {
                let mut map = vec![0.0; 64 * 64];
                virtual_shadow_map_reference(f, &scene, &mut map);
                map
            })
            .collect();
        let written: usize = reference
            .iter()
            .map(|m| m.iter().filter(|z| z.is_finite()).count())
            .sum();
        assert!(
            written > 8 * 1000,
            "only {written} texels written: a weak test"
        );
        // Some triangle must cross some light's near plane.
        assert!(scene.triangles.iter().any(|t| frusta.iter().any(|f| {
            t.vertices
                .iter()
                .any(|v| f.light_space(Vec3A::from(*v)).z < NEAR)
        })));
        assert_groups_match(&frusta, &reference, |kernel, group| {
            let mut maps = vec![vec![0.0; 64 * 64]; group.len()];
            let mut targets: Vec<VirtualTarget> = group
                .iter()
                .zip(maps.iter_mut())
                .map(|(frustum, map)| VirtualTarget { frustum, map })
                .collect();
            virtual_shadow_maps(kernel, &mut targets, &scene);
            maps
        });
    }
}
