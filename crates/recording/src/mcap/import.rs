//! `relume import mcap`: a ROS 2 or Foxglove MCAP log to a recording, in two passes:
//! [`Scan`] learns the topics, intrinsics and transforms; the second pass converts the
//! chosen color and depth topics' images (in parallel batches, written in file order
//! on a thread of its own)
//! and stamps each color image with the camera's pose at its header stamp.

use super::choose::{PoseSource, choose_images, fail, intrinsics_for, pose_source};
use super::container;
use super::messages::{self, Message};
use super::pixels::{self, ImageRole};
use super::read::{Channel, Event, ReadOptions};
use super::realsense;
use super::scan::Scan;
use crate::codec;
use crate::error::ImportError;
use crate::importers::{CameraIntrinsics, ImportSummary, StoreMode, import_header};
use crate::register::{Extrinsic, Registration, Scratch, register_depth};
use crate::types::{ColorRecord, DepthRecord, EncodedImage, Pose, PoseRecord, Record, StreamKind};
use crate::writer::RecordingWriter;
use rayon::prelude::*;
use relume_base::pinhole::Intrinsics;
use std::path::Path;
use std::sync::Arc;

pub use super::options::McapOptions;

/// REP 118: 16-bit depth images hold millimetres.
pub const ROS_DEPTH_UNIT_M: f64 = 0.001;

/// Imports the MCAP file `file` into `out`. `progress` gets (done, total) messages.
pub fn import(
    file: &Path,
    out: &Path,
    options: &McapOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    let read_options = ReadOptions {
        skip_corrupt: options.skip_corrupt,
    };
    let scan = Scan::read(file, read_options)?;
    let mut warnings = Vec::new();
    let color = choose_images(
        file,
        &scan,
        ImageRole::Color,
        options.color_topic.as_deref(),
        "--color-topic",
    )?
    .ok_or_else(|| {
        let unread: Vec<String> = scan
            .images
            .iter()
            .filter_map(|(id, t)| {
                t.role
                    .as_ref()
                    .err()
                    .map(|e| format!("{}: {e}", scan.channels[id].topic))
            })
            .collect();
        fail(
            file,
            format!(
                "no color images: relume reads sensor_msgs/Image, sensor_msgs/CompressedImage, \
                     foxglove.RawImage and foxglove.CompressedImage{}",
                if unread.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", unread.join("; "))
                }
            ),
        )
    })?;
    let depth = choose_images(
        file,
        &scan,
        ImageRole::Depth,
        options.depth_topic.as_deref(),
        "--depth-topic",
    )?;
    if depth.is_none() {
        // Image topics whose messages relume cannot read: one of them may be the depth
        // the user recorded (an 8UC1 or 32FC3 topic), which deserves more than "no depth".
        let unread: Vec<String> = scan
            .images
            .iter()
            .filter_map(|(id, t)| {
                let why = t.role.as_ref().err()?;
                Some(format!("{}: {why}", scan.channels[id].topic))
            })
            .collect();
        if !unread.is_empty() {
            warnings.push(format!(
                "no depth topic was read; image topics that were not: {}",
                unread.join("; ")
            ));
        }
    }
    let color_topic = &scan.images[&color.id];
    let (color_k, depth_k) = match options.intrinsics {
        Some(given) => {
            let size = |c: Option<&Arc<Channel>>| c.and_then(|c| scan.images[&c.id].size);
            (
                given.for_size(size(Some(color)), size(depth)),
                given.for_size(size(depth), size(Some(color))),
            )
        }
        None => {
            let ck = intrinsics_for(
                file,
                &scan,
                color,
                options.info_topic.as_deref(),
                &mut warnings,
            )?;
            let dk = match depth {
                Some(d) => intrinsics_for(file, &scan, d, None, &mut warnings)?,
                None => None,
            };
            let fallback = CameraIntrinsics::default();
            if ck.is_none() {
                warnings.push(format!(
                    "no camera info for {}: the primesense preset is assumed; give --intrinsics \
                     fx,fy,cx,cy for this camera",
                    color.topic
                ));
            }
            let ck = ck.unwrap_or_else(|| fallback.for_size(color_topic.size, None));
            let dk = dk.unwrap_or_else(|| {
                let size = depth.and_then(|d| scan.images[&d.id].size);
                if size.is_none() || size == Some((ck.width, ck.height)) {
                    ck
                } else {
                    fallback.for_size(size, None)
                }
            });
            (ck, dk)
        }
    };
    let poses = pose_source(file, &scan, options, &color_topic.frame_id, &mut warnings)?;
    let registration = match depth {
        Some(d) => registration(file, &scan, d, color, (depth_k, color_k), &mut warnings)?,
        None => None,
    };
    let realsense_unit = match depth {
        Some(d) => realsense::depth_unit_m(&scan, &d.topic).map_err(|e| fail(file, e))?,
        None => None,
    };
    let depth_unit_m = realsense_unit
        .or(scan.depth_unit_m)
        .unwrap_or(ROS_DEPTH_UNIT_M);
    let mut streams = vec![StreamKind::Color];
    if depth.is_some() {
        streams.push(StreamKind::Depth);
    }
    if !matches!(poses, PoseSource::None) {
        streams.push(StreamKind::Pose);
    }
    let mut settings = vec![("color-topic", color.topic.clone())];
    if let Some(d) = depth {
        settings.push(("depth-topic", d.topic.clone()));
    }
    if let PoseSource::Tree { world, camera, .. } = &poses {
        settings.push(("world-frame", world.clone()));
        settings.push(("camera-frame", camera.clone()));
    }
    if let Some(t) = &options.pose_topic {
        settings.push(("pose-topic", t.clone()));
    }
    let mut header = import_header(
        scan.end.container.importer(),
        file,
        &options.common,
        &settings,
        (
            color_topic.size,
            depth.and_then(|d| scan.images[&d.id].size),
        ),
        depth_unit_m,
        streams,
    );
    header.color_intrinsics = color_k;
    header.depth_intrinsics = depth_k;
    if let Some(r) = &registration {
        // The recording stores the depth registered into the color view.
        header.depth_intrinsics = color_k;
        let t = r.depth_to_color.translation;
        header.provenance.settings.insert(
            "registered".into(),
            format!(
                "depth {}x{} to color, depth camera at ({:.4}, {:.4}, {:.4}) m in the color \
                 camera, turned {:.3} degrees",
                depth_k.width,
                depth_k.height,
                t.x,
                t.y,
                t.z,
                r.depth_to_color
                    .rotation
                    .angle_between(glam::DQuat::IDENTITY)
                    .to_degrees()
            ),
        );
    }
    if options.intrinsics.is_none() {
        header
            .provenance
            .settings
            .insert("intrinsics".into(), "camera info".into());
    }
    let writer = RecordingWriter::create(out, &header)?;
    let summary = ImportSummary {
        color: 0,
        depth: 0,
        poses: 0,
        skipped_frames: 0,
        warnings,
    };
    let mut written = Written {
        writer,
        summary,
        color_size: None,
        depth_size: None,
        zero_stamps: 0,
        skipped_span: None,
    };
    let mut batch: Vec<Pending> = Vec::new();
    let total = scan.end.messages as usize;
    let convert_batch = |batch: &mut Vec<Pending>| -> Vec<Converted> {
        let results: Vec<_> = batch
            .par_iter()
            .map(|p| convert(p, depth_unit_m, registration.as_ref(), options))
            .collect();
        batch
            .drain(..)
            .zip(results)
            .map(|(p, result)| Converted {
                role: p.role,
                what: format!("message {} on {}", p.index, p.topic),
                log_time_ns: p.log_time_ns,
                result,
            })
            .collect()
    };
    // Batches are converted on this thread (in parallel) while the one before is written
    // on a thread of its own, so that writing, which is most of the time a raw image
    // costs, overlaps the next batch's reading and registration. At most one batch
    // waits between them.
    let (to_writer, batches) = std::sync::mpsc::sync_channel::<Vec<Converted>>(1);
    let (streamed, writing) = std::thread::scope(|scope| {
        let writing = scope.spawn(|| -> Result<Written, ImportError> {
            for batch in batches {
                written.write(file, batch, &poses)?;
            }
            Ok(written)
        });
        let mut seen = 0usize;
        let streamed = container::stream(file, read_options, &mut |event| {
            let Event::Message {
                channel,
                index,
                log_time_ns,
                data,
            } = event
            else {
                return Ok(());
            };
            seen += 1;
            let role = if channel.id == color.id {
                ImageRole::Color
            } else if depth.is_some_and(|d| d.id == channel.id) {
                ImageRole::Depth
            } else {
                return Ok(());
            };
            batch.push(Pending {
                role,
                ty: channel
                    .ty
                    .clone()
                    .ok()
                    .flatten()
                    .expect("image topics have a type"),
                topic: channel.topic.clone(),
                index,
                log_time_ns,
                bytes: data.to_vec(),
            });
            if batch.len() >= BATCH {
                if to_writer.send(convert_batch(&mut batch)).is_err() {
                    // The writer stopped on an error, the one reported.
                    return Err(fail(file, "the writer stopped".into()));
                }
                progress(seen, total);
            }
            Ok(())
        });
        let streamed = streamed.and_then(|end| {
            to_writer
                .send(convert_batch(&mut batch))
                .map_err(|_| fail(file, "the writer stopped".into()))?;
            Ok(end)
        });
        drop(to_writer);
        let writing = writing
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (streamed, writing)
    });
    // A writer's error comes first: the reading stopped because of it.
    let Written {
        writer,
        mut summary,
        zero_stamps,
        skipped_span,
        ..
    } = writing?;
    let end = streamed?;
    progress(total, total);
    if let (0, Some((first, last)), PoseSource::Tree { tree, camera, .. }) =
        (summary.color, skipped_span, &poses)
    {
        let s = |ns: i64| format!("{:.3} s", ns as f64 * 1e-9);
        let span = match tree.span(camera) {
            Some((a, b)) => format!("{} to {}", s(a), s(b)),
            None => "none".into(),
        };
        return Err(fail(
            file,
            format!(
                "none of the {} color images (stamped {} to {}) lies within the camera's \
                 transforms ({span}): are the transforms stamped by another clock (sim time)? \
                 nothing was written",
                summary.skipped_frames,
                s(first),
                s(last)
            ),
        ));
    }
    writer.finish()?;
    if zero_stamps > 0 {
        summary.warnings.push(format!(
            "{zero_stamps} images have a zero header stamp: they are stamped with their log time"
        ));
    }
    if let Some(t) = &scan.end.truncated {
        summary.warnings.push(t.clone());
    }
    if let Some(s) = end.skipped() {
        summary.warnings.push(s);
    }
    if summary.skipped_frames > 0 {
        summary.warnings.push(format!(
            "{} color images lie outside the camera's poses (before the first transform or \
             after the last, which tf2 would not extrapolate either): they are not imported",
            summary.skipped_frames
        ));
    }
    Ok(summary)
}

/// Images converted together (in parallel), then written in file order.
const BATCH: usize = 16;

/// An image converted for the recording, or why it cannot be.
struct Converted {
    role: ImageRole,
    /// "message N on TOPIC", for errors.
    what: String,
    log_time_ns: u64,
    result: Result<(i64, EncodedImage), String>,
}

/// The writing side of an import: the recording, and what it has counted.
struct Written {
    writer: RecordingWriter,
    summary: ImportSummary,
    /// The color images' size (all of a topic's images keep its first's).
    color_size: Option<(u32, u32)>,
    /// The depth images' size.
    depth_size: Option<(u32, u32)>,
    zero_stamps: usize,
    /// The stamps of the color images skipped for want of a pose.
    skipped_span: Option<(i64, i64)>,
}

impl Written {
    /// Writes a batch of converted images in file order, each color image with its pose.
    fn write(
        &mut self,
        file: &Path,
        batch: Vec<Converted>,
        poses: &PoseSource,
    ) -> Result<(), ImportError> {
        for c in batch {
            let what = c.what;
            let (stamp_ns, image) = c.result.map_err(|e| fail(file, format!("{what}: {e}")))?;
            let stamp_ns = if stamp_ns == 0 && c.log_time_ns != 0 {
                self.zero_stamps += 1;
                i64::try_from(c.log_time_ns).map_err(|_| {
                    fail(
                        file,
                        format!("{what}: log time {} ns is out of range", c.log_time_ns),
                    )
                })?
            } else {
                stamp_ns
            };
            match c.role {
                ImageRole::Color => {
                    check_size(file, &what, &image, &mut self.color_size)?;
                    let pose = match poses {
                        PoseSource::None => None,
                        PoseSource::Tree {
                            tree,
                            world,
                            camera,
                        } => {
                            match tree
                                .lookup(world, camera, stamp_ns)
                                .map_err(|e| fail(file, e))?
                            {
                                Some(pose) => Some(pose),
                                None => {
                                    self.summary.skipped_frames += 1;
                                    self.skipped_span = Some(match self.skipped_span {
                                        None => (stamp_ns, stamp_ns),
                                        Some((a, b)) => (a.min(stamp_ns), b.max(stamp_ns)),
                                    });
                                    continue;
                                }
                            }
                        }
                    };
                    self.writer
                        .write(&Record::Color(ColorRecord { stamp_ns, image }))?;
                    self.summary.color += 1;
                    if let Some(pose) = pose {
                        check_pose(file, &what, &pose)?;
                        self.writer
                            .write(&Record::Pose(PoseRecord { stamp_ns, pose }))?;
                        self.summary.poses += 1;
                    }
                }
                ImageRole::Depth => {
                    check_size(file, &what, &image, &mut self.depth_size)?;
                    self.writer
                        .write(&Record::Depth(DepthRecord { stamp_ns, image }))?;
                    self.summary.depth += 1;
                }
            }
        }
        Ok(())
    }
}

struct Pending {
    role: ImageRole,
    ty: (messages::MessageType, messages::Encoding),
    topic: String,
    index: u64,
    log_time_ns: u64,
    bytes: Vec<u8>,
}

fn convert(
    p: &Pending,
    depth_unit_m: f64,
    registration: Option<&Registration>,
    options: &McapOptions,
) -> Result<(i64, EncodedImage), String> {
    let Message::Image(img) = messages::decode(p.ty.0, p.ty.1, &p.bytes)? else {
        unreachable!("image types decode to images");
    };
    let store = options.common.store;
    let image = match (p.role, registration) {
        (ImageRole::Color, _) => pixels::color_image(&img.data, store)?,
        (ImageRole::Depth, None) => pixels::depth_image(&img.data, depth_unit_m, store)?,
        (ImageRole::Depth, Some(r)) => {
            let image = pixels::depth_image(&img.data, depth_unit_m, StoreMode::Raw)?;
            let (w, h) = (r.depth.width, r.depth.height);
            if (image.width, image.height) != (w, h) {
                return Err(format!(
                    "the depth image is {}x{}, the depth intrinsics say {w}x{h}",
                    image.width, image.height
                ));
            }
            let units: Vec<u16> = image
                .bytes
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            let mut registered = Vec::new();
            SCRATCH
                .with_borrow_mut(|scratch| {
                    register_depth(&units, depth_unit_m, r, &mut registered, scratch)
                })
                .map_err(|e| e.to_string())?;
            codec::raw_depth(r.color.width, r.color.height, registered)
        }
    };
    Ok((img.stamp_ns, image))
}

thread_local! {
    /// Each import thread's registration buffers, kept from image to image.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// How the depth camera relates to the color camera, when the depth needs registering:
/// a RealSense recording's extrinsics, else a static transform between the two images'
/// frames, else the same optical centre (the intrinsics alone differ). `None` when the
/// depth is already in the color view.
fn registration(
    file: &Path,
    scan: &Scan,
    depth: &Arc<Channel>,
    color: &Arc<Channel>,
    (depth_k, color_k): (Intrinsics, Intrinsics),
    warnings: &mut Vec<String>,
) -> Result<Option<Registration>, ImportError> {
    let (depth_frame, color_frame) = (
        &scan.images[&depth.id].frame_id,
        &scan.images[&color.id].frame_id,
    );
    let extrinsic = match realsense::depth_to_color(scan, &depth.topic, &color.topic)
        .map_err(|e| fail(file, e))?
    {
        Some(e) => Some(e),
        None if !depth_frame.is_empty()
            && !color_frame.is_empty()
            && depth_frame != color_frame =>
        {
            let linked = scan.tf.static_between(depth_frame, color_frame);
            if linked.is_none() {
                warnings.push(format!(
                    "the depth images ({}) are in frame {depth_frame:?} and the color images in \
                     {color_frame:?}, and no static transform links the two: relume takes \
                     them as one camera centre; if they are not, record depth aligned to \
                     color (e.g. a camera driver's aligned_depth_to_color topic)",
                    depth.topic
                ));
            }
            linked.map(|p| Extrinsic {
                rotation: p.rotation(),
                translation: p.translation(),
            })
        }
        None => None,
    };
    let r = Registration::new(depth_k, color_k, extrinsic.unwrap_or(Extrinsic::IDENTITY));
    Ok((!r.is_identity()).then_some(r))
}

/// A topic's images keep the size of its first: an error naming the file and message
/// otherwise.
fn check_size(
    file: &Path,
    what: &str,
    image: &EncodedImage,
    expected: &mut Option<(u32, u32)>,
) -> Result<(), ImportError> {
    let size = (image.width, image.height);
    match *expected {
        None => *expected = Some(size),
        Some(first) if first != size => {
            return Err(fail(
                file,
                format!(
                    "{what}: the image is {}x{}, but the topic's first is {}x{}",
                    size.0, size.1, first.0, first.1
                ),
            ));
        }
        Some(_) => {}
    }
    Ok(())
}

fn check_pose(file: &Path, what: &str, pose: &Pose) -> Result<(), ImportError> {
    pose.check()
        .map_err(|e| fail(file, format!("{what}: the camera pose {e}")))
}
