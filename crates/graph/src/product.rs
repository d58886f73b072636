//! The values that flow between stages: a [`Product`] is a [`Payload`] under its
//! [`ProductKind`].
//!
//! The runtime knows no payload type. Each crate declares the kinds of the types it
//! defines (`relume_base::raster::DEPTH`, `relume_recording::RECORD`,
//! `relume_scene::light::ENVIRONMENT`, `relume_stages::compensate::COMPENSATION`), and
//! `relume_stages::kind` names them all in one place for stage authors.

pub use relume_base::payload::{Payload, ProductKind};
use std::sync::Arc;

/// A product of a stage (or of the source): immutable once made, cheap to clone.
#[derive(Clone, Debug)]
pub struct Product {
    kind: ProductKind,
    value: Arc<dyn Payload>,
}

impl Product {
    /// `value` as a product of `kind`.
    ///
    /// # Panics
    /// When `kind`'s values are not `T`s: a stage's own mistake, which its first test
    /// meets, not something a recording or a config can cause.
    pub fn new<T: Payload>(kind: ProductKind, value: T) -> Product {
        assert!(
            kind.holds::<T>(),
            "a {} holds {}, not {}",
            kind.name(),
            kind.type_name(),
            std::any::type_name::<T>()
        );
        Product {
            kind,
            value: Arc::new(value),
        }
    }

    pub fn kind(&self) -> ProductKind {
        self.kind
    }

    /// True when the product is of `kind`.
    pub fn is(&self, kind: ProductKind) -> bool {
        self.kind == kind
    }

    /// The value, when it is a `T`.
    pub fn value<T: Payload>(&self) -> Option<&T> {
        (self.value.as_ref() as &dyn std::any::Any).downcast_ref::<T>()
    }

    /// The value, when the product is of `kind` (whose values are `T`s).
    pub fn get<T: Payload>(&self, kind: ProductKind) -> Option<&T> {
        if self.kind == kind {
            self.value()
        } else {
            None
        }
    }

    /// The value itself when it is a `T` that nothing else shares (so that a stage can
    /// reuse its buffers), else the product back.
    pub fn into_value<T: Payload>(self) -> Result<T, Product> {
        if (self.value.as_ref() as &dyn std::any::Any).is::<T>() {
            let any: Arc<dyn std::any::Any + Send + Sync> = self.value;
            let typed = any.downcast::<T>().expect("the type was checked");
            Arc::try_unwrap(typed).map_err(|typed| Product {
                kind: self.kind,
                value: typed,
            })
        } else {
            Err(self)
        }
    }

    /// A 64-bit digest of the product's content (xxh3 over its canonical bytes: sizes,
    /// then samples little-endian, floats by bit pattern; see [`Payload::digest`]).
    pub fn digest(&self) -> u64 {
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        self.value.digest(&mut h);
        h.digest()
    }
}
