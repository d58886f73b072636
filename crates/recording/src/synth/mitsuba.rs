//! The synthetic room as a Mitsuba 3 scene: an independent check of [`super::render`].
//!
//! [`export_scene`] writes `scene.xml` (Mitsuba 3's XML, `version="3.0.0"`) with the
//! room's six surfaces and the visible faces of its blocks as `rectangle` shapes whose
//! albedo is baked into float EXR textures, the ball as a `sphere`, the two emitters as
//! one-sided `area` lights, the lamp when it is on as a `spot` emitter, virtual objects as PLY meshes, and one `perspective` sensor
//! per [`View`] that reproduces relume's pinhole. `scripts/mitsuba_render.py` renders it
//! (variant `scalar_rgb`, `path` integrator) and writes one PFM of linear RGB radiance
//! per view, which [`read_radiance`] reads back.
//!
//! Where the Mitsuba scene departs from relume's renderer:
//! - albedo comes from textures baked as texel means ([`bake_face`], looked up without
//!   interpolation, see [`export_scene`]) instead of the procedural functions at each
//!   hit, so pattern edges are blurred within a texel;
//! - the emitters sit [`EMITTER_OFFSET`] inside the room, in front of the surface they
//!   lie on, instead of on it (coplanar shapes would z-fight);
//! - Mitsuba box-filters each pixel (its samples spread over the pixel's square), where
//!   relume shoots one ray through each pixel centre: pixels at geometric or pattern
//!   edges differ, interiors agree;
//! - Mitsuba traces full paths (up to its `max_depth`) where relume adds its own model
//!   of the light the room reflects to the direct light. With `max_depth = 2` Mitsuba
//!   computes direct light only: relume's [`super::render::shade`] on a room without
//!   interreflection.
//! - only Lambertian materials: Mitsuba 3 has no Phong lobe, so virtual objects are
//!   diffuse with a constant albedo.

use super::render::View;
use super::scene::{Hit, Scene, Surface};
use super::texture::room_albedo;
use crate::types::Intrinsics;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// How far (metres) the emitter rectangles sit in front of the room surface they lie on.
pub const EMITTER_OFFSET: f32 = 1e-4;

/// A virtual object for the Mitsuba scene: a triangle mesh with a constant diffuse albedo.
#[derive(Clone, Debug, PartialEq)]
pub struct MitsubaObject {
    /// World-space triangles; counter-clockwise seen from the front.
    pub triangles: Vec<[Vec3; 3]>,
    /// Per-corner unit shading normals, one triple per triangle; `None`: flat faces,
    /// facing the side from which the corners run counter-clockwise.
    pub normals: Option<Vec<[Vec3; 3]>>,
    /// Linear RGB diffuse albedo in [0, 1].
    pub albedo: Vec3,
}

/// An axis-aligned rectangle of the scene, `corner + u * edge_u + v * edge_v` for u, v in
/// [0, 1], seen from the side of `normal` (`edge_u x edge_v` points along `normal`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Face {
    pub corner: Vec3,
    pub edge_u: Vec3,
    pub edge_v: Vec3,
    /// Unit normal on the visible side.
    pub normal: Vec3,
    /// The surface it belongs to.
    pub surface: Surface,
}

impl Face {
    /// The rectangle on plane `axis = at` spanning `lo..hi` on the other two axes, facing
    /// `normal`, with its edges ordered so that `edge_u x edge_v` points along `normal`.
    fn on_plane(axis: usize, at: f32, lo: Vec3, hi: Vec3, normal: Vec3, surface: Surface) -> Face {
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut corner = lo;
        corner[axis] = at;
        let mut edge_u = Vec3::ZERO;
        edge_u[a] = hi[a] - lo[a];
        let mut edge_v = Vec3::ZERO;
        edge_v[b] = hi[b] - lo[b];
        if edge_u.cross(edge_v).dot(normal) < 0.0 {
            std::mem::swap(&mut edge_u, &mut edge_v);
        }
        Face {
            corner,
            edge_u,
            edge_v,
            normal,
            surface,
        }
    }

    /// Mitsuba's `rectangle` is [-1, 1]^2 in the local xy plane with normal +z and
    /// uv = ((x + 1) / 2, (y + 1) / 2): this row-major 4x4 maps it onto the face, local x
    /// along `edge_u`, y along `edge_v`, z along the normal.
    fn transform(self, offset: f32) -> [f32; 16] {
        let c = self.corner + 0.5 * (self.edge_u + self.edge_v) + self.normal * offset;
        let (u, v, n) = (0.5 * self.edge_u, 0.5 * self.edge_v, self.normal);
        [
            u.x, v.x, n.x, c.x, u.y, v.y, n.y, c.y, u.z, v.z, n.z, c.z, 0.0, 0.0, 0.0, 1.0,
        ]
    }
}

/// The rectangles of the room that [`export_scene`] writes: floor, ceiling and the four
/// walls (facing into the room), then each block's faces (facing out), except faces that
/// lie in the plane of a room surface (a block's bottom on the floor, a back against a
/// wall): they are never seen.
pub fn faces(scene: &Scene) -> Vec<Face> {
    let room = scene.room;
    let mut out = Vec::new();
    let room_surfaces = [
        (Surface::WestWall, Surface::EastWall),
        (Surface::Floor, Surface::Ceiling),
        (Surface::NorthWall, Surface::SouthWall),
    ];
    for (axis, (low, high)) in room_surfaces.into_iter().enumerate() {
        let mut n = Vec3::ZERO;
        n[axis] = 1.0;
        out.push(Face::on_plane(
            axis,
            room.min[axis],
            room.min,
            room.max,
            n,
            low,
        ));
        out.push(Face::on_plane(
            axis,
            room.max[axis],
            room.min,
            room.max,
            -n,
            high,
        ));
    }
    for (i, block) in scene.blocks.iter().enumerate() {
        let b = block.bounds;
        for axis in 0..3 {
            let mut n = Vec3::ZERO;
            n[axis] = 1.0;
            for (at, normal) in [(b.min[axis], -n), (b.max[axis], n)] {
                if at == room.min[axis] || at == room.max[axis] {
                    continue;
                }
                out.push(Face::on_plane(
                    axis,
                    at,
                    b.min,
                    b.max,
                    normal,
                    Surface::Block(i),
                ));
            }
        }
    }
    out
}

/// Sub-samples per axis of each baked texel: a texel holds the mean albedo of a
/// regular `TEXEL_SUBSAMPLES` x `TEXEL_SUBSAMPLES` grid over its square.
pub const TEXEL_SUBSAMPLES: u32 = 4;

/// The albedo texture of `face`: `width x height` texels (`ceil(edge length *
/// texels_per_metre)` each way), row-major, row `j` column `i` covering
/// `corner + u * edge_u + v * edge_v` for u in [i, i + 1] / width and v in [j, j + 1] /
/// height (Mitsuba's texture row 0 is at v = 0). Each texel holds the mean of
/// `scene.material`'s albedo over a regular grid of [`TEXEL_SUBSAMPLES`]^2 points of its
/// square: its area mean, so thin features (1.6 cm grout, 2 cm drawer gaps) keep their
/// share of the surface instead of growing or vanishing to whole texels, which would bias
/// region means (centre samples at 1 cm texels made the floor's grout 2 cm wide: +1.6 %
/// in blue). The hit handed to `material` lies on the face with the face's normal, as a
/// ray would find it (block textures are then evaluated just inside the block, as in
/// relume). Under an emitter `material` gives no albedo; the texel takes the surface's
/// own texture there, which the emitter hides.
pub fn bake_face(scene: &Scene, face: &Face, texels_per_metre: f32) -> (u32, u32, Vec<Vec3>) {
    let side = |edge: Vec3| ((edge.length() * texels_per_metre).ceil() as u32).max(1);
    let (width, height) = (side(face.edge_u), side(face.edge_v));
    let n = TEXEL_SUBSAMPLES;
    let albedo = |position: Vec3| {
        let hit = Hit {
            t: 1.0,
            position,
            normal: face.normal,
            surface: face.surface,
        };
        let material = scene.material(&hit);
        if material.emission != Vec3::ZERO {
            room_albedo(face.surface, position)
        } else {
            material.albedo
        }
    };
    let texels = (0..width * height)
        .into_par_iter()
        .map(|t| {
            let (i, j) = (t % width, t / width);
            let mut sum = Vec3::ZERO;
            for b in 0..n {
                for a in 0..n {
                    let u = (i as f32 + (a as f32 + 0.5) / n as f32) / width as f32;
                    let v = (j as f32 + (b as f32 + 0.5) / n as f32) / height as f32;
                    sum += albedo(face.corner + face.edge_u * u + face.edge_v * v);
                }
            }
            sum / (n * n) as f32
        })
        .collect();
    (width, height, texels)
}

/// Mitsuba's `perspective` settings for relume's pinhole `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorParameters {
    /// Vertical field of view in degrees (`fov` with `fov_axis = "y"`):
    /// `2 atan(height / (2 fy))`.
    pub fov_y_deg: f64,
    /// `principal_point_offset_x`: `0.5 - (cx + 0.5) / width`.
    pub principal_point_offset_x: f64,
    /// `principal_point_offset_y`: `0.5 - (cy + 0.5) / height`.
    pub principal_point_offset_y: f64,
}

/// The `perspective` settings that reproduce `k`, or why none can (Mitsuba's pixels are
/// square: fx must equal fy).
///
/// Conventions (measured on Mitsuba 3.9 with `Sensor.sample_ray`): the film position
/// (s, t) in [0, 1]^2 runs right and down over the image, pixel (x, y) covering
/// [x, x + 1] x [y, y + 1] of `width * s, height * t`; relume's pixel centre (x, y)
/// therefore sits at film coordinates (x + 0.5, y + 0.5). The optical axis meets the film
/// at (0.5 - offset_x, 0.5 - offset_y), in fractions of the film's width and height.
/// `fov` along y sets the focal length in pixels to `height / (2 tan(fov / 2))` on both
/// axes.
pub fn sensor_parameters(k: &Intrinsics) -> Result<SensorParameters, String> {
    if !(k.fx.is_finite() && k.fy.is_finite() && k.fx > 0.0 && k.fy > 0.0) {
        return Err(format!(
            "focal lengths fx {} fy {} must be finite and positive",
            k.fx, k.fy
        ));
    }
    if ((k.fx - k.fy) / k.fy).abs() > 1e-6 {
        return Err(format!(
            "Mitsuba's perspective camera has square pixels: fx {} differs from fy {}",
            k.fx, k.fy
        ));
    }
    let (w, h) = (k.width as f64, k.height as f64);
    Ok(SensorParameters {
        fov_y_deg: (2.0 * (h / (2.0 * k.fy)).atan()).to_degrees(),
        principal_point_offset_x: 0.5 - (k.cx + 0.5) / w,
        principal_point_offset_y: 0.5 - (k.cy + 0.5) / h,
    })
}

/// The sensor's `to_world`, row-major 4x4: Mitsuba's camera looks down +z with x to the
/// left and y up, relume's with x right and y down, so the rotation is relume's
/// camera-to-world times diag(-1, -1, 1) (a rotation by pi about the optical axis).
pub fn sensor_to_world(view: &View) -> [f64; 16] {
    let r = view.rotation.as_dmat3();
    let (x, y, z) = (-r.x_axis, -r.y_axis, r.z_axis);
    let p: DVec3 = view.position.as_dvec3();
    [
        x.x, y.x, z.x, p.x, x.y, y.y, z.y, p.y, x.z, y.z, z.z, p.z, 0.0, 0.0, 0.0, 1.0,
    ]
}

fn numbers<T: std::fmt::Display>(values: &[T]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

fn rgb(v: Vec3) -> String {
    format!("{}, {}, {}", v.x, v.y, v.z)
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> String {
    format!("cannot write {}: {e}", path.display())
}

/// Writes `dir/scene.xml` and its files for Mitsuba 3: the room of `scene` seen by
/// `views` (sensor `k` is `views[k]`, id `view_k`), with `objects` added. Creates `dir`
/// if needed; fails with a message naming the file that could not be written, or the
/// view whose intrinsics Mitsuba cannot reproduce.
///
/// - Each [`faces`] rectangle is a `rectangle` shape with a `diffuse` BSDF whose
///   reflectance is a `bitmap` texture (`textures/face_N.exr`, linear float RGB,
///   `raw = true`, `wrap_mode = clamp`) baked by [`bake_face`] at `texels_per_metre`.
///   Its `filter_type` is `nearest`: the room's textures are mostly piecewise constant
///   (tiles, grout, stripes, checkers, drawer gaps), and a nearest lookup of texel
///   means returns the exact procedural albedo everywhere except in texels that a
///   pattern edge crosses, where it returns their mean; bilinear filtering would blur
///   every edge over a further texel, and at a face's border blend in the clamped
///   border texels.
/// - The ball is a `sphere` with the constant albedo `scene.material` gives it.
/// - Each light is a one-sided `rectangle` moved [`EMITTER_OFFSET`] along its normal
///   into the room, with an `area` emitter of its RGB radiance and a black `diffuse`
///   BSDF (relume's emitters reflect nothing).
/// - The lamp, when it is on, is a `spot` emitter of its intensity, `cutoff_angle` and
///   `beam_width` (the profile relume's lamp shines), placed by a `lookat` along its axis.
/// - Each object is `objects/object_N.ply` (ASCII PLY, three unshared vertices per
///   triangle) with a `diffuse` BSDF of its albedo; `face_normals` when it has no normals.
/// - Each view is a `perspective` sensor ([`sensor_parameters`], [`sensor_to_world`])
///   with an `hdrfilm` of the view's size, `pixel_format` rgb, and a `box` reconstruction
///   filter (each pixel averages its samples over the pixel's square), and an
///   `independent` sampler; the render script sets the sample count and integrator.
/// - The scene's integrator is `path` with `max_depth` -1 and visible emitters.
pub fn export_scene(
    dir: &Path,
    scene: &Scene,
    views: &[View],
    objects: &[MitsubaObject],
    texels_per_metre: f32,
) -> Result<(), String> {
    if !(texels_per_metre.is_finite() && texels_per_metre > 0.0) {
        return Err(format!(
            "texels per metre {texels_per_metre} must be finite and positive"
        ));
    }
    for sub in ["textures", "objects"] {
        let path = dir.join(sub);
        std::fs::create_dir_all(&path).map_err(|e| io_error(&path, e))?;
    }
    let mut xml = String::new();
    let _ = writeln!(
        xml,
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n\
         <!-- The relume synthetic room, written by relume_recording::synth::mitsuba. -->\n\
         <scene version=\"3.0.0\">\n\
         \x20   <integrator type=\"path\">\n\
         \x20       <integer name=\"max_depth\" value=\"-1\"/>\n\
         \x20       <boolean name=\"hide_emitters\" value=\"false\"/>\n\
         \x20   </integrator>"
    );
    for (index, view) in views.iter().enumerate() {
        let k = &view.intrinsics;
        let p = sensor_parameters(k).map_err(|e| format!("view {index}: {e}"))?;
        let _ = writeln!(
            xml,
            "    <sensor type=\"perspective\" id=\"view_{index}\">\n\
             \x20       <string name=\"fov_axis\" value=\"y\"/>\n\
             \x20       <float name=\"fov\" value=\"{}\"/>\n\
             \x20       <float name=\"principal_point_offset_x\" value=\"{}\"/>\n\
             \x20       <float name=\"principal_point_offset_y\" value=\"{}\"/>\n\
             \x20       <float name=\"near_clip\" value=\"0.001\"/>\n\
             \x20       <float name=\"far_clip\" value=\"1000\"/>\n\
             \x20       <transform name=\"to_world\">\n\
             \x20           <matrix value=\"{}\"/>\n\
             \x20       </transform>\n\
             \x20       <sampler type=\"independent\">\n\
             \x20           <integer name=\"sample_count\" value=\"16\"/>\n\
             \x20       </sampler>\n\
             \x20       <film type=\"hdrfilm\">\n\
             \x20           <integer name=\"width\" value=\"{}\"/>\n\
             \x20           <integer name=\"height\" value=\"{}\"/>\n\
             \x20           <string name=\"pixel_format\" value=\"rgb\"/>\n\
             \x20           <rfilter type=\"box\"/>\n\
             \x20       </film>\n\
             \x20   </sensor>",
            p.fov_y_deg,
            p.principal_point_offset_x,
            p.principal_point_offset_y,
            numbers(&sensor_to_world(view)),
            k.width,
            k.height,
        );
    }
    for (index, face) in faces(scene).iter().enumerate() {
        let (width, height, texels) = bake_face(scene, face, texels_per_metre);
        let name = format!("textures/face_{index}.exr");
        let path = dir.join(&name);
        exr::prelude::write_rgb_file(&path, width as usize, height as usize, |x, y| {
            let t = texels[y * width as usize + x];
            (t.x, t.y, t.z)
        })
        .map_err(|e| io_error(&path, e))?;
        let _ = writeln!(
            xml,
            "    <shape type=\"rectangle\" id=\"face_{index}\">\n\
             \x20       <!-- {:?} -->\n\
             \x20       <transform name=\"to_world\">\n\
             \x20           <matrix value=\"{}\"/>\n\
             \x20       </transform>\n\
             \x20       <bsdf type=\"diffuse\">\n\
             \x20           <texture type=\"bitmap\" name=\"reflectance\">\n\
             \x20               <string name=\"filename\" value=\"{name}\"/>\n\
             \x20               <boolean name=\"raw\" value=\"true\"/>\n\
             \x20               <string name=\"filter_type\" value=\"nearest\"/>\n\
             \x20               <string name=\"wrap_mode\" value=\"clamp\"/>\n\
             \x20           </texture>\n\
             \x20       </bsdf>\n\
             \x20   </shape>",
            face.surface,
            numbers(&face.transform(0.0)),
        );
    }
    let ball = scene.ball;
    let ball_albedo = scene
        .material(&Hit {
            t: 1.0,
            position: ball.center + Vec3::Y * ball.radius,
            normal: Vec3::Y,
            surface: Surface::Ball,
        })
        .albedo;
    let _ = writeln!(
        xml,
        "    <shape type=\"sphere\" id=\"ball\">\n\
         \x20       <point name=\"center\" value=\"{}\"/>\n\
         \x20       <float name=\"radius\" value=\"{}\"/>\n\
         \x20       <bsdf type=\"diffuse\">\n\
         \x20           <rgb name=\"reflectance\" value=\"{}\"/>\n\
         \x20       </bsdf>\n\
         \x20   </shape>",
        rgb(ball.center),
        ball.radius,
        rgb(ball_albedo),
    );
    for (index, light) in scene.lights.iter().enumerate() {
        let mut face = Face {
            corner: light.corner,
            edge_u: light.edge_u,
            edge_v: light.edge_v,
            normal: light.normal,
            surface: light.surface,
        };
        if face.edge_u.cross(face.edge_v).dot(face.normal) < 0.0 {
            std::mem::swap(&mut face.edge_u, &mut face.edge_v);
        }
        let _ = writeln!(
            xml,
            "    <shape type=\"rectangle\" id=\"light_{index}\">\n\
             \x20       <transform name=\"to_world\">\n\
             \x20           <matrix value=\"{}\"/>\n\
             \x20       </transform>\n\
             \x20       <bsdf type=\"diffuse\">\n\
             \x20           <rgb name=\"reflectance\" value=\"0, 0, 0\"/>\n\
             \x20       </bsdf>\n\
             \x20       <emitter type=\"area\">\n\
             \x20           <rgb name=\"radiance\" value=\"{}\"/>\n\
             \x20       </emitter>\n\
             \x20   </shape>",
            numbers(&face.transform(EMITTER_OFFSET)),
            rgb(light.radiance),
        );
    }
    if let Some(lamp) = &scene.lamp {
        // Mitsuba's spot shines along its local +z, which `lookat` turns to the target.
        let _ = writeln!(
            xml,
            "    <emitter type=\"spot\" id=\"lamp\">\n\
             \x20       <transform name=\"to_world\">\n\
             \x20           <lookat origin=\"{}\" target=\"{}\" up=\"0, 1, 0\"/>\n\
             \x20       </transform>\n\
             \x20       <rgb name=\"intensity\" value=\"{}\"/>\n\
             \x20       <float name=\"cutoff_angle\" value=\"{}\"/>\n\
             \x20       <float name=\"beam_width\" value=\"{}\"/>\n\
             \x20   </emitter>",
            rgb(lamp.position),
            rgb(lamp.position + lamp.direction),
            rgb(lamp.intensity),
            lamp.cutoff.to_degrees(),
            lamp.beam.to_degrees(),
        );
    }
    for (index, object) in objects.iter().enumerate() {
        let name = format!("objects/object_{index}.ply");
        let path = dir.join(&name);
        std::fs::write(&path, ply(object)?).map_err(|e| io_error(&path, e))?;
        let _ = writeln!(
            xml,
            "    <shape type=\"ply\" id=\"object_{index}\">\n\
             \x20       <string name=\"filename\" value=\"{name}\"/>\n\
             \x20       <boolean name=\"face_normals\" value=\"{}\"/>\n\
             \x20       <bsdf type=\"diffuse\">\n\
             \x20           <rgb name=\"reflectance\" value=\"{}\"/>\n\
             \x20       </bsdf>\n\
             \x20   </shape>",
            object.normals.is_none(),
            rgb(object.albedo),
        );
    }
    xml.push_str("</scene>\n");
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).map_err(|e| io_error(&path, e))
}

/// An ASCII PLY of `object`: three vertices per triangle (with normals when it has
/// them) and one face per triangle.
fn ply(object: &MitsubaObject) -> Result<String, String> {
    if let Some(normals) = &object.normals
        && normals.len() != object.triangles.len()
    {
        return Err(format!(
            "an object has {} triangles but {} normal triples",
            object.triangles.len(),
            normals.len()
        ));
    }
    let n = object.triangles.len();
    let mut out = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\n",
        3 * n
    );
    if object.normals.is_some() {
        out.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    let _ = write!(
        out,
        "element face {n}\nproperty list uchar int vertex_indices\nend_header\n"
    );
    for (t, triangle) in object.triangles.iter().enumerate() {
        for (c, p) in triangle.iter().enumerate() {
            let _ = write!(out, "{} {} {}", p.x, p.y, p.z);
            if let Some(normals) = &object.normals {
                let q = normals[t][c];
                let _ = write!(out, " {} {} {}", q.x, q.y, q.z);
            }
            out.push('\n');
        }
    }
    for t in 0..n {
        let _ = writeln!(out, "3 {} {} {}", 3 * t, 3 * t + 1, 3 * t + 2);
    }
    Ok(out)
}

/// Reads a colour PFM (`PF`, as `scripts/mitsuba_render.py` writes): width, height and
/// the pixels as linear RGB, row-major from the top row (PFM stores rows bottom to top).
/// Either byte order; fails with a message naming the file and what is wrong.
pub fn read_radiance(path: &Path) -> Result<(u32, u32, Vec<Vec3>), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let bad = |why: &str| format!("{} is not a colour PFM: {why}", path.display());
    // Header: "PF", width, height, scale, each followed by one whitespace byte.
    let mut tokens = Vec::new();
    let mut at = 0;
    while tokens.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if start == at || at >= bytes.len() || at - start > 32 {
            return Err(bad("the header ends early"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
        at += 1;
    }
    if tokens[0] != "PF" {
        return Err(bad(&format!("it starts with {:?}, not \"PF\"", tokens[0])));
    }
    let size = |s: &str| {
        s.parse::<u32>()
            .ok()
            .filter(|&v| v > 0 && v <= relume_base::pinhole::MAX_IMAGE_SIDE)
    };
    let (Some(width), Some(height)) = (size(&tokens[1]), size(&tokens[2])) else {
        return Err(bad(&format!("bad size {} x {}", tokens[1], tokens[2])));
    };
    let scale: f32 = tokens[3]
        .parse()
        .ok()
        .filter(|s: &f32| s.is_finite() && *s != 0.0)
        .ok_or_else(|| bad(&format!("bad scale {}", tokens[3])))?;
    let count = width as usize * height as usize * 3;
    let data = &bytes[at..];
    if data.len() != count * 4 {
        return Err(bad(&format!(
            "{} bytes of pixels, expected {} for {width} x {height}",
            data.len(),
            count * 4
        )));
    }
    let value = |i: usize| {
        let b: [u8; 4] = data[4 * i..4 * i + 4].try_into().unwrap();
        if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let (w, h) = (width as usize, height as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for y in 0..h {
        let row = h - 1 - y;
        for x in 0..w {
            let i = 3 * (row * w + x);
            pixels.push(Vec3::new(value(i), value(i + 1), value(i + 2)));
        }
    }
    Ok((width, height, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::camera::camera_pose;
    use crate::synth::render::pixel_direction;
    use glam::{DMat3, DVec4, Mat3};

    /// Mitsuba's perspective camera as measured (see [`sensor_parameters`]): the film
    /// position in pixels, (0, 0) the top-left corner, where the world point `p` lands.
    fn mitsuba_film_position(view: &View, p: Vec3) -> (f64, f64) {
        let k = &view.intrinsics;
        let s = sensor_parameters(k).unwrap();
        let m = sensor_to_world(view);
        let to_world = glam::DMat4::from_cols_array(&m).transpose();
        let local = to_world.inverse() * DVec4::new(p.x as f64, p.y as f64, p.z as f64, 1.0);
        // Camera x left, y up; tan(fov/2) spans half the film's height.
        let tan_half = (s.fov_y_deg.to_radians() / 2.0).tan();
        let (w, h) = (k.width as f64, k.height as f64);
        let half_height_px = h / 2.0;
        let x_tan = -local.x / local.z;
        let y_tan = -local.y / local.z;
        let s_axis = 0.5 - s.principal_point_offset_x;
        let t_axis = 0.5 - s.principal_point_offset_y;
        (
            s_axis * w + x_tan / tan_half * half_height_px,
            t_axis * h + y_tan / tan_half * half_height_px,
        )
    }

    #[test]
    fn a_point_lands_on_the_same_pixel_in_both_cameras() {
        let pose = camera_pose(0.7);
        // Not 4:3 and off-centre, so the field of view's axis and both principal-point
        // offsets count.
        let mut k = Intrinsics {
            width: 80,
            height: 50,
            fx: 61.0,
            fy: 61.0,
            cx: 31.3,
            cy: 27.8,
        };
        let view = View {
            rotation: DMat3::from_quat(pose.rotation()).as_mat3(),
            position: pose.translation().as_vec3(),
            intrinsics: k,
        };
        for (x, y) in [(0u32, 0u32), (79, 0), (0, 49), (40, 20), (12, 33)] {
            let d = view.rotation * pixel_direction(&k, x, y);
            let p = view.position + d * 2.3;
            let (fx, fy) = mitsuba_film_position(&view, p);
            assert!(
                (fx - (x as f64 + 0.5)).abs() < 1e-3 && (fy - (y as f64 + 0.5)).abs() < 1e-3,
                "pixel ({x}, {y}) lands at film ({fx}, {fy})"
            );
        }
        k.fx *= 1.01;
        assert!(sensor_parameters(&k).unwrap_err().contains("square pixels"));
    }

    #[test]
    fn faces_face_the_viewer_and_textures_hold_the_material() {
        let scene = crate::synth::interreflection::room();
        let faces = faces(&scene);
        // 6 room surfaces; blocks 0, 1, 2: 5 faces each; block 3 also stands on the
        // north wall: 4.
        assert_eq!(faces.len(), 6 + 5 + 5 + 5 + 4);
        for f in &faces {
            assert!((f.edge_u.cross(f.edge_v).normalize() - f.normal).length() < 1e-6);
            let centre = f.corner + 0.5 * (f.edge_u + f.edge_v);
            let inside_room = (scene.room.min + scene.room.max) * 0.5;
            if let Surface::Block(i) = f.surface {
                let b = scene.blocks[i].bounds;
                assert!(f.normal.dot(centre - (b.min + b.max) * 0.5) > 0.0);
            } else {
                assert!(f.normal.dot(inside_room - centre) > 0.0);
            }
            let m = f.transform(0.0);
            // Local (-1, -1) maps to the corner, local +z to the normal.
            let at = |x: f32, y: f32| {
                Vec3::new(
                    m[0] * x + m[1] * y + m[3],
                    m[4] * x + m[5] * y + m[7],
                    m[8] * x + m[9] * y + m[11],
                )
            };
            assert!((at(-1.0, -1.0) - f.corner).length() < 1e-5);
            assert!((at(1.0, -1.0) - (f.corner + f.edge_u)).length() < 1e-5);
            assert_eq!(Vec3::new(m[2], m[6], m[10]), f.normal);
        }
        // The floor: texels hold the mean procedural albedo over their squares.
        let floor = faces.iter().find(|f| f.surface == Surface::Floor).unwrap();
        let (w, h, texels) = bake_face(&scene, floor, 20.0);
        assert_eq!((w, h), (100, 100));
        let (i, j) = (37usize, 61usize);
        let n = TEXEL_SUBSAMPLES;
        let mut mean = Vec3::ZERO;
        for b in 0..n {
            for a in 0..n {
                let p = floor.corner
                    + floor.edge_u * ((i as f32 + (a as f32 + 0.5) / n as f32) / 100.0)
                    + floor.edge_v * ((j as f32 + (b as f32 + 0.5) / n as f32) / 100.0);
                mean += room_albedo(Surface::Floor, p) / (n * n) as f32;
            }
        }
        assert!((texels[j * 100 + i] - mean).abs().max_element() < 1e-6);
        // The ceiling under the panel keeps the ceiling's albedo.
        let ceiling = faces
            .iter()
            .find(|f| f.surface == Surface::Ceiling)
            .unwrap();
        let (_, _, texels) = bake_face(&scene, ceiling, 10.0);
        let ceiling_albedo = Vec3::new(0.80, 0.80, 0.78);
        assert!(
            texels
                .iter()
                .all(|t| (*t - ceiling_albedo).abs().max_element() < 1e-6)
        );
    }

    #[test]
    fn export_writes_the_scene_and_pfm_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let view = View {
            rotation: Mat3::IDENTITY,
            position: Vec3::new(0.0, 1.0, 0.0),
            intrinsics: Intrinsics::PRIMESENSE.scaled_to(32, 24),
        };
        let object = MitsubaObject {
            triangles: vec![[Vec3::ZERO, Vec3::X, Vec3::Y]],
            normals: None,
            albedo: Vec3::splat(0.5),
        };
        export_scene(
            dir.path(),
            &crate::synth::interreflection::room(),
            &[view],
            &[object],
            4.0,
        )
        .unwrap();
        let xml = std::fs::read_to_string(dir.path().join("scene.xml")).unwrap();
        assert!(xml.contains("<scene version=\"3.0.0\">"));
        assert_eq!(xml.matches("<sensor ").count(), 1);
        assert_eq!(xml.matches("<emitter type=\"area\">").count(), 2);
        assert_eq!(xml.matches("type=\"bitmap\"").count(), 25);
        assert!(dir.path().join("textures/face_24.exr").is_file());
        let ply = std::fs::read_to_string(dir.path().join("objects/object_0.ply")).unwrap();
        assert!(ply.ends_with("0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), "{ply}");

        // A 2 x 1 little-endian PFM: bottom row first, which is the only row.
        let mut pfm = b"PF\n2 1\n-1.0\n".to_vec();
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
            pfm.extend(v.to_le_bytes());
        }
        let path = dir.path().join("a.pfm");
        std::fs::write(&path, &pfm).unwrap();
        let (w, h, px) = read_radiance(&path).unwrap();
        assert_eq!((w, h), (2, 1));
        assert_eq!(px, vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]);
        std::fs::write(&path, &pfm[..pfm.len() - 1]).unwrap();
        assert!(
            read_radiance(&path)
                .unwrap_err()
                .contains("bytes of pixels")
        );
    }
}
