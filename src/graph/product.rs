//! The values that flow between stages: [`Product`] and its [`ProductKind`].

use crate::light::voxels::VoxelVolume;
use crate::light::{AreaLights, EnvMap, LightTable};
use crate::raster::{DepthImage, LabelImage, Rgb8Image, ScalarImage, Vec3Image};
use crate::recording::{FrameRecords, Pose};
use glam::{Mat3, Vec3};
use std::sync::Arc;

/// The type of a product, checked when a pipeline is loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ProductKind {
    /// The encoded records of a frame, as read from the recording.
    Record,
    /// 8-bit sRGB color.
    Color,
    /// Depth in metres (0 or non-finite = missing).
    Depth,
    /// Camera-space positions in metres (non-finite = missing).
    Points,
    /// Camera-space unit normals facing the camera (zero = invalid).
    Normals,
    /// Camera-to-world pose.
    Pose,
    /// Linear HDR RGB radiance in the reference color space (non-finite = missing).
    Radiance,
    /// One f32 per pixel (e.g. the fusion weight).
    Scalar,
    /// One small integer per pixel (e.g. neighbour counts, validity codes).
    Labels,
    /// A frame's color compensation c_t, its inverse and diagnostics.
    Compensation,
    /// The world-space cloud of environment samples.
    Cloud,
    /// An HDR lat-long environment map ([`crate::light::EnvMap`]).
    Environment,
    /// Importance samples of an environment map ([`crate::light::LightTable`]).
    LightTable,
    /// Virtual area lights and SH9 indirect light ([`crate::light::AreaLights`]).
    AreaLights,
    /// A mip-mapped voxel volume of the scene ([`crate::light::voxels::VoxelVolume`]).
    Voxels,
}

impl ProductKind {
    /// Lower-case name used in messages.
    pub fn name(self) -> &'static str {
        match self {
            ProductKind::Record => "record",
            ProductKind::Color => "color image",
            ProductKind::Depth => "depth map",
            ProductKind::Points => "point map",
            ProductKind::Normals => "normal map",
            ProductKind::Pose => "pose",
            ProductKind::Radiance => "HDR radiance image",
            ProductKind::Scalar => "scalar map",
            ProductKind::Labels => "label map",
            ProductKind::Compensation => "color compensation",
            ProductKind::Cloud => "environment-sample cloud",
            ProductKind::Environment => "environment map",
            ProductKind::LightTable => "light sample table",
            ProductKind::AreaLights => "set of area lights",
            ProductKind::Voxels => "voxel volume",
        }
    }

    /// The kinds that are images and can be written to image files: the first
    /// [`ProductKind::WRITABLE`] kinds.
    pub const IMAGES: &'static [ProductKind] = Self::WRITABLE.split_at(7).0;

    /// True for the kinds in [`ProductKind::IMAGES`].
    pub fn is_image(self) -> bool {
        Self::IMAGES.contains(&self)
    }

    /// True for the kinds in [`ProductKind::WRITABLE`].
    pub fn is_writable(self) -> bool {
        Self::WRITABLE.contains(&self)
    }

    /// The kinds the `write` stage can save: the images first, then compensation (JSON),
    /// the cloud (PLY) and the light model ([`crate::light::record`]).
    pub const WRITABLE: &'static [ProductKind] = &[
        ProductKind::Color,
        ProductKind::Depth,
        ProductKind::Points,
        ProductKind::Normals,
        ProductKind::Radiance,
        ProductKind::Scalar,
        ProductKind::Labels,
        ProductKind::Compensation,
        ProductKind::Cloud,
        ProductKind::AreaLights,
    ];
}

/// Why sample pairs were kept or rejected by `color.compensate` (paper 000 Sec. 4.1), in
/// the order the tests run: a pair is counted under the first test it fails.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairCounts {
    /// Pixels considered (the whole image).
    pub candidates: u32,
    /// No data in the reference image at that pixel.
    pub no_reference: u32,
    /// Under- or over-saturated in the camera image.
    pub saturated: u32,
    /// A strong color gradient in either image.
    pub gradient: u32,
    /// Too far apart in the hue-saturation plane (first, coarse pass).
    pub hue_saturation: u32,
    /// Too far apart in HSV after applying c_{t-1} (second, strict pass).
    pub hsv: u32,
    /// Pairs that entered the fit.
    pub kept: u32,
}

/// The color compensation of one frame (paper 000 Sec. 4): the 3x3 map c_t from the
/// camera's linearized color to the reference color space, its inverse, the per-channel
/// approximation A_t and what the estimation saw.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensation {
    /// c_t: reference linear RGB = `matrix` * camera linear RGB (C_t of eq. 2, or A_t
    /// when the frame is approximate).
    pub matrix: Mat3,
    /// c_t^-1: back from the reference space into the camera's linear space.
    pub inverse: Mat3,
    /// The diagonal of A_t (per-channel scale s of Sec. 4.2).
    pub gains: Vec3,
    /// Fewer pairs than the minimum: `matrix` is A_t (or c_{t-1} when even A_t had no
    /// pairs), and the frame adds no environment samples.
    pub approximate: bool,
    /// The first frame with no reference: c_0 = I defines the reference space.
    pub initial: bool,
    pub pairs: PairCounts,
}

impl Compensation {
    /// The identity compensation of the first frame (C_0 = I).
    pub fn initial() -> Compensation {
        Compensation {
            matrix: Mat3::IDENTITY,
            inverse: Mat3::IDENTITY,
            gains: Vec3::ONE,
            approximate: false,
            initial: true,
            pairs: PairCounts::default(),
        }
    }

    /// A JSON object with row-major matrices, for files and `relume eval`.
    pub fn to_json(&self) -> serde_json::Value {
        let rows = |m: &Mat3| -> Vec<[f32; 3]> { (0..3).map(|r| m.row(r).to_array()).collect() };
        let p = &self.pairs;
        serde_json::json!({
            "matrix": rows(&self.matrix),
            "inverse": rows(&self.inverse),
            "gains": self.gains.to_array(),
            "approximate": self.approximate,
            "initial": self.initial,
            "pairs": {
                "candidates": p.candidates,
                "kept": p.kept,
                "rejected": {
                    "no_reference": p.no_reference,
                    "saturated": p.saturated,
                    "gradient": p.gradient,
                    "hue_saturation": p.hue_saturation,
                    "hsv": p.hsv,
                },
            },
        })
    }
}

/// Environment samples (paper 000 Sec. 5) as they stand after a frame: world positions
/// (metres), compensated linear colors and unit world normals, in a deterministic order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnvCloud {
    pub positions: Vec<Vec3>,
    pub colors: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

impl EnvCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// A product of a stage (or of the source).
#[derive(Clone, Debug)]
pub enum Product {
    Record(Arc<FrameRecords>),
    Color(Rgb8Image),
    Depth(DepthImage),
    Points(Vec3Image),
    Normals(Vec3Image),
    Pose(Pose),
    Radiance(Vec3Image),
    Scalar(ScalarImage),
    Labels(LabelImage),
    Compensation(Compensation),
    Cloud(Arc<EnvCloud>),
    Environment(Arc<EnvMap>),
    LightTable(Arc<LightTable>),
    AreaLights(Arc<AreaLights>),
    Voxels(Arc<VoxelVolume>),
}

impl Product {
    pub fn kind(&self) -> ProductKind {
        match self {
            Product::Record(_) => ProductKind::Record,
            Product::Color(_) => ProductKind::Color,
            Product::Depth(_) => ProductKind::Depth,
            Product::Points(_) => ProductKind::Points,
            Product::Normals(_) => ProductKind::Normals,
            Product::Pose(_) => ProductKind::Pose,
            Product::Radiance(_) => ProductKind::Radiance,
            Product::Scalar(_) => ProductKind::Scalar,
            Product::Labels(_) => ProductKind::Labels,
            Product::Compensation(_) => ProductKind::Compensation,
            Product::Cloud(_) => ProductKind::Cloud,
            Product::Environment(_) => ProductKind::Environment,
            Product::LightTable(_) => ProductKind::LightTable,
            Product::AreaLights(_) => ProductKind::AreaLights,
            Product::Voxels(_) => ProductKind::Voxels,
        }
    }

    /// A 64-bit digest of the product's content (xxh3 over its canonical bytes: sizes,
    /// then samples little-endian, floats by bit pattern).
    pub fn digest(&self) -> u64 {
        use xxhash_rust::xxh3::Xxh3;
        let mut h = Xxh3::new();
        let dims = |h: &mut Xxh3, w: u32, ht: u32| {
            h.update(&w.to_le_bytes());
            h.update(&ht.to_le_bytes());
        };
        let floats = |h: &mut Xxh3, values: &[f32]| {
            for v in values {
                h.update(&v.to_bits().to_le_bytes());
            }
        };
        let vec3s = |h: &mut Xxh3, values: &[Vec3]| {
            for v in values {
                floats(h, &v.to_array());
            }
        };
        match self {
            Product::Record(r) => {
                h.update(&r.stamp_ns.to_le_bytes());
                h.update(&r.color.image.bytes);
                if let Some(d) = &r.depth {
                    h.update(&d.image.bytes);
                }
            }
            Product::Color(img) => {
                dims(&mut h, img.width, img.height);
                h.update(bytemuck::cast_slice(&img.data));
            }
            Product::Depth(img) | Product::Scalar(img) => {
                dims(&mut h, img.width, img.height);
                floats(&mut h, &img.data);
            }
            Product::Points(img) | Product::Normals(img) | Product::Radiance(img) => {
                dims(&mut h, img.width, img.height);
                vec3s(&mut h, &img.data);
            }
            Product::Labels(img) => {
                dims(&mut h, img.width, img.height);
                h.update(&img.data);
            }
            Product::Pose(p) => {
                for v in p.translation.iter().chain(&p.rotation) {
                    h.update(&v.to_bits().to_le_bytes());
                }
            }
            Product::Compensation(c) => {
                floats(&mut h, &c.matrix.to_cols_array());
                floats(&mut h, &c.inverse.to_cols_array());
                floats(&mut h, &c.gains.to_array());
                h.update(&[c.approximate as u8, c.initial as u8]);
                let p = &c.pairs;
                for n in [
                    p.candidates,
                    p.no_reference,
                    p.saturated,
                    p.gradient,
                    p.hue_saturation,
                    p.hsv,
                    p.kept,
                ] {
                    h.update(&n.to_le_bytes());
                }
            }
            Product::Cloud(cloud) => {
                h.update(&(cloud.len() as u64).to_le_bytes());
                vec3s(&mut h, &cloud.positions);
                vec3s(&mut h, &cloud.colors);
                vec3s(&mut h, &cloud.normals);
            }
            Product::Environment(env) => {
                dims(&mut h, env.width, env.height);
                vec3s(&mut h, &env.radiance);
                floats(&mut h, &env.distance);
                floats(&mut h, &env.center.to_array());
            }
            Product::LightTable(table) => {
                h.update(&(table.samples.len() as u64).to_le_bytes());
                for s in &table.samples {
                    floats(&mut h, &s.direction.to_array());
                    floats(&mut h, &s.radiance.to_array());
                    floats(&mut h, &[s.pdf]);
                }
            }
            Product::AreaLights(set) => {
                h.update(&(set.lights.len() as u64).to_le_bytes());
                for l in &set.lights {
                    floats(&mut h, &l.position.to_array());
                    floats(&mut h, &l.normal.to_array());
                    floats(&mut h, &l.intensity.to_array());
                    floats(&mut h, &[l.area]);
                }
                vec3s(&mut h, &set.sh9);
            }
            Product::Voxels(volume) => {
                floats(&mut h, &volume.origin.to_array());
                floats(&mut h, &[volume.voxel_size]);
                for level in &volume.levels {
                    dims(&mut h, level.dims[0], level.dims[1]);
                    h.update(&level.dims[2].to_le_bytes());
                    for v in &level.voxels {
                        floats(&mut h, &v.to_array());
                    }
                }
            }
        }
        h.digest()
    }
}
