//! Procedural textures of the synthetic room: tiles, stripes, gradients, checkers and
//! value noise. They are fixed functions of position: the same in every frame and for
//! every seed.

use super::room::{ROOM_MAX, Surface};
use glam::Vec3;

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

/// Uniform orange of the sphere.
pub const BALL_ALBEDO: Vec3 = Vec3::new(0.85, 0.42, 0.08);

/// Smooth value noise in [0, 1] on the integer lattice of `p` (a fixed function of
/// position: textures do not change between frames or seeds).
pub fn value_noise(p: Vec3) -> f32 {
    let cell = p.floor();
    let f = p - cell;
    let w = f * f * (Vec3::splat(3.0) - 2.0 * f);
    let (ix, iy, iz) = (cell.x as i64, cell.y as i64, cell.z as i64);
    let lattice = |dx: i64, dy: i64, dz: i64| {
        let h = relume_base::rng::hash(&[(ix + dx) as u64, (iy + dy) as u64, (iz + dz) as u64]);
        relume_base::rng::unit_f32(h)
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

/// Albedo of the floor, walls and ceiling at `p` (other surfaces get a neutral grey).
pub fn room_albedo(surface: Surface, p: Vec3) -> Vec3 {
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
pub fn block_albedo(texture: BlockTexture, p: Vec3) -> Vec3 {
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

    #[test]
    fn value_noise_is_smooth_and_in_range() {
        let mut previous = value_noise(Vec3::new(0.3, 0.7, 0.1));
        for i in 1..2000 {
            let p = Vec3::new(0.3 + i as f32 * 0.001, 0.7, 0.1);
            let v = value_noise(p);
            assert!((0.0..=1.0).contains(&v));
            assert!((v - previous).abs() < 0.01, "jump at {p}");
            previous = v;
        }
    }

    #[test]
    fn floor_has_two_tile_tones_and_grout() {
        let light = room_albedo(Surface::Floor, Vec3::new(0.25, 0.0, 0.25));
        let dark = room_albedo(Surface::Floor, Vec3::new(0.75, 0.0, 0.25));
        let grout = room_albedo(Surface::Floor, Vec3::new(0.5, 0.0, 0.25));
        assert!(light.x > 1.5 * dark.x);
        assert_eq!(grout, Vec3::new(0.45, 0.44, 0.42));
    }
}
