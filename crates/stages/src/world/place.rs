//! Anchors resolved against a recording: each anchored object of a pipeline gets its
//! [`AnchorFrame`], and the user a line saying where it went.

use super::config::DeclaredObject;
use super::floor::{Floor, fit_floor};
use super::surface::surface_at;
use super::views::CameraView;
use glam::{Vec2, Vec3};
use relume_graph::config::ConfigError;
use relume_recording::Replay;
use relume_scene::objects::anchor::{Anchor, AnchorFrame, FLOOR_FRAMES};
use relume_scene::objects::{ObjectError, VirtualScene};
use std::collections::BTreeMap;
use std::ops::Range;

/// A pixel sees the floor when its depth reaches the floor's plane within this share
/// of the depth plus [`SEEN_TOLERANCE_M`].
const SEEN_TOLERANCE: f32 = 0.1;
/// See [`SEEN_TOLERANCE`] (metres).
const SEEN_TOLERANCE_M: f32 = 0.1;

/// A surface pixel whose neighbourhood has less than this share of its depth samples on
/// the fitted surface is said to lie at a depth edge.
const EDGE_SHARE: f32 = 0.7;

/// Where an anchored object was placed.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    pub object: String,
    /// The anchor frame's origin in world coordinates, metres.
    pub origin: Vec3,
    /// The surface normal there (the frame's y axis).
    pub up: Vec3,
    /// How the surface was found, in words.
    pub how: String,
    /// The object's world bounds once built (min, max), so that one placed off-screen
    /// or under the floor by its translation shows; `None` until then.
    pub bounds: Option<(Vec3, Vec3)>,
}

impl std::fmt::Display for Placement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (o, n) = (self.origin, self.up);
        write!(
            f,
            "object `{}`: anchored {}: its frame's origin is [{:.3}, {:.3}, {:.3}] m, its up [{:.3}, {:.3}, {:.3}]",
            self.object, self.how, o.x, o.y, o.z, n.x, n.y, n.z
        )?;
        if let Some((a, b)) = self.bounds {
            write!(
                f,
                "; the object spans [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m",
                a.x, a.y, a.z, b.x, b.y, b.z
            )?;
        }
        Ok(())
    }
}

/// Places every anchored object of `declared` on `replay`'s surfaces (see
/// [`Anchor`]), setting its `anchor_frame`. Errors stand at the key that asked
/// for what the recording cannot give: a frame past its end, a pixel outside its
/// images, a frame without depth or pose, no floor, no surface at the pixel.
///
/// `tracked_from`: on a recording without poses whose pipeline tracks them, the frame
/// the tracker starts from at the identity, whose camera is the world: the one frame
/// anchors can be found on (the floor then fitted to it alone).
pub fn place_objects(
    declared: &mut [DeclaredObject],
    replay: &Replay,
    tracked_from: Option<usize>,
) -> Result<Vec<Placement>, ConfigError> {
    let path = replay.recording.path().display().to_string();
    let color = replay.recording.header().color_intrinsics;
    let mut scene = SceneViews {
        replay,
        identity_at: tracked_from,
        views: BTreeMap::new(),
        floors: BTreeMap::new(),
    };
    let mut placements = Vec::new();
    for object in declared.iter_mut() {
        let Some(sites) = &object.sites else {
            continue;
        };
        let name = object.spec.name.clone();
        let (frame, at_pixel) = match object.spec.anchor {
            Anchor::World => continue,
            Anchor::Floor { at_pixel, frame } => (frame, at_pixel),
            Anchor::Surface { at_pixel, frame } => (frame, Some(at_pixel)),
        };
        let frame_site = sites.frame.as_ref().unwrap_or(&sites.anchor);
        match tracked_from {
            _ if replay.stats.frames_with_pose > 0 => {}
            Some(start) if start == frame => {}
            Some(start) => {
                return Err(frame_site.retold(
                    format!(
                        "object `{name}`: `{path}` has no camera poses, and the tracked world is the camera of frame {start}, where the run starts: anchors are found on that frame alone, not on frame {frame}"
                    ),
                    Some(format!("anchor it on frame {start} (`frame = {start}`), or start the run at frame {frame}")),
                ));
            }
            None => {
                return Err(sites.anchor.retold(
                    format!(
                        "object `{name}`: `{path}` has no camera poses, so no surface it shows has a place in the world"
                    ),
                    Some("anchored objects need poses: a recording with them (a TUM folder's groundtruth.txt, a Redwood trajectory.log), or a pipeline that tracks them (pipelines/*-tracked.toml)".into()),
                ));
            }
        }
        let pixel_site = sites.at_pixel.as_ref().unwrap_or(&sites.anchor);
        if frame >= replay.len() {
            return Err(frame_site.retold(
                format!(
                    "object `{name}`: frame {frame} is past the end of `{path}`, which has {} frames",
                    replay.len()
                ),
                Some("`frame` counts from 0".into()),
            ));
        }
        let (w, h) = (color.width, color.height);
        if let Some(p) = at_pixel
            && (p.x > (w - 1) as f32 || p.y > (h - 1) as f32)
        {
            return Err(pixel_site.retold(
                format!(
                    "object `{name}`: pixel ({}, {}) lies outside `{path}`'s {w}x{h} color images",
                    p.x, p.y
                ),
                Some(format!(
                    "at_pixel = [u, v] runs from the top-left pixel [0, 0] to [{}, {}]",
                    w - 1,
                    h - 1
                )),
            ));
        }
        let view = scene.view(frame).map_err(|reason| {
            frame_site.retold(
                format!("object `{name}`: cannot place it on frame {frame} of `{path}`: {reason}"),
                Some("choose a `frame` with depth and a pose".into()),
            )
        })?;
        let pixel = at_pixel.unwrap_or(Vec2::new((w - 1) as f32, (h - 1) as f32) * 0.5);
        let (u, v) = (pixel.x, pixel.y);
        let (anchor_frame, how) = match object.spec.anchor {
            Anchor::Floor { .. } => {
                let (floor, frames) = scene.floor(frame).map_err(|(frames, reason)| {
                    sites.anchor.retold(
                        format!(
                            "object `{name}`: no floor found in frames {}..{} of `{path}`: {reason}",
                            frames.start, frames.end
                        ),
                        Some("stand it on a surface you can see with at_pixel = [u, v] (and frame = n), or place it in world coordinates without `anchor`".into()),
                    )
                })?;
                let view = scene.view(frame).expect("read above");
                let ray = view.color_ray(pixel);
                let hint = Some(match at_pixel {
                    Some(_) => "give at_pixel = [u, v] a pixel where the floor is seen".into(),
                    None => "add at_pixel = [u, v], a pixel where the floor is seen (without it, the object goes where the image's centre sees the floor)".into(),
                });
                let Some(origin) = floor.ray_hit(view.position, view.rotation * ray) else {
                    return Err(pixel_site.retold(
                        format!(
                            "object `{name}`: the view ray through pixel ({u}, {v}) of frame {frame} does not meet the floor in front of the camera"
                        ),
                        hint.clone(),
                    ));
                };
                // The floor's plane runs on behind walls and furniture, and a plane
                // found in a few frames may be a table's: the pixel must see the floor
                // itself, at the plane's depth.
                let floor_depth = (view.rotation.transpose() * (origin - view.position)).z;
                let Some(seen) = view.depth_near(ray) else {
                    return Err(pixel_site.retold(
                        format!(
                            "object `{name}`: pixel ({u}, {v}) of frame {frame} has no depth, so nothing shows that it sees the floor (its plane lies {floor_depth:.2} m away along the pixel's ray)"
                        ),
                        hint,
                    ));
                };
                if (floor_depth - seen).abs() > seen * SEEN_TOLERANCE + SEEN_TOLERANCE_M {
                    return Err(pixel_site.retold(
                        format!(
                            "object `{name}`: pixel ({u}, {v}) of frame {frame} does not see the floor: it sees a surface {seen:.2} m away, and the floor's plane lies {floor_depth:.2} m away along its ray"
                        ),
                        hint,
                    ));
                }
                let placed = AnchorFrame::on_surface(
                    origin,
                    floor.normal,
                    view.rotation.x_axis,
                    view.rotation.z_axis,
                );
                let how = format!(
                    "on the floor (a plane through {} depth samples of frames {}..{}, its normal {:.1} degrees from the cameras' mean image-up), where pixel ({u}, {v}) of frame {frame} sees it",
                    floor.samples, frames.start, frames.end, floor.tilt_from_cameras_deg
                );
                (placed, how)
            }
            _ => {
                let fit = surface_at(&view.depth, &view.depth_camera, view.color_ray(pixel))
                    .map_err(|e| {
                        pixel_site.retold(
                            format!(
                                "object `{name}`: no surface to stand it on at pixel ({u}, {v}) of frame {frame}: {e}"
                            ),
                            Some("pick a pixel where the depth camera sees a surface, away from its edges".into()),
                        )
                    })?;
                let placed = AnchorFrame::on_surface(
                    view.to_world(fit.point),
                    view.rotation * fit.normal,
                    view.rotation.x_axis,
                    view.rotation.z_axis,
                );
                let mut how = format!(
                    "on the surface seen at pixel ({u}, {v}) of frame {frame} (a plane through {} depth samples)",
                    fit.samples
                );
                if fit.on_surface_share < EDGE_SHARE {
                    how.push_str(&format!(
                        " at a depth edge: only {:.0} % of the depth samples around the pixel lie on that surface, so check that it is the one meant",
                        100.0 * fit.on_surface_share
                    ));
                }
                (placed, how)
            }
        };
        object.spec.anchor_frame = Some(anchor_frame);
        placements.push(Placement {
            object: name,
            origin: anchor_frame.origin,
            up: anchor_frame.axes.y_axis,
            how,
            bounds: None,
        });
    }
    Ok(placements)
}

/// The floor of some frames and those frames, or those frames and why there is none.
type FloorFound = Result<(Floor, Range<usize>), (Range<usize>, String)>;

/// Frames and floors read once for all the objects that use them.
struct SceneViews<'a> {
    replay: &'a Replay,
    /// The frame whose missing pose is the identity (the tracked world's first camera).
    identity_at: Option<usize>,
    views: BTreeMap<usize, Result<CameraView, String>>,
    floors: BTreeMap<usize, FloorFound>,
}

impl SceneViews<'_> {
    fn view(&mut self, n: usize) -> Result<&CameraView, String> {
        let (replay, identity) = (self.replay, self.identity_at == Some(n));
        self.views
            .entry(n)
            .or_insert_with(|| CameraView::read(replay, n, identity))
            .as_ref()
            .map_err(Clone::clone)
    }

    /// The floor of frames `first .. first + FLOOR_FRAMES` (those of them with depth and
    /// a pose; frame `first` alone in a tracked world), and those frames.
    fn floor(&mut self, first: usize) -> FloorFound {
        if let Some(known) = self.floors.get(&first) {
            return known.clone();
        }
        // A tracked world knows one camera before the run: its first.
        let count = match self.identity_at {
            Some(_) => 1,
            None => FLOOR_FRAMES,
        };
        let frames = first..(first + count).min(self.replay.len());
        let (mut points, mut cameras, mut up) = (Vec::new(), Vec::new(), Vec3::ZERO);
        for n in frames.clone() {
            if let Ok(view) = self.view(n) {
                points.extend(view.surface_points());
                cameras.push(view.position);
                up += view.up();
            }
        }
        let floor = if cameras.is_empty() {
            Err((
                frames.clone(),
                "none of them has both depth and a pose".to_string(),
            ))
        } else {
            fit_floor(&points, &cameras, up)
                .map(|floor| (floor, frames.clone()))
                .map_err(|e| (frames.clone(), e.to_string()))
        };
        self.floors.insert(first, floor.clone());
        floor
    }
}

/// The scene of every object of `declared` (anchored ones as placed), declared in the
/// config `file`. A placement that moves a vertex out of bounds (a far anchor with a
/// large translation) is an error at the object's anchor.
pub fn scene_of(declared: &[DeclaredObject], file: &str) -> Result<VirtualScene, ConfigError> {
    let specs: Vec<_> = declared.iter().map(|d| d.spec.clone()).collect();
    VirtualScene::from_specs(&specs).map_err(|e| {
        let object = match &e {
            ObjectError::InvalidSpec { object, .. } => Some(object),
            _ => None,
        };
        let sites = declared
            .iter()
            .find(|d| Some(&d.spec.name) == object)
            .and_then(|d| d.sites.as_ref());
        match sites {
            Some(sites) => sites.anchor.retold(e.to_string(), None),
            None => ConfigError::whole_file(file, e.to_string()),
        }
    })
}
