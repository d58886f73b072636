//! The registry of stage kinds: configs name a kind, the registry knows its parameters,
//! ports and builder.

use super::config::{ConfigError, SourceFile, WorldDecls};
use super::stage::StageInfo;
use super::world::{EmptyWorld, World, WorldResolver};
use std::sync::Arc;

/// All stage kinds a pipeline may use, and how its `[[object]]` tables become its world.
/// `relume_stages::registry()` is the built-in one.
#[derive(Clone, Default)]
pub struct Registry {
    kinds: Vec<StageInfo>,
    world: Option<WorldResolver>,
}

impl Registry {
    /// An empty registry.
    pub fn empty() -> Registry {
        Registry::default()
    }

    /// Sets how configs' `[[object]]` and `[[light]]` tables are checked and resolved.
    pub fn set_world_resolver(&mut self, resolver: WorldResolver) {
        self.world = Some(resolver);
    }

    /// The world of a config's `[[object]]` and `[[light]]` tables: the resolver's, or
    /// [`EmptyWorld`] when there are no tables; tables without a resolver are an error
    /// at the first one.
    pub fn resolve_world(
        &self,
        decls: &WorldDecls,
        src: &SourceFile,
    ) -> Result<Arc<dyn World>, ConfigError> {
        match (self.world, decls.first()) {
            (Some(resolve), _) => resolve(decls, src),
            (None, None) => Ok(Arc::new(EmptyWorld)),
            (None, Some(first)) => Err(src.error(
                first.span.clone(),
                "this registry has no resolver for `[[object]]` or `[[light]]` tables",
                Some("build the registry with relume_stages::registry()".to_string()),
            )),
        }
    }

    /// Adds (or replaces) a kind.
    pub fn register(&mut self, info: StageInfo) {
        self.kinds.retain(|k| k.kind != info.kind);
        self.kinds.push(info);
        self.kinds.sort_by_key(|k| k.kind);
    }

    pub fn get(&self, kind: &str) -> Option<&StageInfo> {
        self.kinds.iter().find(|k| k.kind == kind)
    }

    /// Every kind, sorted by name.
    pub fn kinds(&self) -> &[StageInfo] {
        &self.kinds
    }
}
