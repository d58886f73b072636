//! Placement and material of a virtual object ([`ObjectSpec`]): its world triangles, from
//! which [`VirtualScene::from_specs`](super::VirtualScene::from_specs) builds a scene.
//!
//! An object is a [`Shape`] in its own coordinates, then scaled (uniformly), rotated
//! by R = Rz Ry Rx (about the world x axis first, then y, then z; angles in degrees) and
//! translated: p_world = translation + R (scale p). Normals go through the inverse
//! transpose of the linear part and are renormalized.

use super::anchor::{Anchor, AnchorFrame};
use super::geometry::{Material, Triangle};
use super::motion::Motion;
use super::{mesh, shapes};
use glam::{Mat3, Vec2, Vec3};
use std::path::PathBuf;

pub use super::error::ObjectError;

/// What a virtual object is made of, in its own coordinates (y up, centred on the origin
/// except meshes, which keep the file's origin).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// See [`shapes::sphere`].
    Sphere { radius: f32, segments: u32 },
    /// See [`shapes::cuboid`]; `size` is the edge lengths along x, y, z.
    Box { size: Vec3 },
    /// See [`shapes::torus`].
    Torus {
        major_radius: f32,
        minor_radius: f32,
        segments: u32,
        minor_segments: u32,
    },
    /// See [`shapes::quad`]; `size` is the extents along x and z.
    Quad { size: Vec2 },
    /// A Wavefront OBJ file, see [`mesh::load_obj`].
    Mesh { path: PathBuf },
}

impl Shape {
    /// The names of the shapes as written in configs.
    pub const NAMES: &'static [&'static str] = &["sphere", "box", "torus", "quad", "mesh"];

    /// A sphere of radius 0.25 m, 48 segments (2208 triangles).
    pub const DEFAULT_SPHERE: Shape = Shape::Sphere {
        radius: 0.25,
        segments: 48,
    };
    /// A 0.3 m cube.
    pub const DEFAULT_BOX: Shape = Shape::Box {
        size: Vec3::splat(0.3),
    };
    /// A torus of ring radius 0.25 m and tube radius 0.08 m, 64 x 32 (4096 triangles).
    pub const DEFAULT_TORUS: Shape = Shape::Torus {
        major_radius: 0.25,
        minor_radius: 0.08,
        segments: 64,
        minor_segments: 32,
    };
    /// A 1 m square.
    pub const DEFAULT_QUAD: Shape = Shape::Quad {
        size: Vec2::splat(1.0),
    };

    /// The name as written in configs.
    pub fn name(&self) -> &'static str {
        match self {
            Shape::Sphere { .. } => "sphere",
            Shape::Box { .. } => "box",
            Shape::Torus { .. } => "torus",
            Shape::Quad { .. } => "quad",
            Shape::Mesh { .. } => "mesh",
        }
    }

    /// The triangles in the shape's own coordinates (material 0), after checking its
    /// dimensions; meshes are read from their file.
    pub fn local_triangles(&self) -> Result<Vec<Triangle>, String> {
        let positive = |what: &str, x: f32| {
            if x > 0.0 && x.is_finite() {
                Ok(())
            } else {
                Err(format!("{what} must be positive and finite, got {x}"))
            }
        };
        match self {
            Shape::Sphere { radius, segments } => {
                positive("radius", *radius)?;
                Ok(shapes::sphere(*radius, *segments))
            }
            Shape::Box { size } => {
                size.to_array()
                    .iter()
                    .try_for_each(|&s| positive("size", s))?;
                Ok(shapes::cuboid(*size))
            }
            Shape::Torus {
                major_radius,
                minor_radius,
                segments,
                minor_segments,
            } => {
                positive("major_radius", *major_radius)?;
                positive("minor_radius", *minor_radius)?;
                if minor_radius >= major_radius {
                    return Err(format!(
                        "minor_radius ({minor_radius}) must be smaller than major_radius ({major_radius})"
                    ));
                }
                Ok(shapes::torus(
                    *major_radius,
                    *minor_radius,
                    *segments,
                    *minor_segments,
                ))
            }
            Shape::Quad { size } => {
                size.to_array()
                    .iter()
                    .try_for_each(|&s| positive("size", s))?;
                Ok(shapes::quad(*size))
            }
            Shape::Mesh { path } => mesh::load_obj(path).map_err(|e| e.to_string()),
        }
    }
}

/// A virtual object: shape, placement in the world and material.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectSpec {
    /// Names the object in messages.
    pub name: String,
    pub shape: Shape,
    /// World position of the shape's origin, metres.
    pub translation: Vec3,
    /// Rotation angles about the world x, y and z axes in degrees, applied x first:
    /// R = Rz Ry Rx.
    pub rotation_deg: Vec3,
    /// Uniform scale (positive).
    pub scale: f32,
    /// Diffuse albedo k_V and Phong exponent (paper 001 Sec. 3).
    pub material: Material,
    /// What `translation` and `rotation_deg` are measured from: the world, or a frame on
    /// a real surface found in the recording (see [`super::anchor`]).
    pub anchor: Anchor,
    /// The anchor's frame once placed against a recording (`relume_stages::world::place_objects`);
    /// `None` for world objects and for anchored ones not placed yet.
    pub anchor_frame: Option<AnchorFrame>,
    /// How the object moves (in the placement frame), replacing `translation` and
    /// `rotation_deg` frame by frame; `None` for an object that stays put.
    pub motion: Option<Motion>,
}

impl ObjectSpec {
    /// An object of `shape` at the origin, unrotated, unscaled, diffuse 0.7 gray.
    pub fn new(name: impl Into<String>, shape: Shape) -> ObjectSpec {
        ObjectSpec {
            name: name.into(),
            shape,
            translation: Vec3::ZERO,
            rotation_deg: Vec3::ZERO,
            scale: 1.0,
            material: Material::DIFFUSE_GRAY,
            anchor: Anchor::World,
            anchor_frame: None,
            motion: None,
        }
    }

    /// The frame the placement is measured in: the world's, or the anchor's once
    /// placed; an error for an anchored object that has not been placed.
    pub fn placement_frame(&self) -> Result<AnchorFrame, ObjectError> {
        match (self.anchor, self.anchor_frame) {
            (Anchor::World, _) => Ok(AnchorFrame::WORLD),
            (_, Some(frame)) => Ok(frame),
            (anchor, None) => Err(ObjectError::InvalidSpec {
                object: self.name.clone(),
                message: format!(
                    "it is anchored to the {} of a recording and has not been placed on one yet",
                    match anchor {
                        Anchor::Floor { .. } => "floor",
                        _ => "surface at a pixel",
                    }
                ),
            }),
        }
    }

    /// The linear part of the placement: R (scale I), R = Rz Ry Rx.
    pub fn linear(&self) -> Mat3 {
        let r = self.rotation_deg * (std::f32::consts::PI / 180.0);
        Mat3::from_rotation_z(r.z)
            * Mat3::from_rotation_y(r.y)
            * Mat3::from_rotation_x(r.x)
            * Mat3::from_diagonal(Vec3::splat(self.scale))
    }

    /// The object's triangles in world space with material index `material`: its
    /// placement applied in [`ObjectSpec::placement_frame`] (at frame 0 for a moving
    /// object).
    pub fn world_triangles(&self, material: u32) -> Result<Vec<Triangle>, ObjectError> {
        self.triangles_in(&self.placement_frame()?, material)
    }

    /// The object's triangles with its placement applied in `frame`:
    /// p = frame.origin + frame.axes (translation + R (scale p_local)); a moving object
    /// as it is at frame 0.
    pub fn triangles_in(
        &self,
        frame: &AnchorFrame,
        material: u32,
    ) -> Result<Vec<Triangle>, ObjectError> {
        self.place(&self.local()?, frame, 0.0, material)
    }

    /// The shape's triangles in its own coordinates, after checking the placement and
    /// material; meshes are read from their file.
    pub fn local(&self) -> Result<Vec<Triangle>, ObjectError> {
        self.check().map_err(|m| self.invalid(m))?;
        match &self.shape {
            // Mesh errors keep their own variant (they name the file).
            Shape::Mesh { path } => Ok(mesh::load_obj(path)?),
            shape => shape.local_triangles().map_err(|m| self.invalid(m)),
        }
    }

    /// Translation and linear part R (scale I) at recording frame `at`: the motion's
    /// pose there, or the fixed placement.
    pub fn placement_at(&self, at: f64) -> (Vec3, Mat3) {
        match &self.motion {
            None => (self.translation, self.linear()),
            Some(motion) => (
                motion.pose_at(at).translation,
                motion.linear_at(at, self.scale),
            ),
        }
    }

    /// `local` (from [`ObjectSpec::local`]) placed as at recording frame `at` in
    /// `frame`, with material index `material`; an error when a vertex lands beyond
    /// [`MAX_WORLD_COORDINATE`].
    pub fn place(
        &self,
        local: &[Triangle],
        frame: &AnchorFrame,
        at: f64,
        material: u32,
    ) -> Result<Vec<Triangle>, ObjectError> {
        let (translation, linear) = self.placement_at(at);
        let linear = frame.axes * linear;
        let translation = frame.origin + frame.axes * translation;
        let normal_matrix = linear.inverse().transpose();
        let world: Vec<Triangle> = local
            .iter()
            .map(|t| Triangle {
                vertices: t.vertices.map(|v| linear * v + translation),
                normals: t.normals.map(|n| (normal_matrix * n).normalize_or_zero()),
                material,
            })
            .collect();
        let far = world
            .iter()
            .flat_map(|t| t.vertices)
            .find(|v| v.abs().max_element() > MAX_WORLD_COORDINATE);
        if let Some(v) = far {
            // Huge coordinates in exponent form, the others as they are.
            let shown = v.to_array().map(|c| {
                if c.abs() < 1e6 {
                    c.to_string()
                } else {
                    format!("{c:e}")
                }
            });
            let when = match self.motion {
                Some(_) => format!(" at frame {at}"),
                None => String::new(),
            };
            return Err(self.invalid(format!(
                "a vertex lies at [{}] m{when}, more than {MAX_WORLD_COORDINATE:e} m from the origin along an axis: check the mesh's units and `scale`",
                shown.join(", ")
            )));
        }
        Ok(world)
    }

    fn invalid(&self, message: String) -> ObjectError {
        ObjectError::InvalidSpec {
            object: self.name.clone(),
            message,
        }
    }

    /// Checks the placement and the material.
    fn check(&self) -> Result<(), String> {
        if !(self.scale > 0.0 && self.scale.is_finite()) {
            return Err(format!(
                "scale must be positive and finite, got {}",
                self.scale
            ));
        }
        if !self.translation.is_finite() || !self.rotation_deg.is_finite() {
            return Err("translation and rotation_deg must be finite".into());
        }
        if let Some(motion) = &self.motion {
            motion.check()?;
        }
        let m = &self.material;
        if !(m.albedo.cmpge(Vec3::ZERO).all() && m.albedo.cmple(Vec3::ONE).all()) {
            return Err(format!("albedo must lie in [0, 1], got {}", m.albedo));
        }
        if !(m.exponent >= 0.0 && m.exponent.is_finite()) {
            return Err(format!(
                "exponent must be 0 (diffuse) or positive, got {}",
                m.exponent
            ));
        }
        Ok(())
    }
}

/// The farthest an object's origin (its `translation`) may lie from the world origin
/// along an axis, in metres; also the bound of a light centre placed by hand.
pub const MAX_TRANSLATION: f32 = 1e4;

/// The farthest a vertex may lie from the world origin along an axis, in metres: ten
/// times [`MAX_TRANSLATION`]. Recordings are of rooms; a vertex beyond this is a mesh in
/// the wrong units or a stray value, and would stretch the objects' bounds, which centre
/// the light, far from the scene.
pub const MAX_WORLD_COORDINATE: f32 = 10.0 * MAX_TRANSLATION;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::geometry::{Aabb, tri_normal};

    #[test]
    fn placement_scales_rotates_then_translates() {
        let mut spec = ObjectSpec::new(
            "b",
            Shape::Box {
                size: Vec3::new(2.0, 1.0, 1.0),
            },
        );
        spec.scale = 0.5;
        spec.rotation_deg = Vec3::new(0.0, 90.0, 0.0);
        spec.translation = Vec3::new(1.0, 0.25, 0.0);
        let triangles = spec.world_triangles(0).unwrap();
        // Local x extent 2 scaled to 1, turned by Ry(90) onto z: x in [0.75, 1.25],
        // y in [0, 0.5], z in [-0.5, 0.5].
        let mut b = Aabb::EMPTY;
        triangles
            .iter()
            .flat_map(|t| t.vertices)
            .for_each(|v| b.grow(v));
        assert!(b.min.abs_diff_eq(Vec3::new(0.75, 0.0, -0.5), 1e-6), "{b:?}");
        assert!(b.max.abs_diff_eq(Vec3::new(1.25, 0.5, 0.5), 1e-6), "{b:?}");
        // Normals stay unit and perpendicular to their (flat) faces.
        for t in &triangles {
            let g = tri_normal(&t.vertices);
            assert!(g.abs_diff_eq(t.normals[0], 1e-6), "{g} vs {}", t.normals[0]);
        }
    }

    #[test]
    fn rotation_order_is_x_then_y_then_z() {
        let mut spec = ObjectSpec::new("q", Shape::DEFAULT_QUAD);
        spec.rotation_deg = Vec3::new(90.0, 90.0, 0.0);
        // Rx(90) turns the +y normal to +z; Ry(90) then turns +z to +x.
        let tris = spec.world_triangles(0).unwrap();
        assert!(
            tris[0].normals[0].abs_diff_eq(Vec3::X, 1e-6),
            "{}",
            tris[0].normals[0]
        );
        spec.rotation_deg = Vec3::new(0.0, 90.0, 90.0);
        // Ry(90) keeps +y; Rz(90) turns +y to -x.
        let tris = spec.world_triangles(0).unwrap();
        assert!(tris[0].normals[0].abs_diff_eq(Vec3::NEG_X, 1e-6));
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        let torus = Shape::Torus {
            major_radius: 0.1,
            minor_radius: 0.2,
            segments: 8,
            minor_segments: 8,
        };
        let e = ObjectSpec::new("t", torus).world_triangles(0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object `t`: minor_radius (0.2) must be smaller than major_radius (0.1)"
        );
        let mut s = ObjectSpec::new("s", Shape::DEFAULT_SPHERE);
        s.scale = 0.0;
        let e = s.world_triangles(0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object `s`: scale must be positive and finite, got 0"
        );
        s.scale = 1.0;
        s.material.albedo = Vec3::new(0.5, 1.5, 0.5);
        let e = s.world_triangles(0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object `s`: albedo must lie in [0, 1], got [0.5, 1.5, 0.5]"
        );
        let e = ObjectSpec::new(
            "m",
            Shape::Mesh {
                path: "/nonexistent/x.obj".into(),
            },
        )
        .world_triangles(0)
        .unwrap_err();
        assert!(matches!(e, ObjectError::MeshUnreadable { .. }), "{e}");
    }

    #[test]
    fn vertices_beyond_the_world_limit_are_an_error() {
        let mut far = ObjectSpec::new(
            "far",
            Shape::Box {
                size: Vec3::splat(30.0),
            },
        );
        far.scale = 1e4;
        let e = far.world_triangles(0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object `far`: a vertex lies at [150000, -150000, -150000] m, more than 1e5 m \
             from the origin along an axis: check the mesh's units and `scale`"
        );
        far.scale = 1e3;
        assert!(far.world_triangles(0).is_ok());
    }
}
