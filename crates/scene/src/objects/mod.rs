//! Virtual objects: triangle meshes with materials, placed in world space, and ray
//! queries against them through a BVH (the design guide's "Virtual objects"; paper 001
//! Sec. 3 for the diffuse albedo k_V and Phong exponent of the differential composite).
//!
//! # `[[object]]` in pipeline configs
//!
//! A pipeline file lists its virtual objects as top-level `[[object]]` tables; they are
//! built into one [`VirtualScene`] when the pipeline loads (`Pipeline.objects`, handed
//! to every stage as `BuildContext.objects`). A pipeline without objects has an empty
//! scene. World coordinates are those of the recording's poses, in metres; in the
//! synthetic room y is up, the floor is y = 0 and (0, 0.3, 0) is free.
//!
//! ```toml
//! [[object]]
//! name = "torus"                 # optional, names it in messages; default: the shape
//! shape = "torus"                # sphere | box | torus | quad | mesh
//! major_radius = 0.25            # shape keys, see below
//! minor_radius = 0.08
//! translation = [0.0, 0.08, 0.0] # world position of the shape's origin; default 0
//! rotation_deg = [0.0, 0.0, 0.0] # about world x, then y, then z: R = Rz Ry Rx
//! scale = 1.0                    # uniform
//! albedo = [0.8, 0.3, 0.2]       # diffuse k_V in [0, 1]; default 0.7 gray
//! exponent = 0                   # Phong exponent; 0 = diffuse (default)
//! ```
//!
//! A point p of the shape lands at `translation + R (scale p)`, in world coordinates,
//! or in an anchor's frame on a real surface of the recording ([`anchor`]):
//!
//! ```toml
//! anchor = "floor"               # on the floor found in frames `frame`..`frame`+5
//! at_pixel = [410, 300]          # where this color pixel of frame `frame` sees it
//! frame = 0                      # (at_pixel alone: the surface seen at that pixel)
//! ```
//!
//! An object can move ([`motion`]): through keyframes at recording frames (linear
//! positions, slerp rotations, clamped outside the path), or at a constant velocity:
//!
//! ```toml
//! keyframes = [10, 40]           # frames of the recording
//! keyframe_translation = [[-0.5, 0.09, 0.1], [0.5, 0.09, 0.1]]  # in place of translation
//! keyframe_rotation_deg = [[0, 0, 0], [0, 90, 0]]                # in place of rotation_deg
//! # or: velocity = [0.0, 0.0, 0.01]  # metres per frame from `translation` at frame 0
//! ```
//!
//! [`MovingScene`] places such objects at each frame.
//!
//! Shapes are centred on their origin with y up (meshes keep the file's origin):
//!
//! | shape | keys (defaults) | triangles |
//! |---|---|---|
//! | `sphere` | `radius` (0.25), `segments` (48; half as many rings) | 2 s (s/2 - 1): 2208 |
//! | `box` | `size` = [x, y, z] ([0.3, 0.3, 0.3]), flat normals | 12 |
//! | `torus` | `major_radius` (0.25), `minor_radius` (0.08), `segments` (64), `minor_segments` (32); ring in the xz plane, shadows itself | 2 s m: 4096 |
//! | `quad` | `size` = [x, z] ([1, 1]); in the xz plane facing +y | 2 |
//! | `mesh` | `path` to a Wavefront OBJ file, relative to the pipeline file's directory; file normals when every corner has one, else area-weighted smooth normals; MTL files are ignored | as in the file |
//!
//! Every key is checked when the pipeline loads: unknown keys (with the closest
//! spelling), unknown shapes, wrong types, values out of range, a torus whose tube is
//! wider than its ring, duplicate names, and mesh files that cannot be read or hold no
//! valid triangles are errors with the file, line and column of the offending value.
//! Anchored objects are placed when a run opens its recording
//! (`relume_stages::world::place_objects`); a pixel outside the images, a frame
//! past the end, no floor, or no surface at the pixel is an error at the key that asked.
//! `relume objects` lists every key. The same objects can be built in code with
//! [`ObjectSpec`] and [`VirtualScene::from_specs`].

pub mod anchor;
pub mod bvh;
mod error;
mod geometry;
pub mod mesh;
pub mod motion;
pub mod moving;
mod obj_lines;
pub mod shapes;
pub mod spec;
mod virtual_scene;
pub mod voxelize;

pub use bvh::Bvh;
pub use error::ObjectError;
pub use geometry::{Aabb, Material, Triangle, ray_triangle, ray_triangle_edges, tri_normal};
pub use mesh::{load_obj, parse_obj};
pub use motion::{Keyframe, Motion};
pub use moving::{MovingScene, ObjectMove};
pub use spec::{MAX_TRANSLATION, MAX_WORLD_COORDINATE, ObjectSpec, Shape};
pub use virtual_scene::{VirtualHit, VirtualScene};
