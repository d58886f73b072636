//! Splatting the environment-sample cloud into a view with a depth test (paper 000
//! Sec. 3, "G-Buffer as AR basis"): every sample covers a disk of world radius r (a
//! screen ellipse of radii f r / z pixels, clamped), each covered pixel takes the depth of
//! the sample's tangent plane along its view ray, and the nearest sample wins (ties: the
//! lower sample index).
//!
//! Three passes, each deterministic for any thread count:
//! 1. **Centres** (parallel over samples): each sample is projected; its depth is
//!    depth-tested into its centre pixel only (`AtomicU32::fetch_min` on the depth bits,
//!    order-independent) and the rows its footprint spans are recorded.
//! 2. **Binning** (parallel over fixed chunks of samples): a sample whose centre lies more
//!    than `occlusion_margin` behind the nearest centre depth of the 3x3 pixels around
//!    its centre pixel is occluded and dropped (an occluded layer costs one projection);
//!    the others are sorted by the bands of `BAND_ROWS` rows their footprint touches.
//! 3. **Footprints** (parallel over bands): each band depth-tests the footprints of its
//!    samples, clipped to its rows, into a band-local key buffer (depth bits << 32 |
//!    sample index, plain `min`: no atomics, the band's keys stay in cache), then turns
//!    the winning keys into the G-buffer rows.

use super::{COVERAGE_NONE, COVERAGE_SPLAT, GBuffer};
use crate::graph::{EnvCloud, StageError};
use crate::pinhole::Pinhole;
use crate::recording::Pose;
use glam::{Mat3, Mat4, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// Samples nearer to the camera than this (metres) are not splatted.
pub const NEAR_M: f32 = 0.01;
/// The smallest screen radius in pixels: a little more than sqrt(1/2), so that the disk
/// always contains the nearest pixel centre and every sample in view covers a pixel.
pub const MIN_RADIUS_PX: f32 = 0.75;
/// Below this cosine between the normal and the view direction a splat is drawn at the
/// sample's own depth instead of along its tangent plane.
pub const GRAZING_COS: f32 = 0.25;
/// Tangent-plane depths are clamped to the sample depth +- this many splat radii.
pub const PLANE_DEPTH_SPAN: f32 = 3.0;
/// Rows of a footprint band (pass 3).
pub const BAND_ROWS: usize = 16;

const EMPTY_KEY: u64 = u64::MAX;
/// The centre buffer's empty value: +inf, above every depth as bits.
const EMPTY_CENTRE: u32 = 0x7f80_0000;
const NO_PIXEL: u32 = u32::MAX;
const SAMPLES_PER_TASK: usize = 4096;

/// Parameters of [`splat`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatParams {
    /// World-space radius of a sample's disk, metres.
    pub radius: f32,
    /// Upper bound of the screen radius, pixels (bounds the cost of near samples; holes
    /// between bounded disks are left to push-pull).
    pub max_radius_px: f32,
    /// A sample whose centre lies more than this many metres behind the nearest sample
    /// centre around its centre pixel is not splatted (infinite: every sample is).
    pub occlusion_margin: f32,
}

impl Default for SplatParams {
    fn default() -> Self {
        SplatParams {
            radius: 0.035,
            max_radius_px: DEFAULT_MAX_RADIUS_PX,
            occlusion_margin: DEFAULT_OCCLUSION_MARGIN,
        }
    }
}

/// Default of [`SplatParams::max_radius_px`].
pub const DEFAULT_MAX_RADIUS_PX: f32 = 64.0;
/// Default of [`SplatParams::occlusion_margin`], metres.
pub const DEFAULT_OCCLUSION_MARGIN: f32 = 0.1;

/// A sample's projection after pass 1: the rows its footprint spans (`top > bottom`:
/// none), its centre pixel ([`NO_PIXEL`] outside the image) and depth.
#[derive(Clone, Copy, Debug, Default)]
struct Projected {
    top: u32,
    bottom: u32,
    pixel: u32,
    z: f32,
}

const NOT_DRAWN: Projected = Projected {
    top: 1,
    bottom: 0,
    pixel: NO_PIXEL,
    z: 0.0,
};

/// A sample's footprint as pass 3 draws it, set up once in pass 2: inverse depth
/// `a x + b y + c` over the ellipse of centre (u, v) and radii (rx, ry) on rows
/// `top..=bottom`, clamped to `[w_min, w_max]`.
#[derive(Clone, Copy, Debug)]
struct Footprint {
    u: f32,
    v: f32,
    rx: f32,
    inv_ry2: f32,
    a: f32,
    b: f32,
    c: f32,
    w_min: f32,
    w_max: f32,
    top: u32,
    bottom: u32,
    index: u32,
}

/// One chunk's samples sorted by band: `entries[starts[b]..starts[b + 1]]` touch band b,
/// in sample order.
#[derive(Debug, Default)]
struct ChunkBins {
    starts: Vec<u32>,
    entries: Vec<Footprint>,
}

/// Buffers of [`splat`], kept across frames to avoid reallocation.
#[derive(Debug, Default)]
pub struct SplatBuffer {
    centre: Vec<AtomicU32>,
    front: Vec<f32>,
    projected: Vec<Projected>,
    bins: Vec<ChunkBins>,
    keys: Vec<u64>,
}

/// `ceil(x)` for the first pixel index at or after `x`, at least 0 (no libm call).
#[inline]
fn first_index_from(x: f32) -> i64 {
    if x > 0.0 {
        let t = x.min(1e9) as i64;
        t + ((t as f32) < x) as i64
    } else {
        0
    }
}

/// `floor(x)` for the last pixel index at or before `x`, at most `last`; -1 when `x < 0`.
#[inline]
fn last_index_to(x: f32, last: i64) -> i64 {
    if x >= 0.0 {
        (x.min(1e9) as i64).min(last)
    } else {
        -1
    }
}

/// Splats `cloud` (world space) into the view of `camera` at `pose` (camera-to-world),
/// overwriting every pixel of `out`: the nearest sample's color, its tangent-plane depth
/// and its normal turned into camera space and towards the camera, coverage
/// [`COVERAGE_SPLAT`]; pixels no sample covers get NaN color, depth 0, a zero normal and
/// coverage [`COVERAGE_NONE`]. Samples with a non-finite position or color are skipped,
/// and so are occluded ones (see [`SplatParams::occlusion_margin`]).
pub fn splat(
    cloud: &EnvCloud,
    pose: &Pose,
    camera: &Pinhole,
    params: &SplatParams,
    buffer: &mut SplatBuffer,
    out: &mut GBuffer,
) -> Result<(), StageError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if (out.width(), out.height()) != (camera.width, camera.height) || !out.is_consistent() {
        return Err(StageError::Failed(format!(
            "G-buffer is {}x{}, camera is {w}x{h}",
            out.width(),
            out.height()
        )));
    }
    let n = cloud.len();
    if cloud.colors.len() != n || cloud.normals.len() != n {
        return Err(StageError::Failed(format!(
            "cloud has {n} positions, {} colors and {} normals",
            cloud.colors.len(),
            cloud.normals.len()
        )));
    }
    if n >= u32::MAX as usize || w * h >= u32::MAX as usize {
        return Err(StageError::Failed(format!(
            "cloud of {n} samples or image of {w}x{h} is too large to splat"
        )));
    }
    if !(params.radius.is_finite()
        && params.radius >= 0.0
        && params.max_radius_px.is_finite()
        && params.occlusion_margin >= 0.0)
    {
        return Err(StageError::Failed(
            "splat radius must be finite and >= 0, the occlusion margin >= 0".into(),
        ));
    }
    let world_to_camera = pose.matrix().inverse().as_mat4();
    let rotation = Mat3::from_mat4(world_to_camera);
    if w == 0 || h == 0 {
        return Ok(());
    }
    let raster = Raster {
        camera,
        world_to_camera,
        rotation,
        radius: params.radius,
        max_radius_px: params.max_radius_px.max(MIN_RADIUS_PX),
    };

    // Pass 1: centre depths and row spans.
    let centre = &mut buffer.centre;
    if centre.len() != w * h {
        *centre = (0..w * h).map(|_| AtomicU32::new(EMPTY_CENTRE)).collect();
    } else {
        centre
            .par_iter_mut()
            .with_min_len(1 << 14)
            .for_each(|c| *c.get_mut() = EMPTY_CENTRE);
    }
    let centre = &buffer.centre[..];
    buffer.projected.resize(n, NOT_DRAWN);
    buffer
        .projected
        .par_chunks_mut(SAMPLES_PER_TASK)
        .zip(cloud.positions.par_chunks(SAMPLES_PER_TASK))
        .zip(cloud.colors.par_chunks(SAMPLES_PER_TASK))
        .for_each(|((projected, positions), colors)| {
            for ((out, p), c) in projected.iter_mut().zip(positions).zip(colors) {
                *out = NOT_DRAWN;
                if !c.is_finite() {
                    continue;
                }
                let Some(s) = raster.screen(*p) else {
                    continue;
                };
                let (cu, cv) = (s.u + 0.5, s.v + 0.5);
                let pixel = if cu >= 0.0 && cv >= 0.0 && cu < w as f32 && cv < h as f32 {
                    let i = cv as usize * w + cu as usize;
                    let z = s.p.z.to_bits();
                    // A load first: most samples lose and need no locked instruction.
                    if z < centre[i].load(Relaxed) {
                        centre[i].fetch_min(z, Relaxed);
                    }
                    i as u32
                } else {
                    NO_PIXEL
                };
                *out = Projected {
                    top: s.top,
                    bottom: s.bottom,
                    pixel,
                    z: s.p.z,
                };
            }
        });

    // The nearest centre depth over the 3x3 pixels around each pixel.
    let front = &mut buffer.front;
    let cull = params.occlusion_margin.is_finite();
    if cull {
        front.resize(w * h, 0.0);
        front.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let rows =
                [y.saturating_sub(1), y, (y + 1).min(h - 1)].map(|r| &centre[r * w..(r + 1) * w]);
            let column_min = |x: usize| {
                rows.iter()
                    .map(|r| r[x].load(Relaxed))
                    .min()
                    .unwrap_or(EMPTY_CENTRE)
            };
            let (mut left, mut here) = (column_min(0), column_min(0));
            for (x, out) in row.iter_mut().enumerate() {
                let right = if x + 1 < w { column_min(x + 1) } else { here };
                *out = f32::from_bits(left.min(here).min(right));
                (left, here) = (here, right);
            }
        });
    }

    // Pass 2: occlusion culling and binning by band.
    let bands = h.div_ceil(BAND_ROWS);
    let chunks = n.div_ceil(SAMPLES_PER_TASK);
    buffer.bins.resize_with(chunks, ChunkBins::default);
    let front = &buffer.front[..];
    let margin = params.occlusion_margin;
    buffer
        .bins
        .par_iter_mut()
        .zip(buffer.projected.par_chunks(SAMPLES_PER_TASK))
        .enumerate()
        .for_each(|(chunk, (bins, projected))| {
            let first = (chunk * SAMPLES_PER_TASK) as u32;
            let drawn = |s: &Projected| {
                s.top <= s.bottom
                    && !(cull && s.pixel != NO_PIXEL && s.z > front[s.pixel as usize] + margin)
            };
            bins.starts.clear();
            bins.starts.resize(bands + 1, 0);
            for s in projected.iter().filter(|s| drawn(s)) {
                for b in s.top as usize / BAND_ROWS..=s.bottom as usize / BAND_ROWS {
                    bins.starts[b + 1] += 1;
                }
            }
            for b in 0..bands {
                bins.starts[b + 1] += bins.starts[b];
            }
            let unused = Footprint {
                u: 0.0,
                v: 0.0,
                rx: 0.0,
                inv_ry2: 0.0,
                a: 0.0,
                b: 0.0,
                c: 0.0,
                w_min: 0.0,
                w_max: 0.0,
                top: 0,
                bottom: 0,
                index: 0,
            };
            bins.entries.resize(bins.starts[bands] as usize, unused);
            let mut next = bins.starts.clone();
            let first = first as usize;
            for (j, s) in projected.iter().enumerate() {
                if drawn(s) {
                    let i = first + j;
                    let Some(entry) =
                        raster.footprint(cloud.positions[i], cloud.normals[i], i as u32)
                    else {
                        continue;
                    };
                    let bands = s.top as usize / BAND_ROWS..=s.bottom as usize / BAND_ROWS;
                    for slot in &mut next[bands] {
                        bins.entries[*slot as usize] = entry;
                        *slot += 1;
                    }
                }
            }
        });

    // Pass 3: footprints per band, then the G-buffer rows.
    buffer.keys.resize(w * h, EMPTY_KEY);
    let bins = &buffer.bins[..];
    let band_len = BAND_ROWS * w;
    out.color
        .data
        .par_chunks_mut(band_len)
        .zip(out.depth.data.par_chunks_mut(band_len))
        .zip(out.normals.data.par_chunks_mut(band_len))
        .zip(out.coverage.data.par_chunks_mut(band_len))
        .zip(buffer.keys.par_chunks_mut(band_len))
        .enumerate()
        .for_each(|(band, ((((color, depth), normals), coverage), keys))| {
            keys.fill(EMPTY_KEY);
            let y0 = band * BAND_ROWS;
            let y1 = y0 + keys.len() / w - 1;
            for chunk in bins {
                let range = chunk.starts[band] as usize..chunk.starts[band + 1] as usize;
                for f in &chunk.entries[range] {
                    draw(f, w, (y0, y1), keys);
                }
            }
            let rows = color
                .chunks_mut(w)
                .zip(depth.chunks_mut(w))
                .zip(normals.chunks_mut(w))
                .zip(coverage.chunks_mut(w))
                .zip(keys.chunks(w));
            for (y, ((((color, depth), normals), coverage), keys)) in (y0..).zip(rows) {
                for (x, key) in keys.iter().enumerate() {
                    if *key == EMPTY_KEY {
                        color[x] = Vec3::NAN;
                        depth[x] = 0.0;
                        normals[x] = Vec3::ZERO;
                        coverage[x] = COVERAGE_NONE;
                        continue;
                    }
                    let i = (key & 0xffff_ffff) as usize;
                    let n = (rotation * cloud.normals[i]).normalize_or_zero();
                    let ray = camera.ray(x as f32, y as f32);
                    color[x] = cloud.colors[i];
                    depth[x] = 1.0 / f32::from_bits(!((key >> 32) as u32));
                    normals[x] = if n.dot(ray) > 0.0 { -n } else { n };
                    coverage[x] = COVERAGE_SPLAT;
                }
            }
        });
    Ok(())
}

/// A sample in screen space: camera-space position, projected centre, screen radii and
/// the rows its footprint spans.
struct Screen {
    p: Vec3,
    u: f32,
    v: f32,
    rx: f32,
    ry: f32,
    top: u32,
    bottom: u32,
}

/// What one sample's rasterization needs.
struct Raster<'a> {
    camera: &'a Pinhole,
    world_to_camera: Mat4,
    rotation: Mat3,
    radius: f32,
    max_radius_px: f32,
}

impl Raster<'_> {
    /// The screen footprint of the sample at world position `world`; `None` when it is
    /// not finite, too near or behind the camera, or its ellipse misses the image.
    #[inline]
    fn screen(&self, world: Vec3) -> Option<Screen> {
        let cam = self.camera;
        let p = self.world_to_camera.transform_point3(world);
        if !p.is_finite() || p.z <= NEAR_M {
            return None;
        }
        let inv_z = 1.0 / p.z;
        let (u, v) = (cam.fx * p.x * inv_z + cam.cx, cam.fy * p.y * inv_z + cam.cy);
        let rx = (cam.fx * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let ry = (cam.fy * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let w = cam.width as f32;
        let top = first_index_from(v - ry);
        let bottom = last_index_to(v + ry, cam.height as i64 - 1);
        if top > bottom || u + rx < 0.0 || u - rx > w - 1.0 {
            return None;
        }
        Some(Screen {
            p,
            u,
            v,
            rx,
            ry,
            top: top as u32,
            bottom: bottom as u32,
        })
    }

    /// The footprint of sample `index` at world position `world` with world normal
    /// `normal` (`None` when it is not drawn): the depth along pixel (x, y)'s ray on the
    /// tangent plane n . X = n . p is z = (n . p) / (n . ray(x, y)), and
    /// n . ray(x, y) = a x + b y + c, so its inverse is linear in x and y. Near grazing,
    /// the sample's own depth. Depths are clamped to p.z +- PLANE_DEPTH_SPAN r (and
    /// beyond NEAR_M).
    #[inline]
    fn footprint(&self, world: Vec3, normal: Vec3, index: u32) -> Option<Footprint> {
        let s = self.screen(world)?;
        let cam = self.camera;
        let p = s.p;
        let n = self.rotation * normal;
        let n_len = n.length();
        let n_dot_p = n.dot(p);
        let tangent = n_len > 0.0 && n_dot_p.abs() >= GRAZING_COS * n_len * p.length();
        let (a, b, c) = if tangent {
            let inv = 1.0 / n_dot_p;
            (
                n.x / cam.fx * inv,
                n.y / cam.fy * inv,
                (n.z - n.x * cam.cx / cam.fx - n.y * cam.cy / cam.fy) * inv,
            )
        } else {
            (0.0, 0.0, 1.0 / p.z)
        };
        let span = PLANE_DEPTH_SPAN * self.radius;
        let (near, far) = ((p.z - span).max(NEAR_M), p.z + span);
        Some(Footprint {
            u: s.u,
            v: s.v,
            rx: s.rx,
            inv_ry2: 1.0 / (s.ry * s.ry),
            a,
            b,
            c,
            w_min: 1.0 / far,
            w_max: 1.0 / near,
            top: s.top,
            bottom: s.bottom,
            index,
        })
    }
}

/// Depth-tests footprint `f` into every pixel centre of rows `rows` (inclusive) inside
/// its screen ellipse; `keys` holds those rows of an image `width` wide. A key is the
/// complemented inverse-depth bits << 32 | sample index: the smallest is the nearest
/// sample, ties going to the lower index.
#[inline]
fn draw(f: &Footprint, width: usize, rows: (usize, usize), keys: &mut [u64]) {
    let last_x = width as i64 - 1;
    let low_index = f.index as u64;
    let (first_row, last_row) = (
        (f.top as usize).max(rows.0),
        (f.bottom as usize).min(rows.1),
    );
    for y in first_row..=last_row {
        let dy = y as f32 - f.v;
        let half = f.rx * (1.0 - dy * dy * f.inv_ry2).max(0.0).sqrt();
        let (left, right) = (
            first_index_from(f.u - half),
            last_index_to(f.u + half, last_x),
        );
        if left > right {
            continue;
        }
        let (left, right) = (left as usize, right as usize);
        let start = (y - rows.0) * width;
        let row = &mut keys[start + left..=start + right];
        let row_w = f.b * y as f32 + f.c;
        for (k, slot) in row.iter_mut().enumerate() {
            let w = f.a * (left + k) as f32 + row_w;
            // Negative inverse depths (ray past the plane's horizon) and NaN fall to near.
            let w = if w > 0.0 {
                w.max(f.w_min).min(f.w_max)
            } else {
                f.w_max
            };
            let key = ((!w.to_bits() as u64) << 32) | low_index;
            *slot = (*slot).min(key);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::Intrinsics;
    use glam::{DQuat, DVec3};

    fn camera() -> Pinhole {
        Pinhole::new(&Intrinsics::PRIMESENSE, 160, 120)
    }

    /// Samples on a 5 cm grid over the plane n . X = n . X0 around X0 (camera space of
    /// `pose`), returned in world space.
    fn plane_cloud(pose: &Pose, centre: Vec3, normal: Vec3, half_extent: f32) -> EnvCloud {
        let m = pose.matrix().as_mat4();
        let tangent = normal.any_orthonormal_vector();
        let bitangent = normal.cross(tangent);
        let steps = (half_extent / 0.05) as i32;
        let mut cloud = EnvCloud::default();
        for i in -steps..=steps {
            for j in -steps..=steps {
                let p = centre + tangent * (i as f32 * 0.05) + bitangent * (j as f32 * 0.05);
                cloud.positions.push(m.transform_point3(p));
                cloud.colors.push(Vec3::new(0.25, 0.5, (i + j) as f32));
                cloud.normals.push(m.transform_vector3(-normal));
            }
        }
        cloud
    }

    fn splat_all(cloud: &EnvCloud, pose: &Pose, params: &SplatParams) -> GBuffer {
        let cam = camera();
        let mut out = GBuffer::new(cam.width, cam.height);
        splat(
            cloud,
            pose,
            &cam,
            params,
            &mut SplatBuffer::default(),
            &mut out,
        )
        .unwrap();
        out
    }

    #[test]
    fn a_tilted_plane_splats_to_its_exact_depth_and_normal() {
        let pose = Pose::from_parts(DVec3::new(1.0, 2.0, -0.5), DQuat::from_rotation_y(0.4));
        // The plane z = 2 + 0.4 x (camera space): normal (0.4, 0, -1) facing the camera.
        let normal = Vec3::new(-0.4, 0.0, 1.0).normalize();
        let cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), normal, 2.0);
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        let cam = camera();
        let facing = -normal;
        let mut hits = 0;
        for y in 30..90 {
            for x in 40..120 {
                let i = y * 160 + x;
                if out.coverage.data[i] != COVERAGE_SPLAT {
                    continue;
                }
                hits += 1;
                let ray = cam.ray(x as f32, y as f32);
                let expected = 2.0 / (1.0 - 0.4 * ray.x);
                assert!((out.depth.data[i] - expected).abs() < 1e-4, "({x}, {y})");
                assert!((out.normals.data[i] - facing).length() < 1e-5);
                assert_eq!(out.color.data[i].x, 0.25);
            }
        }
        assert!(hits > 60 * 80 * 9 / 10, "most pixels are hit: {hits}");
    }

    #[test]
    fn the_nearest_sample_wins_and_covers_its_footprint() {
        let pose = Pose::IDENTITY;
        let mut cloud = EnvCloud::default();
        // Far sample first, near sample second, both on the optical axis; a third one
        // exactly as near as the second (tie: the lower index wins).
        for (z, tag) in [(3.0, 0.0), (1.0, 1.0), (1.0, 2.0)] {
            cloud.positions.push(Vec3::new(0.0, 0.0, z));
            cloud.colors.push(Vec3::splat(tag));
            cloud.normals.push(Vec3::Z);
        }
        let params = SplatParams {
            radius: 0.01,
            max_radius_px: 64.0,
            ..SplatParams::default()
        };
        let out = splat_all(&cloud, &pose, &params);
        // Both project to (79.5, 59.5). Near: radius 0.01 * 131.25 / 1 = 1.3 px; far:
        // 0.44 px, raised to 0.75. The 4 nearest centres lie at 0.71 px, the next 8 at
        // 1.58 px: both cover the same 4 pixels and the near one wins them all.
        for (x, y) in [(79, 59), (80, 59), (79, 60), (80, 60)] {
            let i = y * 160 + x;
            assert_eq!(out.depth.data[i], 1.0);
            assert_eq!(out.color.data[i], Vec3::splat(1.0), "tie: lower index");
            assert_eq!(
                out.normals.data[i],
                Vec3::NEG_Z,
                "turned towards the camera"
            );
        }
        let covered = out
            .coverage
            .data
            .iter()
            .filter(|&&c| c == COVERAGE_SPLAT)
            .count();
        assert_eq!(covered, 4);
        assert!(out.color.data[0].is_nan() && out.depth.data[0] == 0.0);
        assert_eq!(out.normals.data[0], Vec3::ZERO);
    }

    #[test]
    fn deterministic_for_any_thread_count() {
        let pose = Pose::from_parts(DVec3::new(0.1, 0.0, 0.0), DQuat::from_rotation_x(0.1));
        let mut cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), Vec3::NEG_Z, 1.5);
        // A second, interpenetrating plane makes many exact and near ties.
        let other = plane_cloud(
            &pose,
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.3, 0.1, -1.0).normalize(),
            1.5,
        );
        cloud.positions.extend(&other.positions);
        cloud.colors.extend(&other.colors);
        cloud.normals.extend(&other.normals);
        let run = || splat_all(&cloud, &pose, &SplatParams::default());
        let a = crate::stages::with_threads(1, run);
        let b = crate::stages::with_threads(3, run);
        assert_eq!(a.bits(), b.bits());
    }

    #[test]
    fn empty_cloud_and_samples_behind_the_camera_leave_no_data() {
        let pose = Pose::IDENTITY;
        let mut cloud = EnvCloud::default();
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
        cloud.positions.push(Vec3::new(0.0, 0.0, -1.0));
        cloud.colors.push(Vec3::ONE);
        cloud.normals.push(Vec3::Z);
        cloud.positions.push(Vec3::new(0.0, 0.0, 1.0));
        cloud.colors.push(Vec3::NAN);
        cloud.normals.push(Vec3::Z);
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
        assert!(out.depth.data.iter().all(|&d| d == 0.0));
    }
}
