//! The data model of a `.relume` recording: header, stream records and encoded images.
//!
//! Everything here is serialized with MessagePack (rmp-serde) inside the framing of
//! [`super::format`]. Byte payloads use `serde_bytes` so they are stored as MessagePack
//! `bin`, not as arrays of integers.

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub use relume_base::pinhole::Intrinsics;
/// Where a recording came from: the tool, its version, the source and the settings used.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Provenance {
    /// e.g. `"relume synth"`, `"relume import redwood"`.
    pub tool: String,
    pub tool_version: String,
    /// The source directory or scene name.
    pub source: String,
    /// Settings that shaped the content (seed, size, fps, intrinsics preset, ...).
    pub settings: BTreeMap<String, String>,
}

/// The kinds of record stream in a recording.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum StreamKind {
    Color,
    Depth,
    Pose,
    /// Per-frame ground truth of synthetic recordings.
    Truth,
}

impl StreamKind {
    pub const ALL: [StreamKind; 4] = [
        StreamKind::Color,
        StreamKind::Depth,
        StreamKind::Pose,
        StreamKind::Truth,
    ];

    /// Lower-case name used in messages and JSON.
    pub fn name(self) -> &'static str {
        match self {
            StreamKind::Color => "color",
            StreamKind::Depth => "depth",
            StreamKind::Pose => "pose",
            StreamKind::Truth => "truth",
        }
    }
}

/// The first record of every recording.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Header {
    pub name: String,
    pub provenance: Provenance,
    pub color_intrinsics: Intrinsics,
    pub depth_intrinsics: Intrinsics,
    /// Metres per depth unit of the stored depth images (0.001 for millimetres,
    /// 0.0002 for TUM's scale of 5000).
    pub depth_unit_m: f64,
    /// The streams this recording carries.
    pub streams: Vec<StreamKind>,
    /// Scene-level ground truth of synthetic recordings.
    pub ground_truth: Option<SceneTruth>,
    /// Named attachments, e.g. an HDR environment map.
    pub attachments: Vec<Attachment>,
}

pub use relume_base::pinhole::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};

/// The finest and coarsest depth units a recording may declare (metres per stored
/// unit): a micrometre (sensors store millimetres, TUM a fifth of one) to 10 m (float
/// depth in metres stores 1). Outside them every stored depth turns into a distance no
/// sensor measures, or into infinity.
pub const DEPTH_UNIT_RANGE_M: (f64, f64) = (1e-6, 10.0);

/// The largest world coordinate (metres) a recording's ground truth may name: recordings
/// are of rooms and buildings, and beyond this f32 positions lose their millimetres.
pub const MAX_SCENE_COORDINATE_M: f64 = 1e4;

impl Header {
    /// Why the header cannot describe a recording, if it cannot (see
    /// [`Intrinsics::check`]; the depth unit must lie in [`DEPTH_UNIT_RANGE_M`]).
    pub fn check(&self) -> Result<(), String> {
        self.color_intrinsics
            .check()
            .map_err(|e| format!("color intrinsics: {e}"))?;
        self.depth_intrinsics
            .check()
            .map_err(|e| format!("depth intrinsics: {e}"))?;
        let unit = self.depth_unit_m;
        if !(unit.is_finite() && unit > 0.0) {
            return Err(format!(
                "depth unit {unit} m is not a finite positive length"
            ));
        }
        let (finest, coarsest) = DEPTH_UNIT_RANGE_M;
        if !(finest..=coarsest).contains(&unit) {
            return Err(format!(
                "depth unit {} m is not a depth sensor's: it must lie between {} m and \
                 {coarsest} m per stored unit",
                relume_base::pinhole::readable(unit),
                relume_base::pinhole::readable(finest),
            ));
        }
        if let Some(truth) = &self.ground_truth {
            let p = truth.object_position;
            if !p
                .iter()
                .all(|c| c.is_finite() && c.abs() <= MAX_SCENE_COORDINATE_M)
            {
                return Err(format!(
                    "ground truth: the object position [{}, {}, {}] is not a point of a \
                     room: each coordinate must be finite and within {MAX_SCENE_COORDINATE_M} m",
                    p[0], p[1], p[2]
                ));
            }
        }
        Ok(())
    }

    /// A header for one camera with both sensors at `intrinsics`, and no provenance,
    /// streams, ground truth or attachments (for sources built in code).
    pub fn new(name: &str, intrinsics: Intrinsics, depth_unit_m: f64) -> Header {
        Header {
            name: name.to_string(),
            provenance: Provenance::default(),
            color_intrinsics: intrinsics,
            depth_intrinsics: intrinsics,
            depth_unit_m,
            streams: Vec::new(),
            ground_truth: None,
            attachments: Vec::new(),
        }
    }

    /// The attachment called `name`, if any.
    pub fn attachment(&self, name: &str) -> Option<&Attachment> {
        self.attachments.iter().find(|a| a.name == name)
    }
}

/// Scene-level ground truth: where the virtual object goes and what it would see.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SceneTruth {
    /// World position (metres) at which a virtual object will be placed; the
    /// environment map attachment named `environment` is seen from here.
    pub object_position: [f64; 3],
    pub description: String,
}

/// A named blob in the header, e.g. the HDR environment map.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Attachment {
    pub name: String,
    /// What the attachment is, e.g. `"envmap/latlong"` (image rows from theta = 0 at
    /// world +y down to theta = pi, columns from phi = 0 .. 2 pi).
    pub kind: String,
    pub image: EncodedImage,
}

/// How the bytes of an [`EncodedImage`] are stored.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageEncoding {
    /// A PNG file (8-bit RGB color or 16-bit gray depth).
    Png,
    /// A JPEG file (8-bit color).
    Jpeg,
    /// Raw 8-bit samples, `channels` per pixel.
    RawU8,
    /// Raw little-endian u16 samples.
    RawU16,
    /// Little-endian f32 samples, byte planes shuffled and deflated.
    ShuffledF32,
    /// Little-endian f16 samples, byte planes shuffled and deflated.
    ShuffledF16,
}

/// Image bytes as stored: decoded on replay, not at import.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct EncodedImage {
    pub encoding: ImageEncoding,
    pub width: u32,
    pub height: u32,
    pub channels: u8,
    #[serde(with = "serde_bytes")]
    pub bytes: Vec<u8>,
}

/// A color image at a timestamp.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ColorRecord {
    pub stamp_ns: i64,
    pub image: EncodedImage,
}

/// A depth image at a timestamp, in units of the header's `depth_unit_m`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct DepthRecord {
    pub stamp_ns: i64,
    pub image: EncodedImage,
}

/// A camera-to-world rigid transform, metres; the camera looks down +z, x right, y down.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub translation: [f64; 3],
    /// Unit quaternion (x, y, z, w).
    pub rotation: [f64; 4],
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        translation: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
    };

    pub fn from_parts(translation: DVec3, rotation: DQuat) -> Pose {
        Pose {
            translation: translation.to_array(),
            rotation: rotation.normalize().to_array(),
        }
    }

    pub fn translation(&self) -> DVec3 {
        DVec3::from_array(self.translation)
    }

    /// `Err` saying why this is not a rigid transform: a non-finite value, or a rotation
    /// whose quaternion is not of unit length (within 1e-3; writers store it normalised).
    pub fn check(&self) -> Result<(), String> {
        if !self
            .translation
            .iter()
            .chain(&self.rotation)
            .all(|v| v.is_finite())
        {
            return Err(format!(
                "the pose holds a non-finite value (translation {:?}, rotation {:?})",
                self.translation, self.rotation
            ));
        }
        let length = self.rotation().length();
        if (length - 1.0).abs() > 1e-3 {
            return Err(format!(
                "the pose's rotation quaternion has length {length:.4}, expected 1"
            ));
        }
        Ok(())
    }

    pub fn rotation(&self) -> DQuat {
        DQuat::from_array(self.rotation)
    }

    /// The 4x4 camera-to-world matrix.
    pub fn matrix(&self) -> glam::DMat4 {
        glam::DMat4::from_rotation_translation(self.rotation(), self.translation())
    }

    /// Interpolates between two poses: lerp of the translations, slerp of the rotations.
    pub fn interpolate(a: &Pose, b: &Pose, t: f64) -> Pose {
        let ta = a.translation();
        let tb = b.translation();
        Pose::from_parts(ta.lerp(tb, t), a.rotation().slerp(b.rotation(), t))
    }
}

/// A pose at a timestamp.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct PoseRecord {
    pub stamp_ns: i64,
    pub pose: Pose,
}

/// Per-frame ground truth of a synthetic recording, at the color stamp.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TruthRecord {
    pub stamp_ns: i64,
    /// The camera's linear color map of this frame (row-major 3x3): camera linear RGB =
    /// M * scene radiance, before contrast, gamma 2.2, clipping and quantization.
    pub color_transform: [f32; 9],
    /// Contrast exponent applied after the linear map (1 = none).
    pub contrast: f32,
    /// Noise-free depth in metres (f32, 1 channel; 0 where nothing is hit).
    pub depth: EncodedImage,
    /// Camera-space unit normals (3 channels).
    pub normals: EncodedImage,
    /// HDR scene radiance before the camera model (linear RGB, 3 channels).
    pub radiance: EncodedImage,
}

/// Any record of a recording, as read back.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    Color(ColorRecord),
    Depth(DepthRecord),
    Pose(PoseRecord),
    Truth(Box<TruthRecord>),
}

impl Record {
    pub fn kind(&self) -> StreamKind {
        match self {
            Record::Color(_) => StreamKind::Color,
            Record::Depth(_) => StreamKind::Depth,
            Record::Pose(_) => StreamKind::Pose,
            Record::Truth(_) => StreamKind::Truth,
        }
    }

    pub fn stamp_ns(&self) -> i64 {
        match self {
            Record::Color(r) => r.stamp_ns,
            Record::Depth(r) => r.stamp_ns,
            Record::Pose(r) => r.stamp_ns,
            Record::Truth(r) => r.stamp_ns,
        }
    }
}
