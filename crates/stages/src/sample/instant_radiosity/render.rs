//! One frame of Differential Instant Radiosity: the VPLs and their maps, then the
//! interleaved gather and the blur (the order of paper 002 Fig. 2).
//!
//! ## Bounces
//!
//! The bounce VPLs (paper 002 Secs. 3.6, 3.7): candidates on the real surface and on
//! the meshes, lit by the lights of the bounce before, resampled into each bounce's
//! slots with their maps.
//!
//! - **First bounce** (lit by the environment VPLs): a real candidate's outgoing light
//!   is the camera's (compensated) radiance times its area in the real world, and that
//!   times the fraction f of its direct light the objects let through in the combined
//!   world; a virtual one's is k_V E_RV^dir / pi times its area, in the combined world
//!   only.
//! - **Further bounces** (`bounces` > 1, Sec. 3.6): every candidate gathers the last
//!   bounce's VPLs (with their maps) as a receiver of its kind, E_R^ind and E_RV^ind;
//!   it reflects rho / pi of them, rho / pi = L_cam / (E_R^dir + the E_R^ind gathered
//!   so far) on a real surface (the albedo the camera and the real solution imply, as
//!   `material.estimate` does after paper 000 eq. 5; clamped to 1 / pi) and k_V / pi on
//!   a virtual one, which passes light on in the combined world only. Light that
//!   reached a real candidate over a path with a virtual object on it lands in L_rv
//!   alone, light the objects took away in L_r alone, so the flags of eq. 9 (x-bar =
//!   x-bar_prev r(p_VPL), ir copied) follow from the two sums ([`super::vpl::split`]).
//!
//! The `vpls - environment_vpls` bounce slots are shared evenly between the bounces (the
//! first takes the remainder), and within a bounce `virtual_share` of them go to the
//! meshes' candidates.

use super::blur::blur_layers;
use super::gather_lanes::gather_each;
use super::interleave::{Interleaved, RowScratch, object_rect, primary_hit};
use super::ism::{Projection, fill_holes, frame_about};
use super::params::Flags;
use super::params::{DirInputs, DirParams};
use super::points::{MeshPoints, RealSurface};
use super::shade::{LightSet, Receiver, gather};
use super::splat::splat_with;
use super::spots::{SpotMaps, SpotSet, split_by_coverage};
use super::vpl::{Candidate, Emitter, Vpl, environment_vpls, resample};
use crate::OpError;
use crate::sample::layers::{IrradianceLayers, check_sizes, shade_rows};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng;
use relume_base::simd::Kernel;
use relume_scene::light::split::luminance;
use std::f32::consts::{FRAC_1_PI, PI};

/// Shades frames with reusable buffers (real surface, VPLs, shadow maps, the
/// un-blurred layers).
pub struct DirRenderer {
    pub(super) real: RealSurface,
    pub(super) vpls: Vec<Vpl>,
    pub(super) projections: Vec<[Projection; 2]>,
    pub(super) rects: Vec<[[u16; 4]; 2]>,
    pub(super) maps: Vec<f32>,
    /// Texels per side of `maps` (they are cleared where `rects` say, frame to frame).
    map_size: usize,
    pub(super) candidates: Vec<Candidate>,
    /// Per candidate, what its surface reflects (see [Bounces](self#bounces)).
    pub(super) reflectors: Vec<Reflector>,
    /// Real points and mesh points lit by the virtual spots: what they reflect of
    /// that light (in L_rv only), the candidates of the spots' own bounce VPLs.
    pub(super) spot_candidates: Vec<Candidate>,
    /// Per interleaving class, the indices of its VPLs.
    members: Vec<Vec<u32>>,
    /// The environment VPLs' indices (0..n).
    pub(super) environment: Vec<u32>,
    /// The spot lights' shadow maps.
    pub(super) spot_maps: SpotMaps,
    raw: Option<IrradianceLayers>,
    /// The blur's pass along x.
    between: Option<IrradianceLayers>,
    /// What the last [`DirRenderer::lights`] made lights for (`None` before, or after
    /// one that failed): the frame's width and height, the interleaving, the maps'
    /// size, the number of spot lights and the flags, which [`DirRenderer::shade`]
    /// must be asked for.
    lit: Option<[u32; 6]>,
    /// The lanes that gather, blur and project eight receivers, pixels or points at a
    /// time; `None`: one at a time (the same bits).
    pub(super) kernel: Option<Kernel>,
}

impl Default for DirRenderer {
    fn default() -> Self {
        // The lanes only where they are fast: the portable ones are slower than
        // the one-pixel gather.
        let kernel = (Kernel::detect() == Kernel::Avx2Fma).then_some(Kernel::Avx2Fma);
        DirRenderer::with_kernel(kernel)
    }
}

impl DirRenderer {
    /// A renderer that runs `kernel`'s lanes, or one receiver, pixel and point at a time
    /// (`None`); every choice gives the same bits.
    pub fn with_kernel(kernel: Option<Kernel>) -> DirRenderer {
        DirRenderer {
            real: RealSurface::default(),
            vpls: Vec::new(),
            projections: Vec::new(),
            rects: Vec::new(),
            maps: Vec::new(),
            map_size: 0,
            candidates: Vec::new(),
            reflectors: Vec::new(),
            spot_candidates: Vec::new(),
            members: Vec::new(),
            environment: Vec::new(),
            spot_maps: SpotMaps::default(),
            raw: None,
            between: None,
            lit: None,
            kernel,
        }
    }

    /// Renders one frame into `out` (the depth map's size): [`DirRenderer::lights`],
    /// then [`DirRenderer::shade`].
    pub fn render(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        mesh: &MeshPoints,
        out: &mut IrradianceLayers,
    ) -> Result<(), OpError> {
        self.lights(inputs, params, mesh)?;
        self.shade(inputs, params, out)
    }

    /// The frame's VPLs and their shadow maps (steps 1-3 of the module docs).
    pub fn lights(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        mesh: &MeshPoints,
    ) -> Result<(), OpError> {
        let (w, h) = (inputs.depth.width, inputs.depth.height);
        self.lit = None;
        check_sizes(
            "sample.dir",
            (w, h),
            &[
                ("normals", inputs.normals.width, inputs.normals.height),
                ("radiance", inputs.radiance.width, inputs.radiance.height),
                ("camera", inputs.camera.width, inputs.camera.height),
            ],
        )?;
        if !inputs.camera_to_world.is_finite() {
            return Err(OpError::BadInput(
                "sample.dir: the camera pose is not finite".into(),
            ));
        }
        params.check()?;
        self.real.update(
            inputs.depth,
            inputs.normals,
            inputs.camera,
            inputs.camera_to_world,
        );
        let key = rng::hash(&[params.seed, inputs.frame, 0xD1_0001]);
        self.spot_maps.build(
            inputs.spots,
            &self.real,
            inputs.camera_to_world.translation.into(),
            params.spot_map_size as usize,
            params.fill_levels as usize,
            self.kernel,
        );

        // The primary light's VPLs and their maps.
        let (center, object_radius) = objects_sphere(inputs, &self.real);
        self.vpls.clear();
        self.vpls
            .extend(environment_vpls(inputs.table, params.environment_vpls, key));
        let environment = self.vpls.len();
        self.environment.clear();
        self.environment.extend(0..environment as u32);
        self.projections.clear();
        for v in &self.vpls {
            let Emitter::Direction(d) = v.emitter else {
                unreachable!("environment VPLs are directions")
            };
            let frame = frame_about(d);
            self.projections.push([
                Projection::Orthographic {
                    center,
                    radius: object_radius + params.max_distance,
                    frame,
                },
                Projection::Orthographic {
                    center,
                    radius: object_radius.max(1e-3),
                    frame,
                },
            ]);
        }
        self.build_maps(0, params, mesh, key);

        // The bounces (Secs. 3.6, 3.7): candidates lit by the last lights, resampled
        // into the slots, and their maps.
        self.bounces(inputs, params, mesh, key, environment);
        let classes = (params.interleave * params.interleave) as usize;
        for members in &mut self.members {
            members.clear();
        }
        self.members.resize(classes, Vec::new());
        for (i, v) in self.vpls.iter().enumerate() {
            self.members[v.slot as usize % classes].push(i as u32);
        }
        self.lit = Some(lit_frame(w, h, params, inputs.spots.len()));
        Ok(())
    }

    /// The interleaved gather and the blur into `out` (steps 4-5), from the VPLs of the
    /// last [`DirRenderer::lights`] on the same inputs. An error when the last lights
    /// were not made for a frame of this size with this interleaving and map size, or
    /// `out` is not that size.
    pub fn shade(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        out: &mut IrradianceLayers,
    ) -> Result<(), OpError> {
        let (w, h) = (inputs.depth.width, inputs.depth.height);
        let k = params.interleave as usize;
        if self.lit != Some(lit_frame(w, h, params, inputs.spots.len())) {
            return Err(OpError::BadInput(format!(
                "sample.dir: no lights made for a {w}x{h} frame with interleave {k}, {s}x{s} maps, {n} spot lights and flags {f:?} to shade",
                s = params.shadow_map_size,
                n = inputs.spots.len(),
                f = params.flags
            )));
        }
        if out.size() != Some((w, h)) {
            return Err(OpError::SizeMismatch(format!(
                "sample.dir: output buffers are not all {w}x{h}"
            )));
        }
        let raw = match &mut self.raw {
            Some(raw) if raw.size() == Some((w, h)) => raw,
            slot => slot.insert(IrradianceLayers::new(w, h)),
        };
        let lights = light_set(
            &self.vpls,
            &self.projections,
            &self.rects,
            &self.maps,
            params,
        );
        let interleaved = Interleaved {
            inputs,
            lights: &lights,
            real: &self.real,
            members: &self.members,
            k,
            kernel: self.kernel,
            object_rect: object_rect(inputs),
        };
        shade_rows(
            raw,
            w as usize,
            1,
            RowScratch::default,
            |scratch, y, mut row| interleaved.shade_row(y, &mut row, scratch),
        );
        let between = match &mut self.between {
            Some(between) if between.size() == Some((w, h)) => between,
            slot => slot.insert(IrradianceLayers::new(w, h)),
        };
        blur_layers(raw, &self.real, k, self.kernel, between, out);
        let spots = self.spot_set(inputs, params);
        if !spots.is_empty() {
            let real = &self.real;
            let rect = object_rect(inputs);
            shade_rows(
                out,
                w as usize,
                1,
                || (),
                |_, y, mut row| add_spots(&spots, inputs, real, rect, y, &mut row),
            );
        }
        Ok(())
    }

    /// The spots with their maps from the last [`DirRenderer::lights`].
    pub(super) fn spot_set<'a>(&'a self, inputs: &'a DirInputs, params: &DirParams) -> SpotSet<'a> {
        SpotSet {
            spots: inputs.spots,
            maps: &self.spot_maps,
            objects: inputs.objects,
            bias: params.bias,
            slope: params.slope_bias,
            flags: params.flags,
        }
    }

    /// Splats and fills the maps of slots `first..`: `points_per_vpl` real points into
    /// the real map, as many mesh points into the virtual one, each VPL its own subset.
    pub(super) fn build_maps(
        &mut self,
        first: usize,
        params: &DirParams,
        mesh: &MeshPoints,
        key: u64,
    ) {
        let size = params.shadow_map_size as usize;
        let texels = size * size;
        let n = self.projections.len();
        if self.map_size != size {
            // Another size: the rectangles no longer say where the old depths are.
            self.maps.clear();
            self.rects.clear();
            self.map_size = size;
        }
        // Only grown: slots past this frame's keep their maps and rectangles (what the
        // next frame to use them clears).
        if self.maps.len() < 2 * n * texels {
            self.maps.resize(2 * n * texels, f32::INFINITY);
        }
        if self.rects.len() < n {
            self.rects.resize(n, [[0; 4]; 2]);
        }
        let count = params.points_per_vpl as usize;
        let (real, projections) = (&self.real, &self.projections);
        let levels = params.fill_levels as usize;
        let kernel = self.kernel;
        self.maps[2 * first * texels..]
            .par_chunks_mut(2 * texels)
            .zip(self.rects[first..n].par_iter_mut())
            .enumerate()
            .for_each_init(Vec::new, |scratch, (j, (maps, rects))| {
                let i = first + j;
                let (real_map, virtual_map) = maps.split_at_mut(texels);
                let vpl_key = rng::hash(&[key, 0x15A, i as u64]);
                // Every depth the slot's maps held lies in last frame's rectangles.
                clear(real_map, size, rects[0]);
                clear(virtual_map, size, rects[1]);
                let real_splats = splat_with(
                    kernel,
                    real_map,
                    size,
                    &projections[i][0],
                    real.subset(count, vpl_key),
                );
                let virtual_splats = splat_with(
                    kernel,
                    virtual_map,
                    size,
                    &projections[i][1],
                    mesh.subset(count, vpl_key ^ 1),
                );
                *rects = [
                    fill_holes(real_map, size, levels, real_splats, scratch),
                    fill_holes(virtual_map, size, levels, virtual_splats, scratch),
                ];
            });
    }
}

/// What [`DirRenderer::lit`] records of a frame `w` x `h` lit with `params` and
/// `spots` spot lights.
fn lit_frame(w: u32, h: u32, params: &DirParams, spots: usize) -> [u32; 6] {
    let flags = params.flags as u32;
    [
        w,
        h,
        params.interleave,
        params.shadow_map_size,
        spots as u32,
        flags,
    ]
}

/// Empties the rectangle `[x0, y0, x1, y1)` of a `size`-texel map.
fn clear(map: &mut [f32], size: usize, rect: [u16; 4]) {
    let [x0, y0, x1, y1] = rect.map(usize::from);
    for y in y0..y1.min(size) {
        map[y * size + x0..y * size + x1.min(size)].fill(f32::INFINITY);
    }
}

pub(super) fn light_set<'a>(
    vpls: &'a [Vpl],
    projections: &'a [[Projection; 2]],
    rects: &'a [[[u16; 4]; 2]],
    maps: &'a [f32],
    params: &DirParams,
) -> LightSet<'a> {
    let n = projections.len().min(rects.len());
    LightSet {
        vpls,
        projections: &projections[..n],
        rects: &rects[..n],
        maps,
        size: params.shadow_map_size as usize,
        bias: params.bias,
        slope: params.slope_bias,
        clamp_squared: params.clamp_distance * params.clamp_distance,
        reach: params.max_distance,
        flags: params.flags,
    }
}

/// Adds the spots' direct light to row `y` of the blurred layers: at the real point
/// to E_R, and to E_RV at the object the view ray meets in front of it, else at the
/// real point (see `spots.rs`).
fn add_spots(
    spots: &SpotSet,
    inputs: &DirInputs,
    real: &RealSurface,
    object_rect: [usize; 4],
    y: usize,
    row: &mut crate::sample::layers::LayerRow<'_>,
) {
    let w = inputs.depth.width as usize;
    let in_rect_row = (object_rect[1]..object_rect[3]).contains(&y);
    for x in 0..w {
        let i = y * w + x;
        let (p, n) = (real.position[i], real.normal[i]);
        let at_real = (n != Vec3::ZERO).then(|| spots.gather(p, n, Receiver::Real));
        let inside = in_rect_row && (object_rect[0]..object_rect[2]).contains(&x);
        let hit = inside
            .then(|| primary_hit(inputs, x, y, at_real.map(|_| p)))
            .flatten();
        let at_hit = hit.map(|h| spots.gather(h.position, h.normal, Receiver::Virtual));
        if let Some(r) = at_real {
            row.e_r_dir[x] += r.r_dir;
        }
        let Some(v) = at_hit.or(at_real) else {
            continue;
        };
        row.e_rv_dir[x] += v.rv_dir();
        let nearest = at_real.map_or(f32::INFINITY, |r| r.direct_min_distance);
        row.direct_min_distance[x] = row.direct_min_distance[x]
            .min(nearest)
            .min(v.direct_min_distance);
        if v.touched || at_real.is_some_and(|r| r.touched) {
            row.touched[x] = 1;
        }
    }
}

/// The sphere around the objects (their bounding box's), or around the real points
/// with radius 0 when there are none: the environment maps' discs are centred there.
fn objects_sphere(inputs: &DirInputs, real: &RealSurface) -> (Vec3, f32) {
    if !inputs.objects.is_empty() {
        let b = inputs.objects.bounds();
        return (b.center(), (b.max - b.min).length() * 0.5);
    }
    let mut sum = glam::DVec3::ZERO;
    for &i in &real.valid {
        sum += real.position[i as usize].as_dvec3();
    }
    let center = (sum / real.valid.len().max(1) as f64).as_vec3();
    (
        if center.is_finite() {
            center
        } else {
            Vec3::ZERO
        },
        0.0,
    )
}

/// rho / pi of a real surface from its camera radiance and the direct irradiance of
/// the real solution, clamped to 1 / pi (0 where it receives none: nothing to tell).
fn implied_reflectance(radiance: Vec3, received_r: Vec3) -> Vec3 {
    Vec3::select(
        received_r.cmpgt(Vec3::splat(1e-6)),
        (radiance.max(Vec3::ZERO) / received_r).min(Vec3::splat(FRAC_1_PI)),
        Vec3::ZERO,
    )
}

/// What a candidate's surface reflects into the next bounce.
#[derive(Clone, Copy, Debug)]
pub struct Reflector {
    /// Real: the camera's compensated radiance there. Virtual: k_V / pi.
    pub radiance_or_reflectance: Vec3,
    /// Real: the irradiance of the real solution gathered so far (direct, then each
    /// bounce's indirect).
    pub received_r: Vec3,
}

impl DirRenderer {
    /// Places every bounce's VPLs after the `environment` ones, and builds their maps.
    pub(super) fn bounces(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        mesh: &MeshPoints,
        key: u64,
        environment: usize,
    ) {
        self.candidates.clear();
        self.reflectors.clear();
        self.spot_candidates.clear();
        self.real_candidates(inputs, params, key);
        let real_count = self.candidates.len();
        self.virtual_candidates(inputs, params, mesh, key);
        let slots = (params.vpls as usize).saturating_sub(environment);
        let bounces = params.bounces.max(1) as usize;
        let mut first = environment;
        for bounce in 0..bounces {
            if bounce > 0 {
                let last: Vec<u32> = (first as u32..self.vpls.len() as u32).collect();
                first = self.vpls.len();
                self.relight(params, &last);
            }
            let share = slots / bounces + if bounce == 0 { slots % bounces } else { 0 };
            let bounce_key = if bounce == 0 {
                key
            } else {
                rng::hash(&[key, 0xB0, bounce as u64])
            };
            let slots_before = self.projections.len();
            self.place(params, real_count, share, bounce_key);
            self.project_new_slots(first);
            self.build_maps(slots_before, params, mesh, key);
        }
        // The virtual spots' light on the real surface, in slots of its own after
        // every bounce's: the slots above, and so E_R, are those of a run without them.
        if params.spot_vpls > 0 && !self.spot_candidates.is_empty() {
            let (first, slots_before) = (self.vpls.len(), self.projections.len());
            let spot_key = rng::hash(&[key, 0x5B07]);
            let slots = params.spot_vpls as usize;
            let (candidates, first_slot) = (&self.spot_candidates, slots_before as u32);
            let out = &mut self.vpls;
            if params.spot_coverage_split {
                split_by_coverage(candidates, inputs.spots, slots, first_slot, spot_key, out);
            } else {
                resample(candidates, slots, first_slot, spot_key, out);
            }
            self.project_new_slots(first);
            self.build_maps(slots_before, params, mesh, key);
        }
    }

    /// The maps' projections of the slots that the VPLs from `first` on opened: a
    /// paraboloid over each one's hemisphere.
    fn project_new_slots(&mut self, first: usize) {
        for v in &self.vpls[first..] {
            if v.slot as usize == self.projections.len() {
                let Emitter::Surface { position, normal } = v.emitter else {
                    unreachable!("bounce VPLs are surfaces")
                };
                let p = super::ism::Projection::Paraboloid {
                    origin: position,
                    frame: super::ism::frame_about(normal),
                };
                self.projections.push([p, p]);
            }
        }
    }

    /// Resamples the candidates (the first `real_count` real) into `slots` new slots.
    fn place(&mut self, params: &DirParams, real_count: usize, slots: usize, key: u64) {
        let (real, virtual_) = self.candidates.split_at(real_count);
        let lit = |c: &[Candidate]| c.iter().any(|c| luminance(c.power_r.max(c.power_rv)) > 0.0);
        let virtual_slots = match (lit(real), lit(virtual_)) {
            (_, false) => 0,
            (false, true) => slots,
            (true, true) => (slots as f32 * params.virtual_share).round() as usize,
        };
        let next_slot = self.projections.len() as u32;
        resample(real, slots - virtual_slots, next_slot, key, &mut self.vpls);
        let next_slot = self.vpls.last().map_or(0, |v| v.slot + 1).max(next_slot);
        resample(
            virtual_,
            virtual_slots,
            next_slot,
            key ^ 0x7EA1,
            &mut self.vpls,
        );
    }

    /// The candidates' powers for the next bounce: what they reflect of the light of
    /// the VPLs `last` (see the module docs).
    fn relight(&mut self, params: &DirParams, last: &[u32]) {
        let lights = light_set(
            &self.vpls,
            &self.projections,
            &self.rects,
            &self.maps,
            params,
        );
        let updated: Vec<(Candidate, Reflector)> = self
            .candidates
            .par_iter()
            .zip(self.reflectors.par_iter())
            .map(|(c, s)| {
                let receiver = if c.real {
                    Receiver::Real
                } else {
                    Receiver::Virtual
                };
                let got = gather(&lights, last, c.position, c.normal, receiver);
                if !c.real {
                    let power_rv = s.radiance_or_reflectance * got.rv_ind * c.area;
                    return (
                        Candidate {
                            power_r: Vec3::ZERO,
                            power_rv,
                            ..*c
                        },
                        *s,
                    );
                }
                let received_r = s.received_r + got.r_ind;
                let reflectance = implied_reflectance(s.radiance_or_reflectance, received_r);
                let power_rv = reflectance * got.rv_ind * c.area;
                let power_r = reflectance * got.r_ind * c.area;
                let candidate = Candidate {
                    power_r: match params.flags {
                        Flags::Reciprocal => power_r,
                        Flags::Knecht2010 => power_r.min(power_rv),
                    },
                    power_rv,
                    ..*c
                };
                (candidate, Reflector { received_r, ..*s })
            })
            .collect();
        for (i, (c, s)) in updated.into_iter().enumerate() {
            self.candidates[i] = c;
            self.reflectors[i] = s;
        }
    }

    /// Real candidates: one pixel per `real_grid` x `real_grid` cell (hashed within
    /// it; cells are cut at the image's edge), standing for the cell's area; their
    /// direct light with and without the objects from the environment VPLs.
    fn real_candidates(&mut self, inputs: &DirInputs, params: &DirParams, key: u64) {
        let (w, h) = (inputs.depth.width as usize, inputs.depth.height as usize);
        let g = params.real_grid as usize;
        let lights = light_set(
            &self.vpls,
            &self.projections,
            &self.rects,
            &self.maps,
            params,
        );
        let cam = inputs.camera;
        let (real, environment, kernel) = (&self.real, &self.environment[..], self.kernel);
        let (spots, flags) = (self.spot_set(inputs, params), params.flags);
        let found: Vec<(Candidate, Reflector, Option<Candidate>)> = (0..h.div_ceil(g))
            .into_par_iter()
            .flat_map_iter(|cy| {
                // The row's cells with a usable pixel, and the area each stands for.
                let cells: Vec<(usize, f32)> = (0..w.div_ceil(g))
                    .filter_map(|cx| {
                        let hsh = rng::hash(&[key, 0xCA4D, cx as u64, cy as u64]);
                        // The cell, cut at the image's edge.
                        let (gw, gh) = (g.min(w - cx * g), g.min(h - cy * g));
                        let x = cx * g + ((rng::unit_f32(hsh) * gw as f32) as usize).min(gw - 1);
                        let y = cy * g
                            + ((rng::unit_f32(rng::mix64(hsh)) * gh as f32) as usize).min(gh - 1);
                        let i = y * w + x;
                        let (p, n) = (real.position[i], real.normal[i]);
                        if n == Vec3::ZERO || !inputs.radiance.data[i].is_finite() {
                            return None;
                        }
                        let z = inputs.depth.data[i];
                        let view = (p - Vec3::from(inputs.camera_to_world.translation))
                            .normalize_or_zero();
                        let area = (gw * gh) as f32 * z * z
                            / (cam.fx * cam.fy)
                            / n.dot(view).abs().max(0.2);
                        Some((i, area))
                    })
                    .collect();
                let mut lit = Vec::with_capacity(cells.len());
                let point = |&(i, _): &(usize, f32)| Some((real.position[i], real.normal[i]));
                gather_each(
                    kernel,
                    &lights,
                    environment,
                    Receiver::Real,
                    &cells,
                    point,
                    |g| lit.push(g.expect("every cell's point gathers")),
                );
                cells.into_iter().zip(lit).map(|((i, area), lit)| {
                    let radiance = inputs.radiance.data[i];
                    let (p, n) = (real.position[i], real.normal[i]);
                    // The spots join the environment's direct light (without them,
                    // the same bits as before they existed).
                    let (r_dir, rv_dir, virtual_light) = if spots.is_empty() {
                        (lit.r_dir, lit.rv_dir, Vec3::ZERO)
                    } else {
                        let s = spots.gather(p, n, Receiver::Real);
                        (
                            lit.r_dir + s.r_dir,
                            lit.rv_dir + s.rv_dir_real,
                            s.rv_dir_virtual,
                        )
                    };
                    let (r, rv) = (luminance(r_dir), luminance(rv_dir));
                    let unblocked = if r > 0.0 {
                        (rv / r).clamp(0.0, 1.0)
                    } else {
                        1.0
                    };
                    let power_r = radiance.max(Vec3::ZERO) * area;
                    let power_rv = power_r * unblocked;
                    // A virtual spot's light, reflected with the albedo the camera
                    // and the real direct light imply: a path with a virtual light
                    // on it (x-bar = 0), in L_rv only.
                    let spot_lit = Candidate {
                        position: p,
                        normal: n,
                        power_r: Vec3::ZERO,
                        power_rv: implied_reflectance(radiance, r_dir) * virtual_light * area,
                        real: true,
                        area,
                    };
                    let candidate = Candidate {
                        position: p,
                        normal: n,
                        // [4] places no VPL where the objects block the light: no
                        // ir = 1 VPL cancels the real bleeding there.
                        power_r: match flags {
                            Flags::Reciprocal => power_r,
                            Flags::Knecht2010 => power_r.min(power_rv),
                        },
                        power_rv,
                        real: true,
                        area,
                    };
                    let reflector = Reflector {
                        radiance_or_reflectance: radiance.max(Vec3::ZERO),
                        received_r: r_dir,
                    };
                    let spot_lit = (spot_lit.power_rv.max_element() > 0.0).then_some(spot_lit);
                    (candidate, reflector, spot_lit)
                })
            })
            .collect();
        for (c, s, spot_lit) in found {
            self.candidates.push(c);
            self.reflectors.push(s);
            self.spot_candidates.extend(spot_lit);
        }
    }

    /// Virtual candidates: `points_per_vpl` mesh points (a subset that changes per
    /// frame), each lit by the environment VPLs in the combined world.
    fn virtual_candidates(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        mesh: &MeshPoints,
        key: u64,
    ) {
        let lights = light_set(
            &self.vpls,
            &self.projections,
            &self.rects,
            &self.maps,
            params,
        );
        let picks: Vec<usize> =
            super::points::strided(mesh.len(), params.points_per_vpl as usize, key ^ 0x71C7)
                .collect();
        let area = mesh.area * mesh.len() as f32 / picks.len().max(1) as f32;
        let (environment, kernel) = (&self.environment[..], self.kernel);
        let spots = self.spot_set(inputs, params);
        let found: Vec<(Candidate, Reflector, Option<Candidate>)> = picks
            .par_chunks(64)
            .flat_map_iter(|picks| {
                let mut lit = Vec::with_capacity(picks.len());
                let point = |&j: &usize| Some((mesh.position[j], mesh.normal[j]));
                gather_each(
                    kernel,
                    &lights,
                    environment,
                    Receiver::Virtual,
                    picks,
                    point,
                    |g| lit.push(g.expect("every mesh point gathers")),
                );
                picks.iter().zip(lit).map(|(&j, lit)| (j, lit))
            })
            .map(|(j, lit)| {
                let (p, n) = (mesh.position[j], mesh.normal[j]);
                let reflectance = mesh.material[j].albedo / PI;
                // The real spots join the environment's direct light; the virtual
                // ones' light goes to their own slots (as on the real surface), so
                // that no slot of the bounces, and no later bounce, carries it.
                let (rv_dir, virtual_light) = if spots.is_empty() {
                    (lit.rv_dir, Vec3::ZERO)
                } else {
                    let s = spots.gather(p, n, Receiver::Virtual);
                    (lit.rv_dir + s.rv_dir_real, s.rv_dir_virtual)
                };
                let candidate = Candidate {
                    position: p,
                    normal: n,
                    power_r: Vec3::ZERO,
                    power_rv: reflectance * rv_dir * area,
                    real: false,
                    area,
                };
                let reflector = Reflector {
                    radiance_or_reflectance: reflectance,
                    received_r: Vec3::ZERO,
                };
                let spot_lit = Candidate {
                    power_rv: reflectance * virtual_light * area,
                    ..candidate
                };
                let spot_lit = (spot_lit.power_rv.max_element() > 0.0).then_some(spot_lit);
                (candidate, reflector, spot_lit)
            })
            .collect();
        for (c, s, spot_lit) in found {
            self.candidates.push(c);
            self.reflectors.push(s);
            self.spot_candidates.extend(spot_lit);
        }
    }
}
