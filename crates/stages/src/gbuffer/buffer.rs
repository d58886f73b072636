//! The G-buffer `gbuffer.splat` fills: the reference color, depth, normals and coverage
//! of one view, and the row bands that splatting and push-pull write in parallel.

use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{DepthImage, Image, LabelImage, Vec3Image};

/// Coverage label: no data.
pub const COVERAGE_NONE: u8 = 0;
/// Coverage label: filled by push-pull.
pub const COVERAGE_FILLED: u8 = 1;
/// Coverage label: hit by a splat.
pub const COVERAGE_SPLAT: u8 = 2;

/// The G-buffer of one view: reference color (linear HDR, NaN = none), depth (metres,
/// 0 = none), camera-space normals facing the camera (zero = none) and coverage
/// ([`COVERAGE_NONE`], [`COVERAGE_FILLED`], [`COVERAGE_SPLAT`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    pub color: Vec3Image,
    pub depth: DepthImage,
    pub normals: Vec3Image,
    pub coverage: LabelImage,
}

impl GBuffer {
    /// A G-buffer of `width` x `height` with no data (filled in parallel: this is
    /// about 9 MB of fresh memory per 640x480 frame).
    pub fn new(width: u32, height: u32) -> GBuffer {
        GBuffer {
            color: par_filled(width, height, Vec3::NAN),
            depth: par_filled(width, height, 0.0),
            normals: par_filled(width, height, Vec3::ZERO),
            coverage: par_filled(width, height, COVERAGE_NONE),
        }
    }

    pub fn width(&self) -> u32 {
        self.depth.width
    }

    pub fn height(&self) -> u32 {
        self.depth.height
    }

    /// True when the four images have the same size and pixel counts.
    pub fn is_consistent(&self) -> bool {
        let n = self.depth.len();
        self.depth.same_size(&self.color)
            && self.depth.same_size(&self.normals)
            && self.depth.same_size(&self.coverage)
            && [self.color.len(), self.normals.len(), self.coverage.len()] == [n; 3]
            && n == self.width() as usize * self.height() as usize
    }

    /// The four images cut into bands of `rows` image rows (the last band may be
    /// shorter), top to bottom, for writing in parallel.
    pub(crate) fn par_bands_mut(
        &mut self,
        rows: usize,
    ) -> impl IndexedParallelIterator<Item = GBufferRows<'_>> {
        let len = (rows * self.width() as usize).max(1);
        self.color
            .data
            .par_chunks_mut(len)
            .zip(self.depth.data.par_chunks_mut(len))
            .zip(self.normals.data.par_chunks_mut(len))
            .zip(self.coverage.data.par_chunks_mut(len))
            .map(|(((color, depth), normals), coverage)| GBufferRows {
                color,
                depth,
                normals,
                coverage,
            })
    }

    /// Per pixel: depth, color, normal bits and coverage (for bit-exact tests).
    #[cfg(test)]
    pub(crate) fn bits(&self) -> Vec<[u32; 8]> {
        (0..self.depth.len())
            .map(|i| {
                let (c, n) = (self.color.data[i], self.normals.data[i]);
                [
                    self.depth.data[i].to_bits(),
                    c.x.to_bits(),
                    c.y.to_bits(),
                    c.z.to_bits(),
                    n.x.to_bits(),
                    n.y.to_bits(),
                    n.z.to_bits(),
                    self.coverage.data[i] as u32,
                ]
            })
            .collect()
    }
}

/// Some whole rows of a G-buffer's four images, pixel for pixel
/// ([`GBuffer::par_bands_mut`]).
pub(crate) struct GBufferRows<'a> {
    pub color: &'a mut [Vec3],
    pub depth: &'a mut [f32],
    pub normals: &'a mut [Vec3],
    pub coverage: &'a mut [u8],
}

impl GBufferRows<'_> {
    /// The rows one by one, each `width` pixels.
    pub fn rows(&mut self, width: usize) -> impl Iterator<Item = GBufferRows<'_>> {
        let width = width.max(1);
        self.color
            .chunks_mut(width)
            .zip(self.depth.chunks_mut(width))
            .zip(self.normals.chunks_mut(width))
            .zip(self.coverage.chunks_mut(width))
            .map(|(((color, depth), normals), coverage)| GBufferRows {
                color,
                depth,
                normals,
                coverage,
            })
    }
}

/// `Image::filled`, written by the thread pool.
fn par_filled<T: Copy + Send + Sync>(width: u32, height: u32, value: T) -> Image<T> {
    let mut data = Vec::new();
    (0..width as usize * height as usize)
        .into_par_iter()
        .with_min_len(1 << 14)
        .map(|_| value)
        .collect_into_vec(&mut data);
    Image {
        width,
        height,
        data,
    }
}
