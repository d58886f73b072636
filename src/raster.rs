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
