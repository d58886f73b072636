//! The synthetic room's interior and the names of its surfaces: what the scene
//! ([`super::scene`]) intersects and the textures ([`super::texture`]) colour, by
//! surface and position. The world frame and the walls' names are described in
//! [`super::scene`].

use glam::Vec3;

/// Lower corner of the room's interior.
pub const ROOM_MIN: Vec3 = Vec3::new(-2.5, 0.0, -2.5);
/// Upper corner of the room's interior.
pub const ROOM_MAX: Vec3 = Vec3::new(2.5, 2.6, 2.5);

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
    /// Box number `i` of [`Scene::blocks`](super::scene::Scene::blocks).
    Block(usize),
    /// The sphere standing on the floor.
    Ball,
}
