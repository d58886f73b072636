//! One frame of Differential Instant Radiosity: the VPLs and their maps, then the
//! interleaved gather and the blur (the order of paper 002 Fig. 2).

use super::blur::blur_layers;
use super::interleave::{Interleaved, RowScratch, object_rect};
use super::ism::{Projection, fill_holes, frame_about, splat_with};
use super::points::{MeshPoints, RealSurface};
use super::shade::LightSet;
use super::vpl::{Candidate, Emitter, Vpl, environment_vpls};
use super::{DirInputs, DirParams};
use crate::sample::layers::{IrradianceLayers, check_sizes, shade_rows};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng;
use relume_base::simd::Kernel;
use relume_graph::StageError;

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
    /// Per candidate, what its surface reflects (see `bounce.rs`).
    pub(super) reflectors: Vec<super::bounce::Reflector>,
    /// Per interleaving class, the indices of its VPLs.
    members: Vec<Vec<u32>>,
    /// The environment VPLs' indices (0..n).
    pub(super) environment: Vec<u32>,
    raw: Option<IrradianceLayers>,
    /// The blur's pass along x.
    between: Option<IrradianceLayers>,
    /// What the last [`DirRenderer::lights`] made lights for (`None` before, or after
    /// one that failed): the frame's width and height, the interleaving and the maps'
    /// size, which [`DirRenderer::shade`] must be asked for.
    lit: Option<[u32; 4]>,
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
            members: Vec::new(),
            environment: Vec::new(),
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
    ) -> Result<(), StageError> {
        self.lights(inputs, params, mesh)?;
        self.shade(inputs, params, out)
    }

    /// The frame's VPLs and their shadow maps (steps 1-3 of the module docs).
    pub fn lights(
        &mut self,
        inputs: &DirInputs,
        params: &DirParams,
        mesh: &MeshPoints,
    ) -> Result<(), StageError> {
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
            return Err(StageError::Failed(
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
        self.lit = Some(lit_frame(w, h, params));
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
    ) -> Result<(), StageError> {
        let (w, h) = (inputs.depth.width, inputs.depth.height);
        let k = params.interleave as usize;
        if self.lit != Some(lit_frame(w, h, params)) {
            return Err(StageError::Failed(format!(
                "sample.dir: no lights made for a {w}x{h} frame with interleave {k} and {s}x{s} maps to shade",
                s = params.shadow_map_size
            )));
        }
        if out.size() != Some((w, h)) {
            return Err(StageError::Failed(format!(
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
        Ok(())
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

/// What [`DirRenderer::lit`] records of a frame `w` x `h` lit with `params`.
fn lit_frame(w: u32, h: u32, params: &DirParams) -> [u32; 4] {
    [w, h, params.interleave, params.shadow_map_size]
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
