//! Virtual point lights with the flags of Differential Instant Radiosity (paper 002
//! Secs. 3.3-3.7), and where they come from.
//!
//! - **Environment VPLs** (the primary light, real: r(pl) = 1): importance samples of
//!   the environment from the light table, one per stratum of `count` equal strata.
//!   Paper 002 places them on a hemisphere around the scene; relume takes them at
//!   infinity (directions), which is what a light probe is. Each carries the
//!   irradiance it brings at normal incidence, L / (pdf count), so that the sum of
//!   `power * cos+` over them estimates the irradiance (pi L under a constant L).
//! - **Bounce VPLs** (one bounce, LDD paths): where that light meets surfaces.
//!   - On the real surface (the depth map): the room's own outgoing radiance is the
//!     camera's (compensated) color, so a real VPL carries L_cam times the area it
//!     stands for. Where the objects block part of the environment light reaching that
//!     point (the fraction f of its direct irradiance that passes them, from the
//!     environment VPLs' maps), the paper's two VPL kinds split it: f L_cam A with
//!     r(VPL) = 1, ir = 0 (both solutions), and (1 - f) L_cam A with ir(VPL) = 1 (the
//!     special VPL of Sec. 3.3, Fig. 6 "VPL 3": real light that the objects block in
//!     the combined world; it lights only L_r, so the differential removes the real
//!     colour bleeding it would have caused).
//!   - On the virtual meshes: radiance k_V E_RV^dir / pi times the area, with
//!     r(VPL) = 0 (only L_rv: Sec. 3.3, "VPL 2").
//!
//!   The candidates (a grid of real pixels and a subset of the mesh points) are
//!   importance-resampled by their luminance into the bounce slots (systematic
//!   resampling: stronger candidates are drawn more often, each drawn VPL's power is
//!   rescaled so the sum stays unbiased). The real and the virtual candidates are
//!   resampled apart, into the shares of the slots the caller gives each (Sec. 3.7
//!   shares a light's slots between its real and virtual RSM by coverage).

use glam::Vec3;
use relume_base::rng;
use relume_scene::light::LightTable;
use relume_scene::light::split::luminance;

/// Where a VPL's light comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Emitter {
    /// A light at infinity in this unit direction (towards the light).
    Direction(Vec3),
    /// A diffuse emitting patch at `position` facing the unit `normal`.
    Surface { position: Vec3, normal: Vec3 },
}

/// One virtual point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vpl {
    pub emitter: Emitter,
    /// [`Emitter::Direction`]: the irradiance it brings at normal incidence.
    /// [`Emitter::Surface`]: radiance times area; a receiver at distance d gets
    /// `power cos_vpl cos_receiver / d^2`.
    pub power: Vec3,
    /// x-bar of eq. 9: the path that made the VPL met only real things (its primary
    /// light is real and the VPL sits on a real surface); r(pl) r(VPL) of eqs. 2, 7.
    pub real_path: bool,
    /// ir(VPL) of eq. 6: the VPL lights only real surfaces, in L_r alone.
    pub real_only: bool,
    /// [`Emitter::Surface`]: the square metres of surface the VPL stands for (its
    /// candidate's patch, grown by resampling as its power is); within the radius of
    /// that patch its 1 / d^2 is clamped. 0 for directions.
    pub patch: f32,
    /// The slot it occupies: its shadow maps, and its interleaving class. A slot holds
    /// one VPL, or a real VPL and its ir = 1 twin at the same point.
    pub slot: u32,
}

impl Vpl {
    /// Its share of L_r (eq. 7, times r(p) of the receiver).
    #[inline]
    pub fn counts_for_real(&self) -> bool {
        self.real_path
    }

    /// Its share of L_rv (eq. 6).
    #[inline]
    pub fn counts_for_combined(&self) -> bool {
        !self.real_only
    }
}

/// `count` environment VPLs from `table` (one per stratum of the table, at an offset
/// hashed from `key`).
pub fn environment_vpls(table: &LightTable, count: usize, key: u64) -> Vec<Vpl> {
    let n = table.samples.len();
    if n == 0 || count == 0 {
        return Vec::new();
    }
    (0..count)
        .filter_map(|k| {
            let jitter = rng::unit_f64(rng::hash(&[key, 0xE4F1, k as u64]));
            let i = (((k as f64 + jitter) / count as f64) * n as f64) as usize;
            let s = table.samples[i.min(n - 1)];
            (s.pdf > 0.0 && s.pdf.is_finite() && s.radiance.is_finite()).then(|| Vpl {
                emitter: Emitter::Direction(s.direction),
                power: s.radiance / (s.pdf * count as f32),
                real_path: true,
                real_only: false,
                patch: 0.0,
                slot: 0,
            })
        })
        .enumerate()
        .map(|(slot, v)| Vpl {
            slot: slot as u32,
            ..v
        })
        .collect()
}

/// A surface point that may become a bounce VPL.
#[derive(Clone, Copy, Debug)]
pub struct Candidate {
    pub position: Vec3,
    pub normal: Vec3,
    /// Outgoing radiance times area over the paths that count for L_r (real light over
    /// real surfaces only; 0 on a virtual surface).
    pub power_r: Vec3,
    /// The same over the paths that count for L_rv (the combined world).
    pub power_rv: Vec3,
    pub real: bool,
    /// Square metres of surface it stands for.
    pub area: f32,
}

/// A VPL's share of a candidate's light: what counts for both worlds, for L_r alone
/// (the ir = 1 kind: light the objects take away) and for L_rv alone (light the
/// objects add), per channel, so that both + r_only = power_r and both + rv_only =
/// power_rv.
pub fn split(c: &Candidate) -> [Vec3; 3] {
    let both = c.power_r.min(c.power_rv).max(Vec3::ZERO);
    [
        both,
        (c.power_r - both).max(Vec3::ZERO),
        (c.power_rv - both).max(Vec3::ZERO),
    ]
}

/// The bounce VPLs drawn from `candidates` into `slots` slots numbered from
/// `first_slot` (see the module docs), by the luminance of the larger of their two
/// powers. A drawn candidate fills its slot with up to three VPLs at its point
/// ([`split`]): the light both worlds share (r(VPL) = 1, or a virtual surface's, which
/// has none), the light only L_r has (ir = 1: a real surface in the objects' shadow,
/// Sec. 3.3's "VPL 3") and the light only L_rv has (r(VPL) = 0 or x-bar = 0: an object
/// lit it, Sec. 3.6). Keeping them in one slot makes L_r - L_rv carry only the
/// variance of the difference.
pub fn resample(
    candidates: &[Candidate],
    slots: usize,
    first_slot: u32,
    key: u64,
    out: &mut Vec<Vpl>,
) {
    let weight = |c: &Candidate| {
        let l = luminance(c.power_r.max(c.power_rv));
        if l.is_finite() && l > 0.0 {
            l as f64
        } else {
            0.0
        }
    };
    let total: f64 = candidates.iter().map(weight).sum();
    if slots == 0 || total.is_nan() || total <= 0.0 || !total.is_finite() {
        return;
    }
    let step = total / slots as f64;
    let mut next = rng::unit_f64(rng::hash(&[key, 0x5E1E])) * step;
    let (mut below, mut slot) = (0.0f64, first_slot);
    for c in candidates {
        let w = weight(c);
        if w == 0.0 {
            continue;
        }
        let above = below + w;
        while next < above {
            let grow = (step / w) as f32;
            let [both, r_only, rv_only] = split(c);
            let vpl = |power: Vec3, real_path: bool, real_only: bool| Vpl {
                emitter: Emitter::Surface {
                    position: c.position,
                    normal: c.normal,
                },
                power: power * grow,
                real_path,
                real_only,
                patch: c.area * grow,
                slot,
            };
            for (power, real_path, real_only) in [
                (both, c.real, false),
                (r_only, true, true),
                (rv_only, false, false),
            ] {
                if power.max_element() > 0.0 {
                    out.push(vpl(power, real_path, real_only));
                }
            }
            slot += 1;
            next += step;
        }
        below = above;
    }
}
