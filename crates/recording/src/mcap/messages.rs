//! The messages relume reads from MCAP files, decoded from either of two families:
//!
//! | what | ROS 2 (`ros2msg` schema, `cdr` messages) | Foxglove (`jsonschema`, `json`) |
//! |---|---|---|
//! | raw image | `sensor_msgs/msg/Image` | `foxglove.RawImage` |
//! | compressed image | `sensor_msgs/msg/CompressedImage` | `foxglove.CompressedImage` |
//! | intrinsics | `sensor_msgs/msg/CameraInfo` | `foxglove.CameraCalibration` |
//! | transforms | `tf2_msgs/msg/TFMessage` | `foxglove.FrameTransform(s)` |
//! | a pose | `geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/Odometry` | `foxglove.PoseInFrame` |
//!
//! The CDR layouts follow the ROS 2 message definitions (`std_msgs/Header` = `int32 sec,
//! uint32 nanosec, string frame_id`, and so on); the JSON ones Foxglove's schemas, whose
//! `bytes` fields are base64 strings.

use super::cdr::CdrReader;
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
    FoxRawImage,
    FoxCompressedImage,
    FoxCameraCalibration,
    FoxFrameTransform,
    FoxFrameTransforms,
    FoxPoseInFrame,
}

impl MessageType {
    /// The type of a channel from its schema name and message encoding, or why it is not
    /// read (`None`: a type relume has no use for).
    pub fn of(schema: &str, message_encoding: &str) -> Result<Option<MessageType>, String> {
        use MessageType::*;
        let ros = match schema.replace("/msg/", "/").as_str() {
            "sensor_msgs/Image" => Some(RosImage),
            "sensor_msgs/CompressedImage" => Some(RosCompressedImage),
            "sensor_msgs/CameraInfo" => Some(RosCameraInfo),
            "tf2_msgs/TFMessage" => Some(RosTf),
            "geometry_msgs/PoseStamped" => Some(RosPoseStamped),
            "nav_msgs/Odometry" => Some(RosOdometry),
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
            (Some(t), _, "cdr") | (_, Some(t), "json") => Ok(Some(t)),
            (Some(_), _, "ros1") => Err(format!(
                "{schema} in ROS 1 encoding: relume reads ROS 2 (cdr) messages; convert the \
                 bag with `mcap convert` from a ROS 2 installation or rosbags-convert"
            )),
            (Some(_), _, other) | (_, Some(_), other) => Err(format!(
                "{schema} in `{other}` encoding: relume reads ROS 2 messages as cdr and \
                 Foxglove's schemas as json"
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

/// Decodes one message of type `ty`.
pub fn decode(ty: MessageType, bytes: &[u8]) -> Result<Message<'_>, String> {
    use MessageType::*;
    match ty {
        RosImage | RosCompressedImage | RosCameraInfo | RosTf | RosPoseStamped | RosOdometry => {
            decode_cdr(ty, bytes).map_err(|e| e.to_string())
        }
        _ => decode_json(ty, bytes),
    }
}

struct Header {
    stamp_ns: i64,
    frame_id: String,
}

fn cdr_header(r: &mut CdrReader) -> Result<Header, super::cdr::CdrError> {
    let sec = r.i32("header.stamp.sec")?;
    let nsec = r.u32("header.stamp.nanosec")?;
    let frame_id = r.string("header.frame_id")?;
    let stamp_ns = stamp_ns(sec as i64, nsec as i64)
        .map_err(|reason| super::cdr::CdrError { offset: 4, reason })?;
    Ok(Header { stamp_ns, frame_id })
}

fn cdr_pose(r: &mut CdrReader, what: &str) -> Result<([f64; 3], [f64; 4]), super::cdr::CdrError> {
    let t = r.f64_array::<3>(what)?;
    let q = r.f64_array::<4>(what)?;
    Ok((t, q))
}

fn decode_cdr(ty: MessageType, bytes: &[u8]) -> Result<Message<'_>, super::cdr::CdrError> {
    use MessageType::*;
    let mut r = CdrReader::new(bytes)?;
    Ok(match ty {
        RosImage => {
            let h = cdr_header(&mut r)?;
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
            let h = cdr_header(&mut r)?;
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
            let h = cdr_header(&mut r)?;
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
                let h = cdr_header(&mut r)?;
                let child = r.string("child_frame_id")?;
                let (translation, rotation) = cdr_pose(&mut r, "transform")?;
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
            let h = cdr_header(&mut r)?;
            let child = if ty == RosOdometry {
                r.string("child_frame_id")?
            } else {
                String::new()
            };
            let (translation, rotation) = cdr_pose(&mut r, "pose")?;
            Message::Transforms(vec![TransformMsg {
                stamp_ns: h.stamp_ns,
                parent: h.frame_id,
                child,
                translation,
                rotation,
            }])
        }
        _ => unreachable!("JSON types are decoded by decode_json"),
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
        _ => unreachable!("CDR types are decoded by decode_cdr"),
    })
}
