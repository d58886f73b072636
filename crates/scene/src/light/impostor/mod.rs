//! Distance impostors (paper 000 Sec. 6.1, after Szirmay-Kalos et al., ref. 42): the
//! environment-sample cloud splatted into a cube map around a centre near the virtual
//! object, storing radiance and distance per texel, then resampled to a lat-long
//! [`EnvMap`] with finite distances, so a recording without a light probe can still
//! light an object.
//!
//! The samplers use the map as Sec. 6.1's "standard environment mapping": radiance is
//! looked up by direction alone, from every shading point, and occlusion comes from the
//! screen-space tracer and the objects' BVH. Impostor tracing (refining the lookup
//! direction from the stored distances, Szirmay-Kalos et al.) is not done, so light seen
//! from points far from the centre has parallax error. The distances serve `light.split`
//! and `light.val`, which place area lights at them.
//!
//! 1. **Splat**: each sample farther than `min_distance` from the centre covers a small
//!    disk on the cube: its angular radius is `splat_radius / distance` (a world-size
//!    disk, like `gbuffer.splat`'s), turned into face texels with the face's
//!    magnification 1 / m^2 at the sample (m = cosine to the face axis; radial stretch
//!    of the gnomonic projection, so the disk covers the sample's whole footprint), at
//!    most `max_splat_texels`, at least the texel holding the sample. Disks crossing a
//!    cube edge are splatted onto the neighbouring faces too. Each covered texel gets
//!    the distance along its own centre direction to the sample's tangent plane (from
//!    the cloud's normal; the sample's distance where there is no normal or the plane is
//!    grazing), kept within 3 splat radii of the sample's distance. The nearest sample
//!    wins each texel by an atomic minimum of (distance bits, sample index): the result
//!    does not depend on thread order.
//! 2. **Fill**: holes of each face are filled by push-pull (paper 000 Sec. 3) over at
//!    most `fill_levels` coarser levels: radiance and distance are averaged over the
//!    valid texels below, weighted by their count, then pushed down bilinearly into the
//!    holes. Holes wider than about 2^fill_levels texels stay empty: radiance 0,
//!    distance infinite.
//! 3. **Resample**: each lat-long texel takes the cube texel its centre direction falls
//!    in (nearest, so distances are never blended across depth edges).
//!
//! Cube layout: face f = 2 a + s looks along axis a (0 = x, 1 = y, 2 = z), towards +a
//! for s = 0 and -a for s = 1; its texel (i, j) of N x N covers
//! `u = d[(a + 1) % 3] / |d[a]|` in [-1 + 2i/N, -1 + 2(i+1)/N] and
//! `v = d[(a + 2) % 3] / |d[a]|` likewise in j.

use super::EnvMap;
use crate::light::EnvCloud;
// Push-pull hole filling shares the G-buffer's bilinear upsampling taps.
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::upsample_taps as taps;
use std::sync::atomic::{AtomicU64, Ordering};

/// Parameters of [`ImpostorBuilder`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpostorParams {
    /// Texels along each cube face's side.
    pub face_size: u32,
    /// Size of the resampled lat-long map.
    pub width: u32,
    pub height: u32,
    /// Samples nearer the centre than this (metres) are ignored.
    pub min_distance: f32,
    /// World radius of a sample's disk (metres).
    pub splat_radius: f32,
    /// Upper bound of a disk's radius in face texels.
    pub max_splat_texels: f32,
    /// Coarser levels push-pull may use per face (0 = no filling).
    pub fill_levels: u32,
}

impl Default for ImpostorParams {
    fn default() -> Self {
        ImpostorParams {
            face_size: 64,
            width: 256,
            height: 128,
            min_distance: 0.05,
            splat_radius: 0.035,
            max_splat_texels: 8.0,
            fill_levels: 4,
        }
    }
}

/// What one build saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ImpostorCounts {
    /// Samples splatted.
    pub splatted: usize,
    /// Samples within `min_distance` of the centre (ignored).
    pub too_close: usize,
    /// Samples with a non-finite position or color (ignored).
    pub invalid: usize,
    /// Cube texels won by a sample.
    pub covered_texels: usize,
    /// Cube texels filled by push-pull.
    pub filled_texels: usize,
    /// Cube texels left empty.
    pub empty_texels: usize,
}

/// A cube map of radiance and distance: 6 faces of N x N texels, face-major then
/// row-major (see the module docs for the layout); an empty texel has radiance 0 and
/// distance infinite.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CubeImpostor {
    pub face_size: u32,
    pub radiance: Vec<Vec3>,
    pub distance: Vec<f32>,
}

impl CubeImpostor {
    /// The index of the texel holding direction `d` (need not be unit; zero gives
    /// texel 0).
    #[inline]
    pub fn texel_of(&self, d: Vec3) -> usize {
        let n = self.face_size as usize;
        let (face, u, v) = face_coords(d);
        let to_texel = |c: f32| (((c + 1.0) * 0.5 * n as f32) as usize).min(n - 1);
        face * n * n + to_texel(v) * n + to_texel(u)
    }

    /// The unit direction of the centre of texel `index` (the inverse of
    /// [`CubeImpostor::texel_of`] at texel centres).
    pub fn texel_direction(&self, index: usize) -> Vec3 {
        cube_texel_direction(self.face_size, index)
    }
}

/// The unit direction of the centre of texel `index` of a cube of `face_size` texels a
/// side ([`CubeImpostor::texel_direction`] without the cube).
pub fn cube_texel_direction(face_size: u32, index: usize) -> Vec3 {
    let n = face_size as usize;
    let (face, rest) = (index / (n * n), index % (n * n));
    let (row, column) = (rest / n, rest % n);
    let to_coord = |i: usize| -1.0 + (2 * i + 1) as f32 / n as f32;
    let axis = face / 2;
    let mut d = Vec3::ZERO;
    d[axis] = if face % 2 == 0 { 1.0 } else { -1.0 };
    d[(axis + 1) % 3] = to_coord(column);
    d[(axis + 2) % 3] = to_coord(row);
    d.normalize()
}

/// The face looking along `d`'s largest component and `d`'s (u, v) on it, in [-1, 1].
#[inline]
fn face_coords(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let major = a[axis];
    if major <= 0.0 {
        return (0, 0.0, 0.0);
    }
    let inv = 1.0 / major;
    let face = 2 * axis + (d[axis] < 0.0) as usize;
    (face, d[(axis + 1) % 3] * inv, d[(axis + 2) % 3] * inv)
}

/// Scratch of one face's push-pull level.
#[derive(Clone, Debug, Default)]
struct Level {
    size: usize,
    radiance: Vec<Vec3>,
    /// Infinite = hole.
    distance: Vec<f32>,
    /// Valid level-0 texels below (0 for holes and filled texels).
    weight: Vec<f32>,
}

/// Builds distance impostors, keeping its buffers across frames.
#[derive(Debug)]
pub struct ImpostorBuilder {
    params: ImpostorParams,
    /// Per cube texel: (distance bits << 32 | sample index) of the nearest sample so
    /// far, `u64::MAX` when none.
    nearest: Vec<AtomicU64>,
    cube: CubeImpostor,
    /// Per face: its coarse levels.
    pyramids: Vec<Vec<Level>>,
}

impl ImpostorBuilder {
    /// A builder for `params`; fails, naming the value, on sizes of zero or above 4096,
    /// or non-finite or negative lengths.
    pub fn new(params: ImpostorParams) -> Result<ImpostorBuilder, String> {
        let p = &params;
        for (name, value) in [
            ("face_size", p.face_size),
            ("width", p.width),
            ("height", p.height),
        ] {
            if !(1..=4096).contains(&value) {
                return Err(format!("{name} = {value} is not in 1..=4096"));
            }
        }
        for (name, value) in [
            ("min_distance", p.min_distance),
            ("splat_radius", p.splat_radius),
            ("max_splat_texels", p.max_splat_texels),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("{name} = {value} is not a finite length >= 0"));
            }
        }
        let n = p.face_size as usize;
        let texels = 6 * n * n;
        let mut sizes = Vec::new();
        let mut size = n;
        while sizes.len() < p.fill_levels as usize && size > 1 {
            size = size.div_ceil(2);
            sizes.push(size);
        }
        let pyramid: Vec<Level> = sizes
            .iter()
            .map(|&s| Level {
                size: s,
                radiance: vec![Vec3::ZERO; s * s],
                distance: vec![f32::INFINITY; s * s],
                weight: vec![0.0; s * s],
            })
            .collect();
        Ok(ImpostorBuilder {
            params,
            nearest: (0..texels).map(|_| AtomicU64::new(u64::MAX)).collect(),
            cube: CubeImpostor {
                face_size: p.face_size,
                radiance: vec![Vec3::ZERO; texels],
                distance: vec![f32::INFINITY; texels],
            },
            pyramids: vec![pyramid; 6],
        })
    }

    pub fn params(&self) -> &ImpostorParams {
        &self.params
    }

    /// The cube map of the last build.
    pub fn cube(&self) -> &CubeImpostor {
        &self.cube
    }

    /// The impostor of `cloud` seen from `center`: splat, fill, resample (see the module
    /// docs). Deterministic for any number of threads. A cloud with more than 2^32
    /// samples is an error.
    pub fn build(
        &mut self,
        cloud: &EnvCloud,
        center: Vec3,
    ) -> Result<(EnvMap, ImpostorCounts), String> {
        let n_samples = cloud.positions.len();
        if n_samples > u32::MAX as usize || cloud.colors.len() != n_samples {
            return Err(format!(
                "the cloud has {n_samples} positions and {} colors (at most 2^32, one color each)",
                cloud.colors.len()
            ));
        }
        let mut counts = self.splat(cloud, center);
        self.resolve(cloud);
        counts.covered_texels = self.cube.distance.iter().filter(|d| d.is_finite()).count();
        self.fill();
        let valid = self.cube.distance.iter().filter(|d| d.is_finite()).count();
        counts.filled_texels = valid - counts.covered_texels;
        counts.empty_texels = self.cube.distance.len() - valid;
        Ok((self.resample(center), counts))
    }

    /// Step 1: the nearest sample per cube texel, by atomic minimum.
    fn splat(&mut self, cloud: &EnvCloud, center: Vec3) -> ImpostorCounts {
        self.nearest
            .par_iter()
            .for_each(|k| k.store(u64::MAX, Ordering::Relaxed));
        let p = self.params;
        let n = p.face_size as usize;
        let half_n = 0.5 * n as f32;
        let inv_half_n = 1.0 / half_n;
        let nearest = &self.nearest;
        let normals = (cloud.normals.len() == cloud.positions.len()).then_some(&cloud.normals[..]);
        const CHUNK: usize = 4096;
        let per_chunk: Vec<[usize; 3]> = cloud
            .positions
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(chunk, positions)| {
                let mut c = [0usize; 3];
                for (k, &position) in positions.iter().enumerate() {
                    let index = chunk * CHUNK + k;
                    let rel = position - center;
                    let dist = rel.length();
                    if !(dist.is_finite() && cloud.colors[index].is_finite()) {
                        c[2] += 1;
                        continue;
                    }
                    if dist < p.min_distance || dist == 0.0 {
                        c[1] += 1;
                        continue;
                    }
                    c[0] += 1;
                    let normal = normals.map_or(Vec3::ZERO, |n| n[index]);
                    let plane_offset = normal.dot(rel);
                    let has_plane = normal.is_finite() && normal.length_squared() > 0.25;
                    let angle = p.splat_radius / dist;
                    let inv_dist = 1.0 / dist;
                    let largest = rel.abs().max_element();
                    for axis in 0..3 {
                        let major = rel[axis].abs();
                        // Its own face (major = largest), and neighbours whose edge its
                        // disk crosses: there the sample lies at plane coordinate
                        // largest / major > 1, reached if within the disk's radius.
                        if major * 2.0 < largest || major == 0.0 {
                            continue;
                        }
                        let inv = 1.0 / major;
                        let m = major * inv_dist;
                        let radius = (angle / (m * m) * half_n).min(p.max_splat_texels);
                        if largest * inv > 1.0 + radius * inv_half_n {
                            continue;
                        }
                        let sign = if rel[axis] < 0.0 { -1.0 } else { 1.0 };
                        let face = 2 * axis + (sign < 0.0) as usize;
                        let (ua, va) = ((axis + 1) % 3, (axis + 2) % 3);
                        let (u, v) = (rel[ua] * inv, rel[va] * inv);
                        let splat = FaceSplat {
                            x: (u + 1.0) * half_n,
                            y: (v + 1.0) * half_n,
                            radius,
                            inv_half_n,
                            dist,
                            lo: (dist - 3.0 * p.splat_radius).max(0.0),
                            hi: dist + 3.0 * p.splat_radius,
                            plane: has_plane.then_some([
                                plane_offset,
                                sign * normal[axis],
                                normal[ua],
                                normal[va],
                            ]),
                            index: index as u64,
                        };
                        splat.splat(&nearest[face * n * n..(face + 1) * n * n], n);
                    }
                }
                c
            })
            .collect();
        let mut counts = ImpostorCounts::default();
        for c in per_chunk {
            counts.splatted += c[0];
            counts.too_close += c[1];
            counts.invalid += c[2];
        }
        counts
    }

    /// The winners' radiance and distance into the cube.
    fn resolve(&mut self, cloud: &EnvCloud) {
        let nearest = &self.nearest;
        self.cube
            .radiance
            .par_chunks_mut(4096)
            .zip(self.cube.distance.par_chunks_mut(4096))
            .enumerate()
            .for_each(|(chunk, (radiance, distance))| {
                for (k, (r, d)) in radiance.iter_mut().zip(distance).enumerate() {
                    let key = nearest[chunk * 4096 + k].load(Ordering::Relaxed);
                    if key == u64::MAX {
                        (*r, *d) = (Vec3::ZERO, f32::INFINITY);
                    } else {
                        *r = cloud.colors[(key & 0xFFFF_FFFF) as usize];
                        *d = f32::from_bits((key >> 32) as u32);
                    }
                }
            });
    }

    /// Step 2: push-pull per face.
    fn fill(&mut self) {
        let n = self.params.face_size as usize;
        self.cube
            .radiance
            .par_chunks_mut(n * n)
            .zip(self.cube.distance.par_chunks_mut(n * n))
            .zip(self.pyramids.par_iter_mut())
            .for_each(|((radiance, distance), pyramid)| {
                push_pull_face(n, radiance, distance, pyramid);
            });
    }

    /// Step 3: the lat-long map, nearest cube texel per texel centre.
    fn resample(&self, center: Vec3) -> EnvMap {
        let (w, h) = (self.params.width as usize, self.params.height as usize);
        let columns: Vec<(f32, f32)> = (0..w)
            .map(|c| ((c as f32 + 0.5) / w as f32 * std::f32::consts::TAU).sin_cos())
            .collect();
        let mut radiance = vec![Vec3::ZERO; w * h];
        let mut distance = vec![f32::INFINITY; w * h];
        radiance
            .par_chunks_mut(w)
            .zip(distance.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (radiance, distance))| {
                let (st, ct) = ((row as f32 + 0.5) / h as f32 * std::f32::consts::PI).sin_cos();
                for ((r, d), &(sp, cp)) in radiance.iter_mut().zip(distance).zip(&columns) {
                    let texel = self.cube.texel_of(Vec3::new(st * cp, ct, st * sp));
                    (*r, *d) = (self.cube.radiance[texel], self.cube.distance[texel]);
                }
            });
        EnvMap {
            width: w as u32,
            height: h as u32,
            radiance,
            distance,
            center,
        }
    }
}

/// A sample as one cube face sees it: a disk around (x, y) (face texels) of `radius`
/// texels, and the sample's tangent plane, which gives each texel of the disk its own
/// distance (surfel splatting: exact on planar surfaces, where the sample's distance
/// alone would be off by up to the disk radius times the tangent of the incidence).
struct FaceSplat {
    x: f32,
    y: f32,
    radius: f32,
    inv_half_n: f32,
    /// The sample's distance from the centre: the texel distance where the plane is
    /// unknown or grazing.
    dist: f32,
    /// Bounds of a texel's distance (the sample's distance +- 3 splat radii).
    lo: f32,
    hi: f32,
    /// n . (p - centre) and the normal's components along the face's axis (signed
    /// towards the face), u axis and v axis.
    plane: Option<[f32; 4]>,
    index: u64,
}

impl FaceSplat {
    /// The distance from the centre to the sample's plane along texel (tx, ty)'s centre.
    #[inline]
    fn texel_distance(&self, tx: usize, ty: usize) -> f32 {
        let Some([offset, na, nu, nv]) = self.plane else {
            return self.dist;
        };
        let u = (tx as f32 + 0.5) * self.inv_half_n - 1.0;
        let v = (ty as f32 + 0.5) * self.inv_half_n - 1.0;
        // Direction (sign e_a + u e_u + v e_v), length sqrt(1 + u^2 + v^2).
        let len2 = 1.0 + u * u + v * v;
        let cos = na + u * nu + v * nv;
        if cos * offset <= 0.0 || cos * cos < 0.04 * len2 {
            return self.dist;
        }
        (offset / cos * len2.sqrt()).clamp(self.lo, self.hi)
    }

    #[inline]
    fn offer_texel(&self, face: &[AtomicU64], n: usize, tx: usize, ty: usize) {
        let key = (self.texel_distance(tx, ty).to_bits() as u64) << 32 | self.index;
        offer(&face[ty * n + tx], key);
    }

    /// Offers the sample to every texel of an n x n face whose centre lies within the
    /// disk, and to the texel holding (x, y) when it is on the face.
    #[inline]
    fn splat(&self, face: &[AtomicU64], n: usize) {
        let (x, y, radius) = (self.x, self.y, self.radius);
        let size = n as f32;
        if x + radius < 0.0 || y + radius < 0.0 || x - radius >= size || y - radius >= size {
            return;
        }
        if (0.0..size).contains(&x) && (0.0..size).contains(&y) {
            self.offer_texel(face, n, (x as usize).min(n - 1), (y as usize).min(n - 1));
        }
        // Every other texel centre is at least half a texel away.
        if radius < 0.5 {
            return;
        }
        // Texel centres tx + 0.5 within the disk: tx in [x - r - 0.5, x + r - 0.5]
        // (truncating casts of non-negative values are floors).
        let x0 = ceil_non_negative((x - radius - 0.5).max(0.0));
        let y0 = ceil_non_negative((y - radius - 0.5).max(0.0));
        let x1 = (x + radius - 0.5).min(size - 1.0);
        let y1 = (y + radius - 0.5).min(size - 1.0);
        if x1 < 0.0 || y1 < 0.0 {
            return;
        }
        let (x1, y1) = (x1 as usize, y1 as usize);
        let r2 = radius * radius;
        for ty in y0..=y1 {
            let dy = ty as f32 + 0.5 - y;
            for tx in x0..=x1 {
                let dx = tx as f32 + 0.5 - x;
                if dx * dx + dy * dy <= r2 {
                    self.offer_texel(face, n, tx, ty);
                }
            }
        }
    }
}

/// The ceiling of a non-negative float by a truncating cast (no libm call).
#[inline]
fn ceil_non_negative(x: f32) -> usize {
    let t = x as usize;
    if (t as f32) < x { t + 1 } else { t }
}

/// Lowers `texel` to `key` if that is smaller; a plain load first skips the locked
/// operation for the many samples that lose.
#[inline]
fn offer(texel: &AtomicU64, key: u64) {
    if key < texel.load(Ordering::Relaxed) {
        texel.fetch_min(key, Ordering::Relaxed);
    }
}

/// Fills the holes (infinite distance) of one n x n face by push-pull over `pyramid`'s
/// levels; valid texels are left untouched.
fn push_pull_face(n: usize, radiance: &mut [Vec3], distance: &mut [f32], pyramid: &mut [Level]) {
    if pyramid.is_empty() || distance.iter().all(|d| d.is_finite()) {
        return;
    }
    // Pull: level k + 1 is the count-weighted mean of the valid 2x2 children of level k.
    for k in 0..pyramid.len() {
        let (fine, coarse) = pyramid.split_at_mut(k);
        let coarse = &mut coarse[0];
        let (fine_size, fine_r, fine_d, fine_w): (usize, &[Vec3], &[f32], Option<&[f32]>) =
            match fine.last() {
                Some(l) => (l.size, &l.radiance, &l.distance, Some(&l.weight)),
                None => (n, radiance, distance, None),
            };
        for y in 0..coarse.size {
            for x in 0..coarse.size {
                let (mut sr, mut sd, mut sw) = (Vec3::ZERO, 0.0f32, 0.0f32);
                for fy in 2 * y..(2 * y + 2).min(fine_size) {
                    for fx in 2 * x..(2 * x + 2).min(fine_size) {
                        let i = fy * fine_size + fx;
                        if fine_d[i].is_finite() {
                            let w = fine_w.map_or(1.0, |w| w[i]);
                            sr += w * fine_r[i];
                            sd += w * fine_d[i];
                            sw += w;
                        }
                    }
                }
                let i = y * coarse.size + x;
                if sw > 0.0 {
                    (coarse.radiance[i], coarse.distance[i]) = (sr / sw, sd / sw);
                } else {
                    (coarse.radiance[i], coarse.distance[i]) = (Vec3::ZERO, f32::INFINITY);
                }
                coarse.weight[i] = sw;
            }
        }
    }
    // Push: holes of level k take the bilinear mean of the valid texels of level k + 1.
    for k in (0..pyramid.len()).rev() {
        let (fine, coarse) = pyramid.split_at_mut(k);
        let coarse = &coarse[0];
        let (fine_size, fine_r, fine_d): (usize, &mut [Vec3], &mut [f32]) = match fine.last_mut() {
            Some(l) => (l.size, &mut l.radiance, &mut l.distance),
            None => (n, &mut *radiance, &mut *distance),
        };
        for y in 0..fine_size {
            for x in 0..fine_size {
                let i = y * fine_size + x;
                if fine_d[i].is_finite() {
                    continue;
                }
                let (mut sr, mut sd, mut sw) = (Vec3::ZERO, 0.0f32, 0.0f32);
                for (cy, wy) in taps(y, coarse.size) {
                    for (cx, wx) in taps(x, coarse.size) {
                        let c = cy * coarse.size + cx;
                        let w = wx * wy;
                        if w > 0.0 && coarse.distance[c].is_finite() {
                            sr += w * coarse.radiance[c];
                            sd += w * coarse.distance[c];
                            sw += w;
                        }
                    }
                }
                if sw > 0.0 {
                    (fine_r[i], fine_d[i]) = (sr / sw, sd / sw);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
