//! What flows through a pipeline: a [`Frame`] holding named [`Product`]s.

pub use super::product::{Compensation, EnvCloud, Product, ProductKind};
use crate::raster::{DepthImage, LabelImage, Rgb8Image, ScalarImage, Vec3Image};
use crate::recording::{FrameRecords, Pose};
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
typed_getter!(radiance, Radiance, Vec3Image);
typed_getter!(scalar, Scalar, ScalarImage);
typed_getter!(labels, Labels, LabelImage);
typed_getter!(compensation, Compensation, Compensation);
typed_getter!(cloud, Cloud, Arc<EnvCloud>);
typed_getter!(environment, Environment, Arc<crate::light::EnvMap>);
typed_getter!(light_table, LightTable, Arc<crate::light::LightTable>);
typed_getter!(area_lights, AreaLights, Arc<crate::light::AreaLights>);
typed_getter!(voxels, Voxels, Arc<crate::light::voxels::VoxelVolume>);
