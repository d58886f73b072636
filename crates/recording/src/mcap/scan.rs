//! The first pass over an MCAP file: its channels, what each image topic holds (from
//! its first message), the camera infos, the transform tree and the pose topics. The
//! import chooses its topics from this; `relume import mcap --list` prints it.

use super::container;
use super::messages::{self, CameraInfoMsg, Encoding, Message, MessageType, TransformMsg};
use super::pixels::{self, ImageRole};
use super::read::{Channel, Event, ReadOptions, StreamEnd};
use super::tf::TfTree;
use crate::error::ImportError;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;

/// The MCAP metadata record relume's exporter writes: `depth_unit_m` says what the
/// 16-bit depth values are (REP 118's millimetres otherwise).
pub const RELUME_METADATA: &str = "relume";

/// What an image topic holds, from its first message.
#[derive(Clone, Debug)]
pub struct ImageTopic {
    /// Color or depth, or why neither.
    pub role: Result<ImageRole, String>,
    /// Encoding and size, or compressed format.
    pub format: String,
    pub frame_id: String,
    /// Width and height of the first image, when it could be read.
    pub size: Option<(u32, u32)>,
}

/// Everything the first pass learned.
#[derive(Debug, Default)]
pub struct Scan {
    pub channels: BTreeMap<u16, Arc<Channel>>,
    pub counts: BTreeMap<u16, u64>,
    pub images: BTreeMap<u16, ImageTopic>,
    /// The first camera info of each channel.
    pub infos: BTreeMap<u16, CameraInfoMsg>,
    /// Per channel, the first camera info whose size or camera matrix differs from the
    /// first one, with its message index (as the other messages name it).
    pub info_changes: BTreeMap<u16, (u64, CameraInfoMsg)>,
    /// Transforms of the TF topics.
    pub tf: TfTree,
    /// Messages of the pose topics (PoseStamped, Odometry, PoseInFrame) as transforms.
    pub poses: BTreeMap<u16, Vec<TransformMsg>>,
    /// The first bare `geometry_msgs/Transform` of each channel (translation, quaternion
    /// x, y, z, w): RealSense bags' extrinsics.
    pub extrinsics: BTreeMap<u16, ([f64; 3], [f64; 4])>,
    /// The first `std_msgs/Float32` of each channel: RealSense bags' option values.
    pub values: BTreeMap<u16, f32>,
    /// From relume's own metadata record.
    pub depth_unit_m: Option<f64>,
    pub end: StreamEnd,
}

fn is_static_tf(topic: &str) -> bool {
    topic.trim_end_matches('/').ends_with("tf_static")
}

impl Scan {
    /// Reads `path` once, decoding every message but the images (only the first of each
    /// image topic). `options` says what a damaged chunk does.
    pub fn read(path: &Path, options: ReadOptions) -> Result<Scan, ImportError> {
        let mut scan = Scan::default();
        let bad = |reason: String| ImportError::File {
            path: path.to_path_buf(),
            reason,
        };
        let end = container::stream(path, options, &mut |event| {
            match event {
                Event::Channel(c) => {
                    scan.channels.insert(c.id, c.clone());
                }
                Event::Metadata { name, values } if name == RELUME_METADATA => {
                    if let Some(v) = values.get("depth_unit_m") {
                        let unit: f64 = v
                            .parse()
                            .ok()
                            .filter(|u: &f64| *u > 0.0 && u.is_finite())
                            .ok_or_else(|| {
                                bad(format!(
                                    "metadata `relume` has an invalid depth_unit_m {v:?}"
                                ))
                            })?;
                        scan.depth_unit_m = Some(unit);
                    }
                }
                Event::Metadata { .. } => {}
                Event::Message {
                    channel,
                    index,
                    data,
                    ..
                } => {
                    let count = scan.counts.entry(channel.id).or_default();
                    *count += 1;
                    let first = *count == 1;
                    let Ok(Some((ty, encoding))) = channel.ty else {
                        return Ok(());
                    };
                    if ty.is_image() {
                        if first {
                            let topic = image_topic(ty, encoding, data);
                            scan.images.insert(channel.id, topic);
                        }
                        return Ok(());
                    }
                    let message = messages::decode(ty, encoding, data).map_err(|e| {
                        bad(format!(
                            "message {index} on {} ({}): {e}",
                            channel.topic, channel.schema
                        ))
                    })?;
                    match message {
                        Message::CameraInfo(info) => match scan.infos.get(&channel.id) {
                            None => {
                                scan.infos.insert(channel.id, info);
                            }
                            Some(first)
                                if (first.width, first.height, first.k)
                                    != (info.width, info.height, info.k) =>
                            {
                                scan.info_changes.entry(channel.id).or_insert((index, info));
                            }
                            Some(_) => {}
                        },
                        Message::Transforms(t)
                            if matches!(ty, MessageType::RosTf)
                                || matches!(
                                    ty,
                                    MessageType::FoxFrameTransform
                                        | MessageType::FoxFrameTransforms
                                ) =>
                        {
                            scan.tf.add(&t, is_static_tf(&channel.topic)).map_err(|e| {
                                bad(format!("message {index} on {}: {e}", channel.topic))
                            })?;
                        }
                        Message::Transforms(t) => {
                            scan.poses.entry(channel.id).or_default().extend(t);
                        }
                        Message::Extrinsic {
                            translation,
                            rotation,
                        } => {
                            scan.extrinsics
                                .entry(channel.id)
                                .or_insert((translation, rotation));
                        }
                        Message::Value(v) => {
                            scan.values.entry(channel.id).or_insert(v);
                        }
                        Message::Image(_) => {}
                    }
                }
            }
            Ok(())
        })?;
        scan.end = end;
        scan.tf.finish();
        Ok(scan)
    }

    /// Image channels of one role, in channel order.
    pub fn image_channels(&self, role: ImageRole) -> Vec<&Arc<Channel>> {
        self.images
            .iter()
            .filter(|(_, t)| t.role == Ok(role))
            .map(|(id, _)| &self.channels[id])
            .collect()
    }

    /// The channel of `topic`.
    pub fn channel(&self, topic: &str) -> Option<&Arc<Channel>> {
        self.channels.values().find(|c| c.topic == topic)
    }

    /// A listing of what the file holds, for `--list`.
    pub fn listing(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{} messages on {} topics",
            self.end.messages,
            self.channels.len()
        );
        // RealSense topics run to 50 characters; a driver's to 40.
        let topic_width = self
            .channels
            .values()
            .map(|c| c.topic.chars().count())
            .max()
            .unwrap_or(0)
            .max(40);
        for (id, c) in &self.channels {
            let n = self.counts.get(id).copied().unwrap_or(0);
            let what = match (&c.ty, self.images.get(id), self.infos.get(id)) {
                (_, Some(img), _) => match &img.role {
                    Ok(role) => format!(
                        "{} images, {}, frame {:?}{}",
                        role.name(),
                        img.format,
                        img.frame_id,
                        if c.topic.starts_with("/relume/") {
                            " (a saved product: not imported by default)"
                        } else {
                            ""
                        }
                    ),
                    Err(e) => format!("images not read: {e}"),
                },
                (_, _, Some(info)) => format!(
                    "camera info {}x{}, fx {} fy {} cx {} cy {}, frame {:?}",
                    info.width,
                    info.height,
                    info.k[0],
                    info.k[4],
                    info.k[2],
                    info.k[5],
                    info.frame_id
                ),
                (Ok(Some((MessageType::RosTf, _))), _, _)
                | (Ok(Some((MessageType::FoxFrameTransform, _))), _, _)
                | (Ok(Some((MessageType::FoxFrameTransforms, _))), _, _) => "transforms".into(),
                (Ok(Some(_)), _, _) if self.poses.contains_key(id) => {
                    let p = &self.poses[id];
                    let frame = p.first().map_or("", |t| t.parent.as_str());
                    format!("poses in frame {frame:?}")
                }
                (Ok(Some(_)), _, _) if self.extrinsics.contains_key(id) => {
                    let (t, q) = self.extrinsics[id];
                    format!(
                        "extrinsic: translation {:?} m, rotation (x y z w) {:?}",
                        t, q
                    )
                }
                (Ok(Some(_)), _, _) if self.values.contains_key(id) => {
                    format!("value {}", self.values[id])
                }
                (Ok(_), _, _) => "not used".into(),
                (Err(e), _, _) => format!("not read: {e}"),
            };
            let _ = writeln!(
                out,
                "  {:<topic_width$} {:>7}  {:<32} {what}",
                c.topic, n, c.schema
            );
        }
        let edges = self.tf.describe();
        if !edges.is_empty() {
            let _ = writeln!(out, "transform tree (child <- parent):");
            for (child, parent, is_static, n, first, last) in edges {
                let when = if is_static {
                    "static".to_string()
                } else {
                    format!(
                        "{n} samples, {:.3} s to {:.3} s",
                        first as f64 * 1e-9,
                        last as f64 * 1e-9
                    )
                };
                let _ = writeln!(out, "  {child} <- {parent} ({when})");
            }
        }
        if let Some(t) = &self.end.truncated {
            let _ = writeln!(out, "warning: {t}");
        }
        if let Some(s) = self.end.skipped() {
            let _ = writeln!(out, "warning: {s}");
        }
        out
    }
}

fn image_topic(ty: MessageType, encoding: Encoding, data: &[u8]) -> ImageTopic {
    match messages::decode(ty, encoding, data) {
        Ok(Message::Image(img)) => {
            let size = match &img.data {
                messages::ImageData::Raw { width, height, .. } => Some((*width, *height)),
                messages::ImageData::Compressed { format, data } => {
                    pixels::compressed_file(format, data)
                        .ok()
                        .and_then(|(_, file)| crate::codec::wrap_image_file(file.to_vec()).ok())
                        .map(|(i, _)| (i.width, i.height))
                }
            };
            ImageTopic {
                role: pixels::role_of(&img.data),
                format: pixels::describe(&img.data),
                frame_id: super::tf::frame_name(&img.frame_id).to_string(),
                size,
            }
        }
        Ok(_) => unreachable!("image types decode to images"),
        Err(e) => ImageTopic {
            role: Err(format!("its first message cannot be read: {e}")),
            format: String::new(),
            frame_id: String::new(),
            size: None,
        },
    }
}
