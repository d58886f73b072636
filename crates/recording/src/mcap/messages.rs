//! The messages relume reads from MCAP files and ROS 1 bags, decoded from either of two
//! families:
//!
//! | what | ROS (`cdr` for ROS 2, `ros1` for ROS 1) | Foxglove (`jsonschema`, `json`) |
//! |---|---|---|
//! | raw image | `sensor_msgs/msg/Image` | `foxglove.RawImage` |
//! | compressed image | `sensor_msgs/msg/CompressedImage` | `foxglove.CompressedImage` |
//! | intrinsics | `sensor_msgs/msg/CameraInfo` | `foxglove.CameraCalibration` |
//! | transforms | `tf2_msgs/msg/TFMessage` (ROS 1 `tf/tfMessage` too) | `foxglove.FrameTransform(s)` |
//! | a pose | `geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/Odometry` | `foxglove.PoseInFrame` |
//! | an extrinsic | `geometry_msgs/msg/Transform` (RealSense bags' `.../tf/N`) | |
//! | a value | `std_msgs/msg/Float32` (RealSense bags' `.../option/NAME/value`) | |
//!
//! The ROS layouts follow the message definitions; ROS 1 and ROS 2 order the fields the
//! same way and differ in the header (ROS 1's `std_msgs/Header` = `uint32 seq, time
//! stamp, string frame_id`, ROS 2's = `int32 sec, uint32 nanosec, string frame_id`) and in
//! the wire format ([`super::wire`]). The JSON ones follow Foxglove's schemas, whose
//! `bytes` fields are base64 strings.

use super::wire::{WireError, WireReader};
use base64::Engine;
use serde::Deserialize;
use std::borrow::Cow;

/// The message types relume reads, by schema name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MessageType {
    RosImage,
    RosCompressedImage,
    RosCameraInfo,
    RosTf,
    RosPoseStamped,
    RosOdometry,
    RosTransform,
    RosFloat32,
    FoxRawImage,
    FoxCompressedImage,
    FoxCameraCalibration,
    FoxFrameTransform,
    FoxFrameTransforms,
    FoxPoseInFrame,
}

impl MessageType {
    /// The type of a channel and the wire format of its messages, from its schema name
    /// and message encoding, or why it is not read (`None`: a type relume has no use for).
    pub fn of(
        schema: &str,
        message_encoding: &str,
    ) -> Result<Option<(MessageType, Encoding)>, String> {
        use MessageType::*;
        let ros = match schema.replace("/msg/", "/").as_str() {
            "sensor_msgs/Image" => Some(RosImage),
            "sensor_msgs/CompressedImage" => Some(RosCompressedImage),
            "sensor_msgs/CameraInfo" => Some(RosCameraInfo),
            "tf2_msgs/TFMessage" | "tf/tfMessage" => Some(RosTf),
            "geometry_msgs/PoseStamped" => Some(RosPoseStamped),
            "nav_msgs/Odometry" => Some(RosOdometry),
            "geometry_msgs/Transform" => Some(RosTransform),
            "std_msgs/Float32" => Some(RosFloat32),
            _ => None,
        };
        let foxglove = match schema {
            "foxglove.RawImage" => Some(FoxRawImage),
            "foxglove.CompressedImage" => Some(FoxCompressedImage),
            "foxglove.CameraCalibration" => Some(FoxCameraCalibration),
            "foxglove.FrameTransform" => Some(FoxFrameTransform),
            "foxglove.FrameTransforms" => Some(FoxFrameTransforms),
            "foxglove.PoseInFrame" => Some(FoxPoseInFrame),
            _ => None,
        };
        match (ros, foxglove, message_encoding) {
            (Some(t), _, "cdr") => Ok(Some((t, Encoding::Cdr))),
            (Some(t), _, "ros1") => Ok(Some((t, Encoding::Ros1))),
            (_, Some(t), "json") => Ok(Some((t, Encoding::Json))),
            (Some(_), _, other) | (_, Some(_), other) => Err(format!(
                "{schema} in `{other}` encoding: relume reads ROS messages as cdr (ROS 2) or \
                 ros1 and Foxglove's schemas as json"
            )),
            _ => Ok(None),
        }
    }

    /// Whether messages of this type are images.
    pub fn is_image(self) -> bool {
        use MessageType::*;
        matches!(
            self,
            RosImage | RosCompressedImage | FoxRawImage | FoxCompressedImage
        )
    }
}

/// The pixels of an image message, as sent.
#[derive(Clone, Debug, PartialEq)]
pub enum ImageData<'a> {
    /// Uncompressed rows: `encoding` is a ROS image encoding (`rgb8`, `16UC1`, ...).
    Raw {
        width: u32,
        height: u32,
        encoding: String,
        big_endian: bool,
        step: u32,
        data: Cow<'a, [u8]>,
    },
    /// A compressed file: `format` as the message gives it (`jpeg`, `png`,
    /// `bgr8; jpeg compressed bgr8`, `16UC1; compressedDepth png`, ...).
    Compressed { format: String, data: Cow<'a, [u8]> },
}

/// An image message: header stamp, frame and pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageMsg<'a> {
    pub stamp_ns: i64,
    pub frame_id: String,
    pub data: ImageData<'a>,
}

/// Pinhole intrinsics of a CameraInfo or CameraCalibration message.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfoMsg {
    pub frame_id: String,
    pub width: u32,
    pub height: u32,
    /// Row-major 3x3 camera matrix.
    pub k: [f64; 9],
    pub distortion_model: String,
    pub d: Vec<f64>,
}

/// One transform: the pose of `child` in `parent` at `stamp_ns`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformMsg {
    pub stamp_ns: i64,
    pub parent: String,
    pub child: String,
    pub translation: [f64; 3],
    /// Quaternion x, y, z, w.
    pub rotation: [f64; 4],
}

/// A decoded message relume uses.
#[derive(Clone, Debug, PartialEq)]
pub enum Message<'a> {
    Image(ImageMsg<'a>),
    CameraInfo(CameraInfoMsg),
    /// TF transforms, or a pose message as a transform (`child` empty for a
    /// PoseStamped / PoseInFrame, which does not name the frame it places).
    Transforms(Vec<TransformMsg>),
    /// A bare `geometry_msgs/Transform` (no stamp, no frames: the topic says what it
    /// relates), as translation and quaternion x, y, z, w.
    Extrinsic {
        translation: [f64; 3],
        rotation: [f64; 4],
    },
    /// A `std_msgs/Float32`.
    Value(f32),
}

/// The wire format of a channel's messages, from its message encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 2's CDR (`cdr`).
    Cdr,
    /// ROS 1 serialization (`ros1`: ROS 1 bags, and MCAP files converted from them).
    Ros1,
    /// Foxglove's JSON schemas (`json`).
    Json,
}

/// Nanoseconds of a ROS or Foxglove time (seconds, nanoseconds).
fn stamp_ns(sec: i64, nsec: i64) -> Result<i64, String> {
    if !(0..1_000_000_000).contains(&nsec) {
        return Err(format!("stamp nanoseconds {nsec} out of 0..1e9"));
    }
    sec.checked_mul(1_000_000_000)
        .and_then(|s| s.checked_add(nsec))
        .ok_or_else(|| format!("stamp of {sec} s is out of range"))
}

/// Decodes one message of type `ty` sent in `encoding`.
pub fn decode(ty: MessageType, encoding: Encoding, bytes: &[u8]) -> Result<Message<'_>, String> {
    let reader = match encoding {
        Encoding::Json => return decode_json(ty, bytes),
        Encoding::Cdr => WireReader::cdr(bytes).map_err(|e| e.to_string())?,
        Encoding::Ros1 => WireReader::ros1(bytes),
    };
    decode_ros(ty, reader).map_err(|e| e.to_string())
}

struct Header {
    stamp_ns: i64,
    frame_id: String,
}

/// `std_msgs/Header`: ROS 2's (`int32 sec, uint32 nanosec, string frame_id`) in CDR,
/// ROS 1's (`uint32 seq, uint32 secs, uint32 nsecs, string frame_id`) otherwise.
fn ros_header(r: &mut WireReader) -> Result<Header, WireError> {
    let (sec, at, nsec) = if r.is_cdr() {
        let at = r.position();
        (
            r.i32("header.stamp.sec")? as i64,
            at,
            r.u32("header.stamp.nanosec")?,
        )
    } else {
        r.u32("header.seq")?;
        let at = r.position();
        (
            r.u32("header.stamp.secs")? as i64,
            at,
            r.u32("header.stamp.nsecs")?,
        )
    };
    let frame_id = r.string("header.frame_id")?;
    let stamp_ns = stamp_ns(sec, nsec as i64).map_err(|reason| WireError { offset: at, reason })?;
    Ok(Header { stamp_ns, frame_id })
}

fn ros_pose(r: &mut WireReader, what: &str) -> Result<([f64; 3], [f64; 4]), WireError> {
    let t = r.f64_array::<3>(what)?;
    let q = r.f64_array::<4>(what)?;
    Ok((t, q))
}

fn decode_ros<'a>(ty: MessageType, mut r: WireReader<'a>) -> Result<Message<'a>, WireError> {
    use MessageType::*;
    let r = &mut r;
    Ok(match ty {
        RosImage => {
            let h = ros_header(r)?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let encoding = r.string("encoding")?;
            let big_endian = r.u8("is_bigendian")? != 0;
            let step = r.u32("step")?;
            let data = r.bytes("data")?;
            Message::Image(ImageMsg {
                stamp_ns: h.stamp_ns,
                frame_id: h.frame_id,
                data: ImageData::Raw {
                    width,
                    height,
                    encoding,
                    big_endian,
                    step,
                    data: Cow::Borrowed(data),
                },
            })
        }
        RosCompressedImage => {
            let h = ros_header(r)?;
            let format = r.string("format")?;
            let data = r.bytes("data")?;
            Message::Image(ImageMsg {
                stamp_ns: h.stamp_ns,
                frame_id: h.frame_id,
                data: ImageData::Compressed {
                    format,
                    data: Cow::Borrowed(data),
                },
            })
        }
        RosCameraInfo => {
            let h = ros_header(r)?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let distortion_model = r.string("distortion_model")?;
            let d = r.f64_seq("d")?;
            let k = r.f64_array::<9>("k")?;
            Message::CameraInfo(CameraInfoMsg {
                frame_id: h.frame_id,
                width,
                height,
                k,
                distortion_model,
                d,
            })
        }
        RosTf => {
            // TransformStamped: header (>= 12 bytes), child frame (>= 4), 7 float64.
            let n = r.seq_len("transforms", 72)?;
            let mut out = Vec::with_capacity(n);
            for _ in 0..n {
                let h = ros_header(r)?;
                let child = r.string("child_frame_id")?;
                let (translation, rotation) = ros_pose(r, "transform")?;
                out.push(TransformMsg {
                    stamp_ns: h.stamp_ns,
                    parent: h.frame_id,
                    child,
                    translation,
                    rotation,
                });
            }
            Message::Transforms(out)
        }
        RosPoseStamped | RosOdometry => {
            let h = ros_header(r)?;
            let child = if ty == RosOdometry {
                r.string("child_frame_id")?
            } else {
                String::new()
            };
            let (translation, rotation) = ros_pose(r, "pose")?;
            Message::Transforms(vec![TransformMsg {
                stamp_ns: h.stamp_ns,
                parent: h.frame_id,
                child,
                translation,
                rotation,
            }])
        }
        RosTransform => {
            let (translation, rotation) = ros_pose(r, "transform")?;
            Message::Extrinsic {
                translation,
                rotation,
            }
        }
        RosFloat32 => Message::Value(r.f32("data")?),
        _ => {
            return Err(WireError {
                offset: 0,
                reason: format!("{ty:?} is a Foxglove schema, sent as json"),
            });
        }
    })
}

#[derive(Deserialize)]
struct FoxTime {
    sec: i64,
    nsec: i64,
}

#[derive(Deserialize)]
struct FoxVec3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Deserialize)]
struct FoxQuat {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Deserialize)]
struct FoxRawImage {
    timestamp: FoxTime,
    #[serde(default)]
    frame_id: String,
    width: u32,
    height: u32,
    encoding: String,
    step: u32,
    #[serde(default)]
    data: Option<String>,
}

#[derive(Deserialize)]
struct FoxCompressedImage {
    timestamp: FoxTime,
    #[serde(default)]
    frame_id: String,
    format: String,
    #[serde(default)]
    data: Option<String>,
}

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct FoxCalibration {
    #[serde(default)]
    frame_id: String,
    width: u32,
    height: u32,
    #[serde(default)]
    distortion_model: String,
    #[serde(default)]
    D: Vec<f64>,
    K: Vec<f64>,
}

#[derive(Deserialize)]
struct FoxFrameTransform {
    timestamp: FoxTime,
    parent_frame_id: String,
    child_frame_id: String,
    translation: FoxVec3,
    rotation: FoxQuat,
}

#[derive(Deserialize)]
struct FoxFrameTransforms {
    transforms: Vec<FoxFrameTransform>,
}

#[derive(Deserialize)]
struct FoxPose {
    position: FoxVec3,
    orientation: FoxQuat,
}

#[derive(Deserialize)]
struct FoxPoseInFrame {
    timestamp: FoxTime,
    frame_id: String,
    pose: FoxPose,
}

fn base64_field(data: Option<String>) -> Result<Vec<u8>, String> {
    base64::engine::general_purpose::STANDARD
        .decode(data.unwrap_or_default())
        .map_err(|e| format!("data is not base64: {e}"))
}

fn fox_transform(t: FoxFrameTransform) -> Result<TransformMsg, String> {
    Ok(TransformMsg {
        stamp_ns: stamp_ns(t.timestamp.sec, t.timestamp.nsec)?,
        parent: t.parent_frame_id,
        child: t.child_frame_id,
        translation: [t.translation.x, t.translation.y, t.translation.z],
        rotation: [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w],
    })
}

fn decode_json(ty: MessageType, bytes: &[u8]) -> Result<Message<'static>, String> {
    fn parse<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, String> {
        serde_json::from_slice(bytes).map_err(|e| format!("not a valid message: {e}"))
    }
    Ok(match ty {
        MessageType::FoxRawImage => {
            let m: FoxRawImage = parse(bytes)?;
            Message::Image(ImageMsg {
                stamp_ns: stamp_ns(m.timestamp.sec, m.timestamp.nsec)?,
                frame_id: m.frame_id,
                data: ImageData::Raw {
                    width: m.width,
                    height: m.height,
                    encoding: m.encoding,
                    big_endian: false,
                    step: m.step,
                    data: Cow::Owned(base64_field(m.data)?),
                },
            })
        }
        MessageType::FoxCompressedImage => {
            let m: FoxCompressedImage = parse(bytes)?;
            Message::Image(ImageMsg {
                stamp_ns: stamp_ns(m.timestamp.sec, m.timestamp.nsec)?,
                frame_id: m.frame_id,
                data: ImageData::Compressed {
                    format: m.format,
                    data: Cow::Owned(base64_field(m.data)?),
                },
            })
        }
        MessageType::FoxCameraCalibration => {
            let m: FoxCalibration = parse(bytes)?;
            let k: [f64; 9] =
                m.K.try_into()
                    .map_err(|k: Vec<f64>| format!("K has {} values, not 9", k.len()))?;
            Message::CameraInfo(CameraInfoMsg {
                frame_id: m.frame_id,
                width: m.width,
                height: m.height,
                k,
                distortion_model: m.distortion_model,
                d: m.D,
            })
        }
        MessageType::FoxFrameTransform => Message::Transforms(vec![fox_transform(parse(bytes)?)?]),
        MessageType::FoxFrameTransforms => {
            let m: FoxFrameTransforms = parse(bytes)?;
            Message::Transforms(
                m.transforms
                    .into_iter()
                    .map(fox_transform)
                    .collect::<Result<_, _>>()?,
            )
        }
        MessageType::FoxPoseInFrame => {
            let m: FoxPoseInFrame = parse(bytes)?;
            let (p, q) = (m.pose.position, m.pose.orientation);
            Message::Transforms(vec![TransformMsg {
                stamp_ns: stamp_ns(m.timestamp.sec, m.timestamp.nsec)?,
                parent: m.frame_id,
                child: String::new(),
                translation: [p.x, p.y, p.z],
                rotation: [q.x, q.y, q.z, q.w],
            }])
        }
        _ => return Err(format!("{ty:?} is a ROS message, sent as cdr or ros1")),
    })
}
