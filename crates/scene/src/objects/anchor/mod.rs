//! Placement of virtual objects relative to the recorded scene rather than in world
//! coordinates: on the floor (`anchor = "floor"`) or on the surface seen at a pixel
//! (`at_pixel = [u, v]`, `frame = n`). A user with a new recording does not know where
//! its world origin is or which way is up; these anchors find a frame on a real surface
//! from the recording's own depth and poses, and the object's `translation` and
//! `rotation_deg` then apply in that frame.
//!
//! An anchor frame has its origin on the surface, its y axis along the surface normal
//! (pointing towards the camera, so up from a floor), its x axis along the image's
//! rightward direction in frame `frame` as it lies in the surface, and z = x cross y:
//! on a floor or a table, towards the camera; on a wall, down. A shape centred on its origin with y up (every built-in
//! shape) therefore stands on the surface when its `translation` lifts it by half its
//! height, as it would on the synthetic room's floor at y = 0.
//!
//! This module holds the anchors as declared and the frames they resolve to; resolving
//! them against a recording (the floor fit, the surface at a pixel, the report printed to
//! users) is `relume_stages::world`'s, which has the plane fit and the config's spans.
//!
//! Nothing here departs from a paper: the papers place their objects by hand, or on a
//! marker (paper 001 Sec. 8).

use glam::{Mat3, Vec2, Vec3};

/// How many frames, from the anchor's `frame` on, the floor is fitted to.
pub const FLOOR_FRAMES: usize = 5;

/// Where an object's `translation` and `rotation_deg` are measured from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Anchor {
    /// The world coordinates of the recording's poses (the default).
    World,
    /// The floor: the lowest well-supported upward-facing plane below the cameras in
    /// frames `frame .. frame + FLOOR_FRAMES` (see `relume_stages::world::floor::fit_floor`). The origin is
    /// where the view ray through `at_pixel` of frame `frame` (the image centre when
    /// `None`) meets it.
    Floor {
        at_pixel: Option<Vec2>,
        frame: usize,
    },
    /// The surface seen at `at_pixel` (color image pixels) in frame `frame`: a plane
    /// fitted to the depth around it (see `relume_stages::world::surface::surface_at`); the origin is where
    /// the pixel's view ray meets that plane.
    Surface { at_pixel: Vec2, frame: usize },
}

impl Anchor {
    /// The anchor's name as configs write it.
    pub fn name(&self) -> &'static str {
        match self {
            Anchor::World => "world",
            Anchor::Floor { .. } => "floor",
            Anchor::Surface { .. } => "surface",
        }
    }

    /// The names configs may give `anchor`.
    pub const NAMES: &'static [&'static str] = &["world", "floor", "surface"];
}

/// A rigid frame in world space: `origin` and orthonormal `axes` (columns x, y, z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnchorFrame {
    pub origin: Vec3,
    pub axes: Mat3,
}

impl AnchorFrame {
    /// The world frame itself.
    pub const WORLD: AnchorFrame = AnchorFrame {
        origin: Vec3::ZERO,
        axes: Mat3::IDENTITY,
    };

    /// The frame at `origin` whose y axis is the unit `normal` and whose x axis is
    /// `right` (the camera's rightward direction) made perpendicular to it; when
    /// `right` lies almost along the normal (a surface seen edge-on), `forward`
    /// (the camera's viewing direction) takes its place.
    pub fn on_surface(origin: Vec3, normal: Vec3, right: Vec3, forward: Vec3) -> AnchorFrame {
        let y = normal.normalize();
        let in_plane = |v: Vec3| v - y * y.dot(v);
        let mut x = in_plane(right);
        if x.length() < 0.1 {
            x = in_plane(forward);
        }
        let x = x.normalize();
        AnchorFrame {
            origin,
            axes: Mat3::from_cols(x, y, x.cross(y)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_floor_frame_seen_from_the_side_has_x_right_y_up_z_towards_the_camera() {
        // A camera at z = +3 looking along -z with its image right along +x.
        let frame = AnchorFrame::on_surface(Vec3::ZERO, Vec3::Y, Vec3::X, Vec3::NEG_Z);
        assert!(frame.axes.x_axis.abs_diff_eq(Vec3::X, 1e-6));
        assert!(frame.axes.y_axis.abs_diff_eq(Vec3::Y, 1e-6));
        assert!(frame.axes.z_axis.abs_diff_eq(Vec3::Z, 1e-6));
        // A tilted camera: its right vector leans into the floor; x stays in the floor.
        let right = Vec3::new(1.0, 0.3, 0.0).normalize();
        let frame = AnchorFrame::on_surface(Vec3::ONE, Vec3::Y, right, Vec3::NEG_Z);
        assert!(frame.axes.x_axis.abs_diff_eq(Vec3::X, 1e-6));
        assert!((frame.axes.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn a_surface_seen_edge_on_takes_x_from_the_viewing_direction() {
        // A wall facing +x, the camera's right along its normal.
        let frame = AnchorFrame::on_surface(Vec3::ZERO, Vec3::X, Vec3::X, Vec3::Z);
        assert!(frame.axes.x_axis.abs_diff_eq(Vec3::Z, 1e-6));
        assert!(frame.axes.y_axis.abs_diff_eq(Vec3::X, 1e-6));
        assert!((frame.axes.determinant() - 1.0).abs() < 1e-5);
    }
}
