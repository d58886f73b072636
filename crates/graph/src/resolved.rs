//! What a checked pipeline is made of: its [`ResolvedStage`]s and [`Feedback`] edges,
//! and the names and defaults the check, the tree and the runtime all read (the source
//! product, the `@prev` suffix, the default channel capacity). Plain data, so that the
//! files that check, shape and run a pipeline can share it without importing each
//! other; [`super::pipeline`] re-exports all of it.

use super::params::Params;
use std::collections::BTreeMap;

/// The product the source puts into every frame: the frame's encoded records.
pub const SOURCE_PRODUCT: &str = "record";
/// Suffix of an input that reads the previous frame's value of a product.
pub const PREVIOUS_SUFFIX: &str = "@prev";
/// Frames buffered between two stages when the config does not say.
pub const DEFAULT_CHANNEL_CAPACITY: usize = 2;

/// A checked stage of a pipeline.
#[derive(Clone, Debug)]
pub struct ResolvedStage {
    pub name: String,
    pub kind: &'static str,
    pub params: Params,
    /// Role -> product (with `@prev` for previous-frame inputs).
    pub inputs: BTreeMap<String, String>,
    /// Role -> product.
    pub outputs: BTreeMap<String, String>,
    /// Line of the stage in its file.
    pub line: usize,
    /// The stage runs on every `every`-th frame and lends its last products to the
    /// frames between (see [`super::every`]); 1 = every frame.
    pub every: u32,
    /// The stage runs `lag` frames behind on its own thread (see [`super::lag`]); 0 =
    /// in step.
    pub lag: u32,
}

/// A feedback edge: `producer`'s `product` of frame t-1 goes to `consumer` at frame t.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Feedback {
    pub producer: usize,
    pub consumer: usize,
    pub product: String,
}
