//! What flows through a pipeline: a [`Frame`] holding named [`Product`]s.

use crate::raster::{DepthImage, Rgb8Image, Vec3Image};
use crate::recording::{FrameRecords, Pose};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

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
        }
    }

    /// The kinds that are images and can be written to files.
    pub const IMAGES: &'static [ProductKind] = &[
        ProductKind::Color,
        ProductKind::Depth,
        ProductKind::Points,
        ProductKind::Normals,
    ];
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
            Product::Depth(img) => {
                dims(&mut h, img.width, img.height);
                for v in &img.data {
                    h.update(&v.to_bits().to_le_bytes());
                }
            }
            Product::Points(img) | Product::Normals(img) => {
                dims(&mut h, img.width, img.height);
                for v in &img.data {
                    for c in v.to_array() {
                        h.update(&c.to_bits().to_le_bytes());
                    }
                }
            }
            Product::Pose(p) => {
                for v in p.translation.iter().chain(&p.rotation) {
                    h.update(&v.to_bits().to_le_bytes());
                }
            }
        }
        h.digest()
    }
}

/// One frame in flight: its position in the recording, its stamp and its products.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Index among the recording's associated frames.
    pub index: usize,
    pub stamp_ns: i64,
    /// When the source started reading this frame (for end-to-end latency).
    pub entered: Instant,
    products: BTreeMap<String, Arc<Product>>,
}

impl Frame {
    pub fn new(index: usize, stamp_ns: i64) -> Frame {
        Frame {
            index,
            stamp_ns,
            entered: Instant::now(),
            products: BTreeMap::new(),
        }
    }

    /// Adds or replaces a product.
    pub fn insert(&mut self, name: &str, product: Product) {
        self.products.insert(name.to_string(), Arc::new(product));
    }

    /// Adds a shared product (e.g. a feedback value) without copying it.
    pub fn insert_shared(&mut self, name: &str, product: Arc<Product>) {
        self.products.insert(name.to_string(), product);
    }

    pub fn remove(&mut self, name: &str) -> Option<Arc<Product>> {
        self.products.remove(name)
    }

    pub fn get(&self, name: &str) -> Option<&Product> {
        self.products.get(name).map(|p| p.as_ref())
    }

    pub fn get_shared(&self, name: &str) -> Option<&Arc<Product>> {
        self.products.get(name)
    }

    /// Products in name order.
    pub fn products(&self) -> impl Iterator<Item = (&str, &Product)> {
        self.products.iter().map(|(k, v)| (k.as_str(), v.as_ref()))
    }
}

/// Typed access to a frame's inputs; errors name the product and what was expected.
macro_rules! typed_getter {
    ($fn:ident, $variant:ident, $ty:ty) => {
        impl Frame {
            #[doc = concat!("The product `name` as a ", stringify!($variant), ".")]
            pub fn $fn(&self, name: &str) -> Result<&$ty, crate::graph::StageError> {
                match self.get(name) {
                    Some(Product::$variant(v)) => Ok(v),
                    Some(other) => Err(crate::graph::StageError::WrongKind {
                        product: name.to_string(),
                        expected: ProductKind::$variant.name(),
                        found: other.kind().name(),
                    }),
                    None => Err(crate::graph::StageError::MissingInput(name.to_string())),
                }
            }
        }
    };
}
typed_getter!(record, Record, Arc<FrameRecords>);
typed_getter!(color, Color, Rgb8Image);
typed_getter!(depth, Depth, DepthImage);
typed_getter!(points, Points, Vec3Image);
typed_getter!(normals, Normals, Vec3Image);
typed_getter!(pose, Pose, Pose);
