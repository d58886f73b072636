//! `light.val` (paper 004 Secs. 4.3-4.4): virtual area lights from the direct part of the
//! environment light (importance samples, k-means on position and normal warm-started
//! from the previous frame, per-cluster integration of eq. 7) and the nine SH
//! coefficients of the indirect part. See [`relume_scene::light::val::ValBuilder`].
//!
//! `source = "map"` (the default) takes the direct part of a map around the objects
//! (`light.split`'s); `source = "atlas"` takes paper 004's near-field radiance atlas
//! (Secs. 4.1-4.3, [`relume_scene::light::val::atlas`]): the environment-sample cloud as
//! texels of the room's surfaces, its brightest `atlas_share` as the direct part, the
//! lights placed on the surfaces where the light is, facing as they face, whether or
//! not the objects' centre sees them. The indirect part stays the map's (SH9 at the
//! objects).

use super::split::{check_map, same_map};
use crate::kind;
use crate::kind::FrameProducts;
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
use relume_scene::light::cloud::EnvCloud;
use relume_scene::light::val::atlas;
use relume_scene::light::{AreaLights, EnvMap, LightMethod, ValBuilder, ValParams};
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "method",
        ParamDefault::Str("clusters"),
        "how the direct part becomes lights: clusters = k-means area lights that integrate their texels (Sec. 4.3, steady from frame to frame); vpls = `lights` classic virtual point lights, importance samples with I = I_s / (N p_s) (eq. 14, Fig. 10's baseline: redrawn every update, so they flicker)",
    )
    .choices(LightMethod::NAMES),
    ParamSpec::new(
        "lights",
        ParamDefault::Int(16),
        "number of lights M: k-means clusters, or point lights with method = vpls (paper 004: 8 <= M <= 64)",
    )
    .range(8.0, 64.0),
    ParamSpec::new(
        "samples",
        ParamDefault::Int(4096),
        "importance samples of the direct part that k-means clusters (paper 004: 4k)",
    )
    .range(16.0, 1_000_000.0),
    ParamSpec::new(
        "iterations",
        ParamDefault::Int(10),
        "k-means iterations per update, warm-started from the previous frame's centres (a cold start runs to convergence, at most 100)",
    )
    .range(1.0, 1000.0),
    ParamSpec::new(
        "normal_weight",
        ParamDefault::Float(1.0),
        "w in the clustering distance |dp|^2 + w |dn|^2, square metres (normals are unit)",
    )
    .range(0.0, 1e6),
    ParamSpec::new(
        "source",
        ParamDefault::Str("map"),
        "where the direct light comes from: map = the direct part of the map around the objects (direct_light); atlas = paper 004's radiance atlas, the environment-sample cloud (input cloud) as texels of the room's surfaces, the lights placed on them (Secs. 4.1-4.3)",
    )
    .choices(&["map", "atlas"]),
    ParamSpec::new(
        "atlas_share",
        ParamDefault::Float(0.9),
        "with source = atlas: the share of the atlas's light (L dA) its brightest texels take as the direct part (Sec. 4.2; light.split's ratio for a map)",
    )
    .range(0.01, 1.0),
    ParamSpec::new(
        "atlas_cell_size",
        ParamDefault::Float(0.02),
        "with source = atlas: the cloud's grid cell, metres (cloud.samples' cell_size): a sample stands for cell^2 / (|n_x| + |n_y| + |n_z|) of surface",
    )
    .range(0.001, 10.0),
    ParamSpec::new(
        "distant_radius",
        ParamDefault::Float(100.0),
        "metres from the map's centre where texels of infinite distance are placed (their area is dOmega r^2, so irradiance at the centre is unchanged)",
    )
    .range(0.01, 1e7),
];

pub const INFO: StageInfo = StageInfo {
    kind: "light.val",
    summary: "virtual area lights by importance sampling + k-means, and SH9 of the indirect light (paper 004 Secs. 4.3-4.4)",
    params: PARAMS,
    ports: |params| match params.str("source") {
        "atlas" => Ports::fixed(
            &[
                ("cloud", &[kind::CLOUD]),
                ("indirect_light", &[kind::ENVIRONMENT]),
            ],
            &[("lights", &[kind::AREA_LIGHTS])],
        ),
        _ => Ports::fixed(
            &[
                ("direct_light", &[kind::ENVIRONMENT]),
                ("indirect_light", &[kind::ENVIRONMENT]),
            ],
            &[("lights", &[kind::AREA_LIGHTS])],
        ),
    },
    build: |ctx| {
        let p = ctx.params;
        let (lights, samples) = (p.int("lights"), p.int("samples"));
        if samples < lights {
            // k-means cannot make more clusters than it has samples.
            return Err(StageError::Failed(format!(
                "samples = {samples} is fewer than lights = {lights}: each light is a cluster of samples"
            )));
        }
        let source = match p.str("source") {
            "atlas" => DirectSource::Atlas {
                cloud: ctx.input("cloud"),
                share: p.float("atlas_share") as f32,
                cell_size: p.float("atlas_cell_size") as f32,
            },
            _ => DirectSource::Map(ctx.input("direct_light")),
        };
        Ok(Box::new(Val {
            source,
            indirect: ctx.input("indirect_light"),
            lights: ctx.output("lights"),
            builder: ValBuilder::new(ValParams {
                lights: lights as usize,
                samples: samples as usize,
                iterations: p.int("iterations") as u32,
                normal_weight: p.float("normal_weight") as f32,
                distant_radius: p.float("distant_radius") as f32,
                seed: ctx.seed,
                method: LightMethod::from_name(p.str("method")).unwrap_or_default(),
            }),
            last: None,
        }))
    },
};

/// Where the direct light comes from.
enum DirectSource {
    /// The direct part of a map around the objects (product name).
    Map(String),
    /// The radiance atlas of the cloud (product name), its direct share, its grid cell.
    Atlas {
        cloud: String,
        share: f32,
        cell_size: f32,
    },
}

/// The last direct input, indirect input and the lights made from them.
enum Cached {
    Map(Arc<EnvMap>, Arc<EnvMap>, Arc<AreaLights>),
    Atlas(Arc<EnvCloud>, Arc<EnvMap>, Arc<AreaLights>),
}

struct Val {
    source: DirectSource,
    indirect: String,
    lights: String,
    builder: ValBuilder,
    last: Option<Cached>,
}

impl Stage for Val {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let indirect = frame.environment(&self.indirect)?.clone();
        let lights = match &self.source {
            DirectSource::Map(name) => {
                let direct = frame.environment(name)?.clone();
                match &self.last {
                    Some(Cached::Map(d, i, lights))
                        if same_map(d, &direct) && same_map(i, &indirect) =>
                    {
                        lights.clone()
                    }
                    _ => {
                        check_map(name, &direct)?;
                        check_map(&self.indirect, &indirect)?;
                        let lights = Arc::new(self.builder.update(&direct, &indirect));
                        self.last = Some(Cached::Map(direct, indirect, lights.clone()));
                        lights
                    }
                }
            }
            DirectSource::Atlas {
                cloud: name,
                share,
                cell_size,
            } => {
                let cloud = frame.cloud(name)?.clone();
                match &self.last {
                    Some(Cached::Atlas(c, i, lights))
                        if Arc::ptr_eq(c, &cloud) && same_map(i, &indirect) =>
                    {
                        lights.clone()
                    }
                    _ => {
                        check_map(&self.indirect, &indirect)?;
                        let texels = atlas::atlas_of_cloud(&cloud, *cell_size);
                        let direct = atlas::direct_part(&texels, *share);
                        let lights = Arc::new(self.builder.update_atlas(&direct, &indirect));
                        self.last = Some(Cached::Atlas(cloud, indirect, lights.clone()));
                        lights
                    }
                }
            }
        };
        frame.insert(&self.lights, Product::new(kind::AREA_LIGHTS, lights));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_graph::{BuildContext, ParamValue, Params, Ports};
    use relume_recording::{Header, Intrinsics};
    use relume_scene::light::split::split_direct_indirect;
    use relume_scene::light::val::val_center_drift;
    use std::collections::BTreeMap;

    fn stage() -> Box<dyn Stage> {
        build(Params::defaults(PARAMS)).unwrap()
    }

    fn build(params: Params) -> Result<Box<dyn Stage>, StageError> {
        let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let ctx = BuildContext {
            stage_name: "val",
            params: &params,
            inputs: &BTreeMap::new(),
            outputs: &BTreeMap::new(),
            header: &header,
            out_dir: std::path::Path::new("."),
            seed: 3,
            world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
        };
        (INFO.build)(&ctx)
    }

    #[test]
    fn fewer_samples_than_lights_is_an_error() {
        let mut params = Params::defaults(PARAMS);
        params.set("lights", ParamValue::Int(64));
        params.set("samples", ParamValue::Int(16));
        let message = build(params.clone()).err().unwrap().to_string();
        assert_eq!(
            message,
            "samples = 16 is fewer than lights = 64: each light is a cluster of samples"
        );
        params.set("samples", ParamValue::Int(64));
        assert!(build(params).is_ok());
    }

    fn frame(env: &EnvMap) -> Frame {
        let (d, i) = split_direct_indirect(env, 0.9);
        let mut f = Frame::new(0, 0);
        f.insert("direct_light", Product::new(kind::ENVIRONMENT, Arc::new(d)));
        f.insert(
            "indirect_light",
            Product::new(kind::ENVIRONMENT, Arc::new(i)),
        );
        f
    }

    #[test]
    fn lights_per_frame_are_static_under_static_light() {
        let env = EnvMap::from_fn(64, 32, |d| {
            Vec3::splat(0.2) + Vec3::new(30.0, 20.0, 10.0) * (d.y > 0.9) as u8 as f32
        });
        let mut s = stage();
        let mut a = frame(&env);
        s.process(&mut a).unwrap();
        let first = a.area_lights("lights").unwrap().clone();
        assert!(!first.lights.is_empty() && first.lights.len() <= 16);
        // New Arcs with the same content (as a source that re-splats every frame gives).
        let mut b = frame(&env);
        s.process(&mut b).unwrap();
        let second = b.area_lights("lights").unwrap();
        assert!(
            Arc::ptr_eq(&first, second),
            "unchanged light is not recomputed"
        );
        assert_eq!(val_center_drift(&first, second), 0.0);
        // Defaults: 16 lights, distant texels at 100 m from the centre.
        for l in &first.lights {
            assert!((l.position.length() - 100.0).abs() < 1e-3, "{}", l.position);
        }
    }

    #[test]
    fn the_atlas_source_places_lights_on_the_cloud_where_the_light_is() {
        let mut params = Params::defaults(PARAMS);
        params.set("source", ParamValue::Str("atlas".into()));
        params.set("atlas_share", ParamValue::Float(0.6));
        let roles = |ports: Ports| {
            ports
                .inputs
                .iter()
                .map(|p| p.role.clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(roles((INFO.ports)(&params)), ["cloud", "indirect_light"]);
        assert_eq!(
            roles((INFO.ports)(&Params::defaults(PARAMS))),
            ["direct_light", "indirect_light"]
        );
        // A dim floor of 2 cm samples and a bright ceiling patch facing down.
        let mut cloud = EnvCloud::default();
        for i in 0..100 {
            for j in 0..100 {
                let (x, z) = (i as f32 * 0.02 - 1.0, j as f32 * 0.02 - 1.0);
                cloud.positions.push(Vec3::new(x, 0.0, z));
                cloud.normals.push(Vec3::Y);
                cloud.colors.push(Vec3::splat(0.1));
                if i < 20 && j < 20 {
                    cloud.positions.push(Vec3::new(x + 0.5, 2.4, z + 0.5));
                    cloud.normals.push(Vec3::NEG_Y);
                    cloud.colors.push(Vec3::new(8.0, 7.0, 6.0));
                }
            }
        }
        let env = EnvMap::from_fn(64, 32, |_| Vec3::splat(0.2));
        let mut f = frame(&env);
        f.insert("cloud", Product::new(kind::CLOUD, Arc::new(cloud)));
        let mut s = build(params).unwrap();
        s.process(&mut f).unwrap();
        let lights = f.area_lights("lights").unwrap();
        assert!(!lights.lights.is_empty());
        let mut intensity = Vec3::ZERO;
        for l in &lights.lights {
            assert!((l.position.y - 2.4).abs() < 1e-5, "{}", l.position);
            assert!((-0.5..=-0.1).contains(&l.position.x), "{}", l.position);
            assert_eq!(l.normal, Vec3::NEG_Y);
            intensity += l.intensity;
        }
        // 400 samples of 4 cm^2: 0.16 m^2 of (8, 7, 6).
        let expected = Vec3::new(8.0, 7.0, 6.0) * 0.16;
        assert!(
            (intensity - expected).abs().max_element() < 1e-4,
            "{intensity}"
        );
    }
}
