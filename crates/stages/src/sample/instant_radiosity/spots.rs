//! The pipeline's spot lights in Differential Instant Radiosity (paper 002 Secs. 3.3,
//! 3.4, 3.7): direct light from real and virtual spot lights (`[[light]]` tables).
//!
//! - **Real and virtual visibility apart** (Sec. 3.3: "two RSMs are created each
//!   frame" for a real light): the real blockers from a shadow map splatted from every
//!   valid pixel of the depth map, a paraboloid over the hemisphere about the spot's
//!   axis, `spot_map_size` texels a side, holes filled as the VPLs' maps are; the
//!   virtual blockers from a ray from the spot to the receiver through the objects'
//!   BVH (the nearest hit to the light, as a map would keep). A virtual spot tests
//!   the same two (the paper's single RSM holds both kinds: its test is their
//!   minimum).
//! - **Direct light** (Sec. 3.4, eqs. 4-5): at a receiver, a real spot adds its
//!   irradiance times the real visibility to L_r (r(pl) r(p) = 1) and times
//!   min(real, virtual) to L_rv; a virtual spot adds to L_rv only, real receivers
//!   included (r(pl) = 0), so the composite brightens the real surfaces it lights and
//!   darkens nothing. Spots are gathered at every pixel, not interleaved, and added to
//!   the layers after the blur: a point light's shadow is sharp.
//! - **Their bounce** (Sec. 3.7): the first bounce's candidates count the real spots in
//!   their direct light (`render.rs`): a real candidate the objects shade from a real
//!   spot gets the ir = 1 VPL that cancels its real colour bleeding; a virtual
//!   candidate reflects the real spots' light as the environment's. The virtual spots'
//!   light, in L_rv only, takes `spot_vpls` slots of its own after every other slot:
//!   off a real candidate with the albedo its camera radiance and its real direct light
//!   imply, off a virtual one with its albedo; so no bounce's slots, and no E_R bit,
//!   depend on a virtual spot. Those slots go to the real surfaces and the objects by
//!   light (`spot_split = "flux"`), or as the paper splits them between a spot's two
//!   RSMs (`"coverage"`, `split_by_coverage`: by the solid angle each covers as the
//!   spots see it, slot by slot with a Halton sequence).
//! - **The \[4\] switch** (`flags = "knecht2010"`): the earlier method keeps one map per
//!   light whose nearest blocker alone decides. Where a virtual blocker stands between
//!   a real spot and a real one, it hides the real blocker: L_r takes the light the
//!   real blocker stops, the camera shows the real shadow, and the composite darkens it
//!   a second time (the double shadow of paper 002 Fig. 5).
//!
//! Where relume departs: the real map holds only what the camera sees (the paper's
//! RSM renders the reconstructed mesh from the light: surfaces hidden from the camera
//! do not block here); the objects' shadows are traced, exact and hard-edged, where
//! the paper rasterizes their RSM (a map splatted from mesh points leaks light through
//! its holes, and its texels show as steps along the shadow's edge); the spot's own
//! RSM importance sampling (Sec. 3.7, Clarberg et al.) is replaced by resampling the
//! candidates the environment's bounce already uses, in proportion to their light; a
//! real spot has no slots of its own: the real surfaces' bounce light is what the
//! camera measured (their candidates' power), which already holds the real spots'.

use super::ism::{MapView, Projection, fill_holes, frame_about};
use super::params::Flags;
use super::points::RealSurface;
use super::shade::{Receiver, shadow_terms};
use super::splat::splat_with;
use super::vpl::{Candidate, Vpl, resample};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::simd::Kernel;
use relume_scene::light::{LightWorld, SpotLight};
use relume_scene::objects::VirtualScene;

/// Every spot light's shadow map of the real surface (see the module docs).
#[derive(Default)]
pub struct SpotMaps {
    projections: Vec<Projection>,
    /// Per spot, a map of `size * size` texels.
    maps: Vec<f32>,
    /// Per spot: the filled rectangle of its map.
    rects: Vec<[u16; 4]>,
    size: usize,
}

impl SpotMaps {
    /// Splats the real surface (every valid pixel, seen from the camera at
    /// `camera_origin`) into each spot's `size`-texel map, and fills its holes
    /// (`levels`).
    pub fn build(
        &mut self,
        spots: &[SpotLight],
        real: &RealSurface,
        camera_origin: Vec3,
        size: usize,
        levels: usize,
        kernel: Option<Kernel>,
    ) {
        let texels = size * size;
        self.size = size;
        self.projections.clear();
        self.projections
            .extend(spots.iter().map(|s| Projection::Paraboloid {
                origin: s.position,
                frame: frame_about(s.direction),
            }));
        self.maps.clear();
        self.maps.resize(spots.len() * texels, f32::INFINITY);
        self.rects.clear();
        self.rects.resize(spots.len(), [0; 4]);
        if texels == 0 {
            return;
        }
        let projections = &self.projections;
        self.maps
            .par_chunks_mut(texels)
            .zip(self.rects.par_iter_mut())
            .enumerate()
            .for_each_init(Vec::new, |scratch, (i, (map, rect))| {
                let points = real_patches(real, camera_origin);
                let splats = splat_with(kernel, map, size, &projections[i], points);
                *rect = fill_holes(map, size, levels, splats, scratch);
            });
    }

    /// Spot `i`'s map.
    fn map(&self, i: usize, bias: f32, slope: f32) -> MapView<'_> {
        let texels = self.size * self.size;
        MapView {
            projection: &self.projections[i],
            depth: &self.maps[i * texels..(i + 1) * texels],
            size: self.size,
            rect: self.rects[i],
            bias,
            slope,
        }
    }
}

/// Every valid pixel's point with the radius of the circle around the surface it
/// sees: a rectangle sqrt(A) by sqrt(A) / cos, A its area facing the camera and cos
/// that of the view (at least 0.2: grazing views). Neighbouring pixels' splats then
/// overlap, so that a surface the camera sees at a slant closes in the map as a
/// rasterized mesh would (what lies behind it must not show through).
fn real_patches(real: &RealSurface, camera_origin: Vec3) -> impl Iterator<Item = (Vec3, f32)> + '_ {
    real.valid.iter().map(move |&i| {
        let (p, n) = (real.position[i as usize], real.normal[i as usize]);
        let cos = n
            .dot((camera_origin - p).normalize_or_zero())
            .abs()
            .max(0.2);
        let side = real.area[i as usize].sqrt();
        (p, 0.5 * side * (1.0 + 1.0 / (cos * cos)).sqrt())
    })
}

/// The spots and their maps, with the shadow test's settings: what a receiver needs
/// to gather them.
#[derive(Clone, Copy)]
pub struct SpotSet<'a> {
    pub spots: &'a [SpotLight],
    pub maps: &'a SpotMaps,
    pub objects: &'a VirtualScene,
    pub bias: f32,
    pub slope: f32,
    pub flags: Flags,
}

/// What one receiver gathers from the spots.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpotGathered {
    /// Direct irradiance of L_r (real spots, real receivers).
    pub r_dir: Vec3,
    /// Direct irradiance of L_rv from the real spots.
    pub rv_dir_real: Vec3,
    /// Direct irradiance of L_rv from the virtual spots.
    pub rv_dir_virtual: Vec3,
    /// Some spot added differently to L_r and L_rv.
    pub touched: bool,
    /// The nearest blocker of a shadowed spot over the cosine (as the VPLs' gather
    /// records it); INFINITY where none.
    pub direct_min_distance: f32,
}

impl SpotGathered {
    /// Direct irradiance of L_rv from every spot.
    pub fn rv_dir(&self) -> Vec3 {
        self.rv_dir_real + self.rv_dir_virtual
    }
}

impl SpotSet<'_> {
    /// True when there are no spots: gathering gives nothing.
    pub fn is_empty(&self) -> bool {
        self.spots.is_empty()
    }

    /// The spots' direct light at `position` with unit `normal` (see the module docs).
    pub fn gather(&self, position: Vec3, normal: Vec3, receiver: Receiver) -> SpotGathered {
        let mut g = SpotGathered {
            direct_min_distance: f32::INFINITY,
            ..SpotGathered::default()
        };
        for (i, spot) in self.spots.iter().enumerate() {
            let Some(arrival) = spot.arrival(position, normal) else {
                continue;
            };
            let real_light = spot.world == LightWorld::Real;
            let for_real = real_light && receiver == Receiver::Real;
            let (st_r, behind_r) = self
                .maps
                .map(i, self.bias, self.slope)
                .visibility(position, arrival.cos);
            let (st_v, behind_v) = self.virtual_visibility(spot, position, arrival.distance);
            let (st_r, st_rv) =
                shadow_terms(self.flags, real_light, (st_r, behind_r), (st_v, behind_v));
            let light = arrival.irradiance;
            if for_real {
                g.r_dir += light * st_r;
            }
            if real_light {
                g.rv_dir_real += light * st_rv;
            } else {
                g.rv_dir_virtual += light * st_rv;
            }
            if !for_real || st_rv != st_r {
                g.touched = true;
            }
            let behind = behind_r.min(behind_v);
            if behind.is_finite() {
                g.direct_min_distance = g.direct_min_distance.min(behind / arrival.cos.max(1e-3));
            }
        }
        g
    }
}

impl SpotSet<'_> {
    /// 1 when no object stands between `spot` and `position` (`distance` metres
    /// apart), else 0 with the metres from `position` back to the blocker nearest the
    /// light. The ray stops a millimetre (and 0.1 %) short of the receiver, so that a
    /// point on an object does not shadow itself.
    fn virtual_visibility(&self, spot: &SpotLight, position: Vec3, distance: f32) -> (f32, f32) {
        if self.objects.is_empty() {
            return (1.0, f32::INFINITY);
        }
        let dir = (position - spot.position) / distance;
        let end = distance * (1.0 - 1e-3) - 1e-3;
        match self.objects.intersect(spot.position, dir, 0.0, end) {
            Some(hit) => (0.0, distance - hit.t),
            None => (1.0, f32::INFINITY),
        }
    }
}

/// Paper 002 Sec. 3.7's split of a spot's VPL slots between its two reflective shadow
/// maps (`spot_split = "coverage"`): the real surfaces' and the objects' shares are the
/// solid angles they cover as the virtual spots see them (the maps' pixel counts: a
/// candidate of area A at distance d, its normal at angle theta to the spot, covers
/// A cos(theta) / d^2 of each spot whose cone holds it), normalized to a probability
/// p; slot i goes to the objects when the base-2 Halton value of i is below p. Each
/// kind's slots are then drawn by light ([`resample`], the RSM's importance sampling).
/// `candidates` are the virtual spots' candidates (real first or mixed, `real` says).
pub(super) fn split_by_coverage(
    candidates: &[Candidate],
    spots: &[SpotLight],
    slots: usize,
    first_slot: u32,
    key: u64,
    out: &mut Vec<Vpl>,
) {
    let p_virtual = virtual_coverage(candidates, spots);
    let virtual_slots = (0..slots as u32)
        .filter(|&i| halton2(i) < p_virtual)
        .count();
    let (real, virtual_): (Vec<Candidate>, Vec<Candidate>) =
        candidates.iter().partition(|c| c.real);
    resample(&real, slots - virtual_slots, first_slot, key, out);
    let next_slot = out
        .last()
        .map_or(first_slot, |v| v.slot + 1)
        .max(first_slot);
    resample(&virtual_, virtual_slots, next_slot, key ^ 0x7EA1, out);
}

/// The objects' share of the solid angle the candidates cover as the virtual spots
/// see them (0 when nothing is covered).
pub(super) fn virtual_coverage(candidates: &[Candidate], spots: &[SpotLight]) -> f64 {
    let (mut real, mut virtual_) = (0.0f64, 0.0f64);
    for c in candidates {
        let covered: f64 = spots
            .iter()
            .filter(|s| s.world == LightWorld::Virtual && s.arrival(c.position, c.normal).is_some())
            .map(|s| {
                let v = s.position - c.position;
                let d2 = v.length_squared() as f64;
                c.area as f64 * c.normal.dot(v).abs() as f64 / (d2 * d2.sqrt())
            })
            .filter(|w| w.is_finite())
            .sum();
        if c.real {
            real += covered;
        } else {
            virtual_ += covered;
        }
    }
    if real + virtual_ > 0.0 {
        virtual_ / (real + virtual_)
    } else {
        0.0
    }
}

/// The base-2 Halton value (radical inverse) of `i`, in [0, 1).
fn halton2(i: u32) -> f64 {
    i.reverse_bits() as f64 / (1u64 << 32) as f64
}
