//! A pipeline's world as the runtime sees it: what the config's `[[object]]` and
//! `[[light]]` tables declare, resolved by the registry's [`WorldResolver`] into a value that the runtime
//! only compares (branches share a stage only when their worlds are the same) and hands
//! to every stage builder ([`super::BuildContext::world`]).
//!
//! The runtime knows no object type. The stages crate defines the world of virtual
//! objects (`relume_stages::world`), registers its resolver with the built-in registry,
//! and reads the world back in its builders by downcasting.

use super::config::{ConfigError, SourceFile, WorldDecls};
use std::any::Any;
use std::fmt::Debug;
use std::sync::Arc;

/// The world of a pipeline (see the module docs).
pub trait World: Any + Send + Sync + Debug {
    /// Why the pipeline cannot run yet, one message each (an object anchored to the
    /// recorded scene and not placed on a recording, say); empty when it can. Building
    /// fails with the first.
    fn waiting(&self) -> Vec<String>;

    /// True when every stage sees the same world in `self` and `other`, so that two
    /// pipelines may share their leading stages.
    fn same_as(&self, other: &dyn World) -> bool;
}

/// The world of a registry without a [`WorldResolver`]: nothing in it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EmptyWorld;

impl World for EmptyWorld {
    fn waiting(&self) -> Vec<String> {
        Vec::new()
    }

    fn same_as(&self, other: &dyn World) -> bool {
        (other as &dyn Any).is::<EmptyWorld>()
    }
}

/// Checks a config's `[[object]]` and `[[light]]` tables (each kind in file order) and
/// builds its world; errors stand at the offending key, as every config error does.
pub type WorldResolver = fn(&WorldDecls, &SourceFile) -> Result<Arc<dyn World>, ConfigError>;
