//! Ray primitives of the synthetic scene: rays, axis-aligned boxes and spheres, and
//! their intersection tests. Directions need not be unit length.

use super::room::Surface;
use glam::Vec3;

/// A ray `origin + t * direction`. The direction need not be unit length; distances
/// `t` are then in multiples of its length (a camera ray with direction z = 1 in camera
/// space gives `t` = depth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
}

impl Ray {
    /// A ray from `origin` along `direction` (not normalized here).
    pub fn new(origin: impl Into<Vec3>, direction: impl Into<Vec3>) -> Ray {
        Ray {
            origin: origin.into(),
            direction: direction.into(),
        }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }
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

/// True when the ray `origin + t * direction` (`inv_direction` = 1 / direction per
/// component) meets box `b` for some t in (t_min, t_max): the slab test.
#[inline]
pub fn segment_crosses_box(
    origin: Vec3,
    inv_direction: Vec3,
    b: &AxisBox,
    t_min: f32,
    t_max: f32,
) -> bool {
    let t0 = (b.min - origin) * inv_direction;
    let t1 = (b.max - origin) * inv_direction;
    let near = t0.min(t1).max_element().max(t_min);
    let far = t0.max(t1).min_element().min(t_max);
    near <= far
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_enters_box_through_the_facing_side() {
        let b = AxisBox {
            min: Vec3::new(-1.0, -1.0, 4.0),
            max: Vec3::new(1.0, 1.0, 6.0),
        };
        let (t, n) =
            ray_box_entry(&Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 4.0).abs() < 1e-6);
        assert_eq!(n, Vec3::NEG_Z);
        // Unnormalized direction: t is in multiples of its length.
        let (t, _) =
            ray_box_entry(&Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 2.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        // From the side, through the +x face.
        let (t, n) =
            ray_box_entry(&Ray::new([3.0, 0.5, 5.0], [-1.0, 0.0, 0.0]), &b, 0.0, 100.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        assert_eq!(n, Vec3::X);
        // Misses, beyond t_max, and from inside.
        assert!(
            ray_box_entry(&Ray::new([0.0, 2.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).is_none()
        );
        assert!(ray_box_entry(&Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &b, 0.0, 3.9).is_none());
        assert!(
            ray_box_entry(&Ray::new([0.0, 0.0, 5.0], [0.0, 0.0, 1.0]), &b, 0.0, 100.0).is_none()
        );
    }

    #[test]
    fn ray_hits_sphere_at_the_near_root() {
        let s = Sphere {
            center: Vec3::new(0.0, 0.0, 5.0),
            radius: 1.0,
        };
        let t = ray_sphere(&Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), &s, 0.0, 100.0).unwrap();
        assert!((t - 4.0).abs() < 1e-5);
        let t = ray_sphere(&Ray::new([0.0, 0.0, 0.0], [0.0, 0.0, 0.5]), &s, 0.0, 100.0).unwrap();
        assert!((t - 8.0).abs() < 1e-4);
        // From inside: the far root.
        let t = ray_sphere(&Ray::new([0.0, 0.0, 5.0], [1.0, 0.0, 0.0]), &s, 0.0, 100.0).unwrap();
        assert!((t - 1.0).abs() < 1e-5);
        // Tangent-ish miss.
        assert!(ray_sphere(&Ray::new([1.01, 0.0, 0.0], [0.0, 0.0, 1.0]), &s, 0.0, 100.0).is_none());
    }
}
