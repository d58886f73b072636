//! Image buffers that flow through the pipeline: a width, a height and row-major pixels.

use glam::Vec3;

/// A row-major image of `T` pixels. Pixel (x, y) is `data[y * width + x]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Image<T> {
    pub width: u32,
    pub height: u32,
    pub data: Vec<T>,
}

impl<T: bytemuck::Zeroable> Image<T> {
    /// An image of all-zero values, from a zeroed allocation (`calloc`: fresh pages
    /// need no fill pass, reused heap memory gets a memset), for outputs a stage
    /// overwrites.
    pub fn zeroed(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            data: bytemuck::zeroed_vec(width as usize * height as usize),
        }
    }
}

impl<T: Clone> Image<T> {
    /// An image filled with `value`.
    pub fn filled(width: u32, height: u32, value: T) -> Self {
        Image {
            width,
            height,
            data: vec![value; width as usize * height as usize],
        }
    }
}

impl<T> Image<T> {
    /// Wraps `data`; returns `None` when its length is not `width * height`.
    pub fn from_vec(width: u32, height: u32, data: Vec<T>) -> Option<Self> {
        (data.len() == width as usize * height as usize).then_some(Image {
            width,
            height,
            data,
        })
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The pixel at (x, y); panics when out of bounds, like slice indexing.
    #[inline]
    pub fn at(&self, x: u32, y: u32) -> &T {
        &self.data[y as usize * self.width as usize + x as usize]
    }

    /// The rows of the image, top to bottom.
    pub fn rows(&self) -> std::slice::Chunks<'_, T> {
        self.data.chunks(self.width.max(1) as usize)
    }

    /// True when both images have the same width and height.
    pub fn same_size<U>(&self, other: &Image<U>) -> bool {
        self.width == other.width && self.height == other.height
    }
}

/// 8-bit sRGB color as delivered by a sensor.
pub type Rgb8Image = Image<[u8; 3]>;
/// Depth in metres; 0 or non-finite means missing.
pub type DepthImage = Image<f32>;
/// A map of 3-vectors: camera-space positions (metres) or unit normals (zero = invalid).
pub type Vec3Image = Image<Vec3>;
/// One f32 per pixel: weights, confidences.
pub type ScalarImage = Image<f32>;
/// One small integer per pixel: counts, validity codes, coverage classes.
pub type LabelImage = Image<u8>;

/// True when a depth sample holds a measurement (finite and positive).
#[inline]
pub fn depth_is_valid(z: f32) -> bool {
    z.is_finite() && z > 0.0
}

/// Push-pull's upsampling along one axis: the two coarse neighbours of fine index `x` along one axis with their bilinear
/// weights (3/4 for the parent, 1/4 for the next one on the side of `x`); a neighbour
/// outside [0, n) gets weight 0 (its index is clamped).
#[inline]
pub fn upsample_taps(x: usize, n: usize) -> [(usize, f32); 2] {
    let parent = x / 2;
    let side = if x.is_multiple_of(2) {
        parent.checked_sub(1)
    } else {
        Some(parent + 1).filter(|&s| s < n)
    };
    match side {
        Some(s) => [(parent, 0.75), (s, 0.25)],
        None => [(parent, 0.75), (parent, 0.0)],
    }
}

/// Images as products ([`crate::payload`]): their kinds and digests (width, height, then
/// the samples).
mod products {
    use super::{Image, LabelImage, Rgb8Image, ScalarImage, Vec3Image};
    use crate::payload::{Payload, ProductKind, digest};
    use glam::Vec3;
    use xxhash_rust::xxh3::Xxh3;

    /// 8-bit sRGB color.
    pub const COLOR: ProductKind = ProductKind::of::<Rgb8Image>("color image");
    /// Depth in metres (0 or non-finite = missing).
    pub const DEPTH: ProductKind = ProductKind::of::<ScalarImage>("depth map");
    /// Camera-space positions in metres (non-finite = missing).
    pub const POINTS: ProductKind = ProductKind::of::<Vec3Image>("point map");
    /// Camera-space unit normals facing the camera (zero = invalid).
    pub const NORMALS: ProductKind = ProductKind::of::<Vec3Image>("normal map");
    /// Linear HDR RGB radiance in the reference color space (non-finite = missing).
    pub const RADIANCE: ProductKind = ProductKind::of::<Vec3Image>("HDR radiance image");
    /// One f32 per pixel (e.g. the fusion weight).
    pub const SCALAR: ProductKind = ProductKind::of::<ScalarImage>("scalar map");
    /// One small integer per pixel (e.g. neighbour counts, validity codes).
    pub const LABELS: ProductKind = ProductKind::of::<LabelImage>("label map");

    impl Payload for Image<[u8; 3]> {
        fn digest(&self, h: &mut Xxh3) {
            digest::dims(h, self.width, self.height);
            h.update(bytemuck::cast_slice(&self.data));
        }
    }

    impl Payload for Image<f32> {
        fn digest(&self, h: &mut Xxh3) {
            digest::dims(h, self.width, self.height);
            digest::floats(h, &self.data);
        }
    }

    impl Payload for Image<Vec3> {
        fn digest(&self, h: &mut Xxh3) {
            digest::dims(h, self.width, self.height);
            digest::vec3s(h, &self.data);
        }
    }

    impl Payload for Image<u8> {
        fn digest(&self, h: &mut Xxh3) {
            digest::dims(h, self.width, self.height);
            h.update(&self.data);
        }
    }
}

pub use products::{COLOR, DEPTH, LABELS, NORMALS, POINTS, RADIANCE, SCALAR};
