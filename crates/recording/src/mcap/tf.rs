//! A transform tree built from TF messages (`/tf` and `/tf_static`), or from a pose
//! topic, and the camera's pose in a world frame looked up along it, as tf2 does: each
//! frame has one parent; a static edge holds at all times, a dynamic edge is
//! interpolated (lerp and slerp) between its two samples around the stamp and is
//! undefined outside its samples (tf2's extrapolation error: the frame gets no pose
//! rather than an invented one).

use super::messages::TransformMsg;
use crate::types::Pose;
use glam::{DQuat, DVec3};
use std::collections::BTreeMap;

/// The samples of one edge (parent to child).
#[derive(Clone, Debug, Default)]
struct Edge {
    parent: String,
    /// Static: one sample, valid at all times.
    is_static: bool,
    /// (stamp, pose of the child in the parent), sorted by stamp after [`TfTree::finish`].
    samples: Vec<(i64, Pose)>,
}

/// Frames and their edges, keyed by child frame.
#[derive(Clone, Debug, Default)]
pub struct TfTree {
    edges: BTreeMap<String, Edge>,
    /// Children whose messages named more than one parent: (child, first, other).
    pub conflicts: Vec<(String, String, String)>,
    /// Children sent both on `/tf_static` and on `/tf`: the static transform replaces
    /// the trajectory (as in tf2), which is said.
    pub mixed: Vec<String>,
    /// Per child, how many of its dynamic samples repeated a stamp with another pose
    /// (the last sent is kept, as in tf2), counted by [`TfTree::finish`].
    pub repeated_stamps: BTreeMap<String, usize>,
}

/// ROS 1 habits: frame names with a leading slash name the same frame.
pub fn frame_name(name: &str) -> &str {
    name.strip_prefix('/').unwrap_or(name)
}

/// A transform message's pose, its quaternion normalized only when it is not unit
/// already (so that poses relume wrote come back bit for bit).
pub fn pose_of(t: &TransformMsg) -> Result<Pose, String> {
    let [x, y, z, w] = t.rotation;
    let q = DQuat::from_xyzw(x, y, z, w);
    let len = q.length();
    if !len.is_finite() || len < 1e-6 || t.translation.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "the transform from {:?} to {:?} at {} ns is not a rigid transform \
             (translation {:?}, quaternion {:?})",
            t.parent, t.child, t.stamp_ns, t.translation, t.rotation
        ));
    }
    let rotation = if (len - 1.0).abs() > 1e-12 {
        q / len
    } else {
        q
    };
    Ok(Pose {
        translation: t.translation,
        rotation: rotation.to_array(),
    })
}

/// `a * b`: the pose of b's child in a's parent.
fn compose(a: &Pose, b: &Pose) -> Pose {
    let (ra, rb) = (a.rotation(), b.rotation());
    Pose::from_parts(a.translation() + ra * DVec3::from(b.translation), ra * rb)
}

impl TfTree {
    /// Adds transforms of a `/tf_static` (`is_static`) or `/tf` message.
    pub fn add(&mut self, transforms: &[TransformMsg], is_static: bool) -> Result<(), String> {
        for t in transforms {
            let pose = pose_of(t)?;
            let (parent, child) = (frame_name(&t.parent), frame_name(&t.child));
            let edge = self.edges.entry(child.to_string()).or_insert_with(|| Edge {
                parent: parent.to_string(),
                is_static,
                samples: Vec::new(),
            });
            if edge.parent != parent {
                if !self.conflicts.iter().any(|c| c.0 == child) {
                    self.conflicts
                        .push((child.into(), edge.parent.clone(), parent.into()));
                }
                continue;
            }
            let mixes = is_static != edge.is_static && !edge.samples.is_empty();
            if mixes && !self.mixed.iter().any(|c| c == child) {
                self.mixed.push(child.into());
            }
            if is_static {
                // The latest static transform wins, as in tf2.
                edge.is_static = true;
                edge.samples = vec![(t.stamp_ns, pose)];
            } else if !edge.is_static {
                edge.samples.push((t.stamp_ns, pose));
            }
        }
        Ok(())
    }

    /// Sorts each edge's samples by stamp (stable: of equal stamps the last sent wins,
    /// and a repeat with another pose is counted in `repeated_stamps`).
    pub fn finish(&mut self) {
        for (child, edge) in self.edges.iter_mut() {
            edge.samples.sort_by_key(|s| s.0);
            let mut kept: Vec<(i64, Pose)> = Vec::with_capacity(edge.samples.len());
            let mut repeated = 0;
            for s in edge.samples.drain(..) {
                match kept.last_mut() {
                    Some(last) if last.0 == s.0 => {
                        repeated += usize::from(last.1 != s.1);
                        *last = s;
                    }
                    _ => kept.push(s),
                }
            }
            edge.samples = kept;
            if repeated > 0 {
                *self.repeated_stamps.entry(child.clone()).or_default() += repeated;
            }
        }
    }

    /// The frames of a loop on the way from `frame` to its root (`[a, b, a]`), if the
    /// tree has one there: tf2 refuses such a tree, and no world frame can be chosen.
    pub fn loop_above(&self, frame: &str) -> Option<Vec<String>> {
        let path = self.path_to_root(frame);
        let last = path.last()?;
        let parent = &self.edges.get(last)?.parent;
        let start = path.iter().position(|f| f == parent)?;
        let mut cycle = path[start..].to_vec();
        cycle.push(parent.clone());
        Some(cycle)
    }

    /// Adds the edges of `other` whose child this tree has no edge for.
    pub fn absorb(&mut self, other: &TfTree) {
        for (child, edge) in &other.edges {
            self.edges
                .entry(child.clone())
                .or_insert_with(|| edge.clone());
        }
    }

    /// Whether the tree knows `frame` (as a child or a parent).
    pub fn has_frame(&self, frame: &str) -> bool {
        self.edges.contains_key(frame) || self.edges.values().any(|e| e.parent == frame)
    }

    /// The frames from `frame` up to its root: `[frame, parent, ..., root]`. A loop in
    /// the tree (a malformed file) ends the walk where it repeats.
    pub fn path_to_root(&self, frame: &str) -> Vec<String> {
        let mut path = vec![frame.to_string()];
        let mut at = frame;
        while let Some(edge) = self.edges.get(at) {
            if path.contains(&edge.parent) {
                break;
            }
            path.push(edge.parent.clone());
            at = &edge.parent;
        }
        path
    }

    /// Whether an edge on the way from `frame` to its root moves (is not static): only
    /// then does the tree give a camera trajectory.
    pub fn moves(&self, frame: &str) -> bool {
        let path = self.path_to_root(frame);
        path.iter()
            .any(|f| self.edges.get(f).is_some_and(|e| !e.is_static))
    }

    /// The time span over which every moving edge from `frame` to its root has
    /// samples (where a lookup can succeed); `None` when nothing moves.
    pub fn span(&self, frame: &str) -> Option<(i64, i64)> {
        let mut span: Option<(i64, i64)> = None;
        for f in self.path_to_root(frame) {
            let Some(e) = self.edges.get(&f).filter(|e| !e.is_static) else {
                continue;
            };
            let (first, last) = (e.samples.first()?.0, e.samples.last()?.0);
            span = Some(match span {
                None => (first, last),
                Some((a, b)) => (a.max(first), b.min(last)),
            });
        }
        span
    }

    /// Edges for a listing: (child, parent, static, samples, first and last stamps).
    pub fn describe(&self) -> Vec<(String, String, bool, usize, i64, i64)> {
        self.edges
            .iter()
            .map(|(child, e)| {
                let first = e.samples.first().map_or(0, |s| s.0);
                let last = e.samples.last().map_or(0, |s| s.0);
                let n = e.samples.len();
                (child.clone(), e.parent.clone(), e.is_static, n, first, last)
            })
            .collect()
    }

    /// The pose of `frame` in `target` when the two hang from a common frame through
    /// static transforms only (a camera's depth and color optical frames under its
    /// mount); `None` otherwise.
    pub fn static_between(&self, frame: &str, target: &str) -> Option<Pose> {
        let (up, target_up) = (self.path_to_root(frame), self.path_to_root(target));
        let common = up.iter().find(|f| target_up.contains(f))?;
        let all_static = |path: &[String]| {
            path.iter()
                .take_while(|f| *f != common)
                .all(|f| self.edges.get(f).is_some_and(|e| e.is_static))
        };
        if !all_static(&up) || !all_static(&target_up) {
            return None;
        }
        let in_common = self.lookup(common, frame, 0).ok()??;
        let target_in_common = self.lookup(common, target, 0).ok()??;
        let inverse = target_in_common.rotation().inverse();
        Some(Pose::from_parts(
            inverse * (in_common.translation() - target_in_common.translation()),
            inverse * in_common.rotation(),
        ))
    }

    /// The pose of `frame` in `world` at `t`, or `None` when a dynamic edge on the path
    /// has no samples around `t`. `Err` when `world` is not above `frame`.
    pub fn lookup(&self, world: &str, frame: &str, t: i64) -> Result<Option<Pose>, String> {
        let path = self.path_to_root(frame);
        let Some(depth) = path.iter().position(|f| f == world) else {
            return Err(format!(
                "the frame {world:?} is not above {frame:?} in the transform tree \
                 (its chain is {})",
                path.join(" -> ")
            ));
        };
        let mut pose: Option<Pose> = None;
        // From the world down: world_T_a * a_T_b * ... * x_T_frame.
        for child in path[..depth].iter().rev() {
            let edge = &self.edges[child];
            let Some(step) = sample_at(edge, t) else {
                return Ok(None);
            };
            pose = Some(match pose {
                None => step,
                Some(p) => compose(&p, &step),
            });
        }
        Ok(Some(pose.unwrap_or(Pose::IDENTITY)))
    }
}

/// The edge's pose at `t`: its sample when a stamp matches exactly (bit for bit),
/// interpolated between the samples around `t`, `None` outside them.
fn sample_at(edge: &Edge, t: i64) -> Option<Pose> {
    if edge.is_static {
        return edge.samples.first().map(|s| s.1);
    }
    let s = &edge.samples;
    let at = s.partition_point(|&(stamp, _)| stamp < t);
    match (at.checked_sub(1).and_then(|i| s.get(i)), s.get(at)) {
        (_, Some(&(stamp, pose))) if stamp == t => Some(pose),
        (Some(&(t0, p0)), Some(&(t1, p1))) => {
            // In i128: stamps of any i64 value, far apart, do not overflow.
            let f = (t as i128 - t0 as i128) as f64 / (t1 as i128 - t0 as i128) as f64;
            Some(Pose::interpolate(&p0, &p1, f))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(stamp_ns: i64, parent: &str, child: &str, t: [f64; 3], q: DQuat) -> TransformMsg {
        TransformMsg {
            stamp_ns,
            parent: parent.into(),
            child: child.into(),
            translation: t,
            rotation: q.to_array(),
        }
    }

    #[test]
    fn a_chain_composes_static_and_interpolated_dynamic_edges() {
        let mut tree = TfTree::default();
        let quarter = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        tree.add(
            &[tf(
                0,
                "base",
                "/camera_optical",
                [0.0, 0.0, 1.0],
                DQuat::IDENTITY,
            )],
            true,
        )
        .unwrap();
        tree.add(&[tf(100, "odom", "base", [0.0; 3], quarter)], false)
            .unwrap();
        tree.add(&[tf(300, "odom", "base", [2.0, 0.0, 0.0], quarter)], false)
            .unwrap();
        tree.finish();
        assert_eq!(
            tree.path_to_root("camera_optical"),
            ["camera_optical", "base", "odom"]
        );
        // Halfway: the base at x = 1, turned a quarter; the camera 1 m above it.
        let p = tree.lookup("odom", "camera_optical", 200).unwrap().unwrap();
        let expect = DVec3::new(1.0, 0.0, 1.0);
        assert!((p.translation() - expect).length() < 1e-12, "{p:?}");
        assert!(p.rotation().angle_between(quarter) < 1e-12);
        // Outside the dynamic samples: no pose, as tf2 refuses to extrapolate.
        assert_eq!(tree.lookup("odom", "camera_optical", 99).unwrap(), None);
        assert_eq!(tree.lookup("odom", "camera_optical", 301).unwrap(), None);
        // A world that is not above the camera is an error naming the chain.
        let e = tree.lookup("map", "camera_optical", 200).unwrap_err();
        assert!(e.contains("camera_optical -> base -> odom"), "{e}");
        // Up to an intermediate frame.
        let p = tree.lookup("base", "camera_optical", 5).unwrap().unwrap();
        assert_eq!(p.translation, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn an_exact_stamp_returns_the_sample_bit_for_bit() {
        let mut tree = TfTree::default();
        let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        let t = [0.1, 0.2, 0.30000000000000004];
        tree.add(&[tf(10, "world", "cam", t, q)], false).unwrap();
        tree.add(&[tf(20, "world", "cam", [0.0; 3], q)], false)
            .unwrap();
        tree.finish();
        let p = tree.lookup("world", "cam", 10).unwrap().unwrap();
        assert_eq!(p.translation, t);
        assert_eq!(p.rotation, q.to_array());
    }

    #[test]
    fn loops_mixed_static_and_dynamic_edges_and_repeated_stamps_are_found() {
        let mut tree = TfTree::default();
        let id = DQuat::IDENTITY;
        tree.add(&[tf(0, "odom", "base", [0.0; 3], id)], false)
            .unwrap();
        tree.add(&[tf(0, "base", "cam", [0.0; 3], id)], true)
            .unwrap();
        // A second sample at stamp 0 with another pose, and one repeating the first.
        tree.add(&[tf(0, "odom", "base", [1.0; 3], id)], false)
            .unwrap();
        tree.add(&[tf(0, "odom", "base", [1.0; 3], id)], false)
            .unwrap();
        // The static edge base -> cam sent again on /tf: mixed, and said.
        tree.add(&[tf(5, "base", "cam", [0.0; 3], id)], false)
            .unwrap();
        tree.finish();
        assert_eq!(tree.mixed, ["cam"]);
        assert_eq!(
            tree.repeated_stamps,
            BTreeMap::from([("base".to_string(), 1)])
        );
        assert_eq!(tree.loop_above("cam"), None);
        // odom -> base -> cam, and now odom's parent is cam: a loop.
        tree.add(&[tf(0, "cam", "odom", [0.0; 3], id)], true)
            .unwrap();
        assert_eq!(
            tree.loop_above("cam").unwrap(),
            ["cam", "base", "odom", "cam"]
        );
    }

    #[test]
    fn a_second_parent_is_reported_and_ignored() {
        let mut tree = TfTree::default();
        tree.add(&[tf(0, "a", "cam", [0.0; 3], DQuat::IDENTITY)], true)
            .unwrap();
        tree.add(&[tf(0, "b", "cam", [1.0; 3], DQuat::IDENTITY)], true)
            .unwrap();
        assert_eq!(tree.conflicts, [("cam".into(), "a".into(), "b".into())]);
        let bad = tf(0, "a", "x", [f64::NAN, 0.0, 0.0], DQuat::IDENTITY);
        assert!(tree.add(&[bad], false).is_err());
    }
}
