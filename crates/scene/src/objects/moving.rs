//! A pipeline's objects as they are at each frame ([`MovingScene`]): the shapes read
//! once in their own coordinates, placed and put under a fresh BVH at the frame asked.
//!
//! The objects are rigid, so a frame's scene is the same local triangles under that
//! frame's poses ([`super::motion`]); the BVH is rebuilt rather than refitted, which
//! costs about a millisecond for the default objects' 6,300 triangles and keeps the
//! tree exactly what [`VirtualScene::from_specs`] builds for the same placement.

use super::anchor::AnchorFrame;
use super::error::ObjectError;
use super::geometry::{Aabb, Triangle};
use super::spec::ObjectSpec;
use super::virtual_scene::VirtualScene;
use glam::Affine3A;

/// One object between two frames (see [`MovingScene::moves_between`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectMove {
    /// Its bounding box at the later frame.
    pub bounds: Aabb,
    /// Whether it stands otherwise than at the earlier frame.
    pub moved: bool,
    /// A point riding on it at the later frame to where it was at the earlier one
    /// (the identity for an object that did not move).
    pub to_earlier: Affine3A,
}

/// One object: its spec, the frame it is placed in, and its shape's own triangles.
#[derive(Clone, Debug, PartialEq)]
struct PlacedShape {
    spec: ObjectSpec,
    frame: AnchorFrame,
    local: Vec<Triangle>,
}

/// The objects of a scene with their motions; [`MovingScene::at`] places them at a frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MovingScene {
    objects: Vec<PlacedShape>,
}

impl MovingScene {
    /// The objects of `specs` (object k gets material k, as in
    /// [`VirtualScene::from_specs`]); each must be placed (world objects are).
    pub fn new(specs: &[ObjectSpec]) -> Result<MovingScene, ObjectError> {
        let objects = specs
            .iter()
            .map(|spec| {
                Ok(PlacedShape {
                    frame: spec.placement_frame()?,
                    local: spec.local()?,
                    spec: spec.clone(),
                })
            })
            .collect::<Result<_, ObjectError>>()?;
        Ok(MovingScene { objects })
    }

    /// True when any object has a motion.
    pub fn moves(&self) -> bool {
        self.objects.iter().any(|o| o.spec.motion.is_some())
    }

    /// The scene at recording frame `frame`, BVH built; the same triangles, bit for bit,
    /// as [`VirtualScene::from_specs`] of the objects posed there.
    pub fn at(&self, frame: u64) -> Result<VirtualScene, ObjectError> {
        let mut triangles = Vec::new();
        let mut materials = Vec::with_capacity(self.objects.len());
        for (k, o) in self.objects.iter().enumerate() {
            triangles.extend(o.spec.place(&o.local, &o.frame, frame as f64, k as u32)?);
            materials.push(o.spec.material);
        }
        Ok(VirtualScene::new(triangles, materials))
    }

    /// Every object between `earlier` and `frame`: its bounding box at `frame`, whether
    /// it stands otherwise than at `earlier`, and the rigid map that takes a point
    /// riding on it at `frame` to where that point was at `earlier`.
    pub fn moves_between(&self, earlier: u64, frame: u64) -> Result<Vec<ObjectMove>, ObjectError> {
        let mut out = Vec::with_capacity(self.objects.len());
        for (k, o) in self.objects.iter().enumerate() {
            let placement = |at: u64| o.spec.placement_at(at as f64);
            let mut bounds = Aabb::EMPTY;
            let placed = o.spec.place(&o.local, &o.frame, frame as f64, k as u32)?;
            placed
                .iter()
                .flat_map(|t| t.vertices)
                .for_each(|v| bounds.grow(v));
            let moved = o.spec.motion.is_some() && placement(earlier) != placement(frame);
            let to_world = |at: u64| {
                let (translation, linear) = placement(at);
                Affine3A::from_mat3_translation(
                    o.frame.axes * linear,
                    o.frame.origin + o.frame.axes * translation,
                )
            };
            let to_earlier = match moved {
                true => to_world(earlier) * to_world(frame).inverse(),
                false => Affine3A::IDENTITY,
            };
            out.push(ObjectMove {
                bounds,
                moved,
                to_earlier,
            });
        }
        Ok(out)
    }

    /// True when every object stands exactly as it did at `earlier` at `frame` (nothing
    /// moved between the two, so whatever was computed of the objects then holds).
    pub fn same_at(&self, earlier: u64, frame: u64) -> bool {
        self.objects.iter().all(|o| {
            o.spec.motion.is_none()
                || o.spec.placement_at(earlier as f64) == o.spec.placement_at(frame as f64)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::motion::{Keyframe, Motion};
    use crate::objects::spec::Shape;
    use glam::Vec3;

    fn sliding_box() -> ObjectSpec {
        let mut b = ObjectSpec::new("b", Shape::DEFAULT_BOX);
        b.motion = Some(Motion::Keyframes(vec![
            Keyframe {
                frame: 10.0,
                translation: Vec3::new(-0.5, 0.15, 0.0),
                rotation_deg: Vec3::ZERO,
            },
            Keyframe {
                frame: 20.0,
                translation: Vec3::new(0.5, 0.15, 0.0),
                rotation_deg: Vec3::new(0.0, 90.0, 0.0),
            },
        ]));
        b
    }

    #[test]
    fn a_frames_scene_is_the_objects_posed_there() {
        let ball = ObjectSpec::new("ball", Shape::DEFAULT_SPHERE);
        let specs = [ball.clone(), sliding_box()];
        let moving = MovingScene::new(&specs).unwrap();
        assert!(moving.moves());
        let at_15 = moving.at(15).unwrap();
        let mut bounds = crate::objects::Aabb::EMPTY;
        let boxed = at_15.triangles.iter().filter(|t| t.material == 1);
        boxed.flat_map(|t| t.vertices).for_each(|v| bounds.grow(v));
        // The box (0.3 m) halfway along, at x = 0, turned by 45 degrees about y: its
        // corners reach 0.15 sqrt(2) along x and z.
        let half = 0.15 * 2f32.sqrt();
        assert!(
            bounds.max.abs_diff_eq(Vec3::new(half, 0.3, half), 1e-5),
            "{bounds:?}"
        );
        // The still ball is the same triangles as a still scene's.
        let still = VirtualScene::from_specs(&[ball]).unwrap();
        assert_eq!(
            at_15.triangles[..still.triangles.len()],
            still.triangles[..]
        );
        // Before the path the box is at its first keyframe; the scene at frame 0 is
        // the one from_specs builds (the static placement of a moving object).
        assert_eq!(
            moving.at(0).unwrap(),
            VirtualScene::from_specs(&specs).unwrap()
        );
        assert!(moving.same_at(0, 10) && moving.same_at(20, 99));
        assert!(
            moving
                .moves_between(0, 10)
                .unwrap()
                .iter()
                .all(|m| !m.moved)
        );
        let moves = moving.moves_between(14, 15).unwrap();
        assert_eq!(moves.len(), 2);
        assert!(!moves[0].moved && moves[0].to_earlier == Affine3A::IDENTITY);
        assert!(moves[1].moved && moves[1].bounds == bounds);
        // A point riding on the box at frame 15 (its top corner) was at frame 14
        // where the box's placement then puts that corner.
        let at = |frame: u64| {
            let scene = moving.at(frame).unwrap();
            scene
                .triangles
                .iter()
                .find(|t| t.material == 1)
                .unwrap()
                .vertices[0]
        };
        let back = moves[1].to_earlier.transform_point3(at(15));
        assert!(back.abs_diff_eq(at(14), 1e-5), "{back} vs {}", at(14));
        assert!(!moving.same_at(10, 11) && !moving.same_at(19, 20));
    }

    #[test]
    fn a_still_scene_does_not_move() {
        let specs = [ObjectSpec::new("ball", Shape::DEFAULT_SPHERE)];
        let moving = MovingScene::new(&specs).unwrap();
        assert!(!moving.moves() && moving.same_at(0, 1000));
        assert_eq!(
            moving.at(7).unwrap(),
            VirtualScene::from_specs(&specs).unwrap()
        );
    }

    #[test]
    fn a_path_out_of_the_world_is_an_error_at_its_frame() {
        let mut far = ObjectSpec::new("far", Shape::DEFAULT_BOX);
        far.motion = Some(Motion::Velocity {
            start: Vec3::ZERO,
            per_frame: Vec3::new(1e3, 0.0, 0.0),
            rotation_deg: Vec3::ZERO,
        });
        let moving = MovingScene::new(&[far]).unwrap();
        assert!(moving.at(99).is_ok());
        let e = moving.at(101).unwrap_err().to_string();
        assert!(
            e.starts_with("object `far`: a vertex lies at [101000.15"),
            "{e}"
        );
        assert!(e.contains(" m at frame 101, more than 1e5 m"), "{e}");
    }
}
