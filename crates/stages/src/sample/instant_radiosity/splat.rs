//! Splatting points into an imperfect shadow map ([`splat`]): one point at a time, or
//! eight at a time (`splat_points`): where each point falls in a map and
//! how many texels its splat reaches, one point per lane, operation for operation as
//! the scalar `Projection::project`, `texel_size` and reach (the same bits). The squares
//! are then written one point at a time (the nearest depth a texel keeps does not
//! depend on the order of the points), eight texels of a square's row at once: a
//! texel takes the point's depth where that is less than its own and keeps its bits
//! otherwise, as the scalar `splat_square` does (a comparison with NaN is false in
//! both).

use super::gather_lanes::{Projected, project};
use super::ism::{
    MAX_SPLAT_RADIUS, Projection, Texel, keep_nearer, project_point, splat_square, square_bounds,
};
use glam::Vec3;
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// Splats `points` into `map` (`size * size` texels, cleared to INFINITY by the caller):
/// each point that projects into the map keeps the nearest depth of the texels its patch
/// covers. A point stands for a disc of the surface of the radius given with it (metres:
/// a sparse subset of a surface stands for all of it); the splat is the square of texels
/// within that radius of its texel (at most [`MAX_SPLAT_RADIUS`]), one texel when the
/// patch is smaller than a texel. Returns the rectangle `[x0, y0, x1, y1)` of the
/// texels written (empty: x1 <= x0).
pub fn splat(
    map: &mut [f32],
    size: usize,
    projection: &Projection,
    points: impl Iterator<Item = (Vec3, f32)>,
) -> [usize; 4] {
    splat_with(None, map, size, projection, points)
}

/// [`splat`], projecting eight points at a time with `kernel`'s lanes (`None`: one at a
/// time; the same bits).
pub(super) fn splat_with(
    kernel: Option<Kernel>,
    map: &mut [f32],
    size: usize,
    projection: &Projection,
    mut points: impl Iterator<Item = (Vec3, f32)>,
) -> [usize; 4] {
    let mut written = [size, size, 0, 0];
    if let Some(kernel) = kernel {
        let mut group = [(Vec3::ZERO, 0.0); LANES];
        loop {
            let mut n = 0;
            for (slot, point) in group.iter_mut().zip(points.by_ref()) {
                *slot = point;
                n += 1;
            }
            if n < LANES {
                // The last few, one at a time.
                for &(p, radius) in &group[..n] {
                    if let Some((texel, reach)) = project_point(projection, size, p, radius) {
                        splat_square(map, size, texel, reach, &mut written);
                    }
                }
                return written;
            }
            splat_points(kernel, projection, size, &group, map, &mut written);
        }
    }
    for (p, radius) in points {
        if let Some((texel, reach)) = project_point(projection, size, p, radius) {
            splat_square(map, size, texel, reach, &mut written);
        }
    }
    written
}

/// Where each of eight points (position, patch radius) falls in a `size`-texel map of
/// `projection`, and its splat's reach in texels; `None` outside the map (the tests'
/// view of what [`splat_points`] splats).
#[cfg(test)]
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

#[cfg(all(test, target_arch = "x86_64"))]
#[target_feature(enable = "avx2,fma")]
fn project_points_avx2(
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
) -> [Option<(Texel, i32)>; LANES] {
    project_points_with::<relume_base::simd::Avx2>(projection, size, points)
}

/// Splats eight points (position, patch radius) into `map` as `splat_square` does
/// each, growing `written` to hold them.
pub(super) fn splat_points(
    kernel: Kernel,
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
    map: &mut [f32],
    written: &mut [usize; 4],
) {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { splat_points_avx2(projection, size, points, map, written) },
        _ => splat_points_with::<Portable>(projection, size, points, map, written),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn splat_points_avx2(
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
    map: &mut [f32],
    written: &mut [usize; 4],
) {
    splat_points_with::<relume_base::simd::Avx2>(projection, size, points, map, written)
}

#[inline(always)]
fn splat_points_with<V: Lanes>(
    projection: &Projection,
    size: usize,
    points: &[(Vec3, f32); LANES],
    map: &mut [f32],
    written: &mut [usize; 4],
) {
    for (texel, reach) in project_points_with::<V>(projection, size, points)
        .into_iter()
        .flatten()
    {
        if reach == 0 {
            splat_square(map, size, texel, reach, written);
        } else {
            splat_square_lanes::<V>(map, size, texel, reach, written);
        }
    }
}

/// `splat_square` with the first eight texels of each row in lanes (the ninth, at
/// reach 4, and rows whose eight lanes would pass the end of `map`, one at a time).
#[inline(always)]
fn splat_square_lanes<V: Lanes>(
    map: &mut [f32],
    size: usize,
    texel: Texel,
    reach: i32,
    written: &mut [usize; 4],
) {
    let [x0, y0, x1, y1] = square_bounds(size, texel, reach, written);
    let head = (x1 - x0).min(LANES);
    let columns = V::from_array(std::array::from_fn(|l| l as f32));
    let in_square = columns.lt(V::splat(head as f32));
    let depth = V::splat(texel.depth);
    for ty in y0..y1 {
        let (start, end) = (ty * size + x0, ty * size + x1);
        let rest = if start + LANES <= map.len() {
            let old = V::load_slice(map, start);
            V::select(in_square.and(depth.lt(old)), depth, old).store_slice(map, start);
            start + head..end
        } else {
            start..end
        };
        keep_nearer(&mut map[rest], texel.depth);
    }
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
