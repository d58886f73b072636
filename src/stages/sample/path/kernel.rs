//! The per-pixel estimator of `sample.path` (paper 001 Sec. 5, two-mode sampling; paper
//! 000 Sec. 7 for the object-aware differential). See the module docs of
//! [`super`] for what each estimate means.

use super::sampling::{
    Basis, PixelRng, Stream, StreamId, below, cosine_hemisphere, phong_lobe, phong_weight,
    strata_bounds, stratum_index,
};
use super::{PathInputs, PathParams};
use crate::light::LightSample;
use crate::objects::{Aabb, VirtualHit, VirtualScene};
use crate::raster::depth_is_valid;
use crate::stages::sample::ssrt::ScreenTracer;
use glam::{Mat3A, Vec3, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI};

/// Offset (metres) of rays leaving a virtual surface along its normal.
const SURFACE_OFFSET: f32 = 1e-4;
/// The most object-aware candidates per pixel (size of the H_a index cache).
pub const MAX_CANDIDATES: usize = 256;

/// What one pixel produces (see [`super::PathOutputs`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelResult {
    pub e_r_dir: Vec3,
    pub e_r_ind: Vec3,
    pub e_rv_dir: Vec3,
    pub e_rv_ind: Vec3,
    pub mask: f32,
    pub k_v: Vec3,
    pub world_position: Vec3,
    pub world_normal: Vec3,
    pub direct_min_distance: f32,
    pub indirect_min_distance: f32,
    pub touched: bool,
}

/// Directions from a point that may meet the objects' bounding sphere: those within
/// the cone of half-angle asin(r / distance) about the direction to its centre.
#[derive(Clone, Copy, Debug)]
struct Cone {
    axis: Vec3,
    cos_half: f32,
}

impl Cone {
    /// Every direction (the point is inside the sphere).
    const ALL: Cone = Cone {
        axis: Vec3::Z,
        cos_half: -2.0,
    };

    #[inline(always)]
    fn admits(&self, dir: Vec3) -> bool {
        self.axis.dot(dir) >= self.cos_half
    }
}

/// The virtual objects with their bounding volumes, for the pretests.
struct Objects<'a> {
    scene: &'a VirtualScene,
    aabb: Aabb,
    center: Vec3,
    /// Squared radius of a sphere holding the box, inflated for rounding.
    radius2: f32,
}

impl Objects<'_> {
    /// The cone of directions from `p` that may meet the bounding sphere.
    #[inline]
    fn cone(&self, p: Vec3) -> Cone {
        let oc = self.center - p;
        let dist2 = oc.length_squared();
        if dist2.is_nan() || dist2 <= self.radius2 {
            return Cone::ALL;
        }
        let dist = dist2.sqrt();
        Cone {
            axis: oc / dist,
            // A margin of 1e-5 keeps the test conservative under rounding.
            cos_half: (1.0 - self.radius2 / dist2).sqrt() - 1e-5,
        }
    }

    /// The nearest object hit along `o + t d` with t < t_max, after the bounding-box
    /// pretest.
    #[inline]
    fn hit(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<VirtualHit> {
        self.aabb.ray_span(o, d.recip(), 0.0, t_max)?;
        self.scene.intersect(o, d, 0.0, t_max)
    }
}

/// A real shading point: the pixel's depth-map point and normal.
struct RealPoint {
    /// The ray origin, raised off the surface along the normal (camera and world
    /// space), and the surface point itself (world).
    camera: Vec3,
    world: Vec3,
    surface: Vec3,
    normal_world: Vec3,
    /// Basis about the camera-space normal (indirect directions are drawn in camera
    /// space, where the screen-space tracer works).
    basis_camera: Basis,
    /// The objects' cone from this point, in world and in camera space.
    cone_world: Cone,
    cone_camera: Cone,
}

/// Sums of one pixel's estimates while its samples are drawn.
struct Acc {
    r_dir: Vec3,
    r_ind: Vec3,
    rv_dir: Vec3,
    rv_ind: Vec3,
    rv_dir_n: u32,
    rv_ind_n: u32,
    /// Indirect samples of E_RV taken at the real point.
    rv_ind_real_n: u32,
    direct_min: f32,
    indirect_min: f32,
    touched: bool,
    /// Draws taken from the bounce stream so far.
    bounces: u64,
}

/// Everything constant over a frame.
pub struct Kernel<'a> {
    inputs: &'a PathInputs<'a>,
    params: &'a PathParams,
    tracer: ScreenTracer<'a>,
    to_world: Mat3A,
    to_camera: Mat3A,
    camera_position: Vec3,
    objects: Option<Objects<'a>>,
    /// The objects' cone from the camera.
    camera_cone: Cone,
    /// Pixel bounds [x0, y0, x1, y1] (inclusive) outside which no primary ray can meet
    /// the objects.
    object_pixels: [i64; 4],
    strata: Vec<u32>,
}

impl<'a> Kernel<'a> {
    pub fn new(
        inputs: &'a PathInputs<'a>,
        params: &'a PathParams,
        tracer: ScreenTracer<'a>,
    ) -> Self {
        let c2w = inputs.camera_to_world;
        let to_world = c2w.matrix3;
        let to_camera = to_world.transpose();
        let camera_position = Vec3::from(c2w.translation);
        let objects = (!inputs.objects.is_empty()).then(|| {
            let aabb = inputs.objects.bounds();
            let half = (aabb.max - aabb.min) * 0.5;
            let radius = half.length() * 1.001 + 1e-4;
            Objects {
                scene: inputs.objects,
                aabb,
                center: aabb.center(),
                radius2: radius * radius,
            }
        });
        let camera_cone = objects
            .as_ref()
            .map_or(Cone::ALL, |o| o.cone(camera_position));
        let object_pixels = objects
            .as_ref()
            .map_or([0, 0, -1, -1], |o| object_pixel_bounds(inputs, &o.aabb));
        Kernel {
            inputs,
            params,
            tracer,
            to_world,
            to_camera,
            camera_position,
            objects,
            camera_cone,
            object_pixels,
            strata: strata_bounds(params.primary * params.direct, inputs.table.samples.len()),
        }
    }

    /// All estimates of pixel (x, y).
    pub fn shade_pixel(&self, x: u32, y: u32) -> PixelResult {
        let inputs = self.inputs;
        let params = self.params;
        let p = y as usize * inputs.depth.width as usize + x as usize;
        let rng = PixelRng::new(params.seed, inputs.frame, p as u64);
        let z = inputs.depth.data[p];
        let real = self.real_point(x, y, z, inputs.normals.data[p]);
        let may_see_objects = {
            let [x0, y0, x1, y1] = self.object_pixels;
            (x0..=x1).contains(&(x as i64)) && (y0..=y1).contains(&(y as i64))
        };
        let mut acc = Acc {
            r_dir: Vec3::ZERO,
            r_ind: Vec3::ZERO,
            rv_dir: Vec3::ZERO,
            rv_ind: Vec3::ZERO,
            rv_dir_n: 0,
            rv_ind_n: 0,
            rv_ind_real_n: 0,
            direct_min: f32::INFINITY,
            indirect_min: f32::INFINITY,
            touched: false,
            bounces: 0,
        };
        let (mut virtual_count, mut albedo) = (0u32, Vec3::ZERO);
        let (mut surfaces, mut position, mut normal) = (0u32, Vec3::ZERO, Vec3::ZERO);
        let primary_stream = rng.stream(StreamId::Primary);
        let direct_stream = rng.stream(StreamId::Direct);
        let indirect_stream = rng.stream(StreamId::Indirect);
        let bounce_stream = rng.stream(StreamId::Bounce);
        for j in 0..params.primary {
            let virtual_hit = if may_see_objects {
                self.primary_hit(&primary_stream, j, x, y, z)
            } else {
                None
            };
            match virtual_hit {
                None => {
                    if let Some(rp) = &real {
                        surfaces += 1;
                        position += rp.surface;
                        normal += rp.normal_world;
                        self.real_samples(
                            rp,
                            j,
                            &direct_stream,
                            &indirect_stream,
                            &bounce_stream,
                            true,
                            &mut acc,
                        );
                    }
                }
                Some((hit, view)) => {
                    virtual_count += 1;
                    albedo += hit.material.albedo;
                    surfaces += 1;
                    position += hit.position;
                    normal += hit.normal;
                    acc.touched = true;
                    if let Some(rp) = &real {
                        self.real_samples(
                            rp,
                            j,
                            &direct_stream,
                            &indirect_stream,
                            &bounce_stream,
                            false,
                            &mut acc,
                        );
                    }
                    self.virtual_samples(
                        &hit,
                        -view,
                        j,
                        &direct_stream,
                        &indirect_stream,
                        &bounce_stream,
                        &mut acc,
                    );
                }
            }
        }
        let mut differential = Vec3::ZERO;
        if params.object_aware && acc.rv_ind_real_n > 0 {
            if let (Some(rp), Some(objects)) = (&real, &self.objects) {
                if let Some(d) = self.object_aware(rp, objects, &rng, &bounce_stream, &mut acc) {
                    differential = d;
                    acc.touched = true;
                }
            }
        }
        let nan = Vec3::NAN;
        let (dir_n, ind_n) = (
            params.primary * params.direct,
            params.primary * params.indirect,
        );
        let (e_r_dir, e_r_ind) = if real.is_some() {
            (mean(acc.r_dir, dir_n, 1.0), mean(acc.r_ind, ind_n, PI))
        } else {
            (nan, nan)
        };
        let any_surface = surfaces > 0;
        let e_rv_dir = if any_surface {
            mean(acc.rv_dir, acc.rv_dir_n, 1.0)
        } else {
            nan
        };
        let mut e_rv_ind = if any_surface {
            mean(acc.rv_ind, acc.rv_ind_n, PI)
        } else {
            nan
        };
        if acc.touched && differential != Vec3::ZERO {
            e_rv_ind += differential * (acc.rv_ind_real_n as f32 / acc.rv_ind_n as f32);
        }
        PixelResult {
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask: 1.0 - virtual_count as f32 / params.primary as f32,
            k_v: if virtual_count > 0 {
                albedo / virtual_count as f32
            } else {
                Vec3::ZERO
            },
            world_position: if any_surface {
                position / surfaces as f32
            } else {
                nan
            },
            world_normal: normal.normalize_or_zero(),
            direct_min_distance: acc.direct_min,
            indirect_min_distance: acc.indirect_min,
            touched: acc.touched,
        }
    }

    /// The pixel's depth-map point and normal, when both are valid.
    fn real_point(&self, x: u32, y: u32, z: f32, normal_camera: Vec3) -> Option<RealPoint> {
        if !depth_is_valid(z) || !normal_camera.is_finite() || normal_camera == Vec3::ZERO {
            return None;
        }
        let normal_camera = normal_camera.normalize();
        let cam = &self.inputs.camera;
        let surface = cam.back_project(x as f32, y as f32, z);
        // Raised by `normal_offset` pixel footprints: a ray grazing the surface then
        // stays in front of the depth map's pixel centres.
        let raise = z / cam.fx.max(cam.fy) * self.params.normal_offset;
        let camera = surface + normal_camera * raise;
        let world = self.inputs.camera_to_world.transform_point3(camera);
        let surface = self.inputs.camera_to_world.transform_point3(surface);
        let normal_world = Vec3::from(self.to_world * Vec3A::from(normal_camera));
        let (cone_world, cone_camera) = match &self.objects {
            Some(o) => {
                let c = o.cone(world);
                let axis = Vec3::from(self.to_camera * Vec3A::from(c.axis));
                (c, Cone { axis, ..c })
            }
            None => (Cone::ALL, Cone::ALL),
        };
        Some(RealPoint {
            camera,
            world,
            surface,
            normal_world,
            basis_camera: Basis::new(normal_camera),
            cone_world,
            cone_camera,
        })
    }

    /// The virtual hit of primary ray j (jittered inside the pixel) when it is nearer
    /// than the pixel's real surface, with the ray's world direction.
    fn primary_hit(
        &self,
        stream: &Stream,
        j: u32,
        x: u32,
        y: u32,
        z: f32,
    ) -> Option<(VirtualHit, Vec3)> {
        let objects = self.objects.as_ref()?;
        let (ju, jv) = stream.pair(j as u64);
        let ray = self
            .inputs
            .camera
            .ray(x as f32 + ju - 0.5, y as f32 + jv - 0.5);
        let length = ray.length();
        let dir = Vec3::from(self.to_world * Vec3A::from(ray / length));
        if !self.camera_cone.admits(dir) {
            return None;
        }
        let t_real = if depth_is_valid(z) {
            z * length
        } else {
            f32::INFINITY
        };
        objects
            .hit(self.camera_position, dir, t_real)
            .map(|h| (h, dir))
    }

    /// The table sample of direct sample `s` of the pixel, if the table has any.
    #[inline]
    fn direct_sample(&self, stream: &Stream, s: u32) -> Option<&'a LightSample> {
        let table = &self.inputs.table.samples;
        let i = stratum_index(&self.strata, s as usize, table.len(), stream.bits(s as u64))?;
        Some(&table[i])
    }

    /// Camera radiance of the real surface at `pixel` (0 where it is missing).
    #[inline]
    fn radiance_at(&self, pixel: (u32, u32)) -> Vec3 {
        let l = *self.inputs.radiance.at(pixel.0, pixel.1);
        if l.is_finite() { l } else { Vec3::ZERO }
    }

    /// Direct and indirect samples of primary j at the real point: always for E_R, and
    /// for E_RV too when `with_rv` (a real primary), with the same random numbers and
    /// paths, adding the virtual objects' blocking and reflection.
    #[allow(clippy::too_many_arguments)]
    fn real_samples(
        &self,
        rp: &RealPoint,
        j: u32,
        direct_stream: &Stream,
        indirect_stream: &Stream,
        bounce_stream: &Stream,
        with_rv: bool,
        acc: &mut Acc,
    ) {
        let params = self.params;
        let max_distance = params.max_distance;
        // The objects E_RV sees from here with the correlated samples.
        let rv_objects = if with_rv { self.objects.as_ref() } else { None };
        for k in 0..params.direct {
            let s = j * params.direct + k;
            let mut c = Vec3::ZERO;
            let mut c_rv = Vec3::ZERO;
            if let Some(ls) = self.direct_sample(direct_stream, s) {
                let cos = rp.normal_world.dot(ls.direction);
                if cos > 0.0 && ls.pdf > 0.0 {
                    let dir_camera = Vec3::from(self.to_camera * Vec3A::from(ls.direction));
                    match self
                        .tracer
                        .trace_camera(rp.camera, dir_camera, max_distance)
                    {
                        Some(hit) => acc.direct_min = acc.direct_min.min(hit.t),
                        None => {
                            c = ls.radiance * (cos / ls.pdf);
                            c_rv = c;
                            let blocker = match rv_objects {
                                Some(o) if rp.cone_world.admits(ls.direction) => {
                                    o.hit(rp.world, ls.direction, f32::INFINITY)
                                }
                                _ => None,
                            };
                            if let Some(hit) = blocker {
                                c_rv = Vec3::ZERO;
                                acc.touched = true;
                                acc.direct_min = acc.direct_min.min(hit.t);
                            }
                        }
                    }
                }
            }
            acc.r_dir += c;
            if with_rv {
                acc.rv_dir += c_rv;
            }
        }
        if with_rv {
            acc.rv_dir_n += params.direct;
            acc.rv_ind_n += params.indirect;
            acc.rv_ind_real_n += params.indirect;
        }
        for k in 0..params.indirect {
            let s = j * params.indirect + k;
            let (u1, u2) = indirect_stream.pair(s as u64);
            let dir_camera = rp.basis_camera.to_world(cosine_hemisphere(u1, u2));
            let real_hit = self
                .tracer
                .trace_camera(rp.camera, dir_camera, max_distance);
            let (l, t_real) = match real_hit {
                Some(hit) => {
                    acc.indirect_min = acc.indirect_min.min(hit.t);
                    (self.radiance_at(hit.pixel), hit.t)
                }
                None => (Vec3::ZERO, f32::INFINITY),
            };
            acc.r_ind += l;
            if with_rv {
                let mut l_rv = l;
                let reflector = match rv_objects {
                    // With object-aware sampling the candidates stand for these paths.
                    Some(o) if !params.object_aware && rp.cone_camera.admits(dir_camera) => {
                        let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
                        o.hit(rp.world, dir, t_real)
                    }
                    _ => None,
                };
                if let Some(hit) = reflector {
                    l_rv = self.object_radiance(&hit, bounce_stream, acc);
                    acc.touched = true;
                    acc.indirect_min = acc.indirect_min.min(hit.t);
                }
                acc.rv_ind += l_rv;
            }
        }
    }

    /// E_RV samples of primary j at a virtual hit seen from direction `to_viewer`.
    #[allow(clippy::too_many_arguments)]
    fn virtual_samples(
        &self,
        hit: &VirtualHit,
        to_viewer: Vec3,
        j: u32,
        direct_stream: &Stream,
        indirect_stream: &Stream,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) {
        let params = self.params;
        let n = hit.normal;
        let material = hit.material;
        let glossy = material.is_glossy();
        let mirror = 2.0 * n.dot(to_viewer) * n - to_viewer;
        let origin = hit.position + n * SURFACE_OFFSET;
        for k in 0..params.direct {
            let s = j * params.direct + k;
            let mut c = Vec3::ZERO;
            if let Some(ls) = self.direct_sample(direct_stream, s) {
                let cos = n.dot(ls.direction);
                if cos > 0.0 && ls.pdf > 0.0 {
                    match self.occluder_distance(origin, ls.direction) {
                        Some(t) => acc.direct_min = acc.direct_min.min(t),
                        None => {
                            let lobe = if glossy {
                                phong_weight(mirror.dot(ls.direction), material.exponent)
                            } else {
                                1.0
                            };
                            c = ls.radiance * (cos / ls.pdf * lobe);
                        }
                    }
                }
            }
            acc.rv_dir += c;
        }
        acc.rv_dir_n += params.direct;
        let basis = Basis::new(if glossy { mirror.normalize_or(n) } else { n });
        for k in 0..params.indirect {
            let s = j * params.indirect + k;
            let (u1, u2) = indirect_stream.pair(s as u64);
            let (dir, weight) = if glossy {
                let dir = basis.to_world(phong_lobe(u1, u2, material.exponent));
                let cos = n.dot(dir);
                let e = material.exponent;
                (
                    dir,
                    if cos > 0.0 {
                        (e + 2.0) / (e + 1.0) * cos
                    } else {
                        0.0
                    },
                )
            } else {
                (basis.to_world(cosine_hemisphere(u1, u2)), 1.0)
            };
            if weight > 0.0 {
                let l = self.incoming(origin, dir, bounce_stream, acc);
                acc.rv_ind += l * weight;
            }
        }
        acc.rv_ind_n += params.indirect;
    }

    /// The distance to the nearest virtual or real occluder along a ray leaving a
    /// virtual surface (real ones within `max_distance`).
    fn occluder_distance(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        let objects = self.objects.as_ref()?;
        if let Some(hit) = objects.hit(origin, dir, f32::INFINITY) {
            return Some(hit.t);
        }
        self.tracer
            .trace(origin, dir, self.params.max_distance)
            .map(|h| h.t)
    }

    /// Radiance arriving at a virtual surface from `dir`: the nearer of the object
    /// (its outgoing radiance) and the real surface (its camera radiance); 0 when the
    /// ray escapes (the environment is counted by direct light).
    fn incoming(&self, origin: Vec3, dir: Vec3, bounce_stream: &Stream, acc: &mut Acc) -> Vec3 {
        let Some(objects) = self.objects.as_ref() else {
            return Vec3::ZERO;
        };
        let real = self.tracer.trace(origin, dir, self.params.max_distance);
        let t_real = real.map_or(f32::INFINITY, |h| h.t);
        if let Some(hit) = objects.hit(origin, dir, t_real) {
            acc.indirect_min = acc.indirect_min.min(hit.t);
            return self.object_radiance(&hit, bounce_stream, acc);
        }
        match real {
            Some(h) => {
                acc.indirect_min = acc.indirect_min.min(h.t);
                self.radiance_at(h.pixel)
            }
            None => Vec3::ZERO,
        }
    }

    /// The outgoing radiance of a virtual surface towards the ray that hit it:
    /// (k_V / pi) E^dir from one importance sample of the table, with virtual
    /// (self-shadowing) and real visibility. Glossy surfaces are treated as diffuse
    /// for this bounce (as paper 000 Sec. 6.4 does); no further bounce.
    fn object_radiance(&self, hit: &VirtualHit, bounce_stream: &Stream, acc: &mut Acc) -> Vec3 {
        let table = &self.inputs.table.samples;
        if table.is_empty() {
            return Vec3::ZERO;
        }
        let h = bounce_stream.bits(acc.bounces);
        acc.bounces += 1;
        let ls = &table[below(h, table.len() as u32) as usize];
        let cos = hit.normal.dot(ls.direction);
        if !(cos > 0.0 && ls.pdf > 0.0) {
            return Vec3::ZERO;
        }
        let origin = hit.position + hit.normal * SURFACE_OFFSET;
        if self.occluder_distance(origin, ls.direction).is_some() {
            return Vec3::ZERO;
        }
        hit.material.albedo * FRAC_1_PI * ls.radiance * (cos / ls.pdf)
    }

    /// Paper 000 Sec. 7: the differential indirect irradiance E_RV - E_R at the real
    /// point from `candidates` cosine directions, of which those meeting the bounding
    /// box (H) are traced, at most `cache_size` of them (H_a, a uniform random subset
    /// by reservoir sampling), the sum scaled by (1 + |H_b| / |H_a|) / candidates.
    /// `None` when no traced direction meets an object.
    fn object_aware(
        &self,
        rp: &RealPoint,
        objects: &Objects,
        rng: &PixelRng,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) -> Option<Vec3> {
        let params = self.params;
        let n = (params.candidates as usize).min(MAX_CANDIDATES);
        let cache_size = (params.cache_size as usize).clamp(1, MAX_CANDIDATES);
        // No cosine direction can meet the sphere when its cone lies below the horizon.
        let cone = rp.cone_camera;
        let sin_half = (1.0 - cone.cos_half * cone.cos_half).max(0.0).sqrt();
        if cone.cos_half > -1.0 && cone.axis.dot(rp.basis_camera.n) < -sin_half - 1e-5 {
            return None;
        }
        let candidates = rng.stream(StreamId::Candidate);
        let reservoir = rng.stream(StreamId::Reservoir);
        let direction = |i: usize| {
            let (u1, u2) = candidates.pair(i as u64);
            rp.basis_camera.to_world(cosine_hemisphere(u1, u2))
        };
        let mut cache = [0u16; MAX_CANDIDATES];
        let mut in_box = 0usize;
        for i in 0..n {
            let dir_camera = direction(i);
            if !cone.admits(dir_camera) {
                continue;
            }
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            if objects
                .aabb
                .ray_span(rp.world, dir.recip(), 0.0, f32::INFINITY)
                .is_none()
            {
                continue;
            }
            if in_box < cache_size {
                cache[in_box] = i as u16;
            } else {
                let r = below(reservoir.bits(i as u64), in_box as u32 + 1) as usize;
                if r < cache_size {
                    cache[r] = i as u16;
                }
            }
            in_box += 1;
        }
        let traced = in_box.min(cache_size);
        let mut sum = Vec3::ZERO;
        let mut met = false;
        for &i in &cache[..traced] {
            let dir_camera = direction(i as usize);
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            let Some(hit) = objects.scene.intersect(rp.world, dir, 0.0, f32::INFINITY) else {
                continue;
            };
            let real = self
                .tracer
                .trace_camera(rp.camera, dir_camera, params.max_distance);
            if real.is_some_and(|r| r.t <= hit.t) {
                continue; // the real surface is in front: no difference
            }
            met = true;
            acc.indirect_min = acc.indirect_min.min(hit.t);
            let l_real = real.map_or(Vec3::ZERO, |r| self.radiance_at(r.pixel));
            sum += self.object_radiance(&hit, bounce_stream, acc) - l_real;
        }
        met.then(|| sum * (PI * in_box as f32 / (traced as f32 * n as f32)))
    }
}

/// `sum` / `count` times `scale`, 0 for no samples.
#[inline]
fn mean(sum: Vec3, count: u32, scale: f32) -> Vec3 {
    if count == 0 {
        Vec3::ZERO
    } else {
        sum * (scale / count as f32)
    }
}

/// Pixels (inclusive bounds) whose footprint may show the box: the projected corners'
/// bounding rectangle grown by a pixel; the whole image when a corner is not in front
/// of the camera.
fn object_pixel_bounds(inputs: &PathInputs, aabb: &Aabb) -> [i64; 4] {
    let (w, h) = (inputs.depth.width as i64, inputs.depth.height as i64);
    let all = [0, 0, w - 1, h - 1];
    let to_camera = inputs.camera_to_world.inverse();
    let (mut lo, mut hi) = (
        glam::Vec2::splat(f32::INFINITY),
        glam::Vec2::splat(f32::NEG_INFINITY),
    );
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { aabb.min.x } else { aabb.max.x },
            if i & 2 == 0 { aabb.min.y } else { aabb.max.y },
            if i & 4 == 0 { aabb.min.z } else { aabb.max.z },
        );
        let c = to_camera.transform_point3(corner);
        if c.z.is_nan() || c.z <= 1e-3 {
            return all;
        }
        let Some(uv) = inputs.camera.project(c) else {
            return all;
        };
        lo = lo.min(uv);
        hi = hi.max(uv);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return all;
    }
    let clamp = |v: f32, max: i64| (v as i64).clamp(-1, max + 1);
    [
        clamp(lo.x - 2.0, w),
        clamp(lo.y - 2.0, h),
        clamp(hi.x + 2.0, w),
        clamp(hi.y + 2.0, h),
    ]
}
