//! The real shadow maps (paper 004 Sec. 5; see [`super::shadow`]): the depth map's
//! world points splatted into each light's frustum, nearest depth per texel, then
//! single-texel holes closed.
//!
//! Every point is visited once for a group of up to eight lights, one light per lane
//! ([`Lanes`]): the point is moved into the eight light spaces and projected at once,
//! and the lanes that land on one texel are written in lanes' order; the rare wider
//! splats go on one by one. (Visiting the points once per light spent most of its time on moving
//! each point into light space and testing it; the writes themselves are few per
//! point.) The lanes do the one-light code's operations in its order (glam's
//! `Vec3A::dot` on x86-64 is (x rx + y ry) + z rz, no fused multiply-add), each light's
//! map sees the same points, and a depth minimum does not depend on the order of the
//! writes: every kernel and grouping gives the maps of `real_shadow_map_reference`, one light
//! and one point at a time (tested).

use super::shadow::{FrustumLanes, ShadowFrustum, Tile};
use glam::Vec3A;
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// Largest splat half-width in texels (bounds the cost of very close, coarse points).
const MAX_SPLAT_RADIUS: f32 = 16.0;

/// Half the diagonal of a square patch, in patch widths (rounded up from 1 / sqrt 2).
const HALF_DIAGONAL: f32 = 0.71;

/// The real surface as the splat reads it: world points (`width` per row, non-finite =
/// none), the world size of the patch each stands for (see
/// [`super::shadow::PointSampling::footprint`]), and the tiles' bounding spheres.
#[derive(Clone, Copy)]
pub(crate) struct RealSurface<'a> {
    pub points: &'a [Vec3A],
    pub patches: &'a [f32],
    pub width: usize,
    pub tiles: &'a [Option<Tile>],
}

/// One light's real map to build: its frustum, the map and a scratch buffer (both
/// size^2).
pub(crate) struct RealTarget<'a> {
    pub frustum: &'a ShadowFrustum,
    pub map: &'a mut [f32],
    pub scratch: &'a mut [f32],
}

/// Builds the real maps of `targets` (at most [`LANES`]) in one pass over the points,
/// with `kernel` (any kernel gives the same maps): each point of a tile that may reach a
/// light's frustum beyond `real_from` is splatted into that light's map over a square
/// of texels as wide as the patch it stands for (so a surface the camera sampled more
/// coarsely than the map's texels still covers it), then single-texel holes are closed.
pub(crate) fn real_shadow_maps(kernel: Kernel, targets: &mut [RealTarget], surface: &RealSurface) {
    assert!(targets.len() <= LANES, "at most {LANES} lights per pass");
    for target in targets.iter_mut() {
        target.map.fill(f32::INFINITY);
    }
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the kernel came from `Kernel::available`: the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { splat_avx2(targets, surface) },
        _ => splat_lanes::<Portable>(targets, surface),
    }
    for target in targets.iter_mut() {
        close_holes(target.map, target.scratch, target.frustum.size);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn splat_avx2(targets: &mut [RealTarget], surface: &RealSurface) {
    splat_lanes::<relume_base::simd::Avx2>(targets, surface)
}

/// The pass of [`real_shadow_maps`] with lanes `V`.
#[inline(always)]
fn splat_lanes<V: Lanes>(targets: &mut [RealTarget], surface: &RealSurface) {
    let frames = FrustumLanes::<V>::new(targets.iter().map(|t| t.frustum));
    let zero = V::splat(0.0);
    let all = f32::from_bits(u32::MAX);
    for tile in surface.tiles.iter().flatten() {
        // The lights whose frustum the tile may reach (as the one-light code skips the
        // others' tiles).
        let mut reaches = [0.0f32; LANES];
        for (l, target) in targets.iter().enumerate() {
            let f = target.frustum;
            if f.may_hold(tile.centre, tile.radius, f.real_from) {
                reaches[l] = all;
            }
        }
        if reaches.iter().all(|r| r.to_bits() == 0) {
            continue;
        }
        let reaches = V::from_array(reaches);
        for y in tile.y0..tile.y1 {
            let row = y * surface.width + tile.x0..y * surface.width + tile.x1;
            for (p, &patch) in surface.points[row.clone()]
                .iter()
                .zip(&surface.patches[row])
            {
                let d = frames.offset(*p);
                let lz = frames.z(d);
                // NaN points fail this test too.
                let in_depth = lz.ge(frames.real_from).and(lz.gt(zero)).and(reaches);
                if !in_depth.any() {
                    continue;
                }
                let (lx, ly) = (frames.x(d), frames.y(d));
                let k = frames.scale.div(lz);
                let fx = lx.mul(k).add(frames.half);
                let fy = ly.mul(k).add(frames.half);
                let radius = V::splat(HALF_DIAGONAL * patch)
                    .mul(k)
                    .min(V::splat(MAX_SPLAT_RADIUS));
                // `splat_point`, its one-texel case in lanes: the lanes that land (the
                // others write +inf into texel 0, which changes nothing), then the
                // wider splats one by one.
                let one_texel = radius.lt(V::splat(0.5));
                let lands = in_depth
                    .and(one_texel)
                    .and(fx.ge(zero))
                    .and(fx.lt(frames.size))
                    .and(fy.ge(zero))
                    .and(fy.lt(frames.size));
                // In the map, the coordinates truncate to texels below `size`.
                let tx = V::select(lands, fx, zero).trunc_to_i32();
                let ty = V::select(lands, fy, zero).trunc_to_i32();
                let depth = V::select(lands, lz, V::splat(f32::INFINITY)).to_array();
                for (l, target) in targets.iter_mut().enumerate() {
                    let t = ty[l] as usize * target.frustum.size + tx[l] as usize;
                    let nearest = target.map[t];
                    // A select, not a branch: neighbouring points often land on one
                    // texel at nearly one depth, which a branch mispredicts.
                    target.map[t] = if depth[l] < nearest {
                        depth[l]
                    } else {
                        nearest
                    };
                }
                let wide = in_depth.and_not(one_texel);
                if wide.any() {
                    let (wide, lz, fx, fy, radius) = (
                        wide.to_array(),
                        lz.to_array(),
                        fx.to_array(),
                        fy.to_array(),
                        radius.to_array(),
                    );
                    for (l, target) in targets.iter_mut().enumerate() {
                        if wide[l].to_bits() != 0 {
                            splat_square(
                                target.frustum,
                                lz[l],
                                fx[l],
                                fy[l],
                                radius[l],
                                target.map,
                            );
                        }
                    }
                }
            }
        }
    }
}

/// Writes depth `z` into the texels of `map` that a point at map coordinates (`fx`,
/// `fy`) covers: its own texel when the splat's half-width `radius` (texels) is below
/// half a texel, else the square of texels within `radius` ([`splat_square`]).
#[cfg(test)]
fn splat_point(frustum: &ShadowFrustum, z: f32, fx: f32, fy: f32, radius: f32, map: &mut [f32]) {
    if radius < 0.5 {
        if let Some(t) = frustum.texel_at(fx, fy)
            && z < map[t]
        {
            map[t] = z;
        }
        return;
    }
    splat_square(frustum, z, fx, fy, radius, map);
}

/// Writes depth `z` into the texels within `radius` (at least half a texel) of map
/// coordinates (`fx`, `fy`), clipped to the map.
#[inline(always)]
fn splat_square(frustum: &ShadowFrustum, z: f32, fx: f32, fy: f32, radius: f32, map: &mut [f32]) {
    let size = frustum.size;
    let s = size as f32;
    let (x0, x1) = ((fx - radius).max(0.0), (fx + radius).min(s - 1e-3));
    let (y0, y1) = ((fy - radius).max(0.0), (fy + radius).min(s - 1e-3));
    if !(x0 <= x1 && y0 <= y1) {
        return;
    }
    for ty in y0 as usize..=y1 as usize {
        for t in &mut map[ty * size + x0 as usize..=ty * size + x1 as usize] {
            if z < *t {
                *t = z;
            }
        }
    }
}

/// One light's real map, one point at a time: the reference the lanes are tested
/// against.
#[cfg(test)]
pub(crate) fn real_shadow_map_reference(target: &mut RealTarget, surface: &RealSurface) {
    let frustum = target.frustum;
    target.map.fill(f32::INFINITY);
    let half = frustum.size as f32 * 0.5;
    for tile in surface.tiles.iter().flatten() {
        if !frustum.may_hold(tile.centre, tile.radius, frustum.real_from) {
            continue;
        }
        for y in tile.y0..tile.y1 {
            let row = y * surface.width + tile.x0..y * surface.width + tile.x1;
            for (p, &patch) in surface.points[row.clone()]
                .iter()
                .zip(&surface.patches[row])
            {
                let l = frustum.light_space(*p);
                // NaN points fail this test too.
                if !(l.z >= frustum.real_from && l.z > 0.0) {
                    continue;
                }
                let k = frustum.scale / l.z;
                let (fx, fy) = (l.x * k + half, l.y * k + half);
                let radius = (HALF_DIAGONAL * patch * k).min(MAX_SPLAT_RADIUS);
                splat_point(frustum, l.z, fx, fy, radius, target.map);
            }
        }
    }
    close_holes(target.map, target.scratch, frustum.size);
}

/// Fills each empty texel whose left and right, or upper and lower, neighbours are both
/// filled, with the farthest of those filled pairs' depths (reads a copy: the result does
/// not depend on the scan order).
fn close_holes(map: &mut [f32], scratch: &mut [f32], size: usize) {
    scratch.copy_from_slice(map);
    for y in 0..size {
        for x in 0..size {
            let i = y * size + x;
            if scratch[i].is_finite() {
                continue;
            }
            let mut fill = f32::NEG_INFINITY;
            if x > 0 && x + 1 < size && scratch[i - 1].is_finite() && scratch[i + 1].is_finite() {
                fill = fill.max(scratch[i - 1]).max(scratch[i + 1]);
            }
            if y > 0
                && y + 1 < size
                && scratch[i - size].is_finite()
                && scratch[i + size].is_finite()
            {
                fill = fill.max(scratch[i - size]).max(scratch[i + size]);
            }
            if fill.is_finite() {
                map[i] = fill;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::shadow::test_support::{assert_groups_match, eight_lights, unit_box};
    use super::super::shadow::{PointSampling, tile_of};
    use super::*;
    use glam::Vec3;
    use relume_base::rng::{hash, unit_f32};
    use relume_scene::objects::Aabb;

    /// How a test builds a map: the one-by-one reference, or a kernel's group pass.
    #[derive(Clone, Copy, Debug)]
    enum Build {
        OneByOne,
        Group(Kernel),
    }

    const BUILDS: [Build; 3] = [
        Build::OneByOne,
        Build::Group(Kernel::Portable),
        Build::Group(Kernel::Avx2Fma),
    ];

    /// The real maps of `frusta` (each `size`^2), built by `build` (the group pass
    /// takes all the frusta at once).
    fn build_maps(build: Build, frusta: &[ShadowFrustum], surface: &RealSurface) -> Vec<Vec<f32>> {
        let texels = frusta.first().map_or(0, |f| f.size * f.size);
        let mut maps = vec![vec![0.0; texels]; frusta.len()];
        let mut scratch = vec![vec![0.0; texels]; frusta.len()];
        let mut targets: Vec<RealTarget> = frusta
            .iter()
            .zip(maps.iter_mut().zip(scratch.iter_mut()))
            .map(|(frustum, (map, scratch))| RealTarget {
                frustum,
                map,
                scratch,
            })
            .collect();
        match build {
            Build::OneByOne => targets
                .iter_mut()
                .for_each(|t| real_shadow_map_reference(t, surface)),
            Build::Group(kernel) => real_shadow_maps(kernel, &mut targets, surface),
        }
        drop(targets);
        maps
    }

    #[test]
    fn real_map_keeps_the_nearest_point_and_closes_single_holes() {
        for build in BUILDS {
            keeps_the_nearest_point_and_closes_single_holes(build);
        }
    }

    fn keeps_the_nearest_point_and_closes_single_holes(build: Build) {
        let b = unit_box();
        let f = ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &b, 32, 1.0).unwrap();
        // A floor sampled at every texel except one column, a nearer point above it, a
        // point of the light's own ceiling (nearer than real_from) and a NaN.
        let mut points = Vec::new();
        let texel_width = f.footprint(5.0);
        for k in 0..32 {
            for i in 0..32 {
                if i == 10 {
                    points.push(Vec3A::NAN);
                    continue;
                }
                let x = (i as f32 - 15.5) * texel_width;
                let z = (k as f32 - 15.5) * texel_width;
                points.push(Vec3A::new(x, 0.0, z));
            }
        }
        points.push(Vec3A::new(0.01, 0.5, 0.01));
        points.push(Vec3A::new(0.0, 4.9, 0.0));
        let width = points.len();
        let tiles = [tile_of(&points, width, 0, width, 0, 1)];
        // Points of negligible footprint: one texel each.
        let sampling = PointSampling {
            origin: Vec3A::new(0.0, 5.0, 0.0),
            pixel_angle: 1e-4,
        };
        let patches = |points: &[Vec3A], sampling: PointSampling| -> Vec<f32> {
            points.iter().map(|p| sampling.footprint(*p)).collect()
        };
        let fine = patches(&points, sampling);
        let surface = RealSurface {
            points: &points,
            patches: &fine,
            width,
            tiles: &tiles,
        };
        let map = build_maps(build, &[f], &surface).remove(0);
        let at = |p: Vec3A| map[f.texel(f.light_space(p)).unwrap()];
        assert!(
            (at(Vec3A::new(0.01, 0.0, 0.01)) - 4.5).abs() < 1e-5,
            "{build:?}: the point above wins"
        );
        assert!((at(Vec3A::new(0.3, 0.0, 0.3)) - 5.0).abs() < 1e-5);
        let hole = Vec3A::new((10.0 - 15.5) * texel_width, 0.0, 0.0);
        assert!(
            (at(hole) - 5.0).abs() < 1e-5,
            "{build:?}: the missing column is closed"
        );
        assert!(
            map.iter().all(|&z| z >= 4.5),
            "{build:?}: the ceiling point is not an occluder"
        );
        // Coarse points cover the texels around them: every fourth point of each row
        // still closes the map.
        let sparse: Vec<Vec3A> = points[..32 * 32].iter().step_by(4).copied().collect();
        let tiles = [tile_of(&sparse, sparse.len(), 0, sparse.len(), 0, 1)];
        let coarse = PointSampling {
            pixel_angle: 4.0 * texel_width / 5.0,
            ..sampling
        };
        let surface = RealSurface {
            points: &sparse,
            patches: &patches(&sparse, coarse),
            width: sparse.len(),
            tiles: &tiles,
        };
        let map = build_maps(build, &[f], &surface).remove(0);
        let inner = (4..28).flat_map(|y| (4..28).map(move |x| y * 32 + x));
        assert!(
            inner.clone().all(|t| (map[t] - 5.0).abs() < 1e-5),
            "{build:?}: no holes"
        );
    }

    /// A group pass gives each light the one-by-one map bit for bit: random points
    /// around and beyond the frusta (some behind a light's depth limit, some NaN), tiles
    /// that reach only some of the lights, patches from sub-texel to past the largest
    /// splat, and groups of 1, 3 and 8 lights from many directions.
    #[test]
    fn a_group_pass_gives_each_light_its_one_by_one_map() {
        let width = 13 * 8;
        let rows = 60;
        let random = |i: usize, k: u64| unit_f32(hash(&[7, i as u64, k]));
        // Each tile's points lie within 0.4 m of a random spot in a 6 x 5 x 6 m box.
        let points: Vec<Vec3A> = (0..width * rows)
            .map(|i| {
                if i % 37 == 5 {
                    return Vec3A::NAN;
                }
                let tile = ((i / width) / 4 * width / 8 + (i % width) / 8) as u64;
                let at = |k: u64| unit_f32(hash(&[8, tile, k]));
                let spot = Vec3A::new(at(0), at(1), at(2)) * Vec3A::new(6.0, 5.0, 6.0)
                    - Vec3A::new(3.0, 0.5, 3.0);
                let p = Vec3A::new(random(i, 0), random(i, 1), random(i, 2));
                spot + (p - 0.5) * 0.8
            })
            .collect();
        // Some patches so wide that their splats reach into a map from tiles that the
        // tile test skips for that light.
        let patches: Vec<f32> = (0..points.len())
            .map(|i| {
                if i % 11 == 3 {
                    3.0
                } else {
                    0.3 * random(i, 3).powi(4)
                }
            })
            .collect();
        let mut tiles = Vec::new();
        for y0 in (0..rows).step_by(4) {
            for x0 in (0..width).step_by(8) {
                tiles.push(tile_of(&points, width, x0, x0 + 8, y0, y0 + 4));
            }
        }
        let surface = RealSurface {
            points: &points,
            patches: &patches,
            width,
            tiles: &tiles,
        };
        let lights = eight_lights(96);
        let reference = build_maps(Build::OneByOne, &lights, &surface);
        let written: usize = reference
            .iter()
            .map(|m| m.iter().filter(|z| z.is_finite()).count())
            .sum();
        assert!(
            written > 8 * 3000,
            "only {written} texels written: a weak test"
        );
        // Some tile must be skipped for one light and splatted for another.
        let reaches = |f: &ShadowFrustum, t: &Tile| f.may_hold(t.centre, t.radius, f.real_from);
        assert!(tiles.iter().flatten().any(|t| {
            lights.iter().any(|f| reaches(f, t)) && lights.iter().any(|f| !reaches(f, t))
        }));
        assert_groups_match(&lights, &reference, |kernel, group| {
            build_maps(Build::Group(kernel), group, &surface)
        });
    }

    /// A tile that the tile test skips for a light leaves that light's map alone in a
    /// group pass too, even where a point's wide splat would reach into the map: a
    /// point just outside a corner of light 0's frustum (outside the cone the tile test
    /// uses), grouped with a light whose wider frustum holds it.
    #[test]
    fn a_group_pass_skips_a_tile_for_the_lights_it_cannot_reach() {
        let f0 =
            ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &unit_box(), 32, 1.0).unwrap();
        let wide = Aabb {
            min: Vec3::new(-2.0, 0.0, -2.0),
            max: Vec3::new(2.0, 1.0, 2.0),
        };
        let f1 = ShadowFrustum::fit(Vec3::new(0.0, 8.0, 0.0), -Vec3::Y, &wide, 32, 1.0).unwrap();
        // 3 % beyond the corner direction (x = y = tan_half z in light space).
        let z = 4.5;
        let lateral = 1.03 * f0.tan_half * z;
        let p = f0.origin + f0.axis * z + (f0.right + f0.up) * lateral;
        let points = [p];
        let tiles = [tile_of(&points, 1, 0, 1, 0, 1)];
        let tile = tiles[0].unwrap();
        assert!(!f0.may_hold(tile.centre, tile.radius, f0.real_from));
        assert!(f1.may_hold(tile.centre, tile.radius, f1.real_from));
        let surface = RealSurface {
            points: &points,
            patches: &[3.0],
            width: 1,
            tiles: &tiles,
        };
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            let maps = build_maps(Build::Group(kernel), &[f0, f1], &surface);
            assert!(maps[0].iter().all(|z| z.is_infinite()), "{kernel:?}");
            assert!(maps[1].iter().any(|z| z.is_finite()), "{kernel:?}");
        }
    }
}
