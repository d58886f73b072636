//! The lat-long HDR environment map, with an optional distance per texel (a distance
//! impostor, paper 000 Sec. 6.1).

use glam::Vec3;
use std::f32::consts::PI;

/// A latitude-longitude map of incident radiance seen from `center`.
///
/// Texels are row-major, row 0 towards world +y (see the module docs of
/// [`crate::light`] for the direction convention). `distance` holds, per texel, how far
/// from `center` the radiance was emitted: `f32::INFINITY` for a distant light probe,
/// finite for a map splatted from the environment-sample cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    pub width: u32,
    pub height: u32,
    /// Linear RGB radiance per texel.
    pub radiance: Vec<Vec3>,
    /// Metres from `center` per texel (`INFINITY` = distant).
    pub distance: Vec<f32>,
    /// World position the map is seen from.
    pub center: Vec3,
}

impl EnvMap {
    /// A distant map (every distance infinite) seen from the world origin.
    ///
    /// Panics if `radiance.len() != width * height` (a programming error).
    pub fn distant(width: u32, height: u32, radiance: Vec<Vec3>) -> EnvMap {
        assert_eq!(radiance.len(), width as usize * height as usize);
        let n = radiance.len();
        EnvMap {
            width,
            height,
            radiance,
            distance: vec![f32::INFINITY; n],
            center: Vec3::ZERO,
        }
    }

    /// A map of constant radiance `value`.
    pub fn constant(width: u32, height: u32, value: Vec3) -> EnvMap {
        EnvMap::distant(width, height, vec![value; width as usize * height as usize])
    }

    /// A map whose texel (column, row) has radiance `f(direction of the texel centre)`.
    pub fn from_fn(width: u32, height: u32, f: impl Fn(Vec3) -> Vec3) -> EnvMap {
        let mut radiance = Vec::with_capacity(width as usize * height as usize);
        for row in 0..height {
            for column in 0..width {
                radiance.push(f(Self::direction_at(
                    column as f32 + 0.5,
                    row as f32 + 0.5,
                    width,
                    height,
                )));
            }
        }
        EnvMap::distant(width, height, radiance)
    }

    /// The unit direction at continuous texel coordinates (`x` along columns, `y` along
    /// rows; texel centres at +0.5) of a `width` x `height` map.
    #[inline]
    pub fn direction_at(x: f32, y: f32, width: u32, height: u32) -> Vec3 {
        let theta = y / height as f32 * PI;
        let phi = x / width as f32 * 2.0 * PI;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        Vec3::new(st * cp, ct, st * sp)
    }

    /// The continuous texel coordinates (x, y) of unit direction `d`: x in [0, width),
    /// y in [0, height].
    #[inline]
    pub fn coords_of(&self, d: Vec3) -> (f32, f32) {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let mut phi = d.z.atan2(d.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let x = phi / (2.0 * PI) * self.width as f32;
        let y = theta / PI * self.height as f32;
        (x.min(self.width as f32 - 1e-3).max(0.0), y)
    }

    /// The index of the texel that holds unit direction `d`.
    #[inline]
    pub fn texel_of(&self, d: Vec3) -> usize {
        let (x, y) = self.coords_of(d);
        let column = (x as u32).min(self.width - 1);
        let row = (y as u32).min(self.height - 1);
        (row * self.width + column) as usize
    }

    /// Radiance arriving from unit direction `d` (the texel that holds it: the map is
    /// piecewise constant, matching the importance sampler's pdf).
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        self.radiance[self.texel_of(d)]
    }

    /// The solid angle of each texel of row `row`: (2 pi / W) (cos theta_0 - cos theta_1).
    #[inline]
    pub fn texel_solid_angle(&self, row: u32) -> f32 {
        let t0 = row as f32 / self.height as f32 * PI;
        let t1 = (row + 1) as f32 / self.height as f32 * PI;
        2.0 * PI / self.width as f32 * (t0.cos() - t1.cos())
    }

    /// The unit direction of the centre of texel `index`.
    #[inline]
    pub fn texel_direction(&self, index: usize) -> Vec3 {
        let column = (index % self.width as usize) as f32 + 0.5;
        let row = (index / self.width as usize) as f32 + 0.5;
        Self::direction_at(column, row, self.width, self.height)
    }

    /// Multiplies every texel's radiance by `factor`.
    pub fn scale_radiance(&mut self, factor: f32) {
        self.radiance.iter_mut().for_each(|c| *c *= factor);
    }

    /// Turns the map about world +y by `degrees` (right-handed: +x turns towards -z, as
    /// `Quat::from_rotation_y`), so that the radiance the map held along d it afterwards
    /// holds along R d: texel column phi takes the old value at phi + angle. A multiple
    /// of 360 / W degrees shifts whole columns exactly; other angles interpolate
    /// linearly between the two nearest columns (distances are taken from the nearer
    /// one, not blended).
    pub fn rotate_about_y(&mut self, degrees: f64) {
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 || degrees % 360.0 == 0.0 {
            return;
        }
        // New column c reads old continuous column c + shift (texel units).
        let shift = (degrees / 360.0 * w as f64).rem_euclid(w as f64);
        let whole = shift.floor();
        let t = (shift - whole) as f32;
        let whole = whole as usize;
        let mut radiance = vec![Vec3::ZERO; w];
        let mut distance = vec![0.0f32; w];
        for row in 0..h {
            let r = &mut self.radiance[row * w..(row + 1) * w];
            let d = &mut self.distance[row * w..(row + 1) * w];
            for c in 0..w {
                let (a, b) = ((c + whole) % w, (c + whole + 1) % w);
                radiance[c] = if t == 0.0 {
                    r[a]
                } else {
                    r[a] * (1.0 - t) + r[b] * t
                };
                distance[c] = if t <= 0.5 { d[a] } else { d[b] };
            }
            r.copy_from_slice(&radiance);
            d.copy_from_slice(&distance);
        }
    }

    /// Irradiance on a surface with unit normal `n` by summing every texel (brute force:
    /// the reference the samplers are tested against).
    pub fn irradiance_brute_force(&self, n: Vec3) -> Vec3 {
        let mut sum = glam::DVec3::ZERO;
        for row in 0..self.height {
            let d_omega = self.texel_solid_angle(row) as f64;
            for column in 0..self.width {
                let index = (row * self.width + column) as usize;
                let cos = n.dot(self.texel_direction(index)).max(0.0) as f64;
                sum += self.radiance[index].as_dvec3() * cos * d_omega;
            }
        }
        sum.as_vec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_round_trip_through_texels_and_solid_angles_sum_to_four_pi() {
        let map = EnvMap::constant(64, 32, Vec3::ONE);
        for index in [0, 17, 64 * 16 + 5, 64 * 32 - 1] {
            assert_eq!(map.texel_of(map.texel_direction(index)), index);
        }
        let total: f32 = (0..32).map(|r| map.texel_solid_angle(r) * 64.0).sum();
        assert!((total - 4.0 * PI).abs() < 1e-4, "{total}");
        assert!((EnvMap::direction_at(0.0, 0.0, 64, 32) - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn rotation_about_y_moves_radiance_with_the_right_hand_rule() {
        let sun = Vec3::new(0.6, 0.5, 0.2).normalize();
        let original = EnvMap::from_fn(64, 32, |d| Vec3::splat(d.dot(sun).max(0.0).powi(8)));
        for degrees in [90.0f64, -33.75, 360.0 + 45.0] {
            let mut turned = original.clone();
            turned.rotate_about_y(degrees);
            let q = glam::Quat::from_rotation_y(degrees.to_radians() as f32);
            for index in 0..original.radiance.len() {
                let d = original.texel_direction(index);
                assert_eq!(
                    turned.radiance(q * d),
                    original.radiance[index],
                    "{degrees} deg, texel {index}"
                );
            }
        }
        // An angle between columns interpolates, and the energy stays the same.
        let mut half = original.clone();
        half.rotate_about_y(360.0 / 64.0 / 2.0);
        let sum = |m: &EnvMap| m.radiance.iter().map(|c| c.x as f64).sum::<f64>();
        assert!((sum(&half) / sum(&original) - 1.0).abs() < 1e-5);
        assert_eq!(
            half.radiance[5],
            (original.radiance[5] + original.radiance[6]) * 0.5
        );
        let mut scaled = original.clone();
        scaled.scale_radiance(2.0);
        assert_eq!(scaled.radiance[100], original.radiance[100] * 2.0);
    }

    #[test]
    fn constant_map_gives_pi_l_irradiance_by_brute_force() {
        let map = EnvMap::constant(128, 64, Vec3::new(1.0, 2.0, 0.5));
        let e = map.irradiance_brute_force(Vec3::new(0.3, 0.8, -0.2).normalize());
        let expected = Vec3::new(1.0, 2.0, 0.5) * PI;
        assert!(
            (e - expected).abs().max_element() < 2e-3 * expected.max_element(),
            "{e}"
        );
    }
}
