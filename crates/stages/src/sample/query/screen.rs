//! Screen-space ray marching as a [`RadianceQuery`]: the real scene is the depth map,
//! marched within `max_distance` ([`ScreenTracer`]); a hit brings the camera's
//! compensated radiance of the pixel it meets. `sample.path` marches its rays in
//! batches with the same tracer ([`crate::sample::ssrt::batch::TraceBatch`], eight
//! lanes at a time), which gives the same hits as this query ray by ray.

use super::interface::{Hit, RadianceQuery, Ray, Source};
use crate::sample::ssrt::{RealHit, ScreenTracer};
use relume_base::raster::Vec3Image;

/// The depth map of a frame and the radiance of its pixels.
#[derive(Clone, Copy)]
pub struct ScreenQuery<'a> {
    pub tracer: &'a ScreenTracer<'a>,
    /// Compensated linear camera radiance (non-finite pixels bring 0).
    pub radiance: &'a Vec3Image,
    /// Metres a ray marches at most: beyond, the environment stands for the room.
    pub max_distance: f32,
}

impl ScreenQuery<'_> {
    /// The answer for a hit the screen-space tracer found.
    #[inline]
    pub fn hit(&self, real: RealHit) -> Hit {
        let l = *self.radiance.at(real.pixel.0, real.pixel.1);
        Hit {
            t: real.t,
            radiance: if l.is_finite() { l } else { glam::Vec3::ZERO },
            source: Source::Surface,
        }
    }
}

impl RadianceQuery for ScreenQuery<'_> {
    #[inline]
    fn query(&self, ray: &Ray) -> Option<Hit> {
        self.tracer
            .trace(ray.origin, ray.dir, ray.t_max.min(self.max_distance))
            .map(|real| self.hit(real))
    }
}
