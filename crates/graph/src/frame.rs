//! What flows through a pipeline: a [`Frame`] holding named [`Product`]s.

use super::error::StageError;
pub use super::product::{Payload, Product, ProductKind};
use relume_base::raster::{DepthImage, LabelImage, Rgb8Image, ScalarImage, Vec3Image};
use relume_recording::{FrameRecords, Pose};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

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

impl Frame {
    /// The product `name` as a value of `kind`; errors name the product and what was
    /// expected.
    pub fn get_as<T: Payload>(&self, name: &str, kind: ProductKind) -> Result<&T, StageError> {
        match self.get(name) {
            Some(p) => p.get(kind).ok_or_else(|| StageError::WrongKind {
                product: name.to_string(),
                expected: kind.name(),
                found: p.kind().name(),
            }),
            None => Err(StageError::MissingInput(name.to_string())),
        }
    }
}

/// Typed access to a frame's inputs of the kinds below the runtime (images, records,
/// poses); errors name the product and what was expected. The stages crate adds the
/// rest (`relume_stages::kind::FrameProducts`).
macro_rules! typed_getter {
    ($fn:ident, $kind:path, $ty:ty) => {
        impl Frame {
            #[doc = concat!("The product `name` as a [`", stringify!($kind), "`].")]
            pub fn $fn(&self, name: &str) -> Result<&$ty, StageError> {
                self.get_as(name, $kind)
            }
        }
    };
}
typed_getter!(record, relume_recording::RECORD, Arc<FrameRecords>);
typed_getter!(color, relume_base::raster::COLOR, Rgb8Image);
typed_getter!(depth, relume_base::raster::DEPTH, DepthImage);
typed_getter!(points, relume_base::raster::POINTS, Vec3Image);
typed_getter!(normals, relume_base::raster::NORMALS, Vec3Image);
typed_getter!(pose, relume_recording::POSE, Pose);
typed_getter!(radiance, relume_base::raster::RADIANCE, Vec3Image);
typed_getter!(scalar, relume_base::raster::SCALAR, ScalarImage);
typed_getter!(labels, relume_base::raster::LABELS, LabelImage);
