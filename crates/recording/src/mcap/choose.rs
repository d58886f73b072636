//! Choosing what `relume import mcap` reads from a [`Scan`]: the color and depth topics,
//! their intrinsics, and where the camera poses come from (the TF tree or a pose topic),
//! each detected when unambiguous and otherwise asked for by its flag.

use super::messages::{self, TransformMsg};
use super::options::McapOptions;
use super::pixels::ImageRole;
use super::read::Channel;
use super::scan::Scan;
use super::tf::{TfTree, frame_name};
use crate::error::ImportError;
use crate::types::Intrinsics;
use std::path::Path;
use std::sync::Arc;

/// Where the camera poses come from.
pub(super) enum PoseSource {
    None,
    /// The camera's pose in `world` along a transform tree.
    Tree {
        tree: TfTree,
        world: String,
        camera: String,
    },
}

pub(super) fn fail(path: &Path, reason: String) -> ImportError {
    ImportError::File {
        path: path.to_path_buf(),
        reason,
    }
}

fn topics_list(channels: &[&Arc<Channel>]) -> String {
    channels
        .iter()
        .map(|c| c.topic.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The image channel of `role`: the one named, or the only one.
pub(super) fn choose_images<'a>(
    path: &Path,
    scan: &'a Scan,
    role: ImageRole,
    named: Option<&str>,
    flag: &str,
) -> Result<Option<&'a Arc<Channel>>, ImportError> {
    let candidates = scan.image_channels(role);
    if let Some(topic) = named {
        let Some(c) = scan.channel(topic) else {
            return Err(fail(
                path,
                format!("{flag} {topic}: no such topic (`--list` shows the topics)"),
            ));
        };
        return match scan.images.get(&c.id).map(|t| &t.role) {
            Some(Ok(r)) if *r == role => Ok(Some(c)),
            Some(Ok(r)) => Err(fail(
                path,
                format!("{flag} {topic}: the topic holds {} images", r.name()),
            )),
            Some(Err(e)) => Err(fail(path, format!("{flag} {topic}: {e}"))),
            None => Err(fail(
                path,
                format!(
                    "{flag} {topic}: the topic holds {}, not images{}",
                    c.schema,
                    match &c.ty {
                        Err(e) => format!(" that relume reads ({e})"),
                        _ => String::new(),
                    }
                ),
            )),
        };
    }
    // Products a replay saved, exported beside the recording (`/relume/<product>`), are
    // never taken by default.
    let sensors: Vec<&Arc<Channel>> = candidates
        .iter()
        .copied()
        .filter(|c| !c.topic.starts_with("/relume/"))
        .collect();
    match (&candidates[..], &sensors[..]) {
        ([], _) => Ok(None),
        ([one], _) | (_, [one]) => Ok(Some(one)),
        _ => Err(fail(
            path,
            format!(
                "{} topics hold {} images ({}): choose one with {flag}",
                candidates.len(),
                role.name(),
                topics_list(&candidates)
            ),
        )),
    }
}

/// The parent namespace of a topic (`/camera/color/image_raw` -> `/camera/color`).
fn namespace(topic: &str) -> &str {
    topic.rsplit_once('/').map_or("", |(ns, _)| ns)
}

/// The intrinsics of an image topic: `--intrinsics`, else its camera info (the named
/// one, else a RealSense stream's own, else one in its namespace, else one in its frame,
/// else the only one), taken
/// for the size it describes. `Ok(None)`: no camera info at all. The camera matrix must
/// be a pinhole's without skew, `[fx 0 cx; 0 fy cy; 0 0 1]`, within the bounds of
/// [`Intrinsics::check`]; a camera info that changes later in the stream is named in
/// `warnings` (the first is used for every frame).
pub(super) fn intrinsics_for(
    path: &Path,
    scan: &Scan,
    images: &Arc<Channel>,
    named: Option<&str>,
    warnings: &mut Vec<String>,
) -> Result<Option<Intrinsics>, ImportError> {
    let topic = &scan.images[&images.id];
    let infos: Vec<(&Arc<Channel>, &messages::CameraInfoMsg)> = scan
        .infos
        .iter()
        .map(|(id, info)| (&scan.channels[id], info))
        .collect();
    let chosen = match named {
        Some(t) => Some(infos.iter().find(|(c, _)| c.topic == t).ok_or_else(|| {
            fail(
                path,
                format!(
                    "--info-topic {t}: no such topic with a camera info (`--list` shows the topics)"
                ),
            )
        })?),
        None => infos
            .iter()
            .find(|(c, _)| Some(&c.topic) == super::realsense::info_topic(&images.topic).as_ref())
            .or_else(|| {
                infos
                    .iter()
                    .find(|(c, _)| namespace(&c.topic) == namespace(&images.topic))
            })
            .or_else(|| {
                infos.iter().find(|(_, i)| {
                    !topic.frame_id.is_empty() && frame_name(&i.frame_id) == topic.frame_id
                })
            })
            .or(if infos.len() == 1 {
                infos.first()
            } else {
                None
            }),
    };
    let Some((channel, info)) = chosen else {
        return Ok(None);
    };
    let k = Intrinsics {
        width: info.width,
        height: info.height,
        fx: info.k[0],
        fy: info.k[4],
        cx: info.k[2],
        cy: info.k[5],
    };
    let m = &info.k;
    // Skew below a millionth of the focal length is rounding in a calibration tool.
    let skewed = m[1].is_nan() || m[1].abs() > 1e-6 * m[0].abs();
    if skewed || [m[3], m[6], m[7]] != [0.0; 3] || m[8] != 1.0 {
        return Err(fail(
            path,
            format!(
                "the camera info on {}: K = {:?} is not a pinhole camera matrix without skew \
                 ([fx 0 cx; 0 fy cy; 0 0 1]); give --intrinsics fx,fy,cx,cy",
                channel.topic, m
            ),
        ));
    }
    if let Some(size) = topic.size
        && size != (info.width, info.height)
    {
        return Err(fail(
            path,
            format!(
                "the camera info on {} describes {}x{} images but {} holds {}x{}: give \
                 --info-topic for the right one, or --intrinsics fx,fy,cx,cy",
                channel.topic, info.width, info.height, images.topic, size.0, size.1
            ),
        ));
    }
    if let Err(e) = k.check() {
        return Err(fail(
            path,
            format!("the camera info on {}: {e}", channel.topic),
        ));
    }
    if let Some((index, changed)) = scan.info_changes.get(&channel.id) {
        warnings.push(format!(
            "the camera info on {} changes at message {index} ({}x{}, K = {:?}, after \
             {}x{}, K = {:?}): every frame is imported with the first; give --intrinsics \
             fx,fy,cx,cy to choose",
            channel.topic,
            changed.width,
            changed.height,
            changed.k,
            info.width,
            info.height,
            info.k
        ));
    }
    Ok(Some(k))
}

/// Where the camera poses come from, or why none are taken (in `warnings`).
pub(super) fn pose_source(
    path: &Path,
    scan: &Scan,
    options: &McapOptions,
    color_frame: &str,
    warnings: &mut Vec<String>,
) -> Result<PoseSource, ImportError> {
    let camera = options
        .camera_frame
        .as_deref()
        .map(frame_name)
        .unwrap_or(color_frame)
        .to_string();
    let on_camera_chain = |child: &str| {
        let child = frame_name(child);
        child == camera || scan.tf.path_to_root(&camera).iter().any(|f| f == child)
    };
    let pose_topic = match &options.pose_topic {
        Some(t) => {
            let c = scan.channel(t).ok_or_else(|| {
                fail(
                    path,
                    format!("--pose-topic {t}: no such topic (`--list` shows the topics)"),
                )
            })?;
            Some((
                t.as_str(),
                scan.poses.get(&c.id).ok_or_else(|| {
                    fail(
                        path,
                        format!(
                            "--pose-topic {t}: the topic holds {}, not PoseStamped, Odometry or PoseInFrame",
                            c.schema
                        ),
                    )
                })?,
            ))
        }
        None if scan.tf.moves(&camera) => None,
        None => {
            // A pose topic is taken by itself only when it says whose poses it holds and
            // that frame is the camera or carries it (an Odometry of the robot base the
            // camera is mounted on): a PoseStamped may be anything (a goal, a marker).
            let linked: Vec<(u16, &Vec<TransformMsg>)> = scan
                .poses
                .iter()
                .filter(|(_, p)| {
                    p.first()
                        .is_some_and(|t| !t.child.is_empty() && on_camera_chain(&t.child))
                })
                .map(|(id, p)| (*id, p))
                .collect();
            match linked[..] {
                [(id, samples)] => Some((scan.channels[&id].topic.as_str(), samples)),
                _ => {
                    let topics: Vec<&str> = scan
                        .poses
                        .keys()
                        .map(|id| scan.channels[id].topic.as_str())
                        .collect();
                    if !topics.is_empty() {
                        warnings.push(format!(
                            "no camera poses are taken from {} by default: give --pose-topic \
                             when a topic holds the camera's poses (or those of a frame that \
                             /tf_static links to it)",
                            topics.join(", ")
                        ));
                    } else if options.camera_frame.is_some() && !scan.tf.has_frame(&camera) {
                        return Err(fail(
                            path,
                            format!(
                                "--camera-frame {camera}: the transform tree has no such frame \
                                 (`--list` shows the tree)"
                            ),
                        ));
                    } else if scan.tf.has_frame(&camera) {
                        warnings.push(format!(
                            "the camera frame {camera:?} is in the transform tree, but nothing \
                             on its chain moves (only static transforms): no poses are written"
                        ));
                    } else if !camera.is_empty() && !scan.tf.describe().is_empty() {
                        warnings.push(format!(
                            "the transform tree does not hold the camera frame {camera:?}: give \
                             --camera-frame to name it"
                        ));
                    }
                    return Ok(PoseSource::None);
                }
            }
        }
    };
    let tree = match pose_topic {
        None => scan.tf.clone(),
        Some((topic, samples)) => {
            // Pose messages become a dynamic edge to their child frame (the camera, for
            // a PoseStamped), linked to the camera by the TF tree where it knows both.
            let mut tree = TfTree::default();
            let edge: Vec<TransformMsg> = samples
                .iter()
                .map(|t| TransformMsg {
                    child: if t.child.is_empty() {
                        camera.clone()
                    } else {
                        t.child.clone()
                    },
                    ..t.clone()
                })
                .collect();
            tree.add(&edge, false).map_err(|e| fail(path, e))?;
            tree.finish();
            tree.absorb(&scan.tf);
            if !tree.moves(&camera) {
                let child = &edge[0].child;
                return Err(fail(
                    path,
                    format!(
                        "the poses on {topic} are of frame {child:?}, which no transform links \
                         to the camera frame {camera:?}: give --camera-frame {child} if they \
                         are the camera's own"
                    ),
                ));
            }
            tree
        }
    };
    if let Some(cycle) = tree.loop_above(&camera) {
        return Err(fail(
            path,
            format!(
                "the transform tree has a loop above the camera frame: {}; tf2 refuses such \
                 a tree, and no world frame can be chosen",
                cycle.join(" -> ")
            ),
        ));
    }
    let world = match &options.world_frame {
        Some(w) => frame_name(w).to_string(),
        None => tree
            .path_to_root(&camera)
            .last()
            .cloned()
            .unwrap_or_default(),
    };
    if let Err(e) = tree.lookup(&world, &camera, 0) {
        return Err(fail(path, e));
    }
    for (child, first, other) in &tree.conflicts {
        warnings.push(format!(
            "the transforms give the frame {child:?} two parents, {first:?} and {other:?}: \
             the first is kept, as tf2 would not accept the tree"
        ));
    }
    for child in &tree.mixed {
        warnings.push(format!(
            "the transform to frame {child:?} is sent both on /tf_static and on /tf: the \
             static one holds at all times and the moving samples are not used (as in tf2)"
        ));
    }
    for (child, n) in &tree.repeated_stamps {
        warnings.push(format!(
            "{n} transform(s) to frame {child:?} repeat a stamp with another pose: the last \
             sent is used (as in tf2)"
        ));
    }
    Ok(PoseSource::Tree {
        tree,
        world,
        camera,
    })
}
