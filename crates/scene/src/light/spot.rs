//! Spot lights that a pipeline knows of (paper 002 Sec. 3.7): a point source with a
//! cone, real (a tracked lamp in the recorded room, whose light the camera already
//! sees) or virtual (a lamp that exists only in the virtual world and lights the real
//! surfaces too).
//!
//! The profile is Mitsuba 3's `spot` emitter, so that a scene exported there shows the
//! same light: radiant intensity `intensity` within `beam` of the axis, falling
//! linearly in angle to 0 at `cutoff`, nothing beyond. Paper 002 calls it "a standard
//! spot light" and gives no profile.

use glam::Vec3;

/// Which world a light source belongs to: r(pl) of paper 002 eqs. 2-9.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LightWorld {
    /// A light of the recorded room (r(pl) = 1): it lights both solutions, L_r and
    /// L_rv, and the objects block it in L_rv only.
    Real,
    /// A light of the virtual world (r(pl) = 0): it lights L_rv only, real surfaces
    /// included, so the composite brightens them.
    Virtual,
}

impl LightWorld {
    /// The names configs use, in the order of the variants.
    pub const NAMES: [&'static str; 2] = ["real", "virtual"];

    /// The variant named `name` ([`LightWorld::NAMES`]).
    pub fn from_name(name: &str) -> Option<LightWorld> {
        match name {
            "real" => Some(LightWorld::Real),
            "virtual" => Some(LightWorld::Virtual),
            _ => None,
        }
    }
}

/// Metres within which a spot's 1 / d^2 is held at its value there: a surface
/// against the lamp (a real lamp seen in the depth map, a virtual one set against a
/// wall) gets a bounded irradiance, not an infinite one.
pub const MIN_DISTANCE: f32 = 0.01;

/// The largest cutoff a spot may have, degrees: its shadow maps are paraboloids over
/// the hemisphere about its axis.
pub const MAX_CUTOFF_DEG: f32 = 89.0;

/// A spot light in world space (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct SpotLight {
    pub name: String,
    pub world: LightWorld,
    pub position: Vec3,
    /// Unit axis of the cone, pointing where the light shines.
    pub direction: Vec3,
    /// Radiant intensity on the axis, per channel (linear radiance units times square
    /// metres, per steradian: a surface at distance d facing it receives intensity / d^2).
    pub intensity: Vec3,
    /// Half-angle of the full-intensity beam, radians (<= `cutoff`).
    pub beam: f32,
    /// Half-angle beyond which the light gives nothing, radians, in (0, 89 degrees].
    pub cutoff: f32,
}

/// What an unoccluded spot light brings to a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotArrival {
    /// Irradiance at the point: intensity * falloff * cos / d^2.
    pub irradiance: Vec3,
    /// Unit direction from the point towards the light.
    pub to_light: Vec3,
    /// Metres from the point to the light.
    pub distance: f32,
    /// Cosine between the point's normal and `to_light` (> 0).
    pub cos: f32,
}

impl SpotLight {
    /// The light's share of its axis intensity towards unit direction `towards` (from
    /// the light): 1 within the beam, linear in angle to 0 at the cutoff, 0 beyond
    /// (Mitsuba 3's `spot` falloff).
    pub fn falloff(&self, towards: Vec3) -> f32 {
        relume_base::spot::falloff(self.direction.dot(towards), self.beam, self.cutoff)
    }

    /// What the light brings, unoccluded, to the point `p` with unit normal `n`:
    /// `None` where it brings nothing (outside the cone, behind the surface, at the
    /// light's own position). Within [`MIN_DISTANCE`] of the lamp, 1 / d^2 is held at
    /// its value there.
    pub fn arrival(&self, p: Vec3, n: Vec3) -> Option<SpotArrival> {
        let to_light = self.position - p;
        let d2 = to_light.length_squared();
        if d2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !d2.is_finite() {
            return None;
        }
        let distance = d2.sqrt();
        let to_light = to_light / distance;
        let cos = n.dot(to_light);
        if cos.is_nan() || cos <= 0.0 {
            return None;
        }
        let falloff = self.falloff(-to_light);
        if falloff <= 0.0 {
            return None;
        }
        Some(SpotArrival {
            irradiance: self.intensity * (falloff * cos / d2.max(MIN_DISTANCE * MIN_DISTANCE)),
            to_light,
            distance,
            cos,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spot() -> SpotLight {
        SpotLight {
            name: "lamp".into(),
            world: LightWorld::Real,
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: Vec3::NEG_Y,
            intensity: Vec3::new(4.0, 2.0, 1.0),
            beam: 20f32.to_radians(),
            cutoff: 30f32.to_radians(),
        }
    }

    #[test]
    fn a_point_under_the_spot_gets_its_intensity_over_the_distance_squared() {
        let a = spot().arrival(Vec3::ZERO, Vec3::Y).unwrap();
        assert_eq!(a.irradiance, Vec3::new(1.0, 0.5, 0.25));
        assert_eq!((a.distance, a.cos, a.to_light), (2.0, 1.0, Vec3::Y));
    }

    #[test]
    fn the_falloff_is_linear_in_angle_between_beam_and_cutoff() {
        let s = spot();
        let at = |deg: f32| {
            let t = deg.to_radians();
            s.falloff(Vec3::new(t.sin(), -t.cos(), 0.0))
        };
        assert_eq!(at(0.0), 1.0);
        assert_eq!(at(19.0), 1.0);
        assert!((at(25.0) - 0.5).abs() < 1e-4, "{}", at(25.0));
        assert!((at(27.5) - 0.25).abs() < 1e-4, "{}", at(27.5));
        assert_eq!(at(31.0), 0.0);
        assert_eq!(at(120.0), 0.0);
    }

    #[test]
    fn a_tilted_surface_gets_the_cosine_and_a_surface_facing_away_nothing() {
        let s = spot();
        let n = Vec3::new(1.0, 1.0, 0.0).normalize();
        let a = s.arrival(Vec3::ZERO, n).unwrap();
        assert!((a.irradiance.x - 1.0 * std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
        assert_eq!(s.arrival(Vec3::ZERO, Vec3::NEG_Y), None);
        // Outside the cone, and at the light itself.
        assert_eq!(s.arrival(Vec3::new(3.0, 0.0, 0.0), Vec3::Y), None);
        assert_eq!(s.arrival(s.position, Vec3::Y), None);
        // A millimetre below it: held at the centimetre's value.
        let close = s.arrival(s.position - Vec3::Y * 1e-3, Vec3::Y).unwrap();
        assert_eq!(close.irradiance, s.intensity * 1e4);
    }
}
