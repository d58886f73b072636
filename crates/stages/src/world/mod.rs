//! The pipeline's world of virtual objects: the `[[object]]` tables of a config checked
//! into [`ObjectSpec`](relume_scene::objects::ObjectSpec)s ([`config`]), objects anchored
//! to the recorded scene placed on its surfaces ([`place`]), and the [`ObjectWorld`] that
//! the runtime carries opaquely ([`relume_graph::World`]) and hands to every builder.
//!
//! - [`config`]: `[[object]]` tables checked key by key, errors at file, line and column.
//! - [`lights`](mod@lights): `[[light]]` tables checked the same way into spot lights.
//! - [`floor`]: the floor plane from the first frames' depth (math only).
//! - [`surface`]: the plane seen around one pixel (math only).
//! - [`views`]: the frames' depth, camera models and poses read from a recording.
//! - [`place`]: anchors resolved against a recording, with the report printed to users.
//! - [`follow`]: the objects a stage renders, posed at each frame when they move.
//!
//! This lives with the stages, not with the objects, because it needs the config's spans
//! (`relume_graph::config`) and the plane fit of [`crate::plane_fit`].

pub mod config;
pub mod floor;
pub mod follow;
pub mod lights;
pub mod place;
pub mod surface;
pub mod views;

pub use config::DeclaredObject;
pub use place::Placement;

use relume_graph::config::{ConfigError, SourceFile, WorldDecls};
use relume_graph::{BuildContext, Pipeline, World};
use relume_recording::Replay;
use relume_scene::light::SpotLight;
use relume_scene::objects::{MovingScene, ObjectError, VirtualScene};
use std::any::Any;
use std::sync::{Arc, LazyLock};

/// A pipeline's virtual objects: every `[[object]]` table as declared, and the scene of
/// those placed (in world coordinates, or anchored and placed on a recording).
#[derive(Clone, Debug, Default)]
pub struct ObjectWorld {
    /// Every `[[object]]` table as declared, in order.
    pub declared: Vec<DeclaredObject>,
    /// The objects in world space, BVH built; anchored objects join it when
    /// [`place_objects`] places them. Moving objects stand where they are at frame 0.
    pub scene: Arc<VirtualScene>,
    /// The same objects with their motions, when any of them moves
    /// ([`ObjectWorld::scene_at`] places them frame by frame).
    pub moving: Option<Arc<MovingScene>>,
    /// The `[[light]]` tables: the light sources besides the environment that the
    /// renderers which take them (`sample.dir`, `sample.path`, `sample.val`) light with, in file
    /// order.
    pub lights: Vec<SpotLight>,
}

impl ObjectWorld {
    /// The world of `scene`'s objects standing still (tests, benches and tools that
    /// build a scene by hand).
    pub fn still(scene: impl Into<Arc<VirtualScene>>) -> ObjectWorld {
        ObjectWorld {
            declared: Vec::new(),
            scene: scene.into(),
            moving: None,
            lights: Vec::new(),
        }
    }

    /// The world of `specs` (those in `scene`, in its order): `scene` alone when
    /// nothing moves.
    fn of(
        declared: Vec<DeclaredObject>,
        scene: VirtualScene,
        specs: &[relume_scene::objects::ObjectSpec],
    ) -> Result<ObjectWorld, ObjectError> {
        let moving = match specs.iter().any(|s| s.motion.is_some()) {
            true => Some(Arc::new(MovingScene::new(specs)?)),
            false => None,
        };
        Ok(ObjectWorld {
            declared,
            scene: Arc::new(scene),
            moving,
            lights: Vec::new(),
        })
    }

    /// True when an object moves.
    pub fn moves(&self) -> bool {
        self.moving.is_some()
    }

    /// The objects as they stand at recording frame `frame`: the scene itself when
    /// nothing moves (the same allocation), else the objects posed there with a BVH of
    /// their own.
    pub fn scene_at(&self, frame: u64) -> Result<Arc<VirtualScene>, ObjectError> {
        match &self.moving {
            None => Ok(Arc::clone(&self.scene)),
            Some(moving) => moving.at(frame).map(Arc::new),
        }
    }

    /// Every object between `earlier` and `frame` (see
    /// [`MovingScene::moves_between`]); empty when nothing moves.
    pub fn moves_between(
        &self,
        earlier: u64,
        frame: u64,
    ) -> Result<Vec<relume_scene::objects::ObjectMove>, ObjectError> {
        match &self.moving {
            None => Ok(Vec::new()),
            Some(moving) => moving.moves_between(earlier, frame),
        }
    }

    /// True when every object stands at `frame` as it stood at `earlier`.
    pub fn same_at(&self, earlier: u64, frame: u64) -> bool {
        self.moving
            .as_ref()
            .is_none_or(|moving| moving.same_at(earlier, frame))
    }

    /// The names of the objects anchored to the scene that have not been placed yet.
    pub fn unplaced(&self) -> Vec<String> {
        self.declared
            .iter()
            .filter(|d| d.spec.placement_frame().is_err())
            .map(|d| d.spec.name.clone())
            .collect()
    }
}

impl World for ObjectWorld {
    fn waiting(&self) -> Vec<String> {
        self.unplaced()
            .into_iter()
            .map(|object| {
                format!(
                    "object `{object}` is anchored to the scene and has not been placed: relume_stages::world::place_objects places it on the recording"
                )
            })
            .collect()
    }

    fn same_as(&self, other: &dyn World) -> bool {
        match (other as &dyn Any).downcast_ref::<ObjectWorld>() {
            Some(o) => {
                (Arc::ptr_eq(&self.scene, &o.scene) || self.scene == o.scene)
                    && self.moving == o.moving
                    && self.lights == o.lights
            }
            None => false,
        }
    }
}

/// The [`relume_graph::WorldResolver`] of the built-in registry.
pub fn resolve(decls: &WorldDecls, src: &SourceFile) -> Result<Arc<dyn World>, ConfigError> {
    let lights = lights::resolve(&decls.lights, src)?;
    let objects = config::resolve(&decls.objects, src)?;
    let specs: Vec<_> = objects
        .declared
        .iter()
        .filter(|d| d.sites.is_none())
        .map(|d| d.spec.clone())
        .collect();
    let world = ObjectWorld::of(objects.declared, objects.world_scene, &specs)
        .map_err(|e| ConfigError::whole_file(&src.name, e.to_string()))?;
    Ok(Arc::new(ObjectWorld { lights, ..world }))
}

/// The world of `pipeline` as objects (an empty one for a world of another kind).
pub fn object_world(world: &Arc<dyn World>) -> &ObjectWorld {
    static EMPTY: LazyLock<ObjectWorld> = LazyLock::new(ObjectWorld::default);
    (world.as_ref() as &dyn Any)
        .downcast_ref::<ObjectWorld>()
        .unwrap_or(&EMPTY)
}

/// The virtual objects a stage's builder receives, in world space.
pub fn objects<'a>(ctx: &BuildContext<'a>) -> &'a Arc<VirtualScene> {
    &object_world(ctx.world).scene
}

/// The light sources a stage's builder receives (`[[light]]`), in world space.
pub fn lights<'a>(ctx: &BuildContext<'a>) -> &'a [SpotLight] {
    &object_world(ctx.world).lights
}

/// Places the objects of `pipeline` anchored to the scene (`anchor = "floor"`,
/// `at_pixel`) on `replay`'s surfaces and rebuilds its world with every object; says
/// where each was placed. Nothing to do (and an empty list) when none is anchored.
/// Errors stand at the anchor's keys in the config.
///
/// `first_frame` is where the run starts. On a recording without poses, a pipeline that
/// tracks them (`pose.track`) has the camera of that frame as its world (the tracker
/// starts there at the identity): anchors are found on that frame.
pub fn place_objects(
    pipeline: &mut Pipeline,
    replay: &Replay,
    first_frame: usize,
) -> Result<Vec<Placement>, ConfigError> {
    let world = object_world(&pipeline.world);
    if world.declared.iter().all(|d| d.sites.is_none()) {
        return Ok(Vec::new());
    }
    let tracks = pipeline
        .stages
        .iter()
        .any(|s| s.kind == crate::track::INFO.kind);
    let tracked_from = (replay.stats.frames_with_pose == 0 && tracks).then_some(first_frame);
    let mut declared = world.declared.clone();
    let mut placements = place::place_objects(&mut declared, replay, tracked_from)?;
    let scene = place::scene_of(&declared, &pipeline.file)?;
    for placed in &mut placements {
        // Object k has material k (VirtualScene::from_specs).
        let k = declared.iter().position(|d| d.spec.name == placed.object);
        let corners = scene
            .triangles
            .iter()
            .filter(|t| Some(t.material as usize) == k)
            .flat_map(|t| t.vertices);
        placed.bounds = corners.fold(None, |b, p| match b {
            None => Some((p, p)),
            Some((lo, hi)) => Some((p.min(lo), p.max(hi))),
        });
    }
    let specs: Vec<_> = declared.iter().map(|d| d.spec.clone()).collect();
    let world = ObjectWorld::of(declared, scene, &specs)
        .map_err(|e| ConfigError::whole_file(&pipeline.file, e.to_string()))?;
    let lights = object_world(&pipeline.world).lights.clone();
    pipeline.world = Arc::new(ObjectWorld { lights, ..world });
    Ok(placements)
}

/// The world of `scene` alone, as builders receive it (tests and benches that build a
/// stage by hand).
pub fn world_of(scene: impl Into<Arc<VirtualScene>>) -> Arc<dyn World> {
    Arc::new(ObjectWorld::still(scene))
}

/// A pipeline's objects read through its world, as the command line, eval and tests
/// use them.
pub trait PipelineObjects {
    /// The objects placed so far, in world space.
    fn objects(&self) -> &Arc<VirtualScene>;
    /// Every `[[object]]` table as declared, in order.
    fn declared_objects(&self) -> &[DeclaredObject];
    /// The names of the objects anchored to the scene that have not been placed yet.
    fn unplaced_objects(&self) -> Vec<String>;
    /// [`place_objects`] on this pipeline, for a run from frame 0.
    fn place_objects(&mut self, replay: &Replay) -> Result<Vec<Placement>, ConfigError> {
        self.place_objects_from(replay, 0)
    }
    /// [`place_objects`] on this pipeline, for a run from `first_frame`.
    fn place_objects_from(
        &mut self,
        replay: &Replay,
        first_frame: usize,
    ) -> Result<Vec<Placement>, ConfigError>;
}

impl PipelineObjects for Pipeline {
    fn objects(&self) -> &Arc<VirtualScene> {
        &object_world(&self.world).scene
    }

    fn declared_objects(&self) -> &[DeclaredObject] {
        &object_world(&self.world).declared
    }

    fn unplaced_objects(&self) -> Vec<String> {
        object_world(&self.world).unplaced()
    }

    fn place_objects_from(
        &mut self,
        replay: &Replay,
        first_frame: usize,
    ) -> Result<Vec<Placement>, ConfigError> {
        place_objects(self, replay, first_frame)
    }
}
