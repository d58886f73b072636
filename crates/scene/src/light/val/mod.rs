//! Virtual area lights and SH9 indirect light (paper 004 Secs. 4.2-4.4).

use super::EnvMap;
use super::kmeans::{self, Feature};
use super::sh::project_sh9;
use super::split::{luminance, texel_area};
use atlas::AtlasTexel;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use relume_base::rng;
use std::ops::AddAssign;

/// One virtual area light (VAL, paper 004 Sec. 4.3): a Lambertian emitter at `position`
/// facing `normal`, with radiant intensity `intensity` = sum of L_k dA_k over its texels
/// (eq. 7) and total area `area`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub position: Vec3,
    pub normal: Vec3,
    pub intensity: Vec3,
    pub area: f32,
}

/// The lights of one frame: VALs from the direct part of the environment and the nine
/// SH coefficients of its indirect part (eq. 10).
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLights {
    pub lights: Vec<AreaLight>,
    /// Radiance SH coefficients C_k of the indirect part, k = 0..9.
    pub sh9: [Vec3; 9],
}

/// Settings of [`ValBuilder`] (paper 004 Sec. 4.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValParams {
    /// Number of virtual area lights M (k-means clusters).
    pub lights: usize,
    /// Importance samples of the direct part that k-means clusters.
    pub samples: usize,
    /// Lloyd iterations per update when warm-started from the previous centres.
    pub iterations: u32,
    /// w in the clustering distance |dp|^2 + w |dn|^2, in m^2.
    pub normal_weight: f32,
    /// Where texels of infinite distance are placed, in metres from the map's centre.
    pub distant_radius: f32,
    /// Seed of the importance samples and of the k-means++ seeding.
    pub seed: u64,
    /// How the direct part becomes lights.
    pub method: LightMethod,
}

/// How [`ValBuilder`] turns the direct part into lights (paper 004 Fig. 10 compares the
/// two).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightMethod {
    /// Importance samples clustered by k-means into area lights that integrate their
    /// texels (Sec. 4.3; warm-started, so lights stay put from frame to frame).
    #[default]
    Clusters,
    /// Classic virtual point lights (eq. 14): `lights` importance samples of the direct
    /// part, each a light with I = I_s / (N p_s); redrawn every update, so they jump
    /// when the map changes (the flicker the paper shows).
    Vpls,
}

impl LightMethod {
    /// The names `light.val`'s `method` parameter takes, in the enum's order.
    pub const NAMES: &'static [&'static str] = &["clusters", "vpls"];

    /// The method of a `method` name.
    pub fn from_name(name: &str) -> Option<LightMethod> {
        match name {
            "clusters" => Some(LightMethod::Clusters),
            "vpls" => Some(LightMethod::Vpls),
            _ => None,
        }
    }
}

impl Default for ValParams {
    fn default() -> Self {
        ValParams {
            lights: 16,
            samples: 4096,
            iterations: 10,
            normal_weight: 1.0,
            distant_radius: 100.0,
            seed: 0,
            method: LightMethod::Clusters,
        }
    }
}

/// Iterations allowed to a cold start (no previous centres), which runs to convergence
/// once so that later warm starts begin at a fixed point.
pub const COLD_START_ITERATIONS: u32 = 100;

/// Salt of the importance samples' hashes.
const SALT_SAMPLES: u64 = 0x7661_6c5f_7361_6d70;

/// One texel of the direct part as a clustering feature and its integration weights.
#[derive(Clone, Copy, Debug)]
struct DirectTexel {
    feature: Feature,
    /// Unit direction from the centre.
    direction: Vec3,
    radiance: Vec3,
    /// dA with distant texels at `distant_radius`.
    area: f32,
    /// Solid angle of the texel.
    d_omega: f32,
    /// Luminance of L dA: the importance weight.
    weight: f64,
}

/// Builds the virtual area lights of successive frames, keeping the k-means centres of
/// the previous frame for the warm start (paper 004 Sec. 4.3) and its buffers.
#[derive(Clone, Debug, Default)]
pub struct ValBuilder {
    params: ValParams,
    centres: Vec<Feature>,
    texels: Vec<DirectTexel>,
    cdf: Vec<f64>,
    samples: Vec<Feature>,
    assignment: Vec<u32>,
    /// What the last update's k-means did.
    pub last_report: Option<kmeans::KMeansReport>,
}

impl ValBuilder {
    pub fn new(params: ValParams) -> ValBuilder {
        ValBuilder {
            params,
            ..Default::default()
        }
    }

    /// The k-means centres after the last update (position, normal).
    pub fn centres(&self) -> &[Feature] {
        &self.centres
    }

    /// The VALs of the direct part `direct` and the SH9 coefficients of the indirect
    /// part `indirect` (both as [`super::split::split_direct_indirect`] makes them, each
    /// with consistent buffer sizes):
    ///
    /// 1. every direct texel with positive luminance becomes a feature: position =
    ///    centre + direction * distance (distant texels at `distant_radius`, their area
    ///    dOmega * radius^2 so that I cos / r^2 at the centre is still L dOmega), normal
    ///    = -direction (facing the centre: the map has no surface normals);
    /// 2. `samples` importance samples by luminance(L) dA, stratified over the CDF with a
    ///    hashed offset per stratum keyed by (seed, sample) only, so the same map always
    ///    gives the same samples;
    /// 3. k-means with M centres, warm-started from the previous update's centres
    ///    (seeded by k-means++ on a cold start, which then runs to convergence);
    /// 4. every direct texel is assigned to its nearest centre by the same distance and
    ///    integrated (eq. 7): I_j = sum L_k dA_k, area_j = sum dA_k. The light sits along
    ///    the cluster's mean direction (weighted by luminance(L) dA) at the distance
    ///    r_j = sqrt(sum lum L dA / sum lum L dOmega), the root-mean-square texel
    ///    distance weighted by each texel's share of the irradiance at the centre, and
    ///    faces the centre; so I_j / r_j^2 = sum L dOmega: at the map's centre, facing
    ///    the light, the VAL gives the irradiance its texels give (exactly in luminance;
    ///    per channel where the cluster's texels share one chromaticity, and leaving out
    ///    the spread of their cosines).
    ///
    /// Clusters that integrate nothing are dropped (fewer than M lights, never NaN); the
    /// lights keep the order of their centres, so a light keeps its index across frames
    /// while the set of non-empty clusters is unchanged.
    ///
    /// With [`LightMethod::Vpls`], steps 2 to 4 are replaced by classic point lights: N =
    /// `lights` stratified samples of the same CDF, I = L_s dA_s / (N p_s) (eq. 14).
    pub fn update(&mut self, direct: &EnvMap, indirect: &EnvMap) -> AreaLights {
        let sh9 = project_sh9(indirect);
        self.gather_texels(direct);
        if self.params.method == LightMethod::Vpls {
            let lights = self.vpls();
            return AreaLights { lights, sh9 };
        }
        self.cluster();
        let lights = self.integrate(direct.center);
        AreaLights { lights, sh9 }
    }

    /// The VALs of the direct part of a radiance atlas (paper 004 Sec. 4.3 as published:
    /// lights placed where the light is, on the room's surfaces, not on a map around the
    /// object) and the SH9 coefficients of `indirect`. `direct` are the atlas's direct
    /// texels ([`atlas::direct_part`]). Steps 2 and 3 are [`ValBuilder::update`]'s, on
    /// features (position, surface normal); step 4 assigns every direct texel to its
    /// nearest centre and integrates eq. 7: I_j = sum L_k dA_k, area_j = sum dA_k, the
    /// light at the clusters' L dA-weighted mean position, facing their weighted mean
    /// normal. Clusters that integrate nothing, or whose normals cancel, are dropped.
    pub fn update_atlas(&mut self, direct: &[AtlasTexel], indirect: &EnvMap) -> AreaLights {
        let sh9 = project_sh9(indirect);
        self.texels.clear();
        self.texels.extend(direct.iter().filter_map(|t| {
            let weight = t.weight();
            (weight > 0.0 && weight.is_finite()).then_some(DirectTexel {
                feature: Feature {
                    position: t.position,
                    normal: t.normal,
                },
                direction: -t.normal,
                radiance: t.radiance,
                area: t.area,
                d_omega: 0.0,
                weight,
            })
        }));
        if self.texels.is_empty() {
            // Nothing emits: no lights, and the centres stay for the next update.
            return AreaLights {
                lights: Vec::new(),
                sh9,
            };
        }
        self.cluster();
        AreaLights {
            lights: self.integrate_on_surfaces(),
            sh9,
        }
    }

    /// Step 4 of [`ValBuilder::update_atlas`]: each direct texel to its nearest centre,
    /// integrated where it lies.
    fn integrate_on_surfaces(&self) -> Vec<AreaLight> {
        #[derive(Clone, Copy, Default)]
        struct Sum {
            intensity: DVec3,
            area: f64,
            position: DVec3,
            normal: DVec3,
            weight: f64,
        }
        impl AddAssign for Sum {
            fn add_assign(&mut self, s: Sum) {
                self.intensity += s.intensity;
                self.area += s.area;
                self.position += s.position;
                self.normal += s.normal;
                self.weight += s.weight;
            }
        }
        let total = self.sum_per_centre(|t| Sum {
            intensity: t.radiance.as_dvec3() * t.area as f64,
            area: t.area as f64,
            position: t.feature.position.as_dvec3() * t.weight,
            normal: t.feature.normal.as_dvec3() * t.weight,
            weight: t.weight,
        });
        total
            .iter()
            .filter(|s| s.area > 0.0 && s.weight > 0.0)
            .filter_map(|s| {
                let light = AreaLight {
                    position: (s.position / s.weight).as_vec3(),
                    normal: s.normal.try_normalize()?.as_vec3(),
                    intensity: s.intensity.as_vec3(),
                    area: s.area as f32,
                };
                (light.position.is_finite() && light.intensity.is_finite()).then_some(light)
            })
            .collect()
    }

    /// Steps 2 and 3: importance samples of the texels, clustered by k-means warm-started
    /// from the previous update's centres (seeded and run to convergence on a cold start).
    fn cluster(&mut self) {
        let p = self.params;
        self.draw_samples(p.samples);
        let cold = self.centres.len() != p.lights.max(1);
        if cold {
            self.centres =
                kmeans::seed_centres(&self.samples, p.lights.max(1), p.normal_weight, p.seed);
        }
        let iterations = if cold {
            COLD_START_ITERATIONS.max(p.iterations)
        } else {
            p.iterations
        };
        self.last_report = Some(kmeans::kmeans(
            &self.samples,
            &mut self.centres,
            iterations,
            p.normal_weight,
            &mut self.assignment,
        ));
    }

    /// Step 1: the direct texels that can emit, with their features and weights.
    fn gather_texels(&mut self, direct: &EnvMap) {
        let radius = self.params.distant_radius;
        let width = direct.width.max(1) as usize;
        let rows: Vec<Vec<DirectTexel>> = direct
            .radiance
            .par_chunks(width)
            .enumerate()
            .map(|(row, texels)| {
                let d_omega = direct.texel_solid_angle(row as u32);
                let mut out = Vec::new();
                for (column, &l) in texels.iter().enumerate() {
                    let index = row * width + column;
                    let lum = luminance(l);
                    if !(lum > 0.0 && lum.is_finite()) {
                        continue;
                    }
                    let direction = direct.texel_direction(index);
                    let d = direct.distance[index];
                    let (distance, area) = if d.is_finite() && d > 0.0 {
                        (d, texel_area(direct, index))
                    } else {
                        (radius, d_omega * radius * radius)
                    };
                    out.push(DirectTexel {
                        feature: Feature {
                            position: direct.center + direction * distance,
                            normal: -direction,
                        },
                        direction,
                        radiance: l,
                        area,
                        d_omega,
                        weight: lum as f64 * area as f64,
                    });
                }
                out
            })
            .collect();
        self.texels.clear();
        self.texels.extend(rows.into_iter().flatten());
    }

    /// The CDF of the texels' weights; returns the total (0 when nothing can emit).
    fn build_cdf(&mut self) -> f64 {
        self.cdf.clear();
        let mut total = 0.0;
        for t in &self.texels {
            total += t.weight;
            self.cdf.push(total);
        }
        if self.texels.is_empty() || total <= 0.0 || !total.is_finite() {
            return 0.0;
        }
        total
    }

    /// The texel of stratified sample `i` of `n` over the CDF (total `total`), with a
    /// hashed offset per stratum keyed by (seed, i).
    fn sample_texel(&self, i: usize, n: usize, total: f64) -> usize {
        let jitter = rng::unit_f64(rng::hash(&[self.params.seed, SALT_SAMPLES, i as u64]));
        let u = (i as f64 + jitter) / n as f64 * total;
        self.cdf
            .partition_point(|&c| c <= u)
            .min(self.texels.len() - 1)
    }

    /// Step 2: `n` stratified importance samples over the texels' CDF.
    fn draw_samples(&mut self, n: usize) {
        let total = self.build_cdf();
        // Taken out and put back, so its allocation serves every frame.
        let mut samples = std::mem::take(&mut self.samples);
        samples.clear();
        if total > 0.0 {
            let n = n.max(1);
            let this = &*self;
            samples.par_extend(
                (0..n)
                    .into_par_iter()
                    .map(|i| this.texels[this.sample_texel(i, n, total)].feature),
            );
        }
        self.samples = samples;
    }

    /// Classic virtual point lights (paper 004 eq. 14): N = `lights` stratified
    /// importance samples s of the direct texels by p_s = luminance(L_s) dA_s / total,
    /// each a light at its texel's position facing the centre with I = L_s dA_s / (N p_s)
    /// and area dA_s / (N p_s), so that I / area is the texel's radiance and the sum of
    /// the lights' intensities is an unbiased estimate of the direct part's. A texel
    /// drawn twice gives two lights.
    fn vpls(&mut self) -> Vec<AreaLight> {
        let total = self.build_cdf();
        if total <= 0.0 {
            return Vec::new();
        }
        let n = self.params.lights.max(1);
        (0..n)
            .map(|i| {
                let t = &self.texels[self.sample_texel(i, n, total)];
                // dA_s / (N p_s) = total / (N luminance(L_s)).
                let share = t.area as f64 * total / (n as f64 * t.weight);
                AreaLight {
                    position: t.feature.position,
                    normal: t.feature.normal,
                    intensity: (t.radiance.as_dvec3() * share).as_vec3(),
                    area: share as f32,
                }
            })
            .filter(|l| l.intensity.is_finite() && l.area.is_finite())
            .collect()
    }

    /// Per centre, the sum of `terms` over the texels nearest it: chunks of 1024
    /// texels in parallel, each summed in order from zero, the chunks' sums then added
    /// in order (the same bits on any thread count).
    fn sum_per_centre<S>(&self, terms: impl Fn(&DirectTexel) -> S + Sync) -> Vec<S>
    where
        S: AddAssign + Copy + Default + Send,
    {
        let m = self.centres.len();
        let w = self.params.normal_weight;
        let partial: Vec<Vec<S>> = self
            .texels
            .par_chunks(1024)
            .map(|chunk| {
                let mut sums = vec![S::default(); m];
                for t in chunk {
                    let (j, _) = kmeans::nearest_centre(&self.centres, &t.feature, w);
                    sums[j] += terms(t);
                }
                sums
            })
            .collect();
        let mut total = vec![S::default(); m];
        for sums in &partial {
            for (t, s) in total.iter_mut().zip(sums) {
                *t += *s;
            }
        }
        total
    }

    /// Step 4: assignment of every direct texel to its nearest centre and integration,
    /// per row in parallel, rows combined in order.
    fn integrate(&self, center: Vec3) -> Vec<AreaLight> {
        #[derive(Clone, Copy, Default)]
        struct Sum {
            intensity: DVec3,
            area: f64,
            weighted_direction: DVec3,
            weight_area: f64,
            weight_omega: f64,
        }
        impl AddAssign for Sum {
            fn add_assign(&mut self, s: Sum) {
                self.intensity += s.intensity;
                self.area += s.area;
                self.weighted_direction += s.weighted_direction;
                self.weight_area += s.weight_area;
                self.weight_omega += s.weight_omega;
            }
        }
        if self.centres.is_empty() || self.texels.is_empty() {
            return Vec::new();
        }
        let total = self.sum_per_centre(|t| Sum {
            intensity: t.radiance.as_dvec3() * t.area as f64,
            area: t.area as f64,
            weighted_direction: t.direction.as_dvec3() * t.weight,
            weight_area: t.weight,
            weight_omega: luminance(t.radiance) as f64 * t.d_omega as f64,
        });
        total
            .iter()
            .filter(|s| s.area > 0.0 && s.weight_omega > 0.0)
            .filter_map(|s| {
                let direction = s.weighted_direction.try_normalize()?.as_vec3();
                let distance = (s.weight_area / s.weight_omega).sqrt() as f32;
                let light = AreaLight {
                    position: center + direction * distance,
                    normal: -direction,
                    intensity: s.intensity.as_vec3(),
                    area: s.area as f32,
                };
                (light.position.is_finite() && light.intensity.is_finite()).then_some(light)
            })
            .collect()
    }
}

/// The mean distance each light centre moved between two frames, matching lights by
/// index (`relume eval`'s `val_center_drift_m`); lights present in only one frame are
/// not counted. 0 when no light is in both.
pub fn val_center_drift(prev: &AreaLights, cur: &AreaLights) -> f32 {
    let n = prev.lights.len().min(cur.lights.len());
    if n == 0 {
        return 0.0;
    }
    let sum: f64 = prev
        .lights
        .iter()
        .zip(&cur.lights)
        .map(|(a, b)| a.position.distance(b.position) as f64)
        .sum();
    (sum / n as f64) as f32
}

pub mod atlas;
#[cfg(test)]
mod tests;
