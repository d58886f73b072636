//! Virtual area lights and SH9 indirect light (paper 004 Secs. 4.2-4.4).

use super::EnvMap;
use super::kmeans::{self, Feature};
use super::sh::project_sh9;
use super::split::{luminance, texel_area};
use crate::rng;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

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
    pub fn update(&mut self, direct: &EnvMap, indirect: &EnvMap) -> AreaLights {
        let sh9 = project_sh9(indirect);
        self.gather_texels(direct);
        self.draw_samples();
        let p = self.params;
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
        let lights = self.integrate(direct.center);
        AreaLights { lights, sh9 }
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

    /// Step 2: stratified importance samples over the texels' CDF.
    fn draw_samples(&mut self) {
        self.cdf.clear();
        let mut total = 0.0;
        for t in &self.texels {
            total += t.weight;
            self.cdf.push(total);
        }
        self.samples.clear();
        if self.texels.is_empty() || total <= 0.0 || !total.is_finite() {
            return;
        }
        let n = self.params.samples.max(1);
        let seed = self.params.seed;
        let (cdf, texels) = (&self.cdf, &self.texels);
        self.samples.par_extend((0..n).into_par_iter().map(|i| {
            let jitter = rng::unit_f64(rng::hash(&[seed, SALT_SAMPLES, i as u64]));
            let u = (i as f64 + jitter) / n as f64 * total;
            let k = cdf.partition_point(|&c| c <= u).min(texels.len() - 1);
            texels[k].feature
        }));
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
        let m = self.centres.len();
        if m == 0 || self.texels.is_empty() {
            return Vec::new();
        }
        let w = self.params.normal_weight;
        let partial: Vec<Vec<Sum>> = self
            .texels
            .par_chunks(1024)
            .map(|chunk| {
                let mut sums = vec![Sum::default(); m];
                for t in chunk {
                    let (j, _) = kmeans::nearest_centre(&self.centres, &t.feature, w);
                    let l = t.radiance;
                    let s = &mut sums[j];
                    s.intensity += l.as_dvec3() * t.area as f64;
                    s.area += t.area as f64;
                    s.weighted_direction += t.direction.as_dvec3() * t.weight;
                    s.weight_area += t.weight;
                    s.weight_omega += luminance(l) as f64 * t.d_omega as f64;
                }
                sums
            })
            .collect();
        let mut total = vec![Sum::default(); m];
        for sums in &partial {
            for (t, s) in total.iter_mut().zip(sums) {
                t.intensity += s.intensity;
                t.area += s.area;
                t.weighted_direction += s.weighted_direction;
                t.weight_area += s.weight_area;
                t.weight_omega += s.weight_omega;
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::split::{split_direct_indirect, total_intensity};

    const LAMP: Vec3 = Vec3::new(0.0, 1.0, 0.0);

    fn window() -> Vec3 {
        Vec3::new(1.0, 0.3, 0.5).normalize()
    }

    /// A room-like impostor seen from (0, 0.3, 0): a dim background, a small warm lamp
    /// overhead and a larger bluish window, every texel 2.5 m away (or distant).
    fn room(distance: f32, lamp_gain: f32) -> EnvMap {
        let mut map = EnvMap::from_fn(128, 64, |d| {
            let lamp = d.dot(LAMP) > 0.985;
            let window = d.dot(window()) > 0.95;
            Vec3::splat(0.15 + 0.05 * d.y)
                + if lamp {
                    Vec3::new(100.0, 85.0, 70.0) * lamp_gain
                } else {
                    Vec3::ZERO
                }
                + if window {
                    Vec3::new(10.0, 11.0, 14.0)
                } else {
                    Vec3::ZERO
                }
        });
        map.distance = vec![distance; map.radiance.len()];
        map.center = Vec3::new(0.0, 0.3, 0.0);
        map
    }

    fn params(lights: usize) -> ValParams {
        ValParams {
            lights,
            seed: 5,
            ..Default::default()
        }
    }

    #[test]
    fn static_light_gives_static_lights_and_slow_change_moves_them_little() {
        let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.9);
        let mut builder = ValBuilder::new(params(16));
        let first = builder.update(&direct, &indirect);
        assert!(
            builder.last_report.unwrap().converged,
            "cold start converges"
        );
        let second = builder.update(&direct, &indirect);
        assert_eq!(builder.last_report.unwrap().iterations, 1);
        assert_eq!(val_center_drift(&first, &second), 0.0);
        assert_eq!(first, second);
        // The lamp 5 % brighter, with a ratio that keeps the same texels direct: the
        // warm-started centres barely move.
        let mut builder = ValBuilder::new(params(16));
        let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.8);
        let before = builder.update(&direct, &indirect);
        let (direct, indirect) = split_direct_indirect(&room(2.5, 1.05), 0.8);
        let after = builder.update(&direct, &indirect);
        assert_eq!(after.lights.len(), before.lights.len());
        let drift = val_center_drift(&before, &after);
        // A cold start on the changed map lands elsewhere: the warm start is what keeps
        // the lights in place.
        let cold = ValBuilder::new(ValParams {
            seed: 6,
            ..params(16)
        })
        .update(&direct, &indirect);
        let cold_drift = val_center_drift(&before, &cold);
        eprintln!("warm drift {drift} m, cold drift {cold_drift} m");
        // Less than half a texel (12 cm at 2.5 m for 128 columns).
        assert!(drift < 0.05 && drift < cold_drift, "drift {drift} m");
    }

    #[test]
    fn intensities_integrate_the_whole_direct_part() {
        for distance in [2.5, f32::INFINITY] {
            let (direct, indirect) = split_direct_indirect(&room(distance, 1.0), 0.9);
            let set = ValBuilder::new(params(16)).update(&direct, &indirect);
            assert!(set.lights.len() >= 8, "{}", set.lights.len());
            let mut total = total_intensity(&direct);
            if !distance.is_finite() {
                // Distant texels sit at the far radius: dA = dOmega R^2.
                total = total.map(|t| t * 100.0 * 100.0);
            }
            let sum = set
                .lights
                .iter()
                .fold(DVec3::ZERO, |s, l| s + l.intensity.as_dvec3());
            for c in 0..3 {
                assert!(
                    (sum[c] - total[c]).abs() < 1e-5 * total[c],
                    "{sum} vs {total:?}"
                );
            }
            // The SH9 term is the indirect part's.
            assert_eq!(set.sh9, project_sh9(&indirect));
        }
    }

    #[test]
    fn lights_sit_at_the_two_sources_and_reproduce_their_irradiance() {
        let map = room(2.5, 1.0);
        // 80 %: the two sources hold about 85 % of the light, the background the rest.
        let (direct, indirect) = split_direct_indirect(&map, 0.8);
        let set = ValBuilder::new(params(8)).update(&direct, &indirect);
        let (mut at_lamp, mut at_window) = (0, 0);
        for l in &set.lights {
            let d = (l.position - map.center).normalize();
            assert!((l.position - map.center).length() - 2.5 < 1e-3);
            assert!((l.normal + d).length() < 1e-5, "faces the centre");
            if d.dot(LAMP) > 0.97 {
                at_lamp += 1;
            } else if d.dot(window()) > 0.93 {
                at_window += 1;
            } else {
                panic!("a light away from both sources: {d}");
            }
        }
        assert!(at_lamp >= 1 && at_window >= 1, "{at_lamp} {at_window}");
        // Irradiance at the centre from the VALs (eq. 6) against the direct part.
        for n in [Vec3::Y, window(), Vec3::new(0.5, 1.0, 0.0).normalize()] {
            let e: Vec3 = set
                .lights
                .iter()
                .map(|l| {
                    let v = l.position - map.center;
                    let r2 = v.length_squared();
                    l.intensity * (n.dot(v).max(0.0) * (-l.normal.dot(v)).max(0.0) / (r2 * r2))
                })
                .sum();
            let reference = direct.irradiance_brute_force(n);
            let error = (e - reference).abs().max_element() / reference.max_element();
            eprintln!("VAL irradiance at the centre, n = {n}: relative error {error}");
            assert!(error < 0.03, "n {n}: {e} vs {reference}");
        }
    }

    #[test]
    fn black_and_empty_maps_give_no_lights() {
        let black = EnvMap::constant(32, 16, Vec3::ZERO);
        let set = ValBuilder::new(params(16)).update(&black, &black);
        assert!(set.lights.is_empty());
        assert_eq!(set.sh9, [Vec3::ZERO; 9]);
        let empty = EnvMap::distant(0, 0, Vec::new());
        assert!(
            ValBuilder::new(params(16))
                .update(&empty, &empty)
                .lights
                .is_empty()
        );
        // One bright texel: one light, the others' clusters are dropped.
        let mut one = black.clone();
        one.radiance[100] = Vec3::ONE;
        let set = ValBuilder::new(params(16)).update(&one, &black);
        assert_eq!(set.lights.len(), 1);
        assert!(set.lights[0].intensity.is_finite());
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.9);
        let run = || {
            let mut b = ValBuilder::new(params(16));
            b.update(&direct, &indirect);
            b.update(&direct, &indirect)
        };
        let one = crate::stages::with_threads(1, run);
        let three = crate::stages::with_threads(3, run);
        let bits = |s: &AreaLights| {
            s.lights
                .iter()
                .flat_map(|l| {
                    [l.position, l.normal, l.intensity]
                        .into_iter()
                        .flat_map(|v| v.to_array())
                        .chain([l.area])
                })
                .map(f32::to_bits)
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&one), bits(&three));
    }

    #[test]
    fn drift_matches_lights_by_index() {
        let light = |x: f32| AreaLight {
            position: Vec3::new(x, 0.0, 0.0),
            normal: Vec3::Y,
            intensity: Vec3::ONE,
            area: 1.0,
        };
        let a = AreaLights {
            lights: vec![light(0.0), light(1.0), light(5.0)],
            sh9: [Vec3::ZERO; 9],
        };
        let b = AreaLights {
            lights: vec![light(0.5), light(2.0)],
            sh9: [Vec3::ZERO; 9],
        };
        assert_eq!(val_center_drift(&a, &b), 0.75);
        assert_eq!(
            val_center_drift(
                &a,
                &AreaLights {
                    lights: vec![],
                    sh9: b.sh9
                }
            ),
            0.0
        );
    }
}
