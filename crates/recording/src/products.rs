//! A frame's records and its pose as pipeline products ([`relume_base::payload`]).

use crate::{FrameRecords, Pose};
use relume_base::payload::{Payload, ProductKind};
use std::sync::Arc;
use xxhash_rust::xxh3::Xxh3;

/// The encoded records of a frame, as read from the recording: what the source makes.
pub const RECORD: ProductKind = ProductKind::of::<Arc<FrameRecords>>("record");
/// Camera-to-world pose.
pub const POSE: ProductKind = ProductKind::of::<Pose>("pose");

/// The stamp and the encoded color and depth bytes.
impl Payload for FrameRecords {
    fn digest(&self, h: &mut Xxh3) {
        h.update(&self.stamp_ns.to_le_bytes());
        h.update(&self.color.image.bytes);
        if let Some(d) = &self.depth {
            h.update(&d.image.bytes);
        }
    }
}

/// Translation, then the quaternion, as f64 bit patterns.
impl Payload for Pose {
    fn digest(&self, h: &mut Xxh3) {
        for v in self.translation.iter().chain(&self.rotation) {
            h.update(&v.to_bits().to_le_bytes());
        }
    }
}
