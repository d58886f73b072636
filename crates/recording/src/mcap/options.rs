//! What `relume import mcap` is asked for ([`McapOptions`]): read by the topic and
//! frame choices (`choose`) and by the import itself.

use crate::importers::{CameraIntrinsics, ImportOptions};

/// Options of `relume import mcap`. Topics and frames left `None` are detected.
#[derive(Clone, Debug, Default)]
pub struct McapOptions {
    pub common: ImportOptions,
    /// `--intrinsics` as given: overrides the camera infos.
    pub intrinsics: Option<CameraIntrinsics>,
    pub color_topic: Option<String>,
    pub depth_topic: Option<String>,
    /// The camera info of the color images.
    pub info_topic: Option<String>,
    /// A PoseStamped, Odometry or PoseInFrame topic instead of TF.
    pub pose_topic: Option<String>,
    /// The frame poses are given in (default: the root of the camera's TF tree).
    pub world_frame: Option<String>,
    /// The camera's optical frame (default: the color images' `frame_id`).
    pub camera_frame: Option<String>,
    /// `--skip-corrupt`: pass over damaged chunks, saying which, instead of stopping.
    pub skip_corrupt: bool,
}
