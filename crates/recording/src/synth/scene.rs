//! The analytic room of the synthetic recordings: its surfaces, furniture and lights,
//! materials, and the first hit and shadow queries over them.
//!
//! World frame: right-handed, metres, +y up, the floor at y = 0. The room spans
//! x in [-2.5, 2.5], z in [-2.5, 2.5] and y in [0, 2.6]. The walls are named by the
//! direction they face away from the room centre: west (x = -2.5), east (x = +2.5, with
//! the window), north (z = -2.5) and south (z = +2.5).
//!
//! The scene is fixed: it does not depend on the seed or on any setting, so every
//! recording shows the same room.

pub use super::geometry::{
    AxisBox, Hit, Ray, Sphere, ray_box_entry, ray_sphere, segment_crosses_box,
};
use super::indirect::IndirectLight;
pub use super::lamp::SpotLamp;
pub use super::room::{ROOM_MAX, ROOM_MIN, Surface};
pub use super::texture::BlockTexture;
use super::texture::{BALL_ALBEDO, block_albedo, room_albedo};
use glam::Vec3;
use relume_base::rng::Counter;
use std::sync::Arc;

/// Centre of the free spot left for a virtual object: 0.3 m above the middle of the
/// floor, so a sphere of radius 0.3 m placed here rests on the floor.
pub const OBJECT_POSITION: Vec3 = Vec3::new(0.0, 0.3, 0.0);
/// [`OBJECT_POSITION`] in double precision, as stored in the header.
pub const OBJECT_POSITION_F64: glam::DVec3 = glam::DVec3::new(0.0, 0.3, 0.0);

/// Reflectance and emission of a surface point (linear RGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Diffuse albedo in [0, 1].
    pub albedo: Vec3,
    /// Emitted radiance (zero for non-emitters).
    pub emission: Vec3,
}

/// A one-sided emissive rectangle `corner + u * edge_u + v * edge_v`, u, v in [0, 1],
/// lying on a room surface and emitting towards `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectLight {
    pub corner: Vec3,
    pub edge_u: Vec3,
    pub edge_v: Vec3,
    /// Unit normal on the emitting side.
    pub normal: Vec3,
    /// Emitted radiance, constant over the rectangle.
    pub radiance: Vec3,
    /// The room surface the rectangle lies on.
    pub surface: Surface,
}

impl RectLight {
    /// Area in square metres.
    pub fn area(&self) -> f32 {
        self.edge_u.cross(self.edge_v).length()
    }

    /// The point at rectangle coordinates (u, v) in [0, 1]^2.
    #[inline]
    pub fn point(&self, u: f32, v: f32) -> Vec3 {
        self.corner + self.edge_u * u + self.edge_v * v
    }

    /// True when `p` (a point on the light's surface) lies inside the rectangle.
    pub fn contains(&self, p: Vec3) -> bool {
        let d = p - self.corner;
        let u = d.dot(self.edge_u) / self.edge_u.length_squared();
        let v = d.dot(self.edge_v) / self.edge_v.length_squared();
        (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)
    }
}

/// An axis-aligned box standing on the floor, with its texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block {
    pub bounds: AxisBox,
    pub texture: BlockTexture,
}

/// The whole scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The room's interior, seen from inside.
    pub room: AxisBox,
    pub blocks: Vec<Block>,
    pub ball: Sphere,
    /// The ceiling light and the window.
    pub lights: [RectLight; 2],
    /// The lamp, when it is on ([`super::lamp`]); `None`: off.
    pub lamp: Option<SpotLamp>,
    /// The light the surfaces reflect onto each other, solved once ([`super::interreflection::room`]);
    /// `None` lights the room by the two lights' direct light alone.
    pub indirect: Option<Arc<IndirectLight>>,
}

impl Scene {
    /// The room's geometry, materials and lights, lit by direct light alone.
    pub fn room_without_interreflection() -> Scene {
        let block = |min: [f32; 3], max: [f32; 3], texture| Block {
            bounds: AxisBox {
                min: Vec3::from_array(min),
                max: Vec3::from_array(max),
            },
            texture,
        };
        Scene {
            room: AxisBox {
                min: ROOM_MIN,
                max: ROOM_MAX,
            },
            blocks: vec![
                block([-1.8, 0.0, 0.8], [-1.0, 0.7, 1.6], BlockTexture::Wood),
                block([1.5, 0.0, -2.4], [2.3, 1.5, -1.9], BlockTexture::Drawers),
                block([0.55, 0.0, 0.45], [0.95, 0.4, 0.85], BlockTexture::Checker),
                block([-0.6, 0.0, -2.5], [0.6, 0.45, -2.1], BlockTexture::Fabric),
            ],
            ball: Sphere {
                center: Vec3::new(-0.8, 0.35, -0.9),
                radius: 0.35,
            },
            lights: [
                // Warm white panel in the middle of the ceiling, emitting downwards.
                RectLight {
                    corner: Vec3::new(-0.6, ROOM_MAX.y, -0.4),
                    edge_u: Vec3::new(1.2, 0.0, 0.0),
                    edge_v: Vec3::new(0.0, 0.0, 0.8),
                    normal: Vec3::NEG_Y,
                    radiance: Vec3::new(7.0, 5.6, 4.0),
                    surface: Surface::Ceiling,
                },
                // Bright sky-blue window on the east wall, emitting into the room.
                RectLight {
                    corner: Vec3::new(ROOM_MAX.x, 0.85, -0.9),
                    edge_u: Vec3::new(0.0, 0.0, 1.6),
                    edge_v: Vec3::new(0.0, 1.2, 0.0),
                    normal: Vec3::NEG_X,
                    radiance: Vec3::new(7.5, 9.0, 11.5),
                    surface: Surface::EastWall,
                },
            ],
            lamp: None,
            indirect: None,
        }
    }

    /// The first surface along `ray` with t > `t_min`. Inside the room every ray hits
    /// something; `None` only for rays starting outside it or degenerate directions.
    pub fn intersect(&self, ray: &Ray, t_min: f32) -> Option<Hit> {
        let (mut t, mut normal, mut surface) = ray_room_exit(ray, &self.room)?;
        for (i, b) in self.blocks.iter().enumerate() {
            if let Some((tb, nb)) = ray_box_entry(ray, &b.bounds, t_min, t) {
                (t, normal, surface) = (tb, nb, Surface::Block(i));
            }
        }
        if let Some(ts) = ray_sphere(ray, &self.ball, t_min, t) {
            let p = ray.at(ts);
            (t, normal, surface) = (ts, (p - self.ball.center) / self.ball.radius, Surface::Ball);
        }
        if t <= t_min || !t.is_finite() {
            return None;
        }
        Some(Hit {
            t,
            position: ray.at(t),
            normal,
            surface,
        })
    }

    /// True when a box or the sphere blocks the segment from `from` to `to`. The room is
    /// convex and the lights lie on its boundary, so walls never occlude.
    pub fn occluded(&self, from: Vec3, to: Vec3) -> bool {
        self.occluded_by(ALL_OCCLUDERS, from, to)
    }

    /// The occluders (bit i: block i, bit [`BALL_BIT`]: the sphere) whose bounds overlap
    /// the bounds of `from` and the whole of `light`: the only ones that can block a
    /// segment from `from` to any point of the light.
    pub fn occluders_towards(&self, from: Vec3, light: &RectLight) -> u32 {
        let far = light.corner + light.edge_u + light.edge_v;
        let lo = from.min(light.corner).min(far);
        let hi = from.max(light.corner).max(far);
        let overlaps = |b: &AxisBox| b.min.cmple(hi).all() && b.max.cmpge(lo).all();
        let mut mask = 0;
        for (i, b) in self.blocks.iter().enumerate().take(BALL_BIT as usize) {
            if overlaps(&b.bounds) {
                mask |= 1 << i;
            }
        }
        let r = Vec3::splat(self.ball.radius);
        if overlaps(&AxisBox {
            min: self.ball.center - r,
            max: self.ball.center + r,
        }) {
            mask |= 1 << BALL_BIT;
        }
        mask
    }

    /// True when one of the occluders in `mask` (see [`Scene::occluders_towards`])
    /// blocks the segment from `from` to `to`.
    pub fn occluded_by(&self, mask: u32, from: Vec3, to: Vec3) -> bool {
        if mask == 0 {
            return false;
        }
        let direction = to - from;
        let inv = direction.recip();
        let (t_min, t_max) = (1e-5, 1.0 - 1e-4);
        for (i, b) in self.blocks.iter().enumerate().take(BALL_BIT as usize) {
            if mask & (1 << i) != 0 && segment_crosses_box(from, inv, &b.bounds, t_min, t_max) {
                return true;
            }
        }
        mask & (1 << BALL_BIT) != 0
            && ray_sphere(
                &Ray {
                    origin: from,
                    direction,
                },
                &self.ball,
                t_min,
                t_max,
            )
            .is_some()
    }

    /// The lamp's direct light at `origin` (a point just off a surface with unit normal
    /// `normal`): zero when it is off, outside its cone, or a box or the sphere blocks
    /// it. One shadow ray: a point source's light is exact.
    pub fn lamp_irradiance(&self, origin: Vec3, normal: Vec3) -> Vec3 {
        match self
            .lamp
            .and_then(|lamp| Some((lamp, lamp.arrival(origin, normal)?)))
        {
            Some((lamp, (irradiance, _, _))) if !self.occluded(origin, lamp.position) => irradiance,
            _ => Vec3::ZERO,
        }
    }

    /// The irradiance the room's surfaces reflect onto `hit` (zero without a solution).
    pub fn indirect_irradiance(&self, hit: &Hit) -> Vec3 {
        self.indirect.as_ref().map_or(Vec3::ZERO, |s| s.at(hit))
    }

    /// Albedo and emission at a hit.
    pub fn material(&self, hit: &Hit) -> Material {
        for light in &self.lights {
            if light.surface == hit.surface && light.contains(hit.position) {
                return Material {
                    albedo: Vec3::ZERO,
                    emission: light.radiance,
                };
            }
        }
        let albedo = match hit.surface {
            Surface::Block(i) => match self.blocks.get(i) {
                // Evaluated just inside the face, so 3D patterns are stable on faces
                // that lie on a pattern boundary.
                Some(b) => block_albedo(b.texture, hit.position - hit.normal * 1e-3),
                None => Vec3::splat(0.5),
            },
            Surface::Ball => BALL_ALBEDO,
            other => room_albedo(other, hit.position),
        };
        Material {
            albedo,
            emission: Vec3::ZERO,
        }
    }
}

/// The irradiance at `position` (unit `normal`) from both area lights: for each, `grid`
/// stratified points on its area (one jittered sample per cell), each weighted by
/// cos_here cos_light / d^2 when no box or the sphere blocks it; and the lamp's, when
/// it is on ([`Scene::lamp_irradiance`], no random numbers: the area lights' draws are
/// the same with the lamp on or off).
pub fn direct_irradiance(
    scene: &Scene,
    position: Vec3,
    normal: Vec3,
    rng: &mut Counter,
    grid: (u32, u32),
) -> Vec3 {
    let origin = position + normal * 1e-4;
    let samples = (grid.0 * grid.1).max(1) as f32;
    let mut irradiance = Vec3::ZERO;
    for light in &scene.lights {
        let occluders = scene.occluders_towards(origin, light);
        let mut geometry_sum = 0.0f32;
        for j in 0..grid.0 {
            for k in 0..grid.1 {
                let u = (j as f32 + rng.next_f32()) / grid.0 as f32;
                let v = (k as f32 + rng.next_f32()) / grid.1 as f32;
                let q = light.point(u, v);
                let w = q - origin;
                // cos_here * cos_light / d^2 with unnormalized w: no square root.
                let here = normal.dot(w);
                let there = -light.normal.dot(w);
                if here <= 0.0 || there <= 0.0 || scene.occluded_by(occluders, origin, q) {
                    continue;
                }
                let d2 = w.length_squared();
                geometry_sum += here * there / (d2 * d2);
            }
        }
        irradiance += light.radiance * (geometry_sum * light.area() / samples);
    }
    if scene.lamp.is_some() {
        irradiance += scene.lamp_irradiance(origin, normal);
    }
    irradiance
}

/// Where a ray from inside `room` leaves it: parameter, inward unit normal and surface.
pub fn ray_room_exit(ray: &Ray, room: &AxisBox) -> Option<(f32, Vec3, Surface)> {
    let mut best: Option<(f32, Vec3, Surface)> = None;
    let faces = [
        (
            ray.direction.x,
            ray.origin.x,
            room.min.x,
            room.max.x,
            Vec3::X,
        ),
        (
            ray.direction.y,
            ray.origin.y,
            room.min.y,
            room.max.y,
            Vec3::Y,
        ),
        (
            ray.direction.z,
            ray.origin.z,
            room.min.z,
            room.max.z,
            Vec3::Z,
        ),
    ];
    let surfaces = [
        (Surface::WestWall, Surface::EastWall),
        (Surface::Floor, Surface::Ceiling),
        (Surface::NorthWall, Surface::SouthWall),
    ];
    for ((d, o, lo, hi, axis), (low_surface, high_surface)) in faces.into_iter().zip(surfaces) {
        let (t, normal, surface) = if d > 0.0 {
            ((hi - o) / d, -axis, high_surface)
        } else if d < 0.0 {
            ((lo - o) / d, axis, low_surface)
        } else {
            continue;
        };
        if best.is_none_or(|(tb, _, _)| t < tb) {
            best = Some((t, normal, surface));
        }
    }
    best.filter(|(t, _, _)| *t > 0.0)
}

/// Bit of the sphere in occluder masks (blocks use the bits below it).
pub const BALL_BIT: u32 = 31;
/// An occluder mask naming every block and the sphere.
pub const ALL_OCCLUDERS: u32 = u32::MAX;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_from_inside_leave_the_room_through_the_right_surface() {
        let room = Scene::room_without_interreflection().room;
        let (t, n, s) = ray_room_exit(&Ray::new([0.0, 1.0, 0.0], [0.0, -1.0, 0.0]), &room).unwrap();
        assert_eq!((t, n, s), (1.0, Vec3::Y, Surface::Floor));
        let (t, n, s) = ray_room_exit(&Ray::new([0.0, 1.0, 0.0], [1.0, 0.1, 0.0]), &room).unwrap();
        assert!((t - 2.5).abs() < 1e-6);
        assert_eq!((n, s), (Vec3::NEG_X, Surface::EastWall));
    }

    #[test]
    fn scene_hits_objects_lights_and_shadows() {
        let scene = Scene::room_without_interreflection();
        // Straight up from the room centre: the ceiling light.
        let up = scene
            .intersect(&Ray::new([0.0, 1.0, 0.0], [0.0, 1.0, 0.0]), 0.0)
            .unwrap();
        assert_eq!(up.surface, Surface::Ceiling);
        assert_eq!(scene.material(&up).emission, scene.lights[0].radiance);
        // Towards the ball.
        let c = scene.ball.center;
        let hit = scene
            .intersect(&Ray::new([c.x, 2.0, c.z], [0.0, -1.0, 0.0]), 0.0)
            .unwrap();
        assert_eq!(hit.surface, Surface::Ball);
        assert!((hit.position.y - (c.y + scene.ball.radius)).abs() < 1e-5);
        assert!((hit.normal - Vec3::Y).length() < 1e-5);
        // The floor under the ball is shadowed from the ceiling light's centre.
        assert!(scene.occluded(Vec3::new(c.x, 0.001, c.z), Vec3::new(0.0, 2.6, 0.0)));
        assert!(!scene.occluded(Vec3::new(0.0, 0.001, 0.0), Vec3::new(0.0, 2.6, 0.0)));
        // The object spot is free.
        let spot = Sphere {
            center: OBJECT_POSITION,
            radius: 0.3,
        };
        for b in &scene.blocks {
            let nearest = spot.center.clamp(b.bounds.min, b.bounds.max);
            assert!(nearest.distance(spot.center) > spot.radius);
        }
    }

    #[test]
    fn culled_occluder_sets_give_the_same_shadows() {
        let scene = Scene::room_without_interreflection();
        let mut rng = relume_base::rng::Counter::new(&[3]);
        let mut blocked = 0;
        for _ in 0..20_000 {
            let p = Vec3::new(
                -2.5 + 5.0 * rng.next_f32(),
                0.001 + 1.0 * rng.next_f32(),
                -2.5 + 5.0 * rng.next_f32(),
            );
            if scene
                .blocks
                .iter()
                .any(|b| p.cmpge(b.bounds.min).all() && p.cmple(b.bounds.max).all())
                || p.distance(scene.ball.center) < scene.ball.radius
            {
                continue;
            }
            for light in &scene.lights {
                let q = light.point(rng.next_f32(), rng.next_f32());
                let mask = scene.occluders_towards(p, light);
                let all = scene.occluded_by(ALL_OCCLUDERS, p, q);
                assert_eq!(scene.occluded_by(mask, p, q), all);
                // The slab test agrees with the entry test for outside origins.
                let ray = Ray {
                    origin: p,
                    direction: q - p,
                };
                let entry = scene
                    .blocks
                    .iter()
                    .any(|b| ray_box_entry(&ray, &b.bounds, 1e-5, 1.0 - 1e-4).is_some())
                    || ray_sphere(&ray, &scene.ball, 1e-5, 1.0 - 1e-4).is_some();
                assert_eq!(all, entry);
                blocked += all as usize;
            }
        }
        assert!(blocked > 500, "{blocked}");
    }

    #[test]
    fn albedos_stay_in_a_plausible_range() {
        let scene = Scene::room_without_interreflection();
        for i in 0..2000 {
            let a = i as f32 * 0.37;
            let dir = Vec3::new(a.cos(), (a * 0.61).sin(), a.sin());
            if let Some(hit) = scene.intersect(
                &Ray {
                    origin: Vec3::new(0.1, 1.2, 0.2),
                    direction: dir,
                },
                0.0,
            ) {
                let m = scene.material(&hit);
                if m.emission == Vec3::ZERO {
                    assert!(
                        m.albedo.min_element() >= 0.03 && m.albedo.max_element() <= 0.9,
                        "{m:?}"
                    );
                }
            }
        }
    }
}
