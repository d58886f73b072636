//! What a pipeline product holds, as every layer sees it: a [`Payload`] (any value with a
//! canonical digest) under a [`ProductKind`] (what the value means: a depth map and a
//! scalar map are both `Image<f32>`).
//!
//! The trait lives in the base crate so that each crate can make its own types products:
//! the raster images here ([`crate::raster`]), the recording's records and poses, the
//! scene's light models, the stages' compensation. The graph runtime stores products
//! without knowing any of these types, so a stage crate adds a product kind by declaring
//! a constant, without touching the runtime.

use std::any::{Any, TypeId};
use std::sync::Arc;
pub use xxhash_rust::xxh3::Xxh3;

/// A value that can travel between stages.
pub trait Payload: Any + Send + Sync + std::fmt::Debug {
    /// Feeds the value's canonical bytes to `h`: sizes, then samples little-endian,
    /// floats by bit pattern. `relume replay --hash` prints the digest of every product.
    fn digest(&self, h: &mut Xxh3);
}

/// A shared value is the value.
impl<T: Payload> Payload for Arc<T> {
    fn digest(&self, h: &mut Xxh3) {
        (**self).digest(h)
    }
}

/// The type of a product, checked when a pipeline is loaded: a name for messages and the
/// Rust type of its values. Kinds are equal when their names are.
#[derive(Clone, Copy)]
pub struct ProductKind {
    name: &'static str,
    type_id: fn() -> TypeId,
    type_name: fn() -> &'static str,
}

impl ProductKind {
    /// The kind called `name` (lower case, used in messages: "depth map") whose values
    /// are `T`s.
    pub const fn of<T: Payload>(name: &'static str) -> ProductKind {
        ProductKind {
            name,
            type_id: TypeId::of::<T>,
            type_name: std::any::type_name::<T>,
        }
    }

    /// Lower-case name used in messages.
    pub fn name(self) -> &'static str {
        self.name
    }

    /// True when values of this kind are `T`s.
    pub fn holds<T: Payload>(self) -> bool {
        (self.type_id)() == TypeId::of::<T>()
    }

    /// The Rust type of the kind's values (for messages to stage authors).
    pub fn type_name(self) -> &'static str {
        (self.type_name)()
    }
}

impl PartialEq for ProductKind {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

impl Eq for ProductKind {}

impl std::hash::Hash for ProductKind {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.name.hash(state)
    }
}

impl PartialOrd for ProductKind {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for ProductKind {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.name.cmp(other.name)
    }
}

impl std::fmt::Debug for ProductKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ProductKind({:?})", self.name)
    }
}

/// Digest helpers shared by the [`Payload`] impls: sizes and samples little-endian,
/// floats by bit pattern.
pub mod digest {
    use glam::Vec3;
    use xxhash_rust::xxh3::Xxh3;

    /// An image's width and height.
    pub fn dims(h: &mut Xxh3, w: u32, ht: u32) {
        h.update(&w.to_le_bytes());
        h.update(&ht.to_le_bytes());
    }

    /// Floats by bit pattern.
    pub fn floats(h: &mut Xxh3, values: &[f32]) {
        for v in values {
            h.update(&v.to_bits().to_le_bytes());
        }
    }

    /// Vectors as three floats each.
    pub fn vec3s(h: &mut Xxh3, values: &[Vec3]) {
        for v in values {
            floats(h, &v.to_array());
        }
    }
}
