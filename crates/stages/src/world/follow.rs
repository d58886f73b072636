//! The objects as a stage sees them frame by frame ([`FollowedObjects`]): the pipeline's
//! scene when nothing moves, else the objects posed at each frame, rebuilt only when an
//! object moved since the frame before, so that what a stage derives from them (a solid
//! volume, points spread on them, a light centre) is rebuilt with them and not otherwise.

use super::{ObjectWorld, object_world};
use relume_graph::{BuildContext, StageError};
use relume_scene::objects::VirtualScene;
use std::sync::Arc;

/// The objects of a pipeline for a stage that renders or centres on them.
#[derive(Clone, Debug)]
pub struct FollowedObjects {
    world: ObjectWorld,
    /// The frame `scene` stands at (`None` before the first frame).
    frame: Option<u64>,
    scene: Arc<VirtualScene>,
}

impl FollowedObjects {
    /// The objects of the stage being built; until the first frame, as at frame 0.
    pub fn new(ctx: &BuildContext) -> FollowedObjects {
        FollowedObjects::of(object_world(ctx.world).clone())
    }

    /// The objects of `world`.
    pub fn of(world: ObjectWorld) -> FollowedObjects {
        FollowedObjects {
            scene: Arc::clone(&world.scene),
            world,
            frame: None,
        }
    }

    /// True when an object moves.
    pub fn moves(&self) -> bool {
        self.world.moves()
    }

    /// The objects before the first frame (as at frame 0).
    pub fn scene(&self) -> &Arc<VirtualScene> {
        &self.scene
    }

    /// The objects at recording frame `frame`, and whether they stand otherwise than at
    /// the frame asked before (never for a world where nothing moves; on the first
    /// call, whether they differ from frame 0's). An object whose path leaves the world
    /// is an error naming it and the frame.
    pub fn at(&mut self, frame: u64) -> Result<(&Arc<VirtualScene>, bool), StageError> {
        let before = self.frame.unwrap_or(0);
        let moved = !self.world.same_at(before, frame);
        if moved {
            self.scene = self
                .world
                .scene_at(frame)
                .map_err(|e| StageError::Failed(e.to_string()))?;
        }
        self.frame = Some(frame);
        Ok((&self.scene, moved))
    }
}
