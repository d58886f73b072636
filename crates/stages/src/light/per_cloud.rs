//! A product derived from the environment-sample cloud, rebuilt only when the cloud
//! changes: what `light.impostor` and `light.voxels` keep between frames.

use crate::kind::FrameProducts;
use relume_graph::{Frame, StageError};
use relume_scene::light::EnvCloud;
use std::sync::Arc;

/// The last cloud a stage saw (none: the frame had no cloud, as the first frame under
/// `cloud@prev`) and what it built from it.
pub(crate) struct PerCloud<T> {
    last: Option<(Option<Arc<EnvCloud>>, Arc<T>)>,
}

impl<T> PerCloud<T> {
    pub(crate) fn new() -> PerCloud<T> {
        PerCloud { last: None }
    }

    /// Drops what was built, so that the next [`PerCloud::get`] builds again (what it
    /// was built from besides the cloud changed).
    pub(crate) fn forget(&mut self) {
        self.last = None;
    }

    /// What `build` makes of the frame's product `cloud` (`None` when the frame has
    /// none), built again only when the cloud is another `Arc` than last time.
    pub(crate) fn get(
        &mut self,
        frame: &Frame,
        cloud: &str,
        build: impl FnOnce(Option<&EnvCloud>) -> Result<T, StageError>,
    ) -> Result<Arc<T>, StageError> {
        let current = match frame.cloud(cloud) {
            Ok(c) => Some(Arc::clone(c)),
            Err(StageError::MissingInput(_)) => None,
            Err(e) => return Err(e),
        };
        let same = match (&self.last, &current) {
            (Some((Some(a), _)), Some(b)) => Arc::ptr_eq(a, b),
            (Some((None, _)), None) => true,
            _ => false,
        };
        if !same {
            let built = Arc::new(build(current.as_deref())?);
            self.last = Some((current, built));
        }
        Ok(Arc::clone(&self.last.as_ref().expect("set above").1))
    }
}
