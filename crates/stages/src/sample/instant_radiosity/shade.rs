//! Shading a point from its share of the VPLs (paper 002 eqs. 1-8); `blur.rs`
//! reassembles the interleaved shares.

use super::ism::{MapView, Projection};
use super::params::Flags;
use super::vpl::{Emitter, Vpl};
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Every VPL of a frame with its two imperfect shadow maps: the real one (points of
/// the depth map) and the virtual one (points of the meshes).
pub struct LightSet<'a> {
    pub vpls: &'a [Vpl],
    /// Per slot: the real map's and the virtual map's projection.
    pub projections: &'a [[Projection; 2]],
    /// Per slot: the filled rectangles of the two maps.
    pub rects: &'a [[[u16; 4]; 2]],
    /// Per slot, two maps of `size * size` texels: real, then virtual.
    pub maps: &'a [f32],
    pub size: usize,
    pub bias: f32,
    pub slope: f32,
    /// Squared distance below which a surface VPL's 1 / d^2 is clamped (or its
    /// patch's radius squared, when larger).
    pub clamp_squared: f32,
    /// Metres beyond which a surface VPL lights nothing.
    pub reach: f32,
    /// How a VPL's two maps decide its visibility in L_r and L_rv
    /// ([`shadow_terms`]); only [`Flags::Reciprocal`] runs in lanes.
    pub flags: Flags,
}

impl LightSet<'_> {
    /// The real (`which` = 0) or virtual (1) map of slot `i`.
    #[inline]
    pub(super) fn map(&self, i: usize, which: usize) -> MapView<'_> {
        let texels = self.size * self.size;
        let start = (2 * i + which) * texels;
        MapView {
            projection: &self.projections[i][which],
            depth: &self.maps[start..start + texels],
            size: self.size,
            rect: self.rects[i][which],
            bias: self.bias,
            slope: self.slope,
        }
    }
}

/// What one receiver gathers from its VPLs, before the interleaving scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gathered {
    pub r_dir: Vec3,
    pub r_ind: Vec3,
    pub rv_dir: Vec3,
    pub rv_ind: Vec3,
    /// Some VPL added differently to L_r and L_rv.
    pub touched: bool,
    /// The nearest occluder of a blocked environment VPL over the cosine (the filter's
    /// z / cos^2, as `sample.path` records it, but of every VPL: `sample.path` skips
    /// the occluders of dim samples), and the nearest surface VPL that lit it.
    pub direct_min_distance: f32,
    pub indirect_min_distance: f32,
}

impl Default for Gathered {
    fn default() -> Self {
        Gathered {
            r_dir: Vec3::ZERO,
            r_ind: Vec3::ZERO,
            rv_dir: Vec3::ZERO,
            rv_ind: Vec3::ZERO,
            touched: false,
            direct_min_distance: f32::INFINITY,
            indirect_min_distance: f32::INFINITY,
        }
    }
}

/// What a receiver is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Receiver {
    /// A real surface point (r(p) = 1): it gathers L_r and L_rv.
    Real,
    /// A virtual surface point (r(p) = 0): it gathers L_rv only, and the ir = 1 VPLs
    /// do not light it.
    Virtual,
}

/// Gathers the light of the VPLs `members` (indices) at `position` with unit
/// `normal` (eqs. 1-8). Per VPL: the unoccluded transfer (cos+ for a direction;
/// cos_vpl cos / max(d^2, clamp^2, patch / pi) within `reach` for a surface), the real visibility
/// st_r and the virtual st_v from its maps; L_r adds `power transfer st_r` when the
/// VPL's path is real (r(pl) r(VPL) r(p), eq. 7), L_rv adds `power transfer
/// min(st_r, st_v)` unless the VPL is ir = 1 (eqs. 6, 8); [`Flags::Knecht2010`] lets a
/// virtual blocker hide a real one behind it ([`shadow_terms`]). Both sums add the same
/// terms in the same order wherever every VPL counts for both and st_v >= st_r, so
/// they are then equal bit for bit.
pub fn gather(
    lights: &LightSet,
    members: &[u32],
    position: Vec3,
    normal: Vec3,
    receiver: Receiver,
) -> Gathered {
    let mut g = Gathered::default();
    let real = receiver == Receiver::Real;
    for &i in members {
        let vpl = &lights.vpls[i as usize];
        let slot = vpl.slot as usize;
        let for_real = real && vpl.counts_for_real();
        let for_combined = vpl.counts_for_combined() && (real || !vpl.real_only);
        if !for_real && !for_combined {
            continue;
        }
        let (transfer, distance, direct, cos) = match vpl.emitter {
            Emitter::Direction(d) => {
                let cos = normal.dot(d).max(0.0);
                (cos, 0.0, true, cos)
            }
            Emitter::Surface {
                position: origin,
                normal: n_vpl,
            } => {
                let to = position - origin;
                let d2 = to.length_squared();
                if d2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                    || d2 > lights.reach * lights.reach
                {
                    continue;
                }
                let d = d2.sqrt();
                let cos_vpl = n_vpl.dot(to) / d;
                let cos_p = -normal.dot(to) / d;
                if cos_vpl <= 0.0 || cos_p <= 0.0 {
                    continue;
                }
                let floor = lights.clamp_squared.max(vpl.patch * FRAC_1_PI);
                (cos_vpl * cos_p / d2.max(floor), d, false, cos_p)
            }
        };
        if transfer.is_nan() || transfer <= 0.0 {
            continue;
        }
        let (real_map, virtual_map) = (lights.map(slot, 0), lights.map(slot, 1));
        let projected = real_map.projection.project(position, lights.size);
        let (st_r, behind_r) = real_map.test(projected, cos);
        let (st_v, behind_v) = if !for_combined || virtual_map.is_empty() {
            (1.0, f32::INFINITY)
        } else if virtual_map.projection == real_map.projection {
            // A surface VPL's two maps share their paraboloid.
            virtual_map.test(projected, cos)
        } else {
            virtual_map.visibility(position, cos)
        };
        let light = vpl.power * transfer;
        let (st_r, st_rv) = match lights.flags {
            Flags::Reciprocal => (st_r, st_r.min(st_v)),
            flags => shadow_terms(flags, vpl.real_path, (st_r, behind_r), (st_v, behind_v)),
        };
        if for_real != for_combined || st_v < st_r {
            g.touched = true;
        }
        let (r, rv) = if direct {
            (&mut g.r_dir, &mut g.rv_dir)
        } else {
            (&mut g.r_ind, &mut g.rv_ind)
        };
        if for_real {
            *r += light * st_r;
        }
        if for_combined {
            *rv += light * st_rv;
        }
        if direct {
            let behind = behind_r.min(behind_v);
            if behind.is_finite() {
                g.direct_min_distance = g.direct_min_distance.min(behind / transfer.max(1e-3));
            }
        } else if st_rv > 0.0 || st_r > 0.0 {
            g.indirect_min_distance = g.indirect_min_distance.min(distance);
        }
    }
    g
}

/// The visibility a light's path gets in L_r and in L_rv from its real map's test
/// `(st_r, behind_r)` and its virtual map's `(st_v, behind_v)` (visibility, and metres
/// from the receiver back to the blocker). Paper 002 (`Reciprocal`): st_r and
/// min(st_r, st_v). Its \[4\] (`Knecht2010`) keeps one map whose nearest blocker (to the
/// light: the one farther from the receiver) alone decides: for a real light blocked
/// by both, with the virtual blocker nearer the light, L_r sees no real blocker (1) and
/// L_rv a virtual one (0).
pub fn shadow_terms(
    flags: Flags,
    real_light: bool,
    (st_r, behind_r): (f32, f32),
    (st_v, behind_v): (f32, f32),
) -> (f32, f32) {
    let hidden_real_blocker = st_r == 0.0 && st_v == 0.0 && behind_v > behind_r;
    if flags == Flags::Knecht2010 && real_light && hidden_real_blocker {
        return (1.0, 0.0);
    }
    (st_r, st_r.min(st_v))
}

/// Whether neighbour `q` (position, normal) shows the same surface as `p` for the
/// blur: both present, normals within about 25 degrees, `q` within `tolerance` metres
/// of `p`'s tangent plane.
#[inline]
pub fn same_surface(p: Vec3, n: Vec3, q: Vec3, m: Vec3, tolerance: f32) -> bool {
    n != Vec3::ZERO
        && m != Vec3::ZERO
        && q.is_finite()
        && n.dot(m) >= 0.9
        && (q - p).dot(n).abs() <= tolerance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_earlier_method_lets_a_virtual_blocker_hide_a_real_one_behind_it() {
        let (free, real_near, virtual_far) = ((1.0, f32::INFINITY), (0.0, 0.2), (0.0, 0.9));
        let paper = Flags::Reciprocal;
        let earlier = Flags::Knecht2010;
        // Both blocked, the virtual blocker nearer the light (farther from the receiver).
        assert_eq!(
            shadow_terms(paper, true, real_near, virtual_far),
            (0.0, 0.0)
        );
        assert_eq!(
            shadow_terms(earlier, true, real_near, virtual_far),
            (1.0, 0.0)
        );
        // The real blocker nearer the light: both methods see it.
        assert_eq!(
            shadow_terms(earlier, true, (0.0, 0.9), (0.0, 0.2)),
            (0.0, 0.0)
        );
        // One blocker, or a virtual light: the same terms.
        for flags in [paper, earlier] {
            assert_eq!(shadow_terms(flags, true, free, virtual_far), (1.0, 0.0));
            assert_eq!(shadow_terms(flags, true, real_near, free), (0.0, 0.0));
            assert_eq!(
                shadow_terms(flags, false, real_near, virtual_far),
                (0.0, 0.0)
            );
            assert_eq!(shadow_terms(flags, true, free, free), (1.0, 1.0));
        }
    }
}
