//! The preparation pass ([`super::planes::prepare`]) for eight pixels of a row at once,
//! one per lane: curvature (eq. 20), bandwidths (eqs. 17, 18) and the cleaned planes,
//! with the same operations in the same order as the scalar functions of
//! [`super::bandwidth`] (glam's `normalize`, `length` and `dot` use no fused
//! multiply-adds, and neither does this), so the same bits.
//!
//! As everywhere in lane code: no lane operations inside closures (they do not inherit
//! `#[target_feature]`).

use super::bandwidth::{MAX_BANDWIDTH, MIN_NEIGHBOUR_DISTANCE, MIN_OCCLUDER_DISTANCE};
use super::planes::{
    B2_IND, B2X_DIR, B2Y_DIR, BandwidthSettings, DIR, IND, MISSING_POSITION, PX, PY, PZ,
    PrepareInputs, RowLayout,
};
use relume_base::simd::xyz::{Xyz, finite, finite_xyz, load_xyz, sub_xyz as sub};
use relume_base::simd::{LANES, Lanes, dot3};

/// Mask of the lanes where `v` is +0 or -0.
#[inline(always)]
fn is_zero<V: Lanes>(v: V) -> V {
    let zero = V::splat(0.0);
    v.ge(zero).and(zero.ge(v))
}

/// `v.normalize()` as glam computes it: v * (1 / sqrt(v . v)).
#[inline(always)]
fn normalize<V: Lanes>(v: &Xyz<V>) -> Xyz<V> {
    let recip = V::splat(1.0).div(dot3(*v, *v).sqrt());
    [v[0].mul(recip), v[1].mul(recip), v[2].mul(recip)]
}

/// `bandwidth::usable` per lane: finite position and normal, normal not zero.
#[inline(always)]
fn usable<V: Lanes>(p: &Xyz<V>, n: &Xyz<V>) -> V {
    let n_zero = is_zero(n[0]).and(is_zero(n[1])).and(is_zero(n[2]));
    finite_xyz(p).and(finite_xyz(n)).and_not(n_zero)
}

/// `bandwidth::curvature_to` per lane from the targets (positions `p`, normalized
/// normals `n_unit`) to the neighbours (`q`, `m`): the curvature, and the mask of the
/// lanes where it exists (neighbour usable and not too close).
#[inline(always)]
fn curvature_to<V: Lanes>(p: &Xyz<V>, n_unit: &Xyz<V>, q: &Xyz<V>, m: &Xyz<V>) -> (V, V) {
    let offset = sub(p, q);
    let d = dot3(offset, offset).sqrt();
    let exists = usable(q, m).and(d.ge(V::splat(MIN_NEIGHBOUR_DISTANCE)));
    // angle_between: c (1 + c^2 (1/24 + c^2 3/640)), c = |a/|a| - b/|b||.
    let chord = sub(n_unit, &normalize(m));
    let c = dot3(chord, chord).sqrt();
    let c2 = c.mul(c);
    let series = c2
        .mul(V::splat(3.0 / 640.0))
        .add(V::splat(1.0 / 24.0))
        .mul(c2)
        .add(V::splat(1.0));
    (c.mul(series).div(d), exists)
}

/// The curvature along one image axis: towards the forward neighbour where it exists
/// (`forward`: whether it is inside the image), else the backward one, else 0.
#[inline(always)]
fn curvature_along<V: Lanes>(
    target: (&Xyz<V>, &Xyz<V>),
    forward: Option<(Xyz<V>, Xyz<V>)>,
    backward: Option<(Xyz<V>, Xyz<V>)>,
) -> V {
    let (p, n_unit) = target;
    let zero = V::splat(0.0);
    let (back, back_exists) = match backward {
        Some((q, m)) => curvature_to(p, n_unit, &q, &m),
        None => (zero, zero),
    };
    let (fwd, fwd_exists) = match forward {
        Some((q, m)) => curvature_to(p, n_unit, &q, &m),
        None => (zero, zero),
    };
    V::select(fwd_exists, fwd, V::select(back_exists, back, zero))
}

/// `bandwidth::inverse_distance` per lane.
#[inline(always)]
fn inverse_distance<V: Lanes>(z: V) -> V {
    let inverse = V::splat(1.0).div(z.max(V::splat(MIN_OCCLUDER_DISTANCE)));
    V::select(finite(z), inverse, V::splat(0.0))
}

/// `bandwidth::clamp_bandwidth` per lane (as `f32::clamp` for finite values: -0 stays
/// -0; +inf gives the maximum, -inf and NaN 0).
#[inline(always)]
fn clamp_bandwidth<V: Lanes>(b: V) -> V {
    let zero = V::splat(0.0);
    let max = V::splat(MAX_BANDWIDTH);
    let low = V::select(b.lt(zero), zero, b);
    V::select(low.gt(max), max, low).zero_if_nan()
}

/// `bandwidth::direct_bandwidth` per lane, from `angular` = B_f + 2 B_rho.
#[inline(always)]
fn direct_bandwidth<V: Lanes>(curvature: V, inverse_distance: V, angular: V, b_e: V) -> V {
    clamp_bandwidth(
        curvature
            .mul(angular)
            .add(inverse_distance.mul(angular.add(b_e))),
    )
}

/// Where a group writes: the row's planes and filter widths.
pub(super) struct RowOut<'a> {
    pub row: &'a mut [f32],
    pub width_dir: &'a mut [f32],
    pub width_ind: &'a mut [f32],
}

/// Prepares pixels (x0 + l, y) of row `y` (see [`super::planes::prepare`]). Pixels
/// x0 - 1 and x0 + LANES must be inside the row (the X neighbours are read in lanes).
#[inline(always)]
pub(super) fn prepare_group<V: Lanes>(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    y: usize,
    x0: usize,
    out: &mut RowOut,
) {
    let (w, h) = (layout.width, layout.height);
    assert!(x0 >= 1 && x0 + LANES < w && y < h);
    let i = y * w + x0;
    let (p, n) = neighbours::<V>(images, i);
    let zero = V::splat(0.0);
    // Curvature (eq. 20), 0 where the target itself is not usable.
    let target_usable = usable(&p, &n);
    let n_unit = normalize(&n);
    let target = (&p, &n_unit);
    let (right, left) = (neighbours(images, i + 1), neighbours(images, i - 1));
    let below = if y + 1 < h {
        Some(neighbours(images, i + w))
    } else {
        None
    };
    let above = if y > 0 {
        Some(neighbours(images, i - w))
    } else {
        None
    };
    let kx = curvature_along(target, Some(right), Some(left)).and(target_usable);
    let ky = curvature_along(target, below, above).and(target_usable);
    // Bandwidths (eqs. 17, 18).
    let m = V::load_slice(&images.exponent.data, i);
    let m = V::select(finite(m), m.max(zero), zero);
    let glossy = m.gt(zero);
    let b_rho = V::select(glossy, V::splat(1.25).mul(m.sqrt()), zero);
    let angular = V::splat(settings.b_f).add(V::splat(2.0).mul(b_rho));
    let b_e = V::splat(settings.b_e);
    let inverse_zd = inverse_distance(V::load_slice(&images.direct_min_distance.data, i));
    let inverse_zi = inverse_distance(V::load_slice(&images.indirect_min_distance.data, i));
    let bx = direct_bandwidth(kx, inverse_zd, angular, b_e);
    let by = direct_bandwidth(ky, inverse_zd, angular, b_e);
    let indirect_brdf = V::select(
        glossy,
        V::splat(4.27).add(V::splat(0.15).mul(m)),
        V::splat(2.8),
    );
    let bi = clamp_bandwidth(indirect_brdf.mul(inverse_zi));
    // The planes.
    let has_position = finite_xyz(&p);
    let missing = V::splat(MISSING_POSITION);
    let row = &mut *out.row;
    for (q, c) in [(PX, 0), (PY, 1), (PZ, 2)] {
        V::select(has_position, p[c], missing).store_slice(row, layout.in_row(q, x0));
    }
    for (q, b) in [(B2X_DIR, bx), (B2Y_DIR, by), (B2_IND, bi)] {
        b.mul(b)
            .and(has_position)
            .store_slice(row, layout.in_row(q, x0));
    }
    for (kind, r, rv) in [(DIR, 0, 2), (IND, 1, 3)] {
        for (slot, layer) in [(0, r), (3, rv)] {
            let v = load_xyz::<V>(&images.layers[layer].data, i);
            let ok = has_position.and(finite_xyz(&v));
            for (c, value) in v.into_iter().enumerate() {
                value
                    .and(ok)
                    .store_slice(row, layout.in_row(kind + slot + c, x0));
            }
            let valid = V::splat(1.0).and(ok);
            valid.store_slice(row, layout.in_row(kind + 6 + slot / 3, x0));
        }
    }
    // Filter sizes 1 / B (paper 001 Fig. 7).
    let one = V::splat(1.0);
    let nan = V::splat(f32::NAN);
    let size_dir = V::splat(0.5).mul(one.div(bx).add(one.div(by)));
    V::select(has_position, size_dir, nan).store_slice(out.width_dir, x0);
    V::select(has_position, one.div(bi), nan).store_slice(out.width_ind, x0);
}

/// Positions and normals of pixels `j..j + LANES`.
#[inline(always)]
fn neighbours<V: Lanes>(images: &PrepareInputs, j: usize) -> (Xyz<V>, Xyz<V>) {
    (
        load_xyz(&images.world_position.data, j),
        load_xyz(&images.world_normal.data, j),
    )
}

#[cfg(test)]
mod tests {
    use super::super::lane_planes::{LaneLayout, LanePlanes, fill_line};
    use super::super::passes::{XSet, prepare_x_pass, x_pass};
    use super::super::planes::{INPUT_PLANES, X_PLANES, prepare, prepare_pixel, row_scratch};
    use super::*;
    use glam::Vec3;
    use relume_base::raster::{Image, ScalarImage, Vec3Image};
    use relume_base::rng::{hash, unit_f32};
    use relume_base::simd::Kernel;
    use relume_base::simd::Portable;

    fn noise(seed: u64, i: usize) -> f32 {
        unit_f32(hash(&[seed, i as u64]))
    }

    /// Picks one of `specials` for about one pixel in five, else `regular`.
    fn sometimes(seed: u64, i: usize, specials: &[f32], regular: f32) -> f32 {
        let k = (noise(seed, i) * 5.0 * specials.len() as f32) as usize;
        specials.get(k).copied().unwrap_or(regular)
    }

    struct Images {
        layers: [Vec3Image; 4],
        position: Vec3Image,
        normal: Vec3Image,
        zd: ScalarImage,
        zi: ScalarImage,
        exponent: ScalarImage,
    }

    /// A bumpy surface with what the bandwidths must survive: missing positions and
    /// normals (NaN, infinite), zero normals, neighbours at the same position, missing
    /// and non-positive distances and exponents, missing values.
    fn images(w: usize, h: usize) -> Images {
        let vec3 = |f: &dyn Fn(usize) -> Vec3| -> Vec3Image {
            Image::from_vec(w as u32, h as u32, (0..w * h).map(f).collect()).unwrap()
        };
        let scalar = |f: &dyn Fn(usize) -> f32| -> ScalarImage {
            Image::from_vec(w as u32, h as u32, (0..w * h).map(f).collect()).unwrap()
        };
        let position = vec3(&|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let z = 2.0 + 0.05 * noise(1, i);
            let p = Vec3::new(0.01 * x, 0.01 * y, z);
            match (noise(2, i) * 20.0) as u32 {
                0 => Vec3::NAN,
                1 => Vec3::new(f32::INFINITY, 0.0, 1.0),
                // The same position as the left neighbour (distance below the minimum).
                2 if i % w > 0 => Vec3::new(0.01 * (x - 1.0), 0.01 * y, z),
                _ => p,
            }
        });
        let normal = vec3(&|i| match (noise(3, i) * 20.0) as u32 {
            0 => Vec3::ZERO,
            1 => Vec3::new(0.0, f32::NAN, 1.0),
            2 => Vec3::new(-0.0, 0.0, -0.0),
            _ => Vec3::new(noise(4, i) - 0.5, noise(5, i) - 0.5, -1.0) * 3.0,
        });
        let distances = [f32::INFINITY, f32::NAN, 0.0, -1.0, 1e-5];
        let layer = |seed: u64| {
            vec3(&|i| {
                let v = Vec3::new(noise(seed, i), noise(seed + 1, i), noise(seed + 2, i));
                if noise(seed + 3, i) < 0.1 {
                    Vec3::new(v.x, f32::NAN, v.z)
                } else {
                    v
                }
            })
        };
        Images {
            layers: [layer(10), layer(20), layer(30), layer(40)],
            position,
            normal,
            zd: scalar(&|i| sometimes(6, i, &distances, 0.1 + noise(7, i))),
            zi: scalar(&|i| sometimes(8, i, &distances, 0.2 + noise(9, i))),
            exponent: scalar(&|i| {
                sometimes(
                    11,
                    i,
                    &[f32::NAN, -3.0, 0.0, -0.0, f32::INFINITY],
                    64.0 * noise(12, i),
                )
            }),
        }
    }

    impl Images {
        fn inputs(&self) -> PrepareInputs<'_> {
            PrepareInputs {
                layers: [
                    &self.layers[0],
                    &self.layers[1],
                    &self.layers[2],
                    &self.layers[3],
                ],
                world_position: &self.position,
                world_normal: &self.normal,
                direct_min_distance: &self.zd,
                indirect_min_distance: &self.zi,
                exponent: &self.exponent,
            }
        }
    }

    const SETTINGS: BandwidthSettings = BandwidthSettings { b_f: 1.0, b_e: 3.0 };

    /// The planes and filter widths of `prepare` with `kernel`, or pixel by pixel.
    fn prepared(images: &Images, kernel: Option<Kernel>) -> Vec<u32> {
        let (w, h) = (images.position.width, images.position.height);
        let inputs = images.inputs();
        let settings = SETTINGS;
        let lanes = LaneLayout::segments(INPUT_PLANES, w as usize, h as usize, 15);
        let mut planes = LanePlanes::new(lanes);
        let mut width_dir = Image::filled(w, h, 0.0);
        let mut width_ind = Image::filled(w, h, 0.0);
        let (w, h) = (w as usize, h as usize);
        match kernel {
            Some(kernel) => prepare(
                kernel,
                &inputs,
                settings,
                &mut planes,
                &mut width_dir,
                &mut width_ind,
            ),
            None => {
                let layout = row_scratch(&lanes);
                let mut scratch = vec![0.0; layout.row_step()];
                let step = lanes.line_step();
                for y in 0..h {
                    let mut out = RowOut {
                        row: &mut scratch,
                        width_dir: &mut width_dir.data[y * w..(y + 1) * w],
                        width_ind: &mut width_ind.data[y * w..(y + 1) * w],
                    };
                    for x in 0..w {
                        prepare_pixel(&inputs, settings, &layout, y, x, &mut out);
                    }
                    let line = &mut planes.data_mut()[y * step..(y + 1) * step];
                    fill_line::<Portable>(&lanes, &scratch, |q| layout.in_row(q, 0), line);
                }
            }
        }
        let floats = planes
            .data()
            .iter()
            .chain(&width_dir.data)
            .chain(&width_ind.data);
        floats.map(|v| v.to_bits()).collect()
    }

    /// Widths around the group boundaries (a group needs a pixel on each side), and
    /// single rows.
    #[test]
    fn groups_of_eight_give_the_bits_of_single_pixels() {
        for (w, h) in [
            (37, 6),
            (1, 1),
            (2, 3),
            (9, 2),
            (10, 1),
            (11, 2),
            (17, 3),
            (18, 1),
        ] {
            let images = images(w, h);
            let expected = prepared(&images, None);
            for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                assert!(
                    prepared(&images, Some(kernel)) == expected,
                    "{kernel:?} differs from pixel by pixel at {w}x{h}"
                );
            }
        }
    }

    /// The bits of the X set and the filter widths from `prepare` then `x_pass`
    /// (`fused` false) or from `prepare_x_pass`.
    fn x_set_bits(images: &Images, kernel: Kernel, radius: usize, fused: bool) -> Vec<u32> {
        let (w, h) = (images.position.width, images.position.height);
        let (wu, hu) = (w as usize, h as usize);
        let inputs = images.inputs();
        let mut x_set = XSet::new(LaneLayout::blocks(X_PLANES, wu, hu, radius));
        let mut width_dir = Image::filled(w, h, 0.0);
        let mut width_ind = Image::filled(w, h, 0.0);
        if fused {
            let widths = [&mut width_dir, &mut width_ind];
            prepare_x_pass(kernel, &inputs, SETTINGS, radius, &mut x_set, widths);
        } else {
            let mut input = LanePlanes::new(LaneLayout::segments(INPUT_PLANES, wu, hu, radius));
            let (dir, ind) = (&mut width_dir, &mut width_ind);
            prepare(kernel, &inputs, SETTINGS, &mut input, dir, ind);
            x_pass(kernel, &input, radius, &mut x_set);
        }
        let floats = x_set
            .planes()
            .data()
            .iter()
            .chain(&width_dir.data)
            .chain(&width_ind.data);
        floats.map(|v| v.to_bits()).collect()
    }

    /// The fused pass (one row prepared at a time into a one-line set) gives the X set
    /// and filter widths of the two passes, bit for bit: heights that are and are not
    /// whole bands of rows (16), widths around the groups of eight, both kernels (on a
    /// CPU without AVX2 + FMA, `Avx2Fma` runs the portable kernel), two radii.
    #[test]
    fn prepare_x_pass_gives_the_bits_of_prepare_then_x_pass() {
        for (w, h) in [
            (37, 6),
            (1, 1),
            (5, 17),
            (9, 2),
            (18, 1),
            (40, 33),
            (64, 16),
        ] {
            let images = images(w, h);
            for radius in [2, 15] {
                for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                    assert!(
                        x_set_bits(&images, kernel, radius, true)
                            == x_set_bits(&images, kernel, radius, false),
                        "{kernel:?}, radius {radius}: the fused pass differs at {w}x{h}"
                    );
                }
            }
        }
    }
}
