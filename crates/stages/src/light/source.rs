//! `light.envmap`: the environment light from an HDR lat-long map, either the
//! recording's attachment (the synthetic recording's ground-truth environment, seen from
//! the object position) or a file (OpenEXR, also tiled multi-resolution, or Radiance
//! `.hdr`; see [`relume_scene::light::loaders`] for the layout). The map is loaded once when
//! the pipeline is built, so a bad path or a missing attachment fails before the run;
//! every frame then carries the same `Arc<EnvMap>`, which lets `light.importance` keep
//! its table.

use crate::kind;
use relume_graph::{
    BuildContext, Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo,
};
use relume_scene::light::EnvMap;
use relume_scene::light::loaders::{LoadedEnvMap, environment_from_header, load_envmap_counted};
use std::path::Path;
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "source",
        ParamDefault::Str("attachment"),
        "attachment: the recording's lat-long map (seen from ground_truth.object_position); file: `path`",
    )
    .choices(&["attachment", "file"]),
    ParamSpec::new(
        "path",
        ParamDefault::Str(""),
        "OpenEXR or Radiance .hdr lat-long map for source = \"file\" (relative to the pipeline file's directory); row 0 = zenith, column c at phi = (c + 0.5) / W 2 pi from +x towards +z",
    )
    .file_path(),
    ParamSpec::new(
        "attachment",
        ParamDefault::Str("environment"),
        "name of the recording's envmap/latlong attachment for source = \"attachment\"",
    ),
    ParamSpec::new(
        "scale",
        ParamDefault::Float(1.0),
        "multiplies the map's radiance (exposure of the probe relative to the scene)",
    )
    .range(0.0, 1e12),
    ParamSpec::new(
        "rotation_deg",
        ParamDefault::Float(0.0),
        "turns the map about world +y, right-handed (+x towards -z); 90 turns OpenEXR's own latlong convention into relume's",
    )
    .range(-3600.0, 3600.0),
];

pub const INFO: StageInfo = StageInfo {
    kind: "light.envmap",
    summary: "an HDR lat-long environment map from the recording's attachment or an EXR/.hdr file, loaded once",
    params: PARAMS,
    ports: |_| Ports::fixed(&[], &[("environment", &[kind::ENVIRONMENT])]),
    build: |ctx| {
        let map = load(ctx)?;
        Ok(Box::new(EnvironmentSource {
            environment: ctx.output("environment"),
            map,
        }))
    },
};

/// The brightest radiance a map may hold after `scale`, per channel. The sun is about
/// 2e7 W/(sr m^2); far beyond that, sums and squares of the estimates would overflow f32.
pub const MAX_RADIANCE: f32 = 1e12;

/// Loads, scales and turns the map the stage's parameters ask for; errors name the stage
/// and the file or attachment.
fn load(ctx: &BuildContext) -> Result<Arc<EnvMap>, StageError> {
    let p = ctx.params;
    let stage = ctx.stage_name;
    // The runtime's error names the stage ("stage `x` could not be set up: ..."), so
    // these say only what is wrong.
    let LoadedEnvMap {
        mut map,
        replaced_texels,
    } = match p.str("source") {
        "file" => {
            let path = p.str("path");
            if path.is_empty() {
                return Err(StageError::Failed(
                    "source = \"file\" needs `path` = an OpenEXR or .hdr lat-long map".into(),
                ));
            }
            let mut loaded = load_envmap_counted(Path::new(path))
                .map_err(|e| StageError::Failed(e.to_string()))?;
            loaded.map.center = super::impostor::object_center(ctx).unwrap_or_default();
            loaded
        }
        _ if !p.str("path").is_empty() => {
            // Lighting from the attachment while the config names a file would be a
            // silent surprise.
            return Err(StageError::Failed(format!(
                "`path` = {:?} is only read with source = \"file\" (the source is \"attachment\"); add source = \"file\" or remove `path`",
                p.str("path")
            )));
        }
        _ => environment_from_header(ctx.header, p.str("attachment"))
            .map_err(|e| StageError::Failed(e.to_string()))?,
    };
    if replaced_texels > 0 && replaced_texels == map.radiance.len() {
        // Zeroed, it would light the frame as an all-black map does, without a word.
        return Err(StageError::Failed(format!(
            "every one of the map's {replaced_texels} texels is non-finite or negative: there is no light in it"
        )));
    }
    if replaced_texels > 0 {
        eprintln!(
            "stage `{stage}` (light.envmap): {replaced_texels} of {} texels were non-finite or negative and are 0",
            map.radiance.len()
        );
    }
    let scale = p.float("scale") as f32;
    if scale != 1.0 {
        map.scale_radiance(scale);
    }
    // Texels are finite and non-negative here (the loaders zero the others), so an
    // overflow of the scaling shows as inf, above the limit.
    let brightest = map
        .radiance
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.max_element().total_cmp(&b.1.max_element()));
    if let Some((i, c)) = brightest.filter(|(_, c)| c.max_element() > MAX_RADIANCE) {
        let (x, y) = (i % map.width as usize, i / map.width as usize);
        return Err(StageError::Failed(format!(
            "the map's radiance reaches {:.3e} at texel ({x}, {y}) after `scale`; relume accepts up to {MAX_RADIANCE:e}: lower `scale`",
            c.max_element()
        )));
    }
    map.rotate_about_y(p.float("rotation_deg"));
    Ok(Arc::new(map))
}

struct EnvironmentSource {
    environment: String,
    map: Arc<EnvMap>,
}

impl Stage for EnvironmentSource {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        frame.insert(
            &self.environment,
            Product::new(kind::ENVIRONMENT, Arc::clone(&self.map)),
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kind::FrameProducts;
    use glam::Vec3;
    use relume_graph::{ParamValue, Params};
    use relume_recording::codec::encode_floats;
    use relume_recording::{Attachment, Header, Intrinsics, SceneTruth};
    use std::collections::BTreeMap;

    fn header(with_attachment: bool) -> Header {
        let mut h = Header::new("room", Intrinsics::PRIMESENSE, 0.001);
        h.ground_truth = Some(SceneTruth {
            object_position: [0.0, 0.3, 0.0],
            description: String::new(),
        });
        if with_attachment {
            let samples: Vec<f32> = (0..8 * 4).flat_map(|i| [i as f32, 1.0, 2.0]).collect();
            h.attachments.push(Attachment {
                name: "environment".into(),
                kind: "envmap/latlong".into(),
                image: encode_floats(8, 4, 3, &samples, false),
            });
        }
        h
    }

    fn build(header: &Header, set: &[(&str, ParamValue)]) -> Result<Box<dyn Stage>, StageError> {
        let mut params = Params::defaults(PARAMS);
        for (name, value) in set {
            params.set(name, value.clone());
        }
        let ctx = BuildContext {
            stage_name: "env",
            params: &params,
            inputs: &BTreeMap::new(),
            outputs: &BTreeMap::new(),
            header,
            out_dir: Path::new("."),
            seed: 1,
            world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
        };
        (INFO.build)(&ctx)
    }

    fn environment(stage: &mut Box<dyn Stage>) -> Arc<EnvMap> {
        let mut frame = Frame::new(0, 0);
        stage.process(&mut frame).unwrap();
        Arc::clone(frame.environment("environment").unwrap())
    }

    #[test]
    fn attachment_is_loaded_once_scaled_turned_and_shared_by_every_frame() {
        let header = header(true);
        let mut stage = build(
            &header,
            &[
                ("scale", ParamValue::Float(2.0)),
                // One column of an 8-wide map: column c takes the old column c + 1.
                ("rotation_deg", ParamValue::Float(45.0)),
            ],
        )
        .unwrap();
        let first = environment(&mut stage);
        assert_eq!((first.width, first.height), (8, 4));
        assert_eq!(first.center, Vec3::new(0.0, 0.3, 0.0));
        assert_eq!(first.radiance[0], Vec3::new(2.0, 2.0, 4.0));
        assert_eq!(first.radiance[7], Vec3::new(0.0, 2.0, 4.0));
        assert!(Arc::ptr_eq(&first, &environment(&mut stage)));
    }

    #[test]
    fn a_map_with_no_finite_texel_is_refused() {
        let mut header = header(true);
        let samples = vec![f32::NAN; 8 * 4 * 3];
        header.attachments[0].image = encode_floats(8, 4, 3, &samples, false);
        let message = build(&header, &[]).err().unwrap().to_string();
        assert_eq!(
            message,
            "every one of the map's 32 texels is non-finite or negative: there is no light in it"
        );
        // One finite texel is a map (the others are zeroed, with a warning).
        let mut one = samples;
        one[..3].copy_from_slice(&[1.0, 1.0, 1.0]);
        header.attachments[0].image = encode_floats(8, 4, 3, &one, false);
        let map = environment(&mut build(&header, &[]).unwrap());
        assert_eq!(map.radiance[0], Vec3::ONE);
        assert!(map.radiance[1..].iter().all(|&c| c == Vec3::ZERO));
    }

    #[test]
    fn missing_attachment_and_bad_file_fail_at_build_saying_why() {
        // The runtime's error names the stage and its line around these messages.
        let message = build(&header(false), &[]).err().unwrap().to_string();
        assert_eq!(
            message,
            "attachment `environment`: recording `room` has no such attachment (it has \
             none); light from a file with `source = \"file\"` and `path`, or from the \
             cloud with `light.impostor`"
        );
        let source = ("source", ParamValue::Str("file".into()));
        let message = build(&header(false), std::slice::from_ref(&source))
            .err()
            .unwrap()
            .to_string();
        assert!(message.contains("needs `path`"), "{message}");
        let path = ("path", ParamValue::Str("/nonexistent/probe.exr".into()));
        let message = build(&header(false), &[source, path])
            .err()
            .unwrap()
            .to_string();
        assert!(message.starts_with("/nonexistent/probe.exr: "), "{message}");
    }

    #[test]
    fn radiance_beyond_the_limit_is_an_error_naming_the_texel() {
        // The attachment holds (i, 1, 2) at texel i of an 8 x 4 map: 31 at (7, 3).
        let scale = ("scale", ParamValue::Float(1e11));
        let message = build(&header(true), &[scale]).err().unwrap().to_string();
        assert_eq!(
            message,
            "the map's radiance reaches 3.100e12 at texel (7, 3) after `scale`; relume accepts up to 1e12: lower `scale`"
        );
        let scale = ("scale", ParamValue::Float(1e10));
        assert!(build(&header(true), &[scale]).is_ok());
    }

    #[test]
    fn a_path_without_source_file_is_an_error_not_the_attachment() {
        let path = ("path", ParamValue::Str("probe.exr".into()));
        let message = build(&header(true), &[path]).err().unwrap().to_string();
        assert_eq!(
            message,
            "`path` = \"probe.exr\" is only read with source = \"file\" (the source is \
             \"attachment\"); add source = \"file\" or remove `path`"
        );
    }

    #[test]
    fn file_source_loads_an_exr_seen_from_the_object_position() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("probe.exr");
        exr::prelude::write_rgb_file(&path, 16, 8, |x, y| (x as f32, y as f32, 1.0)).unwrap();
        let mut stage = build(
            &header(false),
            &[
                ("source", ParamValue::Str("file".into())),
                ("path", ParamValue::Str(path.to_string_lossy().into_owned())),
            ],
        )
        .unwrap();
        let map = environment(&mut stage);
        assert_eq!((map.width, map.height), (16, 8));
        assert_eq!(map.radiance[2 * 16 + 5], Vec3::new(5.0, 2.0, 1.0));
        assert_eq!(map.center, Vec3::new(0.0, 0.3, 0.0));
    }
}
