//! The analytic room of the synthetic recordings: geometry, lights, materials with
//! procedural textures, and ray intersection.
//!
//! World frame: right-handed, metres, +y up, the floor at y = 0. The room spans
//! x in [-2.5, 2.5], z in [-2.5, 2.5] and y in [0, 2.6]. The walls are named by the
//! direction they face away from the room centre: west (x = -2.5), east (x = +2.5, with
//! the window), north (z = -2.5) and south (z = +2.5).
//!
//! The scene is fixed: it does not depend on the seed or on any setting, so every
//! recording shows the same room.

use glam::Vec3;

/// Lower corner of the room's interior.
pub const ROOM_MIN: Vec3 = Vec3::new(-2.5, 0.0, -2.5);
/// Upper corner of the room's interior.
pub const ROOM_MAX: Vec3 = Vec3::new(2.5, 2.6, 2.5);
/// Centre of the free spot left for a virtual object: 0.3 m above the middle of the
/// floor, so a sphere of radius 0.3 m placed here rests on the floor.
pub const OBJECT_POSITION: Vec3 = Vec3::new(0.0, 0.3, 0.0);

/// A ray `origin + t * direction`. The direction need not be unit length; distances
/// `t` are then in multiples of its length (a camera ray with direction z = 1 in camera
/// space gives `t` = depth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
}

impl Ray {
    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisBox {
    pub min: Vec3,
    pub max: Vec3,
}

/// A sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
}

/// Which surface of the scene a ray hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    Floor,
    Ceiling,
    /// The wall at x = -2.5.
    WestWall,
    /// The wall at x = +2.5 (holds the window).
    EastWall,
    /// The wall at z = -2.5.
    NorthWall,
    /// The wall at z = +2.5.
    SouthWall,
    /// Box number `i` of [`Scene::blocks`].
    Block(usize),
    /// The sphere standing on the floor.
    Ball,
}

/// The first surface along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    pub position: Vec3,
    /// Unit world-space normal, on the side the ray came from.
    pub normal: Vec3,
    pub surface: Surface,
}

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

/// Procedural textures of the boxes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BlockTexture {
    /// Wood-like value noise stretched along x.
    Wood,
    /// Horizontal drawer fronts with dark gaps.
    Drawers,
    /// A two-colour 3D checker of 0.1 m cells.
    Checker,
    /// Dark fabric: faint value noise.
    Fabric,
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
    /// Constant incident radiance standing in for indirect light (reflected: albedo times it).
    pub ambient: Vec3,
}

impl Scene {
    /// The room every synthetic recording shows.
    pub fn room() -> Scene {
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
            ambient: Vec3::new(0.055, 0.055, 0.06),
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
        let ray = Ray {
            origin: from,
            direction: to - from,
        };
        let (t_min, t_max) = (1e-5, 1.0 - 1e-4);
        self.blocks
            .iter()
            .any(|b| ray_box_entry(&ray, &b.bounds, t_min, t_max).is_some())
            || ray_sphere(&ray, &self.ball, t_min, t_max).is_some()
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
                Some(b) => block_albedo(b.texture, hit.position),
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

/// Where a ray from outside enters `b`, if within (t_min, t_max): parameter and the unit
/// outward normal of the face it enters.
pub fn ray_box_entry(ray: &Ray, b: &AxisBox, t_min: f32, t_max: f32) -> Option<(f32, Vec3)> {
    let mut near = t_min;
    let mut far = t_max;
    let mut near_axis = None;
    for axis in 0..3 {
        let (o, d) = (ray.origin[axis], ray.direction[axis]);
        let (lo, hi) = (b.min[axis], b.max[axis]);
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d;
        let (t0, t1) = if inv > 0.0 {
            ((lo - o) * inv, (hi - o) * inv)
        } else {
            ((hi - o) * inv, (lo - o) * inv)
        };
        if t0 > near {
            near = t0;
            near_axis = Some((axis, d));
        }
        far = far.min(t1);
        if near > far {
            return None;
        }
    }
    // An origin inside the box (no entering face after t_min) is not an entry.
    let (axis, d) = near_axis?;
    let mut normal = Vec3::ZERO;
    normal[axis] = -d.signum();
    Some((near, normal))
}

/// The nearest intersection of a ray with a sphere's surface in (t_min, t_max).
pub fn ray_sphere(ray: &Ray, s: &Sphere, t_min: f32, t_max: f32) -> Option<f32> {
    let oc = ray.origin - s.center;
    let a = ray.direction.length_squared();
    let half_b = oc.dot(ray.direction);
    let c = oc.length_squared() - s.radius * s.radius;
    let disc = half_b * half_b - a * c;
    if a <= 0.0 || disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    [(-half_b - root) / a, (-half_b + root) / a]
        .into_iter()
        .find(|&t| t > t_min && t < t_max)
}

/// Uniform orange of the sphere.
const BALL_ALBEDO: Vec3 = Vec3::new(0.85, 0.42, 0.08);

/// Smooth value noise in [0, 1] on the integer lattice of `p` (a fixed function of
/// position: textures do not change between frames or seeds).
pub fn value_noise(p: Vec3) -> f32 {
    let cell = p.floor();
    let f = p - cell;
    let w = f * f * (Vec3::splat(3.0) - 2.0 * f);
    let (ix, iy, iz) = (cell.x as i64, cell.y as i64, cell.z as i64);
    let lattice = |dx: i64, dy: i64, dz: i64| {
        let h = crate::rng::hash(&[(ix + dx) as u64, (iy + dy) as u64, (iz + dz) as u64]);
        crate::rng::unit_f32(h)
    };
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(lattice(0, 0, 0), lattice(1, 0, 0), w.x);
    let x10 = lerp(lattice(0, 1, 0), lattice(1, 1, 0), w.x);
    let x01 = lerp(lattice(0, 0, 1), lattice(1, 0, 1), w.x);
    let x11 = lerp(lattice(0, 1, 1), lattice(1, 1, 1), w.x);
    lerp(lerp(x00, x10, w.y), lerp(x01, x11, w.y), w.z)
}

/// Two octaves of value noise, in [0, 1].
fn fbm(p: Vec3) -> f32 {
    (2.0 * value_noise(p) + value_noise(p * 2.03 + Vec3::splat(17.0))) / 3.0
}

/// 1 when `x` lies within `half_width` of a multiple of `period`.
fn near_multiple(x: f32, period: f32, half_width: f32) -> bool {
    let r = x.rem_euclid(period);
    r < half_width || r > period - half_width
}

fn checker(a: f32, b: f32, size: f32) -> bool {
    ((a / size).floor() as i64 + (b / size).floor() as i64).rem_euclid(2) == 0
}

/// Albedo of the floor, walls and ceiling.
fn room_albedo(surface: Surface, p: Vec3) -> Vec3 {
    match surface {
        Surface::Floor => {
            // 0.5 m tiles in two wood tones with light grout, slightly mottled.
            if near_multiple(p.x, 0.5, 0.008) || near_multiple(p.z, 0.5, 0.008) {
                return Vec3::new(0.45, 0.44, 0.42);
            }
            let tile = if checker(p.x, p.z, 0.5) {
                Vec3::new(0.62, 0.48, 0.33)
            } else {
                Vec3::new(0.26, 0.16, 0.09)
            };
            tile * (0.85 + 0.3 * value_noise(Vec3::new(p.x * 6.0, 0.5, p.z * 6.0)))
        }
        Surface::Ceiling => Vec3::new(0.80, 0.80, 0.78),
        Surface::WestWall => {
            if p.y < 0.1 {
                return Vec3::new(0.85, 0.85, 0.82);
            }
            // Sage green, lighter towards the ceiling.
            let s = (p.y / ROOM_MAX.y).clamp(0.0, 1.0);
            Vec3::new(0.22, 0.38, 0.25).lerp(Vec3::new(0.55, 0.70, 0.55), s)
        }
        Surface::EastWall => Vec3::new(0.72, 0.70, 0.64),
        Surface::NorthWall => {
            // Vertical stripes, 0.25 m wide.
            if (p.x / 0.25).floor() as i64 % 2 == 0 {
                Vec3::new(0.72, 0.60, 0.42)
            } else {
                Vec3::new(0.38, 0.46, 0.70)
            }
        }
        Surface::SouthWall => {
            if (1.0..1.2).contains(&p.y) {
                Vec3::new(0.85, 0.80, 0.62)
            } else {
                Vec3::new(0.62, 0.30, 0.20)
            }
        }
        Surface::Block(_) | Surface::Ball => Vec3::splat(0.5),
    }
}

/// Albedo of a box's texture at `p`.
fn block_albedo(texture: BlockTexture, p: Vec3) -> Vec3 {
    match texture {
        BlockTexture::Wood => {
            let grain = fbm(Vec3::new(p.x * 2.0, p.y * 24.0, p.z * 24.0));
            Vec3::new(0.55, 0.30, 0.14) * (0.55 + 0.6 * grain)
        }
        BlockTexture::Drawers => {
            if near_multiple(p.y, 0.3, 0.01) {
                Vec3::splat(0.05)
            } else {
                Vec3::new(0.08, 0.16, 0.48)
            }
        }
        BlockTexture::Checker => {
            let odd = ((p.x / 0.1).floor() as i64
                + (p.y / 0.1).floor() as i64
                + (p.z / 0.1).floor() as i64)
                .rem_euclid(2)
                == 1;
            if odd {
                Vec3::new(0.15, 0.55, 0.20)
            } else {
                Vec3::new(0.85, 0.85, 0.80)
            }
        }
        BlockTexture::Fabric => Vec3::new(0.07, 0.06, 0.08) * (0.8 + 0.4 * fbm(p * 30.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f32; 3], d: [f32; 3]) -> Ray {
        Ray {
            origin: Vec3::from_array(o),
            direction: Vec3::from_array(d),
        }
    }

    #[test]
    fn ray_enters_box_through_the_facing_side() {
        let b = AxisBox {
            min: Vec3::new(-1.0, -1.0, 4.0),
            max: Vec3::new(1.0, 1.0, 6.0),
        };
        let (t, n) = ray_box_entry(&ray([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 4.0).abs() < 1e-6);
        assert_eq!(n, Vec3::NEG_Z);
        // Unnormalized direction: t is in multiples of its length.
        let (t, _) = ray_box_entry(&ray([0.0, 0.0, 0.0], [0.0, 0.0, 2.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        // From the side, through the +x face.
        let (t, n) =
            ray_box_entry(&ray([3.0, 0.5, 5.0], [-1.0, 0.0, 0.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        assert_eq!(n, Vec3::X);
        // Misses, beyond t_max, and from inside.
        assert!(ray_box_entry(&ray([0.0, 2.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).is_none());
        assert!(ray_box_entry(&ray([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 3.9).is_none());
        assert!(ray_box_entry(&ray([0.0, 0.0, 5.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).is_none());
    }

    #[test]
    fn ray_hits_sphere_at_the_near_root() {
        let s = Sphere {
            center: Vec3::new(0.0, 0.0, 5.0),
            radius: 1.0,
        };
        let t = ray_sphere(&ray([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &s, 0.0, 100.0).unwrap();
        assert!((t - 4.0).abs() < 1e-5);
        let t = ray_sphere(&ray([0.0, 0.0, 0.0], [0.0, 0.0, 0.5]), &s, 0.0, 100.0).unwrap();
        assert!((t - 8.0).abs() < 1e-4);
        // From inside: the far root.
        let t = ray_sphere(&ray([0.0, 0.0, 5.0], [1.0, 0.0, 0.0]), &s, 0.0, 100.0).unwrap();
        assert!((t - 1.0).abs() < 1e-5);
        // Tangent-ish miss.
        assert!(ray_sphere(&ray([1.01, 0.0, 0.0], [0.0, 0.0, 1.0]), &s, 0.0, 100.0).is_none());
    }

    #[test]
    fn rays_from_inside_leave_the_room_through_the_right_surface() {
        let room = Scene::room().room;
        let (t, n, s) = ray_room_exit(&ray([0.0, 1.0, 0.0], [0.0, -1.0, 0.0]), &room).unwrap();
        assert_eq!((t, n, s), (1.0, Vec3::Y, Surface::Floor));
        let (t, n, s) = ray_room_exit(&ray([0.0, 1.0, 0.0], [1.0, 0.1, 0.0]), &room).unwrap();
        assert!((t - 2.5).abs() < 1e-6);
        assert_eq!((n, s), (Vec3::NEG_X, Surface::EastWall));
    }

    #[test]
    fn scene_hits_objects_lights_and_shadows() {
        let scene = Scene::room();
        // Straight up from the room centre: the ceiling light.
        let up = scene
            .intersect(&ray([0.0, 1.0, 0.0], [0.0, 1.0, 0.0]), 0.0)
            .unwrap();
        assert_eq!(up.surface, Surface::Ceiling);
        assert_eq!(scene.material(&up).emission, scene.lights[0].radiance);
        // Towards the ball.
        let c = scene.ball.center;
        let hit = scene
            .intersect(&ray([c.x, 2.0, c.z], [0.0, -1.0, 0.0]), 0.0)
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
    fn albedos_stay_in_a_plausible_range() {
        let scene = Scene::room();
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
