//! The registry of stage kinds: configs name a kind, the registry knows its parameters,
//! ports and builder.

use super::stage::StageInfo;

/// All stage kinds a pipeline may use.
#[derive(Clone, Default)]
pub struct Registry {
    kinds: Vec<StageInfo>,
}

impl Registry {
    /// An empty registry.
    pub fn empty() -> Registry {
        Registry::default()
    }

    /// The built-in stage kinds.
    pub fn builtin() -> Registry {
        let mut r = Registry::empty();
        for info in crate::stages::builtin() {
            r.register(info);
        }
        r
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
