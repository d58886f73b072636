//! librealsense's recording layout (RealSense Viewer and `rs-record` `.bag` files, Open3D's
//! RealSense recorder), as its `ros_file_format.h` writes it (file version 3 and up):
//!
//! | topic | what |
//! |---|---|
//! | `/device_D/sensor_S/STREAM_I/image/data` | `sensor_msgs/Image` (`mono16` depth, `rgb8` color) |
//! | `/device_D/sensor_S/STREAM_I/info/camera_info` | the stream's `sensor_msgs/CameraInfo` |
//! | `/device_D/sensor_S/STREAM_I/tf/G` | `geometry_msgs/Transform`: the extrinsic from the reference stream of group `G` to this stream |
//! | `/device_D/sensor_S/option/Depth Units/value` | `std_msgs/Float32`: metres per depth unit (`Depth_Units` in librealsense 2.5x) |
//!
//! A stream's extrinsic maps the reference stream's points into its own camera
//! (librealsense's `rs2_extrinsics` from the reference to the stream, `p = R p_ref + t`;
//! checked against bags that librealsense 2.55's recorder wrote from a software device with
//! a known depth-to-color extrinsic), so the depth camera's points reach the color camera
//! as `ref_to_color ∘ ref_to_depth⁻¹`.

use super::read::Channel;
use super::scan::Scan;
use crate::register::Extrinsic;
use glam::{DQuat, DVec3};
use std::sync::Arc;

/// The stream a RealSense image topic belongs to (`/device_0/sensor_1/Color_0` of
/// `/device_0/sensor_1/Color_0/image/data`), or `None` for another layout.
pub fn stream_of(image_topic: &str) -> Option<&str> {
    let stream = image_topic.strip_suffix("/image/data")?;
    let mut parts = stream.trim_start_matches('/').split('/');
    let ok = parts.next().is_some_and(|p| p.starts_with("device_"))
        && parts.next().is_some_and(|p| p.starts_with("sensor_"))
        && parts.next().is_some_and(|p| p.contains('_'))
        && parts.next().is_none();
    ok.then_some(stream)
}

/// The camera info topic of a RealSense image topic.
pub fn info_topic(image_topic: &str) -> Option<String> {
    stream_of(image_topic).map(|s| format!("{s}/info/camera_info"))
}

fn channel<'a>(scan: &'a Scan, topic: &str) -> Option<&'a Arc<Channel>> {
    scan.channels.values().find(|c| c.topic == topic)
}

/// Metres per depth unit of a RealSense depth topic: its sensor's "Depth Units" option.
/// `Err` for a value no depth camera has.
pub fn depth_unit_m(scan: &Scan, depth_topic: &str) -> Result<Option<f64>, String> {
    let Some(stream) = stream_of(depth_topic) else {
        return Ok(None);
    };
    let sensor = stream.rsplit_once('/').map_or("", |(s, _)| s);
    let found = ["Depth Units", "Depth_Units"].iter().find_map(|name| {
        let topic = format!("{sensor}/option/{name}/value");
        let value = channel(scan, &topic).and_then(|c| scan.values.get(&c.id))?;
        Some((topic, value))
    });
    let Some((topic, value)) = found else {
        return Ok(None);
    };
    // The f32's shortest decimal (0.001, not 0.0010000000474974513).
    let unit: f64 = value.to_string().parse().unwrap_or(f64::NAN);
    if !(unit.is_finite() && (1e-6..=0.1).contains(&unit)) {
        return Err(format!(
            "{topic} gives {value} m per depth unit, outside a depth camera's 1 µm to 10 cm"
        ));
    }
    Ok(Some(unit))
}

/// The transform from a RealSense depth stream's camera to its color stream's, from the
/// two streams' extrinsics to one reference stream; `None` when either is missing.
pub fn depth_to_color(
    scan: &Scan,
    depth_topic: &str,
    color_topic: &str,
) -> Result<Option<Extrinsic>, String> {
    let (Some(depth), Some(color)) = (stream_of(depth_topic), stream_of(color_topic)) else {
        return Ok(None);
    };
    // Extrinsic groups each stream has a transform in, by group number.
    let groups = |stream: &str| -> Vec<(String, Extrinsic, String)> {
        let prefix = format!("{stream}/tf/");
        scan.channels
            .values()
            .filter_map(|c| {
                let group = c.topic.strip_prefix(&prefix)?;
                let (t, q) = scan.extrinsics.get(&c.id)?;
                let extrinsic = Extrinsic {
                    rotation: DQuat::from_xyzw(q[0], q[1], q[2], q[3]),
                    translation: DVec3::from_array(*t),
                };
                Some((group.to_string(), extrinsic, c.topic.clone()))
            })
            .collect()
    };
    let (depth_groups, color_groups) = (groups(depth), groups(color));
    let Some((ref_to_depth, ref_to_color, topics)) = depth_groups.iter().find_map(|(g, d, dt)| {
        color_groups
            .iter()
            .find(|(cg, _, _)| cg == g)
            .map(|(_, c, ct)| (d, c, (dt, ct)))
    }) else {
        return Ok(None);
    };
    for (e, topic) in [(ref_to_depth, topics.0), (ref_to_color, topics.1)] {
        let norm = e.rotation.length();
        let rigid =
            e.translation.is_finite() && e.translation.length() < 10.0 && (norm - 1.0).abs() < 1e-3;
        if !rigid {
            return Err(format!(
                "{topic}: the extrinsic (translation {:?} m, rotation {:?}) is not a rigid \
                 transform between two cameras of one device (a unit quaternion, under 10 m)",
                e.translation.to_array(),
                e.rotation.to_array()
            ));
        }
    }
    let normalized = |e: &Extrinsic| Extrinsic {
        rotation: e.rotation.normalize(),
        translation: e.translation,
    };
    Ok(Some(
        normalized(ref_to_color).after(&normalized(ref_to_depth).inverse()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_recognized_by_the_layouts_topic_names() {
        assert_eq!(
            stream_of("/device_0/sensor_1/Color_0/image/data"),
            Some("/device_0/sensor_1/Color_0")
        );
        assert_eq!(stream_of("/camera/color/image_raw"), None);
        assert_eq!(stream_of("/a/b/image/data"), None);
        assert_eq!(
            info_topic("/device_0/sensor_0/Depth_0/image/data").unwrap(),
            "/device_0/sensor_0/Depth_0/info/camera_info"
        );
    }
}
