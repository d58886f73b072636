//! The synthetic room's switchable lamp: a real spot light on a low stand by the west
//! wall, its head 0.6 m up at [`LAMP_POSITION`], aimed east across the floor at
//! [`LAMP_AIM`], in front of the checker block as the lamp sees it. A virtual object
//! standing there (pipelines/mixed-reality-dir-room-lamp.toml's box) is the front-most
//! blocker of the lamp's light for the floor behind the block, which the block already
//! shadows: paper 002's double-shadow case (Sec. 3.3, Fig. 5), with a truth. The lamp
//! stands between the block's north and south faces, so its light meets the block on
//! the west face and the top, the faces the camera path sees (a depth map holds only
//! what the camera sees). The wooden block and the ball throw long real shadows too.
//!
//! The lamp is a point source with Mitsuba 3's spot profile ([`relume_base::spot`]),
//! the profile a pipeline's `[[light]]` table gives its spot lights, so a pipeline that
//! declares this lamp (`world = "real"`, the same position, aim, intensity and angles)
//! models the light the room really has. A point source lights without noise: its
//! direct light is one shadow ray, exact.

use glam::Vec3;

/// A spot light in the room (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotLamp {
    pub position: Vec3,
    /// Unit axis of the cone.
    pub direction: Vec3,
    /// Radiant intensity on the axis (linear RGB, per steradian).
    pub intensity: Vec3,
    /// Half-angle of the full-intensity beam, radians.
    pub beam: f32,
    /// Half-angle beyond which it gives nothing, radians.
    pub cutoff: f32,
}

/// Metres within which a lamp's 1 / d^2 is held at its value there, as a pipeline's
/// spot lights hold theirs (`relume_scene::light::spot::MIN_DISTANCE`).
pub const MIN_DISTANCE: f32 = 0.01;

/// The lamp's head (metres, world frame).
pub const LAMP_POSITION: Vec3 = Vec3::new(-2.3, 0.6, 0.7);
/// The point the lamp is aimed at: the floor between the lamp and the checker block.
pub const LAMP_AIM: Vec3 = Vec3::new(-0.2, 0.0, 0.6);

/// The room's lamp: a warm spot that brings the floor at its aim 1.2 (red) of
/// irradiance, about what the ceiling panel brings there, so its shadows are dark.
pub fn room_lamp() -> SpotLamp {
    SpotLamp {
        position: LAMP_POSITION,
        direction: (LAMP_AIM - LAMP_POSITION).normalize(),
        intensity: Vec3::new(20.0, 17.0, 13.0),
        beam: 25f32.to_radians(),
        cutoff: 40f32.to_radians(),
    }
}

impl SpotLamp {
    /// The irradiance the lamp brings, unoccluded, to the point `p` with unit normal
    /// `n`, and the point's unit direction towards the lamp and distance to it; `None`
    /// where it brings nothing (outside the cone, behind the surface, at the lamp).
    /// Within [`MIN_DISTANCE`] of the lamp, 1 / d^2 is held at its value there.
    pub fn arrival(&self, p: Vec3, n: Vec3) -> Option<(Vec3, Vec3, f32)> {
        let w = self.position - p;
        let d2 = w.length_squared();
        if !(d2 > 0.0 && d2.is_finite()) {
            return None;
        }
        let d = d2.sqrt();
        let to_lamp = w / d;
        let cos = n.dot(to_lamp);
        if cos.is_nan() || cos <= 0.0 {
            return None;
        }
        let share =
            relume_base::spot::falloff(-self.direction.dot(to_lamp), self.beam, self.cutoff);
        let d2 = d2.max(MIN_DISTANCE * MIN_DISTANCE);
        (share > 0.0).then(|| (self.intensity * (share * cos / d2), to_lamp, d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lamp_lights_the_object_spot_and_not_what_lies_outside_its_cone() {
        let lamp = room_lamp();
        let (e, to_lamp, d) = lamp.arrival(LAMP_AIM, Vec3::Y).unwrap();
        // On the axis: intensity cos / d^2, d^2 = 2.1^2 + 0.6^2 + 0.1^2.
        let d2 = 2.1f32 * 2.1 + 0.6 * 0.6 + 0.1 * 0.1;
        assert!((d - d2.sqrt()).abs() < 1e-5);
        assert!(
            (e - lamp.intensity * (0.6 / d2.sqrt() / d2))
                .abs()
                .max_element()
                < 1e-5
        );
        assert!((to_lamp.length() - 1.0).abs() < 1e-6);
        assert!((1.1..1.3).contains(&e.x), "{e}");
        // Behind the lamp, and a wall facing away.
        assert_eq!(lamp.arrival(Vec3::new(-2.4, 0.0, 2.4), Vec3::Y), None);
        assert_eq!(lamp.arrival(LAMP_AIM, Vec3::NEG_Y), None);
    }
}
