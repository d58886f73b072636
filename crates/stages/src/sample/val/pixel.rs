//! The per-pixel pass of `sample.val`: which surface the pixel shows (real point from
//! the depth map, or the virtual hit at the pixel centre) and its shading.

use super::ValInputs;
use super::raster::NO_ID;
#[cfg(test)]
use super::shade::shade_point;
use super::shade::{Biases, Maps, PreparedLight, Sh9Irradiance, Shaded};
use super::shade_lanes::{Points, shade_points};
use super::shadow::{PointSampling, TILE};
use crate::sample::layers::{LayerRow, PixelLayers};
use glam::{Vec3, Vec3A};
use relume_base::raster::depth_is_valid;
use relume_base::simd::{LANES, Lanes};
use relume_scene::light::prt::{Transfer, barycentrics};
use relume_scene::objects::ray_triangle;

/// How the camera sampled the real points.
pub(super) fn sampling_of(inputs: &ValInputs) -> PointSampling {
    PointSampling {
        origin: inputs.camera_to_world.translation,
        pixel_angle: 1.0 / inputs.camera.fx.abs().min(inputs.camera.fy.abs()),
    }
}

/// Everything the per-pixel pass reads.
pub(super) struct PixelContext<'a> {
    pub(super) inputs: &'a ValInputs<'a>,
    pub(super) real_points: &'a [Vec3A],
    pub(super) real_normals: &'a [Vec3A],
    pub(super) real_patches: &'a [f32],
    pub(super) lookup: &'a [u64],
    pub(super) tiles_per_row: usize,
    pub(super) ids: &'a [u32],
    pub(super) lights: &'a [PreparedLight],
    pub(super) maps: Maps<'a>,
    pub(super) biases: Biases,
    pub(super) sh: Sh9Irradiance,
    pub(super) sampling: PointSampling,
    /// Per object, the other objects' radiance SH coefficients (`bounce.rs`); empty
    /// when off or with fewer than two objects.
    pub(super) object_bounce: &'a [[Vec3; 9]],
}

/// A virtual surface seen at a pixel centre, before shading.
struct VirtualHit {
    x: usize,
    position: Vec3A,
    normal: Vec3A,
    /// The world size of its splat in the maps ([`PointSampling::footprint`]).
    patch: f32,
    albedo: Vec3,
    /// Its indirect irradiance (SH9, through the transfer when there is one).
    e_ind: Vec3,
}

/// The layers a visible virtual surface sets ([`put_virtual`]).
struct VirtualSurface {
    e_rv_dir: Vec3,
    e_rv_ind: Vec3,
    k_v: Vec3,
    position: Vec3,
    normal: Vec3,
    direct_min_distance: f32,
}

/// Pixel `x` of `row` shows the virtual surface `v`: its mask is 0, and E_R stays
/// the real surface's behind it.
#[inline(always)]
fn put_virtual(row: &mut LayerRow<'_>, x: usize, v: &VirtualSurface) {
    row.e_rv_dir[x] = v.e_rv_dir;
    row.e_rv_ind[x] = v.e_rv_ind;
    row.mask[x] = 0.0;
    row.k_v[x] = v.k_v;
    row.world_position[x] = v.position;
    row.world_normal[x] = v.normal;
    row.direct_min_distance[x] = v.direct_min_distance;
}

/// [`PixelContext::row`] with AVX2 + FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn row_avx2(context: &PixelContext, y: usize, out: &mut LayerRow<'_>) {
    context.row::<relume_base::simd::Avx2>(y, out)
}

impl PixelContext<'_> {
    /// Row `y` into `out`: the real surfaces shaded [`LANES`] pixels at a time, then
    /// the row's virtual surfaces [`LANES`] at a time ([`shade_points`], the same bits
    /// as the scalar `shade_point`).
    #[inline(always)]
    pub(super) fn row<V: Lanes>(&self, y: usize, out: &mut LayerRow<'_>) {
        let w = self.inputs.depth.width as usize;
        let mut virtual_hits = Vec::new();
        for x0 in (0..w).step_by(LANES) {
            let lanes = LANES.min(w - x0);
            let mut real = PointArrays::default();
            for l in 0..lanes {
                let i = y * w + x0 + l;
                let (point, normal, real_ok) = self.real_at(i);
                if real_ok {
                    real.set(l, point, normal, self.real_patches[i]);
                }
            }
            // An `if`, not a closure: lane operations stay out of closures (see
            // `relume_base::simd`).
            let shaded = if real.any() {
                // x0 is a multiple of LANES, which divides TILE: one tile.
                const _: () = assert!(TILE.is_multiple_of(LANES));
                let lookup = self.lookup[(y / TILE) * self.tiles_per_row + x0 / TILE];
                let points = real.points::<V>();
                Some(shade_points(
                    &points,
                    lookup,
                    self.lights,
                    self.maps,
                    self.biases,
                ))
            } else {
                None
            };
            for l in 0..lanes {
                let x = x0 + l;
                let real_shaded = shaded
                    .as_ref()
                    .filter(|_| real.is_set(l))
                    .map(|s| s.lane(l));
                out.set(x, &self.real_pixel(y * w + x, real_shaded));
                let id = self.ids[y * w + x];
                if id != NO_ID
                    && let Some(hit) = self.virtual_hit(x, y, id)
                {
                    virtual_hits.push(hit);
                }
            }
        }
        for hits in virtual_hits.chunks(LANES) {
            let mut surfaces = PointArrays::default();
            for (l, hit) in hits.iter().enumerate() {
                surfaces.set(l, hit.position, hit.normal, hit.patch);
            }
            let points = surfaces.points::<V>();
            // The objects lie inside every frustum: always look up.
            let shaded = shade_points(&points, u64::MAX, self.lights, self.maps, self.biases);
            for (l, hit) in hits.iter().enumerate() {
                put_virtual(out, hit.x, &self.virtual_surface(hit, shaded.lane(l)));
            }
        }
    }

    /// The real surface at pixel `i`: world point, normal, and whether both exist.
    #[inline]
    fn real_at(&self, i: usize) -> (Vec3A, Vec3A, bool) {
        let real = self.real_points[i];
        let real_normal = self.real_normals[i];
        (
            real,
            real_normal,
            real.is_finite() && real_normal != Vec3A::ZERO,
        )
    }

    /// Every layer of pixel (x, y) into `row`, each surface shaded by [`shade_point`]
    /// (the reference of [`PixelContext::row`]).
    #[cfg(test)]
    pub(super) fn pixel(&self, x: usize, y: usize, row: &mut LayerRow<'_>) {
        let i = y * self.inputs.depth.width as usize + x;
        let (real, real_normal, real_ok) = self.real_at(i);
        let real_shaded = real_ok.then(|| {
            let lookup = self.lookup[(y / TILE) * self.tiles_per_row + x / TILE];
            let patch = self.real_patches[i];
            let (lights, maps, biases) = (self.lights, self.maps, self.biases);
            shade_point(real, real_normal, patch, lookup, lights, maps, biases)
        });
        row.set(x, &self.real_pixel(i, real_shaded));
        let id = self.ids[i];
        if id != NO_ID
            && let Some(hit) = self.virtual_hit(x, y, id)
        {
            let (lights, maps, biases) = (self.lights, self.maps, self.biases);
            let s = shade_point(
                hit.position,
                hit.normal,
                hit.patch,
                u64::MAX,
                lights,
                maps,
                biases,
            );
            put_virtual(row, x, &self.virtual_surface(&hit, s));
        }
    }

    /// Every output of pixel `i` for its real surface, given that surface's shading
    /// (`None` where it has none). Inlined into the row loops, so that the shading
    /// stays in registers.
    #[inline(always)]
    fn real_pixel(&self, i: usize, real_shaded: Option<Shaded>) -> PixelLayers {
        let (real, real_normal, _) = self.real_at(i);
        let mut out = PixelLayers {
            e_r_dir: Vec3::NAN,
            e_r_ind: Vec3::NAN,
            e_rv_dir: Vec3::NAN,
            e_rv_ind: Vec3::NAN,
            mask: 1.0,
            k_v: Vec3::ZERO,
            // Glossy objects are shaded as diffuse.
            exponent: 0.0,
            world_position: real.into(),
            world_normal: real_normal.into(),
            direct_min_distance: f32::INFINITY,
            // No indirect path is traced, and none is known to miss the objects.
            indirect_min_distance: f32::INFINITY,
            // Not an output (see `OUTPUTS`): no pixel is known to be untouched.
            touched: true,
        };
        if let Some(s) = real_shaded {
            let e_ind = self.sh.at(real_normal);
            out.e_r_dir = s.e_r;
            out.e_r_ind = e_ind;
            out.e_rv_dir = s.e_rv;
            out.e_rv_ind = e_ind;
            out.direct_min_distance = s.min_occluder;
        }
        out
    }

    /// The virtual surface of triangle `id` at the centre of pixel (x, y), where the
    /// camera raster found it; `None` where the real surface is the nearer after all
    /// (or the ray misses at the very edge). Out of line: few pixels show the objects.
    #[inline(never)]
    fn virtual_hit(&self, x: usize, y: usize, id: u32) -> Option<VirtualHit> {
        let i = y * self.inputs.depth.width as usize + x;
        let c = self.inputs.camera;
        let ray = c.ray(x as f32, y as f32);
        let dir = self
            .inputs
            .camera_to_world
            .transform_vector3(ray)
            .normalize();
        let origin = Vec3::from(self.sampling.origin);
        let scene = self.inputs.objects;
        let tri = &scene.triangles[id as usize];
        let (hit, u, v) = match ray_triangle(origin, dir, &tri.vertices, 0.0, f32::INFINITY) {
            Some((t, u, v)) => (scene.hit_record(origin, dir, t, id, u, v), u, v),
            // The raster and the ray test disagree at the very edge: ask the scene.
            None => {
                let hit = scene.intersect(origin, dir, 0.0, f32::INFINITY)?;
                let corners = &scene.triangles[hit.triangle as usize].vertices;
                let (u, v) = barycentrics(corners, hit.position);
                (hit, u, v)
            }
        };
        let z = self.inputs.depth.data[i];
        if depth_is_valid(z) && hit.t >= z * ray.length() {
            return None;
        }
        let position = Vec3A::from(hit.position);
        let e_ind = match self.inputs.transfer {
            Some(transfer) => {
                let room =
                    Transfer::irradiance(&transfer.at(hit.triangle, u, v), &self.inputs.lights.sh9);
                let object = scene.triangles[hit.triangle as usize].material as usize;
                match (
                    self.object_bounce.get(object),
                    transfer.bounce_at(hit.triangle, u, v),
                ) {
                    (Some(others), Some(vector)) => room + Transfer::irradiance(&vector, others),
                    _ => room,
                }
            }
            None => self.sh.at(hit.normal.into()),
        };
        Some(VirtualHit {
            x,
            position,
            normal: hit.normal.into(),
            e_ind,
            patch: self.sampling.footprint(position),
            albedo: hit.material.albedo,
        })
    }

    /// The outputs of virtual surface `hit` given its shading `s`.
    #[inline(always)]
    fn virtual_surface(&self, hit: &VirtualHit, s: Shaded) -> VirtualSurface {
        VirtualSurface {
            e_rv_dir: s.e_rv,
            e_rv_ind: hit.e_ind,
            k_v: hit.albedo,
            position: hit.position.into(),
            normal: hit.normal.into(),
            direct_min_distance: s.min_occluder,
        }
    }
}

/// Up to eight shading points gathered lane by lane, then loaded as [`Points`]; lanes
/// not set hold zeros and are inactive.
#[derive(Default)]
pub(super) struct PointArrays {
    position: [[f32; LANES]; 3],
    normal: [[f32; LANES]; 3],
    patch: [f32; LANES],
    active: [f32; LANES],
}

impl PointArrays {
    #[inline(always)]
    pub(super) fn set(&mut self, l: usize, position: Vec3A, normal: Vec3A, patch: f32) {
        for c in 0..3 {
            self.position[c][l] = position[c];
            self.normal[c][l] = normal[c];
        }
        self.patch[l] = patch;
        self.active[l] = f32::from_bits(u32::MAX);
    }

    #[inline(always)]
    fn is_set(&self, l: usize) -> bool {
        self.active[l].to_bits() != 0
    }

    #[inline(always)]
    fn any(&self) -> bool {
        self.active.iter().any(|a| a.to_bits() != 0)
    }

    #[inline(always)]
    pub(super) fn points<V: Lanes>(&self) -> Points<V> {
        Points {
            position: [
                V::from_array(self.position[0]),
                V::from_array(self.position[1]),
                V::from_array(self.position[2]),
            ],
            normal: [
                V::from_array(self.normal[0]),
                V::from_array(self.normal[1]),
                V::from_array(self.normal[2]),
            ],
            patch: V::from_array(self.patch),
            active: V::from_array(self.active),
        }
    }
}
