//! The true mixed-reality frame: what the camera would have recorded had virtual objects
//! really stood in the synthetic room, under the same lights and the same
//! interreflection ([`super::indirect`]).
//!
//! The truth is rendered as the recorded radiance plus the true differential, with
//! correlated samples (the differential rendering of Debevec 1998, here with the true
//! scene on both sides): every path is traced once through the room, and at each surface
//! it meets, the room's radiance with the objects and without them differ only where the
//! path meets an object, either hitting it or finding a light sample blocked by it. A
//! pixel whose paths never meet an object has a differential of exactly zero, so its
//! truth is the recorded radiance bit for bit; the 8-bit pixel is then the recorded one.
//! Elsewhere the differential converges with the number of paths, and its standard error
//! is returned with it.
//!
//! For a room point x (albedo rho) the differential is
//! dL(x) = rho / pi (dE_dir(x) + dE_ind(x)), where dE_dir removes the light samples that
//! an object blocks (and that the room does not), and dE_ind follows one cosine-distributed
//! direction: pi (L_object(o) - L_room(y)) when it meets an object o before the room
//! point y, pi dL(y) when it meets y (one bounce deeper), with L_room(y) the room's own
//! radiance (its direct light sampled, its interreflection from the solution). An object
//! point's radiance is its direct light (shadow rays through the room and the objects)
//! plus one sampled bounce: another object point, or a room point's radiance plus its
//! differential. Paths stop after [`TrueFrameSettings::bounces`] surfaces; a light met
//! by a bounce adds nothing (its light is counted by the light samples). The lamp, when
//! it is on, is a point source: one shadow ray gives its light exactly, at room and
//! object points alike.
//!
//! Lamps of the virtual world ([`InsertedObjects::lamps`], paper 002's virtual light
//! sources) are part of what is inserted: at a room point the differential gains their
//! light where neither the room nor the objects block it (the room without the objects
//! never had it), and its bounces carry it on; at an object point they light as the
//! room's lamp does.
//!
//! Objects reflect by the normalized Phong BRDF of `sample.path` (paper 001 Sec. 3):
//! rho / pi for exponent 0, rho (n + 2) / (2 pi) cos^n(alpha) about the mirror direction
//! otherwise.

use super::lamp::SpotLamp;
use super::render::{View, pixel_direction};
use super::scene::{Ray, Scene, direct_irradiance};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng::Counter;
use std::f32::consts::PI;

/// Where a ray met an inserted object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsertedHit {
    /// Distance along the unit ray.
    pub t: f32,
    pub position: Vec3,
    /// Unit normal, facing the ray's origin.
    pub normal: Vec3,
    /// Diffuse albedo (linear RGB).
    pub albedo: Vec3,
    /// Phong exponent (0: Lambertian).
    pub exponent: f32,
}

/// The objects inserted into the room: a nearest-hit and an any-hit query along unit
/// rays.
pub trait InsertedObjects: Sync {
    /// The nearest hit along `origin + t direction`, t in (`t_min`, `t_max`).
    fn intersect(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<InsertedHit>;
    /// True when an object lies along `origin + t direction`, t in (`t_min`, `t_max`).
    fn occluded(&self, origin: Vec3, direction: Vec3, t_min: f32, t_max: f32) -> bool;
    /// Lamps of the virtual world (paper 002's virtual light sources): they light the
    /// room and the objects, and the room and the objects block them. None by default.
    fn lamps(&self) -> &[SpotLamp] {
        &[]
    }
}

/// How much work the truth does per pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueFrameSettings {
    /// Paths per pixel.
    pub paths: u32,
    /// Surfaces a path meets at most (1: direct light and shadows only).
    pub bounces: u32,
    /// Light samples per light at each surface a path meets.
    pub light_samples: u32,
    /// The random numbers' seed.
    pub seed: u64,
}

impl Default for TrueFrameSettings {
    fn default() -> Self {
        TrueFrameSettings {
            paths: 256,
            bounces: 4,
            light_samples: 1,
            seed: 0x5452_5545,
        }
    }
}

/// The true radiance of the pixels asked for.
#[derive(Clone, Debug, PartialEq)]
pub struct TrueFrame {
    pub width: u32,
    pub height: u32,
    /// Linear RGB radiance: the recorded radiance where nothing changed.
    pub radiance: Vec<Vec3>,
    /// Standard error of each pixel's radiance (zero where nothing changed).
    pub standard_error: Vec<Vec3>,
    /// Whether the pixel sees an object.
    pub object: Vec<bool>,
    /// Whether the objects changed the pixel's radiance at all.
    pub changed: Vec<bool>,
}

/// Purpose key of the truth's random numbers.
const TRUTH_PURPOSE: u64 = 21;

/// Renders the true radiance of `view` with `objects` inserted, on the pixels `wanted`
/// keeps (the others keep the recorded radiance), from the recorded radiance
/// `recorded` (row-major, one per pixel) of frame `frame`.
pub fn render_inserted(
    scene: &Scene,
    view: &View,
    recorded: &[Vec3],
    objects: &dyn InsertedObjects,
    frame: u64,
    settings: &TrueFrameSettings,
    wanted: &(dyn Fn(u32, u32) -> bool + Sync),
) -> TrueFrame {
    let k = view.intrinsics;
    let width = k.width as usize;
    let n = width * k.height as usize;
    assert_eq!(recorded.len(), n, "one recorded radiance per pixel");
    let tracer = Tracer {
        scene,
        objects,
        settings,
    };
    let pixels: Vec<(Vec3, Vec3, bool, bool)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % width) as u32, (i / width) as u32);
            if !wanted(x, y) {
                return (recorded[i], Vec3::ZERO, false, false);
            }
            let direction = (view.rotation * pixel_direction(&k, x, y)).normalize();
            let mut rng = Counter::new(&[settings.seed, frame, TRUTH_PURPOSE, i as u64]);
            tracer.pixel(view.position, direction, recorded[i], &mut rng)
        })
        .collect();
    TrueFrame {
        width: k.width,
        height: k.height,
        radiance: pixels.iter().map(|p| p.0).collect(),
        standard_error: pixels.iter().map(|p| p.1).collect(),
        object: pixels.iter().map(|p| p.2).collect(),
        changed: pixels.iter().map(|p| p.3).collect(),
    }
}

/// The path tracer of the truth.
struct Tracer<'a> {
    scene: &'a Scene,
    objects: &'a dyn InsertedObjects,
    settings: &'a TrueFrameSettings,
}

/// A room surface point a path met.
#[derive(Clone, Copy)]
struct RoomPoint {
    position: Vec3,
    normal: Vec3,
    albedo: Vec3,
    /// The room's own radiance there is light (an emitter's).
    emitter: bool,
    hit: super::geometry::Hit,
}

/// What a ray from a point meets first: the room, an object in front of it, or nothing.
enum Meets {
    Room(RoomPoint),
    Object(InsertedHit, Option<RoomPoint>),
    Nothing,
}

impl Tracer<'_> {
    /// (radiance, standard error, sees an object, changed) of the pixel whose camera ray
    /// is `origin + t direction`.
    fn pixel(
        &self,
        origin: Vec3,
        direction: Vec3,
        recorded: Vec3,
        rng: &mut Counter,
    ) -> (Vec3, Vec3, bool, bool) {
        let paths = self.settings.paths.max(1);
        let first = self.meets(origin, direction);
        let (mut sum, mut squares) = (Vec3::ZERO, Vec3::ZERO);
        let object = matches!(first, Meets::Object(..));
        for _ in 0..paths {
            let value = match &first {
                Meets::Object(hit, _) => self.object_radiance(hit, -direction, 0, rng),
                Meets::Room(point) => self.differential(point, 0, rng),
                Meets::Nothing => Vec3::ZERO,
            };
            sum += value;
            squares += value * value;
        }
        let mean = sum / paths as f32;
        let variance = (squares / paths as f32 - mean * mean).max(Vec3::ZERO);
        let error = (variance / (paths.max(2) - 1) as f32).powf(0.5);
        if object {
            (mean, error, true, true)
        } else if sum == Vec3::ZERO {
            // No path met an object: the recorded radiance, bit for bit.
            (recorded, Vec3::ZERO, false, false)
        } else {
            (recorded + mean, error, false, true)
        }
    }

    /// What the unit ray `origin + t direction` meets first.
    fn meets(&self, origin: Vec3, direction: Vec3) -> Meets {
        let room = self
            .scene
            .intersect(&Ray { origin, direction }, 0.0)
            .map(|hit| {
                let material = self.scene.material(&hit);
                RoomPoint {
                    position: hit.position,
                    normal: hit.normal,
                    albedo: material.albedo,
                    emitter: material.emission != Vec3::ZERO,
                    hit,
                }
            });
        let t_max = room.map_or(f32::INFINITY, |p| p.hit.t);
        match self.objects.intersect(origin, direction, 1e-4, t_max) {
            Some(hit) => Meets::Object(hit, room),
            None => room.map_or(Meets::Nothing, Meets::Room),
        }
    }

    /// The room's own radiance at `point` (no objects): direct light sampled, the
    /// interreflection from the solution; zero for a light (its light is direct light).
    fn room_radiance(&self, point: &RoomPoint, rng: &mut Counter) -> Vec3 {
        if point.emitter {
            return Vec3::ZERO;
        }
        let grid = (self.settings.light_samples.max(1), 1);
        let direct = direct_irradiance(self.scene, point.position, point.normal, rng, grid);
        point.albedo * ((direct + self.scene.indirect_irradiance(&point.hit)) / PI)
    }

    /// One sample of the change the objects make to the radiance leaving room point
    /// `point` (met at path depth `depth`).
    fn differential(&self, point: &RoomPoint, depth: u32, rng: &mut Counter) -> Vec3 {
        if point.emitter {
            return Vec3::ZERO;
        }
        let origin = point.position + point.normal * 1e-4;
        // The light samples the objects block (and the room does not).
        let mut direct = Vec3::ZERO;
        let m = self.settings.light_samples.max(1);
        for light in &self.scene.lights {
            let mut blocked = 0.0f32;
            for _ in 0..m {
                let q = light.point(rng.next_f32(), rng.next_f32());
                let w = q - origin;
                let (here, there) = (point.normal.dot(w), -light.normal.dot(w));
                if here <= 0.0 || there <= 0.0 {
                    continue;
                }
                let d = w.length();
                if self.objects.occluded(origin, w / d, 1e-4, d * (1.0 - 1e-4))
                    && !self.scene.occluded(origin, q)
                {
                    let d2 = d * d;
                    blocked += here * there / (d2 * d2);
                }
            }
            direct -= light.radiance * (blocked * light.area() / m as f32);
        }
        // The lamp's light, one exact shadow ray.
        if let Some(lamp) = &self.scene.lamp
            && let Some((irradiance, to_lamp, d)) = lamp.arrival(origin, point.normal)
            && self
                .objects
                .occluded(origin, to_lamp, 1e-4, d * (1.0 - 1e-4))
            && !self.scene.occluded(origin, lamp.position)
        {
            direct -= irradiance;
        }
        // The virtual lamps' light, which the room without the objects never had.
        for lamp in self.objects.lamps() {
            direct += self.virtual_lamp(lamp, origin, point.normal, |_| 1.0);
        }
        // One bounce: what the objects change in the light arriving from a cosine-
        // distributed direction.
        let mut indirect = Vec3::ZERO;
        if depth + 1 < self.settings.bounces {
            let direction = cosine_direction(point.normal, rng);
            indirect = match self.meets(origin, direction) {
                Meets::Object(hit, behind) => {
                    let with = self.object_radiance(&hit, -direction, depth + 1, rng);
                    let without = behind.map_or(Vec3::ZERO, |y| self.room_radiance(&y, rng));
                    (with - without) * PI
                }
                Meets::Room(y) => self.differential(&y, depth + 1, rng) * PI,
                Meets::Nothing => Vec3::ZERO,
            };
        }
        point.albedo / PI * (direct + indirect)
    }

    /// The light virtual `lamp` brings to `origin` (a point just off a surface with unit
    /// normal `normal`) where neither the room nor the objects block it, weighted by
    /// `lobe` of the direction towards it.
    fn virtual_lamp(
        &self,
        lamp: &SpotLamp,
        origin: Vec3,
        normal: Vec3,
        lobe: impl Fn(Vec3) -> f32,
    ) -> Vec3 {
        match lamp.arrival(origin, normal) {
            Some((irradiance, wi, d))
                if !self.scene.occluded(origin, lamp.position)
                    && !self.objects.occluded(origin, wi, 1e-4, d * (1.0 - 1e-4)) =>
            {
                irradiance * lobe(wi)
            }
            _ => Vec3::ZERO,
        }
    }

    /// One sample of the radiance leaving object point `hit` towards `to_viewer`.
    fn object_radiance(
        &self,
        hit: &InsertedHit,
        to_viewer: Vec3,
        depth: u32,
        rng: &mut Counter,
    ) -> Vec3 {
        let n = hit.normal;
        let origin = hit.position + n * 1e-4;
        let mirror = (2.0 * n.dot(to_viewer) * n - to_viewer).normalize_or(n);
        let glossy = hit.exponent > 0.0;
        // pi f / rho: 1 for Lambertian, (n + 2) / 2 cos^n(alpha) for Phong.
        let lobe = |wi: Vec3| {
            if glossy {
                let c = mirror.dot(wi);
                if c > 0.0 {
                    0.5 * (hit.exponent + 2.0) * c.powf(hit.exponent)
                } else {
                    0.0
                }
            } else {
                1.0
            }
        };
        let mut direct = Vec3::ZERO;
        let m = self.settings.light_samples.max(1);
        for light in &self.scene.lights {
            let mut sum = 0.0f32;
            for _ in 0..m {
                let q = light.point(rng.next_f32(), rng.next_f32());
                let w = q - origin;
                let (here, there) = (n.dot(w), -light.normal.dot(w));
                if here <= 0.0 || there <= 0.0 {
                    continue;
                }
                let d = w.length();
                let wi = w / d;
                if self.scene.occluded(origin, q)
                    || self.objects.occluded(origin, wi, 1e-4, d * (1.0 - 1e-4))
                {
                    continue;
                }
                let d2 = d * d;
                sum += here * there / (d2 * d2) * lobe(wi);
            }
            direct += light.radiance * (sum * light.area() / m as f32);
        }
        if let Some(lamp) = &self.scene.lamp
            && let Some((irradiance, wi, d)) = lamp.arrival(origin, n)
            && !self.scene.occluded(origin, lamp.position)
            && !self.objects.occluded(origin, wi, 1e-4, d * (1.0 - 1e-4))
        {
            direct += irradiance * lobe(wi);
        }
        for lamp in self.objects.lamps() {
            direct += self.virtual_lamp(lamp, origin, n, lobe);
        }
        let mut indirect = Vec3::ZERO;
        if depth + 1 < self.settings.bounces {
            // pi f cos / pdf / rho: 1 for cosine sampling of a Lambertian surface,
            // (n + 2) / (n + 1) cos for sampling the Phong lobe.
            let (direction, weight) = if glossy {
                let basis = mirror.any_orthonormal_pair();
                let (u1, u2) = (rng.next_f32(), rng.next_f32());
                let cos_a = (1.0 - u1).powf(1.0 / (hit.exponent + 1.0));
                let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
                let (s, c) = (2.0 * PI * u2).sin_cos();
                let d = basis.0 * (sin_a * c) + basis.1 * (sin_a * s) + mirror * cos_a;
                let cos = n.dot(d);
                (
                    d,
                    if cos > 0.0 {
                        (hit.exponent + 2.0) / (hit.exponent + 1.0) * cos
                    } else {
                        0.0
                    },
                )
            } else {
                (cosine_direction(n, rng), 1.0)
            };
            if weight > 0.0 {
                let arriving = match self.meets(origin, direction) {
                    Meets::Object(next, _) => {
                        self.object_radiance(&next, -direction, depth + 1, rng)
                    }
                    Meets::Room(y) => {
                        self.room_radiance(&y, rng) + self.differential(&y, depth + 1, rng)
                    }
                    Meets::Nothing => Vec3::ZERO,
                };
                indirect = arriving * PI * weight;
            }
        }
        hit.albedo / PI * (direct + indirect)
    }
}

/// A cosine-distributed unit direction about `normal`.
fn cosine_direction(normal: Vec3, rng: &mut Counter) -> Vec3 {
    let (tangent, bitangent) = normal.any_orthonormal_pair();
    let (u1, u2) = (rng.next_f32(), rng.next_f32());
    let r = u1.sqrt();
    let (s, c) = (2.0 * PI * u2).sin_cos();
    tangent * (r * c) + bitangent * (r * s) + normal * (1.0 - u1).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::SynthConfig;
    use crate::synth::camera::camera_pose;
    use crate::synth::geometry::{Sphere, ray_sphere};
    use crate::synth::render::render_view;
    use crate::synth::scene::OBJECT_POSITION;
    use glam::DMat3;

    struct NoObjects;

    impl InsertedObjects for NoObjects {
        fn intersect(&self, _: Vec3, _: Vec3, _: f32, _: f32) -> Option<InsertedHit> {
            None
        }
        fn occluded(&self, _: Vec3, _: Vec3, _: f32, _: f32) -> bool {
            false
        }
    }

    /// A sphere resting on the floor at the object position.
    struct Ball {
        sphere: Sphere,
        albedo: Vec3,
    }

    impl InsertedObjects for Ball {
        fn intersect(
            &self,
            origin: Vec3,
            direction: Vec3,
            t_min: f32,
            t_max: f32,
        ) -> Option<InsertedHit> {
            let ray = Ray { origin, direction };
            let t = ray_sphere(&ray, &self.sphere, t_min, t_max)?;
            let position = ray.at(t);
            let mut normal = (position - self.sphere.center) / self.sphere.radius;
            if normal.dot(direction) > 0.0 {
                normal = -normal;
            }
            Some(InsertedHit {
                t,
                position,
                normal,
                albedo: self.albedo,
                exponent: 0.0,
            })
        }
        fn occluded(&self, origin: Vec3, direction: Vec3, t_min: f32, t_max: f32) -> bool {
            ray_sphere(&Ray { origin, direction }, &self.sphere, t_min, t_max).is_some()
        }
    }

    /// Frame 14's view of the default path at 64 x 48 and its recorded radiance.
    fn small_frame(scene: &Scene) -> (View, Vec<Vec3>) {
        let config = SynthConfig {
            width: 64,
            height: 48,
            ..SynthConfig::default()
        };
        let pose = camera_pose(14.0 / config.fps);
        let view = View {
            rotation: DMat3::from_quat(pose.rotation()).as_mat3(),
            position: pose.translation().as_vec3(),
            intrinsics: config.intrinsics(),
        };
        let recorded = render_view(scene, &view, config.seed, 14).radiance;
        (view, recorded)
    }

    #[test]
    fn with_no_objects_the_truth_is_the_recorded_frame() {
        let scene = crate::synth::interreflection::room();
        let (view, recorded) = small_frame(&scene);
        let settings = TrueFrameSettings {
            paths: 8,
            ..TrueFrameSettings::default()
        };
        let truth = render_inserted(
            &scene,
            &view,
            &recorded,
            &NoObjects,
            14,
            &settings,
            &|_, _| true,
        );
        assert_eq!(truth.radiance, recorded);
        assert!(truth.changed.iter().all(|c| !c));
        assert!(truth.object.iter().all(|o| !o));
        assert!(truth.standard_error.iter().all(|e| *e == Vec3::ZERO));
    }

    #[test]
    fn pixels_the_objects_do_not_reach_keep_their_recorded_radiance_and_the_shadow_darkens() {
        let scene = crate::synth::interreflection::room();
        let (view, recorded) = small_frame(&scene);
        let ball = Ball {
            sphere: Sphere {
                center: OBJECT_POSITION,
                radius: 0.3,
            },
            albedo: Vec3::splat(0.2),
        };
        let settings = TrueFrameSettings {
            paths: 32,
            bounces: 3,
            ..TrueFrameSettings::default()
        };
        let truth = render_inserted(&scene, &view, &recorded, &ball, 14, &settings, &|_, _| true);
        let n = recorded.len();
        let objects = truth.object.iter().filter(|o| **o).count();
        let unchanged: Vec<usize> = (0..n).filter(|&i| !truth.changed[i]).collect();
        assert!(objects > 20, "the ball is in view: {objects} pixels");
        assert!(
            unchanged.len() > n / 4,
            "{} of {n} pixels unchanged",
            unchanged.len()
        );
        for &i in &unchanged {
            assert_eq!(
                truth.radiance[i].to_array().map(f32::to_bits),
                recorded[i].to_array().map(f32::to_bits)
            );
            assert_eq!(truth.standard_error[i], Vec3::ZERO);
        }
        // A dark ball takes more light from the room than it gives back: the changed room
        // pixels darken on the whole, and the floor at its foot (within 10 cm) darkens
        // by more than its own noise.
        let (mut change, mut foot_change, mut foot_error, mut foot) = (0.0f32, 0.0f32, 0.0f32, 0);
        for (i, &before) in recorded.iter().enumerate() {
            if !truth.changed[i] || truth.object[i] {
                continue;
            }
            let dl = (truth.radiance[i] - before).element_sum();
            change += dl;
            let (x, y) = ((i % 64) as u32, (i / 64) as u32);
            let direction = (view.rotation * pixel_direction(&view.intrinsics, x, y)).normalize();
            let hit = scene
                .intersect(
                    &Ray {
                        origin: view.position,
                        direction,
                    },
                    0.0,
                )
                .unwrap();
            let p = hit.position;
            let from_axis = (p - Vec3::new(OBJECT_POSITION.x, 0.0, OBJECT_POSITION.z)).length();
            if p.y.abs() < 1e-3 && from_axis < 0.4 {
                foot += 1;
                foot_change += dl;
                foot_error += truth.standard_error[i].element_sum();
            }
        }
        assert!(change < 0.0, "net change {change}");
        assert!(foot > 0, "the floor at the ball's foot is in view");
        assert!(
            -foot_change > 3.0 * foot_error,
            "foot: change {foot_change}, error {foot_error} over {foot} pixels"
        );
        // Object pixels: lit, and with a reported error.
        for i in (0..n).filter(|&i| truth.object[i]) {
            assert!(truth.radiance[i].max_element() > 0.0);
            assert!(truth.standard_error[i].max_element() > 0.0);
        }
    }

    /// Virtual lamps and no objects.
    struct Lamps(Vec<SpotLamp>);

    impl InsertedObjects for Lamps {
        fn intersect(&self, _: Vec3, _: Vec3, _: f32, _: f32) -> Option<InsertedHit> {
            None
        }
        fn occluded(&self, _: Vec3, _: Vec3, _: f32, _: f32) -> bool {
            false
        }
        fn lamps(&self) -> &[SpotLamp] {
            &self.0
        }
    }

    #[test]
    fn a_virtual_lamp_adds_its_exact_light_where_it_reaches_and_nothing_elsewhere() {
        let scene = crate::synth::interreflection::room();
        let (view, recorded) = small_frame(&scene);
        // The room's lamp, but virtual: the recording never had it.
        let lamp = crate::synth::lamp::room_lamp();
        let settings = TrueFrameSettings {
            paths: 4,
            bounces: 1,
            ..TrueFrameSettings::default()
        };
        let truth = render_inserted(
            &scene,
            &view,
            &recorded,
            &Lamps(vec![lamp]),
            14,
            &settings,
            &|_, _| true,
        );
        let (mut lit, mut dark) = (0, 0);
        for (i, &before) in recorded.iter().enumerate() {
            let (x, y) = ((i % 64) as u32, (i / 64) as u32);
            let direction = (view.rotation * pixel_direction(&view.intrinsics, x, y)).normalize();
            let ray = Ray {
                origin: view.position,
                direction,
            };
            let hit = scene.intersect(&ray, 0.0).unwrap();
            let material = scene.material(&hit);
            let origin = hit.position + hit.normal * 1e-4;
            let added = match lamp.arrival(origin, hit.normal) {
                Some((e, _, _)) if !scene.occluded(origin, lamp.position) => {
                    material.albedo / PI * e
                }
                _ => Vec3::ZERO,
            };
            assert!(!truth.object[i]);
            if added == Vec3::ZERO {
                // Outside its cone or in a real shadow of it: the recorded pixel.
                assert_eq!(truth.radiance[i], before, "pixel {i}");
                dark += 1;
            } else {
                // One bounce: the lamp's light alone, the same on every path.
                let error = (truth.radiance[i] - (before + added)).abs().max_element();
                assert!(
                    error <= 1e-5 * (before + added).max_element(),
                    "pixel {i}: {error}"
                );
                assert_eq!(truth.standard_error[i], Vec3::ZERO);
                lit += 1;
            }
        }
        assert!(lit > 200 && dark > 200, "{lit} lit, {dark} not");
    }

    #[test]
    fn the_lamp_switched_on_is_shadowed_by_an_inserted_object_exactly() {
        // The room with its lamp on, and a ball hanging between the lamp and the floor
        // where it is aimed: that floor loses the lamp's light.
        let scene =
            crate::synth::interreflection::room_lit(crate::synth::interreflection::RoomLights {
                panel: true,
                lamp: true,
            });
        let lamp = scene.lamp.unwrap();
        let floor = crate::synth::lamp::LAMP_AIM;
        let ball = Ball {
            sphere: Sphere {
                center: lamp.position + (floor - lamp.position) * 0.6,
                radius: 0.15,
            },
            albedo: Vec3::splat(0.5),
        };
        let tracer = Tracer {
            scene: &scene,
            objects: &ball,
            settings: &TrueFrameSettings {
                paths: 1,
                bounces: 1,
                light_samples: 1,
                seed: 1,
            },
        };
        let point = |p: Vec3| {
            let hit = scene
                .intersect(
                    &Ray {
                        origin: p + Vec3::Y,
                        direction: Vec3::NEG_Y,
                    },
                    0.0,
                )
                .unwrap();
            let material = scene.material(&hit);
            RoomPoint {
                position: hit.position,
                normal: hit.normal,
                albedo: material.albedo,
                emitter: false,
                hit,
            }
        };
        let shadowed = point(floor);
        let lost = lamp
            .arrival(shadowed.position + Vec3::Y * 1e-4, Vec3::Y)
            .unwrap()
            .0;
        // The ball blocks neither the panel nor the window from there: the change is the
        // lamp's light alone, on every draw.
        let mut rng = Counter::new(&[3]);
        let expected = -shadowed.albedo / PI * lost;
        for _ in 0..16 {
            let change = tracer.differential(&shadowed, 0, &mut rng);
            assert!(
                (change - expected).abs().max_element() < 1e-6,
                "{change} vs {expected}"
            );
        }
    }

    #[test]
    fn pixels_left_out_keep_the_recorded_radiance() {
        let scene = crate::synth::interreflection::room();
        let (view, recorded) = small_frame(&scene);
        let ball = Ball {
            sphere: Sphere {
                center: OBJECT_POSITION,
                radius: 0.3,
            },
            albedo: Vec3::splat(0.2),
        };
        let settings = TrueFrameSettings {
            paths: 4,
            bounces: 2,
            ..TrueFrameSettings::default()
        };
        let truth = render_inserted(&scene, &view, &recorded, &ball, 14, &settings, &|x, y| {
            x % 4 == 0 && y % 4 == 0
        });
        for (i, &before) in recorded.iter().enumerate() {
            if (i % 64) % 4 != 0 || (i / 64) % 4 != 0 {
                assert_eq!(truth.radiance[i], before);
                assert!(!truth.changed[i] && !truth.object[i]);
            }
        }
        assert!(truth.object.iter().any(|o| *o));
    }
}
