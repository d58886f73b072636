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

use super::gather_lanes::gather_each;
use super::points::MeshPoints;
use super::render::{DirRenderer, light_set};
use super::shade::{Receiver, gather};
use super::vpl::{Candidate, Emitter, resample};
use super::{DirInputs, DirParams};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng;
use relume_scene::light::split::luminance;
use std::f32::consts::{FRAC_1_PI, PI};

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
        self.real_candidates(inputs, params, key);
        let real_count = self.candidates.len();
        self.virtual_candidates(params, mesh, key);
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
            self.build_maps(slots_before, params, mesh, key);
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
                let reflectance = Vec3::select(
                    received_r.cmpgt(Vec3::splat(1e-6)),
                    (s.radiance_or_reflectance / received_r).min(Vec3::splat(FRAC_1_PI)),
                    Vec3::ZERO,
                );
                let candidate = Candidate {
                    power_r: reflectance * got.r_ind * c.area,
                    power_rv: reflectance * got.rv_ind * c.area,
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
        let found: Vec<(Candidate, Reflector)> = (0..h.div_ceil(g))
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
                    let (r, rv) = (luminance(lit.r_dir), luminance(lit.rv_dir));
                    let unblocked = if r > 0.0 {
                        (rv / r).clamp(0.0, 1.0)
                    } else {
                        1.0
                    };
                    let power_r = radiance.max(Vec3::ZERO) * area;
                    let candidate = Candidate {
                        position: real.position[i],
                        normal: real.normal[i],
                        power_r,
                        power_rv: power_r * unblocked,
                        real: true,
                        area,
                    };
                    let reflector = Reflector {
                        radiance_or_reflectance: radiance.max(Vec3::ZERO),
                        received_r: lit.r_dir,
                    };
                    (candidate, reflector)
                })
            })
            .collect();
        for (c, s) in found {
            self.candidates.push(c);
            self.reflectors.push(s);
        }
    }

    /// Virtual candidates: `points_per_vpl` mesh points (a subset that changes per
    /// frame), each lit by the environment VPLs in the combined world.
    fn virtual_candidates(&mut self, params: &DirParams, mesh: &MeshPoints, key: u64) {
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
        let found: Vec<(Candidate, Reflector)> = picks
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
                let candidate = Candidate {
                    position: p,
                    normal: n,
                    power_r: Vec3::ZERO,
                    power_rv: reflectance * lit.rv_dir * area,
                    real: false,
                    area,
                };
                let reflector = Reflector {
                    radiance_or_reflectance: reflectance,
                    received_r: Vec3::ZERO,
                };
                (candidate, reflector)
            })
            .collect();
        for (c, s) in found {
            self.candidates.push(c);
            self.reflectors.push(s);
        }
    }
}
