//! The profile of a spot light, shared by the synthetic room's lamp (a recording's
//! truth) and the spot lights pipelines declare, so both shine the same cone.
//!
//! It is Mitsuba 3's `spot` emitter: full radiant intensity within `beam` of the axis,
//! falling linearly in angle to 0 at `cutoff`, nothing beyond.

/// The share of a spot's axis intensity sent at an angle whose cosine to the axis is
/// `cos_to_axis`: 1 within `beam` (radians), linear in angle to 0 at `cutoff`
/// (radians), 0 beyond. A beam at or wider than the cutoff gives a hard edge.
pub fn falloff(cos_to_axis: f32, beam: f32, cutoff: f32) -> f32 {
    let cos = cos_to_axis.clamp(-1.0, 1.0);
    if cos <= cutoff.cos() {
        return 0.0;
    }
    if cos >= beam.cos() || cutoff <= beam {
        return 1.0;
    }
    ((cutoff - cos.acos()) / (cutoff - beam)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_within_the_beam_linear_in_angle_to_the_cutoff() {
        let (beam, cutoff) = (20f32.to_radians(), 30f32.to_radians());
        let at = |deg: f32| falloff(deg.to_radians().cos(), beam, cutoff);
        assert_eq!(at(0.0), 1.0);
        assert_eq!(at(19.0), 1.0);
        assert!((at(25.0) - 0.5).abs() < 1e-4, "{}", at(25.0));
        assert_eq!(at(31.0), 0.0);
        assert_eq!(at(150.0), 0.0);
        // A beam as wide as the cutoff: a hard edge.
        assert_eq!(falloff(29f32.to_radians().cos(), cutoff, cutoff), 1.0);
    }
}
