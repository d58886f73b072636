//! `light.impostor` (paper 000 Sec. 6.1): a distance impostor, the environment-sample
//! cloud splatted into a cube map of radiance and distance around a centre near the
//! virtual object and resampled to a lat-long [`EnvMap`] with finite distances, so a
//! recording with no light probe can still light an object. The math is
//! [`relume_scene::light::impostor`].
//!
//! The centre is the `center` parameter when given, else the centre of the pipeline's
//! virtual objects' bounding box (where they stand in each frame, when they move), else
//! the recording's `ground_truth.object_position`. The map is rebuilt only when the
//! cloud changes (a new `Arc`) or the centre moves; a frame without the
//! cloud (the first frame when reading `cloud@prev`) gets an empty map: radiance 0,
//! distances infinite.

use super::per_cloud::PerCloud;
use crate::kind;
use glam::{DVec3, Vec3};
use relume_graph::{
    BuildContext, Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError,
    StageInfo,
};
use relume_scene::light::EnvCloud;
use relume_scene::light::EnvMap;
use relume_scene::light::impostor::{ImpostorBuilder, ImpostorParams};
use relume_scene::objects::MAX_TRANSLATION;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "center",
        ParamDefault::Str(""),
        "world position \"x,y,z\" (metres) the impostor is seen from; empty: the virtual objects' bounding-box centre, else the recording's ground-truth object position",
    )
    .checked(|text| match text.trim() {
        "" => Ok(()),
        text => parse_center(text).map(|_| ()),
    }),
    ParamSpec::new(
        "face_size",
        ParamDefault::Int(64),
        "texels along a cube face's side (6 faces; 64 gives 1.4 degree texels, like the 256 x 128 output)",
    )
    .range(1.0, 4096.0),
    ParamSpec::new("width", ParamDefault::Int(256), "columns of the lat-long output")
        .range(1.0, 4096.0),
    ParamSpec::new("height", ParamDefault::Int(128), "rows of the lat-long output")
        .range(1.0, 4096.0),
    ParamSpec::new(
        "min_distance",
        ParamDefault::Float(0.05),
        "samples nearer the centre than this (metres) are ignored (they would cover half the sphere)",
    )
    .range(0.0, 1e6),
    ParamSpec::new(
        "splat_radius",
        ParamDefault::Float(0.035),
        "world radius of a sample's disk in metres (0.7 x the cloud's 5 cm cells, as gbuffer.splat: neighbouring disks meet)",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "max_splat_texels",
        ParamDefault::Float(8.0),
        "upper bound of a disk's radius in face texels (bounds the cost of samples close to the centre)",
    )
    .range(0.0, 4096.0),
    ParamSpec::new(
        "fill_levels",
        ParamDefault::Int(4),
        "coarser levels push-pull may use per face: holes up to about 2^levels texels wide are filled, wider ones (directions the camera never saw) stay empty",
    )
    .range(0.0, 16.0),
];

pub const INFO: StageInfo = StageInfo {
    kind: "light.impostor",
    summary: "a distance impostor: the environment-sample cloud splatted into a cube map of radiance and distance around the object (paper 000 Sec. 6.1)",
    params: PARAMS,
    ports: |_| Ports {
        // Without a cloud (the first frame under `cloud@prev`) the map is empty.
        inputs: vec![Port::new("cloud", "cloud", &[kind::CLOUD]).optional()],
        outputs: vec![Port::new(
            "environment",
            "environment",
            &[kind::ENVIRONMENT],
        )],
    },
    build: |ctx| {
        let p = ctx.params;
        let objects = crate::world::follow::FollowedObjects::new(ctx);
        let follow = (p.str("center").trim().is_empty() && objects.moves()).then_some(objects);
        let center = match p.str("center").trim() {
            "" => object_center(ctx).ok_or_else(|| {
                StageError::Failed("no centre for the distance impostor: set `center = \"x,y,z\"`, add a virtual object, or use a recording with ground truth".into())
            })?,
            text => parse_center(text).map_err(StageError::Failed)?,
        };
        let params = ImpostorParams {
            face_size: p.int("face_size") as u32,
            width: p.int("width") as u32,
            height: p.int("height") as u32,
            min_distance: p.float("min_distance") as f32,
            splat_radius: p.float("splat_radius") as f32,
            max_splat_texels: p.float("max_splat_texels") as f32,
            fill_levels: p.int("fill_levels") as u32,
        };
        Ok(Box::new(Impostor {
            cloud: ctx.input("cloud"),
            environment: ctx.output("environment"),
            center,
            follow,
            builder: ImpostorBuilder::new(params).map_err(StageError::Failed)?,
            maps: PerCloud::new(),
        }))
    },
};

/// Where a virtual object is: the centre of the pipeline's objects' bounding box, else
/// the recording's ground-truth object position; `None` when neither exists.
pub(crate) fn object_center(ctx: &BuildContext) -> Option<Vec3> {
    if !crate::world::objects(ctx).is_empty() {
        return Some(crate::world::objects(ctx).bounds().center());
    }
    ctx.header
        .ground_truth
        .as_ref()
        .map(|t| DVec3::from_array(t.object_position).as_vec3())
}

/// Parses "x,y,z" (finite numbers within [`MAX_TRANSLATION`], spaces allowed).
fn parse_center(text: &str) -> Result<Vec3, String> {
    let values: Vec<f32> = text
        .split(',')
        .map(|v| v.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| {
            format!("center = {text:?} is not three comma-separated numbers x,y,z ({e})")
        })?;
    match values.as_slice() {
        &[x, y, z] if values.iter().all(|v| v.is_finite()) => {
            if values.iter().all(|v| v.abs() <= MAX_TRANSLATION) {
                Ok(Vec3::new(x, y, z))
            } else {
                Err(format!(
                    "center = {text:?} lies more than {MAX_TRANSLATION} m from the origin along an axis"
                ))
            }
        }
        _ => Err(format!(
            "center = {text:?} is not three comma-separated finite numbers x,y,z"
        )),
    }
}

struct Impostor {
    cloud: String,
    environment: String,
    center: Vec3,
    /// The moving objects the centre follows (`None`: it stays put).
    follow: Option<crate::world::follow::FollowedObjects>,
    builder: ImpostorBuilder,
    maps: PerCloud<EnvMap>,
}

impl Stage for Impostor {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        if let Some(objects) = &mut self.follow {
            let (scene, moved) = objects.at(frame.index as u64)?;
            if moved {
                self.center = scene.bounds().center();
                self.maps.forget();
            }
        }
        let (builder, center, name) = (&mut self.builder, self.center, &self.cloud);
        let map = self.maps.get(frame, &self.cloud, |cloud| {
            builder
                .build(cloud.unwrap_or(&EnvCloud::default()), center)
                .map(|(map, _)| map)
                .map_err(|e| StageError::Failed(format!("cloud `{name}`: {e}")))
        })?;
        frame.insert(&self.environment, Product::new(kind::ENVIRONMENT, map));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kind::FrameProducts;
    use relume_graph::{ParamValue, Params};
    use relume_recording::{Header, Intrinsics, SceneTruth};
    use relume_scene::objects::{Material, Triangle, VirtualScene};
    use std::collections::BTreeMap;
    use std::path::Path;
    use std::sync::Arc;

    fn build(
        header: &Header,
        objects: &Arc<VirtualScene>,
        center: &str,
    ) -> Result<Box<dyn Stage>, StageError> {
        let mut params = Params::defaults(PARAMS);
        params.set("center", ParamValue::Str(center.into()));
        let inputs = BTreeMap::from([("cloud".to_string(), "cloud@prev".to_string())]);
        let ctx = BuildContext {
            stage_name: "impostor",
            params: &params,
            inputs: &inputs,
            outputs: &BTreeMap::new(),
            header,
            out_dir: Path::new("."),
            seed: 1,
            world: &crate::world::world_of(objects.clone()),
        };
        (INFO.build)(&ctx)
    }

    fn run(stage: &mut Box<dyn Stage>, cloud: Option<&Arc<EnvCloud>>) -> Arc<EnvMap> {
        let mut frame = Frame::new(0, 0);
        if let Some(c) = cloud {
            frame.insert("cloud@prev", Product::new(kind::CLOUD, Arc::clone(c)));
        }
        stage.process(&mut frame).unwrap();
        Arc::clone(frame.environment("environment").unwrap())
    }

    #[test]
    fn centre_comes_from_the_parameter_the_objects_or_the_ground_truth() {
        let mut header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let none = Arc::new(VirtualScene::default());
        // The runtime's error names the stage and its line around these messages.
        let message = build(&header, &none, "").err().unwrap().to_string();
        assert_eq!(
            message,
            "no centre for the distance impostor: set `center = \"x,y,z\"`, add a virtual \
             object, or use a recording with ground truth"
        );
        for bad in ["1,2", "1,2,x", "1,2,inf"] {
            let message = build(&header, &none, bad).err().unwrap().to_string();
            assert!(
                message.contains(bad) && message.contains("x,y,z"),
                "{message}"
            );
        }
        let message = build(&header, &none, "1e30,0,0").err().unwrap().to_string();
        assert_eq!(
            message,
            "center = \"1e30,0,0\" lies more than 10000 m from the origin along an axis"
        );
        let cloud = Arc::new(EnvCloud {
            positions: vec![Vec3::new(0.0, 2.0, 0.0)],
            colors: vec![Vec3::ONE],
            normals: vec![Vec3::ZERO],
        });
        let center_of = |stage: &mut Box<dyn Stage>| run(stage, Some(&cloud)).center;
        assert_eq!(
            center_of(&mut build(&header, &none, " 1, 2.5 ,-3").unwrap()),
            Vec3::new(1.0, 2.5, -3.0)
        );
        header.ground_truth = Some(SceneTruth {
            object_position: [0.0, 0.3, 0.0],
            description: String::new(),
        });
        assert_eq!(
            center_of(&mut build(&header, &none, "").unwrap()),
            Vec3::new(0.0, 0.3, 0.0)
        );
        let objects = Arc::new(VirtualScene::new(
            vec![Triangle {
                vertices: [
                    Vec3::new(1.0, 0.0, 0.0),
                    Vec3::new(2.0, 1.0, 0.0),
                    Vec3::new(1.0, 1.0, 2.0),
                ],
                normals: [Vec3::Y; 3],
                material: 0,
            }],
            vec![Material::DIFFUSE_GRAY],
        ));
        assert_eq!(
            center_of(&mut build(&header, &objects, "").unwrap()),
            Vec3::new(1.5, 0.5, 1.0)
        );
    }

    #[test]
    fn map_is_rebuilt_only_when_the_cloud_changes_and_empty_without_one() {
        let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let mut stage = build(&header, &Arc::new(VirtualScene::default()), "0,0,0").unwrap();
        let empty = run(&mut stage, None);
        assert_eq!((empty.width, empty.height), (256, 128));
        assert!(empty.radiance.iter().all(|&c| c == Vec3::ZERO));
        assert!(empty.distance.iter().all(|&d| d == f32::INFINITY));
        assert!(Arc::ptr_eq(&empty, &run(&mut stage, None)));
        let cloud = Arc::new(EnvCloud {
            positions: vec![Vec3::new(0.0, 2.0, 0.0)],
            colors: vec![Vec3::new(3.0, 2.0, 1.0)],
            normals: vec![Vec3::ZERO],
        });
        let lit = run(&mut stage, Some(&cloud));
        assert_eq!(
            lit.radiance[lit.texel_of(Vec3::Y)],
            Vec3::new(3.0, 2.0, 1.0)
        );
        assert_eq!(lit.distance[lit.texel_of(Vec3::Y)], 2.0);
        assert!(Arc::ptr_eq(&lit, &run(&mut stage, Some(&cloud))));
        let copy = Arc::new((*cloud).clone());
        assert!(!Arc::ptr_eq(&lit, &run(&mut stage, Some(&copy))));
    }
}
