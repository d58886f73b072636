//! `relume synth`: a deterministic synthetic RGB-D recording with ground truth.
//!
//! An analytic room ([`scene`], built from [`geometry`] with [`texture`]s inside the
//! extent and surfaces of [`room`]) is rendered along a smooth camera path ([`camera`])
//! with soft shadows from a warm ceiling panel and a bright window and the light its
//! diffuse surfaces pass between them (a precomputed interreflection solution,
//! [`indirect`]) ([`render`]), seen
//! through a camera with automatic exposure, white balance and optional contrast
//! changes, and measured by a Kinect-like depth sensor ([`depth_noise`]).
//!
//! A recording holds, per frame `i`:
//! - color at `round(i / fps * 1e9)` ns: 8-bit sRGB-like PNG, `camera_pixel(M_i,
//!   contrast_i, radiance)` (see [`camera`]);
//! - depth a few milliseconds later ([`depth_stamp_ns`]), registered to the color view:
//!   16-bit PNG in units of [`DEPTH_UNIT_M`] (TUM's scale of 5000), 0 = missing;
//! - the true camera-to-world pose at the color stamp;
//! - a [`crate::TruthRecord`] at the color stamp: the color transform `M_i`
//!   (row-major), the contrast exponent, clean depth (f32), camera-space normals facing the
//!   camera (f16) and the HDR radiance (f16) the color was made from.
//!
//! The header carries the [`crate::SceneTruth`] (object position and a
//! description) and an attachment named `environment` of kind `envmap/latlong`: the HDR
//! radiance seen from the object position, [`ENVIRONMENT_SIZE`] texels of f32 RGB. Texel
//! row r, column c of a W x H map looks along theta = (r + 0.5) / H * pi from world +y,
//! phi = (c + 0.5) / W * 2 pi, d = (sin theta cos phi, cos theta, sin theta sin phi)
//! ([`render::latlong_direction`]).
//!
//! Every random number is a pure function of (seed, frame, purpose, pixel, sample), so
//! the file's bytes depend on the config only, never on the number of threads. The
//! scene, camera path and color settings depend only on the config's non-seed fields;
//! the seed changes the shadow sampling noise and the depth noise.

pub mod camera;
pub mod depth_noise;
pub mod geometry;
pub mod indirect;
pub mod insert;
pub mod interreflection;
pub mod lamp;
pub mod mitsuba;
pub mod render;
pub mod room;
pub mod scene;
pub mod switches;
pub mod texture;

use super::codec::{self, encode_floats};
use super::error::RecordingError;
use super::types::{
    Attachment, ColorRecord, DepthRecord, Header, Intrinsics, PoseRecord, Provenance, Record,
    SceneTruth, StreamKind, TruthRecord,
};
use super::writer::RecordingWriter;
use camera::ColorResponse;
use glam::{DMat3, Vec3};
use rayon::prelude::*;
use relume_base::raster::Image;
use render::View;
use scene::Scene;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
pub use switches::LightSwitches;

/// Version of the generator's output: bumped whenever the same config would give
/// different content, so cached recordings can be told apart.
pub const GENERATOR_VERSION: &str = "3";
/// The provenance tool name of the recordings it writes.
pub const SYNTH_TOOL: &str = "relume synth";
/// Metres per stored depth unit (TUM's scale: 5000 units per metre).
pub const DEPTH_UNIT_M: f64 = 0.0002;
/// Width and height of the environment-map attachment, in texels.
pub const ENVIRONMENT_SIZE: (u32, u32) = (256, 128);
/// Delay of each depth stamp after its color stamp (capped at an eighth of the frame
/// period, so association never picks a neighbour's depth).
pub const DEPTH_STAMP_OFFSET_NS: i64 = 4_000_000;

/// Settings of a synthetic recording.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthConfig {
    /// Number of frames (default 30).
    pub frames: usize,
    /// Image width in pixels (default 640).
    pub width: u32,
    /// Image height in pixels (default 480).
    pub height: u32,
    /// Seed of all random numbers (default 1).
    pub seed: u64,
    /// Frames per second of the stamps and the camera path (default 30).
    pub fps: f64,
    /// Kinect-like depth noise, quantization and holes (default true); clean depth
    /// rounded to the storage unit when false.
    pub depth_noise: bool,
    /// Auto-exposure gain range (default (0.5, 2.0)): the gain varies smoothly per frame
    /// and reaches both ends.
    pub exposure_range: (f32, f32),
    /// White-balance gains vary by up to plus or minus this fraction per channel
    /// (default 0.2).
    pub white_balance: f32,
    /// Amplitude of the contrast exponent's change: exponent = 1 +- contrast (default 0:
    /// none).
    pub contrast: f32,
    /// Focal length multiplier (default 1): at 2, a 320x240 recording sees the central
    /// 320x240 pixels of the 640x480 camera, at the same metres per pixel. Tests use it
    /// for small images whose pixels are as fine as the full camera's.
    pub zoom: f64,
    /// When the ceiling panel switches off and the lamp switches on (default: the panel
    /// on and the lamp off throughout). The truth of every frame is of the room as it is
    /// lit then; the header's `environment` attachment is the room as frame 0 shows it
    /// (a light probe taken at the start).
    pub switches: LightSwitches,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            frames: 30,
            width: 640,
            height: 480,
            seed: 1,
            fps: 30.0,
            depth_noise: true,
            exposure_range: (0.5, 2.0),
            white_balance: 0.2,
            contrast: 0.0,
            zoom: 1.0,
            switches: LightSwitches::default(),
        }
    }
}

impl SynthConfig {
    /// Checks the settings; the message says which one is wrong and why.
    pub fn validate(&self) -> Result<(), String> {
        if self.frames == 0 {
            return Err("frames must be at least 1".into());
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        if self.width as u64 * self.height as u64 > codec::MAX_PIXELS {
            return Err(format!(
                "image size {}x{} exceeds the limit of {} pixels",
                self.width,
                self.height,
                codec::MAX_PIXELS
            ));
        }
        if !crate::FPS_RANGE.contains(&self.fps) {
            return Err(format!(
                "fps must be a number from 0.001 to 1e6, not {}",
                self.fps
            ));
        }
        if (self.frames - 1) as f64 / self.fps * 1e9 > 4e18 {
            return Err("the sequence is too long for nanosecond stamps".into());
        }
        let (low, high) = self.exposure_range;
        if !(low.is_finite() && high.is_finite() && low > 0.0 && low <= high) {
            return Err(format!(
                "exposure range ({low}, {high}) must be finite with 0 < min <= max"
            ));
        }
        if !(0.0..=0.9).contains(&self.white_balance) {
            return Err(format!(
                "white balance {} must lie in [0, 0.9]",
                self.white_balance
            ));
        }
        if !(0.0..=0.9).contains(&self.contrast) {
            return Err(format!("contrast {} must lie in [0, 0.9]", self.contrast));
        }
        if !(0.25..=16.0).contains(&self.zoom) {
            return Err(format!("zoom {} must lie in [0.25, 16]", self.zoom));
        }
        self.switches.validate(self.frames)?;
        Ok(())
    }

    /// The intrinsics of both the color and the depth camera: PrimeSense scaled to the
    /// image size, focal lengths times `zoom`.
    pub fn intrinsics(&self) -> Intrinsics {
        let mut k = Intrinsics::PRIMESENSE.scaled_to(self.width, self.height);
        k.fx *= self.zoom;
        k.fy *= self.zoom;
        k
    }

    /// The room as it is lit at `frame` ([`LightSwitches::scene_at`]).
    pub fn scene_at(&self, frame: usize) -> Scene {
        self.switches.scene_at(frame)
    }
}

/// Summary of what was generated.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSummary {
    /// The file written.
    pub path: PathBuf,
    /// Number of frames (each with color, depth, pose and truth).
    pub frames: usize,
    /// Size of the file in bytes.
    pub bytes: u64,
}

/// The header provenance: tool `relume synth`, this crate's version, source
/// `synthetic room`, and settings naming the generator version and every config field,
/// so a cached file can be matched against a config.
pub fn provenance(config: &SynthConfig) -> Provenance {
    let SynthConfig {
        frames,
        width,
        height,
        seed,
        fps,
        depth_noise,
        exposure_range,
        white_balance,
        contrast,
        zoom,
        switches,
    } = config;
    let mut settings: BTreeMap<String, String> = [
        ("generator", GENERATOR_VERSION.to_string()),
        ("frames", frames.to_string()),
        ("width", width.to_string()),
        ("height", height.to_string()),
        ("seed", seed.to_string()),
        ("fps", fps.to_string()),
        ("depth_noise", depth_noise.to_string()),
        (
            "exposure_range",
            format!("{},{}", exposure_range.0, exposure_range.1),
        ),
        ("white_balance", white_balance.to_string()),
        ("contrast", contrast.to_string()),
        ("zoom", zoom.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    switches.write_settings(&mut settings);
    Provenance {
        tool: SYNTH_TOOL.into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        source: "synthetic room".into(),
        settings,
    }
}

/// Stamp of frame `frame`'s color, pose and truth records: `round(frame / fps * 1e9)` ns.
pub fn color_stamp_ns(config: &SynthConfig, frame: usize) -> i64 {
    (frame as f64 / config.fps * 1e9).round() as i64
}

/// Stamp of frame `frame`'s depth record: the color stamp plus
/// [`DEPTH_STAMP_OFFSET_NS`], or an eighth of the frame period if that is shorter.
pub fn depth_stamp_ns(config: &SynthConfig, frame: usize) -> i64 {
    let eighth_period = (1e9 / config.fps / 8.0).floor() as i64;
    color_stamp_ns(config, frame) + DEPTH_STAMP_OFFSET_NS.min(eighth_period)
}

/// The scene-level ground truth stored in the header.
pub fn scene_truth() -> SceneTruth {
    SceneTruth {
        object_position: scene::OBJECT_POSITION_F64.to_array(),
        description: "analytic room of 5 x 5 x 2.6 m (world +y up, floor at y = 0, \
                      x and z in [-2.5, 2.5]) lit by a warm ceiling panel and a bright \
                      sky window on the wall at x = +2.5; object_position is the centre \
                      of a free spot 0.3 m above the middle of the floor (a sphere of \
                      radius 0.3 placed there rests on the floor); the 'environment' \
                      attachment is the HDR radiance seen from it (lat-long, row 0 \
                      towards +y, phi from +x towards +z)"
            .into(),
    }
}

/// The header of the recording of `config`, with the rendered environment map.
pub fn header(config: &SynthConfig) -> Header {
    let (env_width, env_height) = ENVIRONMENT_SIZE;
    // A light probe taken at the start: the room as frame 0 shows it.
    let env = render::render_environment(&config.scene_at(0), config.seed, env_width, env_height);
    let intrinsics = config.intrinsics();
    Header {
        name: "synthetic-room".into(),
        provenance: provenance(config),
        color_intrinsics: intrinsics,
        depth_intrinsics: intrinsics,
        depth_unit_m: DEPTH_UNIT_M,
        streams: StreamKind::ALL.to_vec(),
        ground_truth: Some(scene_truth()),
        attachments: vec![Attachment {
            name: "environment".into(),
            kind: "envmap/latlong".into(),
            image: encode_floats(env_width, env_height, 3, &env, false),
        }],
    }
}

/// Renders frame `frame` of `config` and returns its records: color, depth, pose, truth.
/// Fails, with a message, only when an image cannot be encoded.
pub fn frame_records(
    config: &SynthConfig,
    scene: &Scene,
    frame: usize,
) -> Result<[Record; 4], String> {
    let k = config.intrinsics();
    let (w, h) = (config.width, config.height);
    let stamp_ns = color_stamp_ns(config, frame);
    let pose = camera::camera_pose(stamp_ns as f64 * 1e-9);
    let view = View {
        rotation: DMat3::from_quat(pose.rotation()).as_mat3(),
        position: pose.translation().as_vec3(),
        intrinsics: k,
    };
    let maps = render::render_view(scene, &view, config.seed, frame as u64);
    // Radiance is stored as f16; the color is made from exactly the stored values.
    let radiance: Vec<f32> = maps
        .radiance
        .iter()
        .flat_map(|v| v.to_array())
        .map(|v| half::f16::from_f32(v).to_f32())
        .collect();
    let response = ColorResponse::for_frame(
        frame,
        config.frames,
        config.exposure_range,
        config.white_balance,
        config.contrast,
    );
    let transform = response.color_transform();
    let color: Vec<[u8; 3]> = radiance
        .par_chunks_exact(3)
        .map(|l| camera::camera_pixel(&transform, response.contrast, Vec3::new(l[0], l[1], l[2])))
        .collect();
    let units = if config.depth_noise {
        depth_noise::noisy_depth_units(
            &maps.depth,
            &maps.normals,
            &k,
            config.seed,
            frame as u64,
            DEPTH_UNIT_M,
        )
    } else {
        depth_noise::clean_depth_units(&maps.depth, DEPTH_UNIT_M)
    };
    let normals: Vec<f32> = maps.normals.iter().flat_map(|n| n.to_array()).collect();
    let color_image = Image::from_vec(w, h, color).ok_or("color image has the wrong size")?;
    let ((color_png, depth_png), (truth_depth, (truth_normals, truth_radiance))) = rayon::join(
        || {
            rayon::join(
                || codec::encode_png_rgb8(&color_image),
                || codec::encode_png_u16(w, h, units),
            )
        },
        || {
            rayon::join(
                || encode_floats(w, h, 1, &maps.depth, false),
                || {
                    rayon::join(
                        || encode_floats(w, h, 3, &normals, true),
                        || encode_floats(w, h, 3, &radiance, true),
                    )
                },
            )
        },
    );
    let color_png =
        color_png.map_err(|e| format!("cannot encode the color of frame {frame}: {e}"))?;
    let depth_png =
        depth_png.map_err(|e| format!("cannot encode the depth of frame {frame}: {e}"))?;
    Ok([
        Record::Color(ColorRecord {
            stamp_ns,
            image: color_png,
        }),
        Record::Depth(DepthRecord {
            stamp_ns: depth_stamp_ns(config, frame),
            image: depth_png,
        }),
        Record::Pose(PoseRecord { stamp_ns, pose }),
        Record::Truth(Box::new(TruthRecord {
            stamp_ns,
            color_transform: transform,
            contrast: response.contrast,
            depth: truth_depth,
            normals: truth_normals,
            radiance: truth_radiance,
        })),
    ])
}

/// Renders the recording of `config` frame by frame and writes it atomically to `path`
/// (nothing appears under `path` unless the whole recording is written).
pub fn generate(config: &SynthConfig, path: &Path) -> Result<SynthSummary, RecordingError> {
    generate_with_progress(config, path, &mut |_, _| {})
}

/// [`generate`], calling `progress(done, total)` after each frame.
pub fn generate_with_progress(
    config: &SynthConfig,
    path: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SynthSummary, RecordingError> {
    let invalid = |reason: String| RecordingError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    config
        .validate()
        .map_err(|reason| invalid(format!("invalid synthetic recording settings: {reason}")))?;
    let mut writer = RecordingWriter::create(path, &header(config))?;
    for frame in 0..config.frames {
        let scene = config.scene_at(frame);
        for record in frame_records(config, &scene, frame).map_err(invalid)? {
            writer.write(&record)?;
        }
        progress(frame + 1, config.frames);
    }
    let path = writer.finish()?;
    let bytes = std::fs::metadata(&path)
        .map_err(|e| RecordingError::io(&path, e))?
        .len();
    Ok(SynthSummary {
        path,
        frames: config.frames,
        bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_rejected_with_a_reason() {
        let ok = SynthConfig::default();
        assert!(ok.validate().is_ok());
        let cases = [
            SynthConfig {
                frames: 0,
                ..ok.clone()
            },
            SynthConfig {
                width: 0,
                ..ok.clone()
            },
            SynthConfig {
                fps: f64::NAN,
                ..ok.clone()
            },
            SynthConfig {
                fps: 0.0,
                ..ok.clone()
            },
            SynthConfig {
                exposure_range: (2.0, 1.0),
                ..ok.clone()
            },
            SynthConfig {
                exposure_range: (0.0, 1.0),
                ..ok.clone()
            },
            SynthConfig {
                white_balance: -0.1,
                ..ok.clone()
            },
            SynthConfig {
                contrast: f32::NAN,
                ..ok.clone()
            },
        ];
        for c in cases {
            assert!(c.validate().is_err(), "{c:?}");
        }
    }

    #[test]
    fn provenance_names_every_setting() {
        let config = SynthConfig {
            contrast: 0.25,
            ..SynthConfig::default()
        };
        let p = provenance(&config);
        assert_eq!(p.tool, "relume synth");
        let keys: Vec<&str> = p.settings.keys().map(|k| k.as_str()).collect();
        for k in [
            "generator",
            "frames",
            "width",
            "height",
            "seed",
            "fps",
            "depth_noise",
            "exposure_range",
            "white_balance",
            "contrast",
        ] {
            assert!(keys.contains(&k), "{k} missing");
        }
        assert_eq!(p.settings["exposure_range"], "0.5,2");
        assert_eq!(p.settings["contrast"], "0.25");
        assert_ne!(provenance(&SynthConfig::default()), p);
    }

    #[test]
    fn the_panel_switches_off_at_its_frame_and_the_provenance_says_so() {
        let config = SynthConfig {
            frames: 10,
            switches: LightSwitches {
                panel_off_at: Some(4),
                lamp_on_at: None,
            },
            ..SynthConfig::default()
        };
        assert_eq!(config.validate(), Ok(()));
        let lit = |frame| config.scene_at(frame).lights[interreflection::PANEL].radiance;
        assert_eq!(lit(3), Vec3::new(7.0, 5.6, 4.0));
        assert_eq!(lit(4), Vec3::ZERO);
        assert_eq!(lit(9), Vec3::ZERO);
        // The window and the geometry stay; the interreflection is the dark room's.
        let (on, off) = (config.scene_at(0), config.scene_at(4));
        assert_eq!(on.lights[1], off.lights[1]);
        assert_eq!(on.blocks, off.blocks);
        let floor = scene::Hit {
            t: 1.0,
            position: Vec3::new(0.0, 0.0, 0.0),
            normal: Vec3::Y,
            surface: room::Surface::Floor,
        };
        let (bright, dark) = (
            on.indirect_irradiance(&floor),
            off.indirect_irradiance(&floor),
        );
        // Measured: 0.92, 0.84, 0.83 lit, 0.71, 0.72, 0.77 dark: the warm panel's red
        // goes most.
        let kept = dark / bright;
        assert!(
            dark.min_element() > 0.0 && kept.max_element() < 0.95 && kept.x < kept.z,
            "{bright} {dark}"
        );

        // The light probe is the room as frame 0 shows it.
        let small = |panel_off_at| SynthConfig {
            frames: 5,
            switches: LightSwitches {
                panel_off_at,
                lamp_on_at: None,
            },
            ..SynthConfig::default()
        };
        let probe = |c: &SynthConfig| header(c).attachments[0].image.clone();
        assert_eq!(probe(&small(Some(4))), probe(&small(None)));
        assert_ne!(probe(&small(Some(0))), probe(&small(None)));

        let p = provenance(&config);
        assert_eq!(p.settings[switches::PANEL_OFF_AT_SETTING], "4");
        assert_eq!(LightSwitches::of(&p), Ok(config.switches));
        // A recording without the switch keeps the header it always had.
        let plain = provenance(&SynthConfig::default());
        assert!(!plain.settings.contains_key(switches::PANEL_OFF_AT_SETTING));
        assert_eq!(LightSwitches::of(&plain), Ok(LightSwitches::default()));
        let mut bad = p.clone();
        bad.settings
            .insert(switches::PANEL_OFF_AT_SETTING.into(), "soon".into());
        assert_eq!(
            LightSwitches::of(&bad),
            Err("the recording's setting panel_off_at = \"soon\" is not a frame number".into())
        );
        let late = SynthConfig {
            switches: LightSwitches {
                panel_off_at: Some(10),
                lamp_on_at: None,
            },
            ..config
        };
        assert_eq!(
            late.validate(),
            Err(
                "the panel cannot switch off at frame 10: the recording's frames are 0 to 9".into()
            )
        );
    }

    #[test]
    fn stamps_are_frame_times_and_depth_follows_color() {
        let c = SynthConfig::default();
        assert_eq!(color_stamp_ns(&c, 0), 0);
        assert_eq!(color_stamp_ns(&c, 1), 33_333_333);
        assert_eq!(depth_stamp_ns(&c, 1), 37_333_333);
        let fast = SynthConfig { fps: 1000.0, ..c };
        assert_eq!(depth_stamp_ns(&fast, 1) - color_stamp_ns(&fast, 1), 125_000);
    }
}
