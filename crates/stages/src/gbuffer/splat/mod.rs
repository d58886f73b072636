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

use super::buffer::{COVERAGE_NONE, COVERAGE_SPLAT, GBuffer};
use crate::OpError;
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_recording::Pose;
use relume_scene::light::EnvCloud;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

mod footprint;

use footprint::{Footprint, Raster, draw};
pub use footprint::{GRAZING_COS, MIN_RADIUS_PX, NEAR_M, PLANE_DEPTH_SPAN};

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
            occlusion_margin: DEFAULT_OCCLUSION_MARGIN as f32,
        }
    }
}

/// Default of [`SplatParams::max_radius_px`].
pub const DEFAULT_MAX_RADIUS_PX: f32 = 64.0;
/// Default of [`SplatParams::occlusion_margin`], metres (f64: the stage's parameter
/// default shows it as written).
pub const DEFAULT_OCCLUSION_MARGIN: f64 = 0.1;

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
) -> Result<(), OpError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if (out.width(), out.height()) != (camera.width, camera.height) || !out.is_consistent() {
        return Err(OpError::SizeMismatch(format!(
            "G-buffer is {}x{}, camera is {w}x{h}",
            out.width(),
            out.height()
        )));
    }
    let n = cloud.len();
    if cloud.colors.len() != n || cloud.normals.len() != n {
        return Err(OpError::SizeMismatch(format!(
            "cloud has {n} positions, {} colors and {} normals",
            cloud.colors.len(),
            cloud.normals.len()
        )));
    }
    if n >= u32::MAX as usize || w * h >= u32::MAX as usize {
        return Err(OpError::BadInput(format!(
            "cloud of {n} samples or image of {w}x{h} is too large to splat"
        )));
    }
    if !(params.radius.is_finite()
        && params.radius >= 0.0
        && params.max_radius_px.is_finite()
        && params.occlusion_margin >= 0.0)
    {
        return Err(OpError::BadParameter(
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
    project_centres(cloud, &raster, (w, h), buffer);
    let cull = params.occlusion_margin.is_finite();
    if cull {
        nearest_centres((w, h), buffer);
    }
    bin_footprints(
        cloud,
        &raster,
        h,
        cull.then_some(params.occlusion_margin),
        buffer,
    );
    draw_bands(cloud, &raster, buffer, out);
    Ok(())
}

/// Pass 1: projects every sample, depth-tests it into its centre pixel of
/// `buffer.centre` and records its row span in `buffer.projected`.
fn project_centres(
    cloud: &EnvCloud,
    raster: &Raster,
    (w, h): (usize, usize),
    buffer: &mut SplatBuffer,
) {
    let n = cloud.len();
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
}

/// The nearest centre depth over the 3x3 pixels around each pixel, into
/// `buffer.front` (for occlusion culling).
fn nearest_centres((w, h): (usize, usize), buffer: &mut SplatBuffer) {
    let centre = &buffer.centre[..];
    let front = &mut buffer.front;
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

/// Pass 2: drops the samples lying more than `margin` behind the front (when given),
/// and sorts the others' footprints by the bands they touch, chunk by chunk, into
/// `buffer.bins`.
fn bin_footprints(
    cloud: &EnvCloud,
    raster: &Raster,
    h: usize,
    margin: Option<f32>,
    buffer: &mut SplatBuffer,
) {
    let n = cloud.len();
    let bands = h.div_ceil(BAND_ROWS);
    let chunks = n.div_ceil(SAMPLES_PER_TASK);
    buffer.bins.resize_with(chunks, ChunkBins::default);
    let front = &buffer.front[..];
    buffer
        .bins
        .par_iter_mut()
        .zip(buffer.projected.par_chunks(SAMPLES_PER_TASK))
        .enumerate()
        .for_each(|(chunk, (bins, projected))| {
            let first = (chunk * SAMPLES_PER_TASK) as u32;
            let drawn = |s: &Projected| {
                s.top <= s.bottom
                    && !margin.is_some_and(|margin| {
                        s.pixel != NO_PIXEL && s.z > front[s.pixel as usize] + margin
                    })
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
            bins.entries
                .resize(bins.starts[bands] as usize, Footprint::default());
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
}

/// Pass 3: depth-tests each band's footprints into its keys, then turns the winning
/// keys into the band's G-buffer rows.
fn draw_bands(cloud: &EnvCloud, raster: &Raster, buffer: &mut SplatBuffer, out: &mut GBuffer) {
    let (camera, rotation) = (raster.camera, raster.rotation);
    let (w, h) = (camera.width as usize, camera.height as usize);
    buffer.keys.resize(w * h, EMPTY_KEY);
    let bins = &buffer.bins[..];
    let band_len = BAND_ROWS * w;
    out.par_bands_mut(BAND_ROWS)
        .zip(buffer.keys.par_chunks_mut(band_len))
        .enumerate()
        .for_each(|(band, (mut pixels, keys))| {
            keys.fill(EMPTY_KEY);
            let y0 = band * BAND_ROWS;
            let y1 = y0 + keys.len() / w - 1;
            for chunk in bins {
                let range = chunk.starts[band] as usize..chunk.starts[band + 1] as usize;
                for f in &chunk.entries[range] {
                    draw(f, w, (y0, y1), keys);
                }
            }
            let rows = pixels.rows(w).zip(keys.chunks(w));
            for (y, (row, keys)) in (y0..).zip(rows) {
                for (x, key) in keys.iter().enumerate() {
                    if *key == EMPTY_KEY {
                        row.color[x] = Vec3::NAN;
                        row.depth[x] = 0.0;
                        row.normals[x] = Vec3::ZERO;
                        row.coverage[x] = COVERAGE_NONE;
                        continue;
                    }
                    let i = (key & 0xffff_ffff) as usize;
                    let n = (rotation * cloud.normals[i]).normalize_or_zero();
                    let ray = camera.ray(x as f32, y as f32);
                    row.color[x] = cloud.colors[i];
                    row.depth[x] = 1.0 / f32::from_bits(!((key >> 32) as u32));
                    row.normals[x] = if n.dot(ray) > 0.0 { -n } else { n };
                    row.coverage[x] = COVERAGE_SPLAT;
                }
            }
        });
}

#[cfg(test)]
mod tests;
