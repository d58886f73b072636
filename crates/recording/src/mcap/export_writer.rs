//! The MCAP file `relume export mcap` writes through ([`Out`]): each topic's channel,
//! and its Foxglove schema in JSON, added as the topic's first message comes; the stamp
//! and byte encodings every Foxglove JSON message uses; and the frame names of the
//! exported poses. The recording's messages (`export`) and the saved products'
//! (`export_products`) are both written here.

use crate::error::ImportError;
use base64::Engine;
use mcap::records::MessageHeader;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

/// The frame the camera poses are given in, and the camera's frame.
pub const WORLD_FRAME: &str = "world";
pub const CAMERA_FRAME: &str = "camera";

pub(super) fn fail(path: &Path, reason: impl Into<String>) -> ImportError {
    ImportError::File {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// A small JSON schema naming the fields, as Foxglove matches schemas by name.
fn schema(title: &str, properties: Value) -> Vec<u8> {
    let s = json!({"title": title, "type": "object", "properties": properties});
    serde_json::to_vec(&s).expect("a JSON value serializes")
}

fn time_schema() -> Value {
    json!({"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}})
}

pub(super) fn time(stamp_ns: i64) -> Value {
    json!({"sec": stamp_ns.div_euclid(1_000_000_000), "nsec": stamp_ns.rem_euclid(1_000_000_000)})
}

pub(super) fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// The channels of an export, created as their first message comes.
pub(super) struct Out<'a> {
    /// The file's writer, for what is not a message (metadata, and the summary
    /// `finish` writes).
    pub(super) writer: mcap::Writer<BufWriter<std::fs::File>>,
    channels: BTreeMap<String, u16>,
    schemas: BTreeMap<&'static str, u16>,
    pub(super) path: &'a Path,
    sequence: u32,
}

impl<'a> Out<'a> {
    /// An export to `writer`, which writes the file `path`; no channels yet.
    pub(super) fn new(writer: mcap::Writer<BufWriter<std::fs::File>>, path: &'a Path) -> Self {
        Out {
            writer,
            channels: BTreeMap::new(),
            schemas: BTreeMap::new(),
            path,
            sequence: 0,
        }
    }

    fn channel(&mut self, topic: &str, schema_name: &'static str) -> Result<u16, ImportError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema_name) {
            Some(&id) => id,
            None => {
                let data = schema_data(schema_name);
                let id = self
                    .writer
                    .add_schema(schema_name, "jsonschema", &data)
                    .map_err(|e| fail(self.path, super::failure::describe(&e)))?;
                self.schemas.insert(schema_name, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| fail(self.path, super::failure::describe(&e)))?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    pub(super) fn write(
        &mut self,
        topic: &str,
        schema: &'static str,
        stamp_ns: i64,
        msg: &Value,
    ) -> Result<(), ImportError> {
        let channel_id = self.channel(topic, schema)?;
        let time = u64::try_from(stamp_ns).map_err(|_| {
            fail(
                self.path,
                format!("stamp {stamp_ns} ns is negative: MCAP log times start at 0"),
            )
        })?;
        let data = serde_json::to_vec(msg).expect("a JSON value serializes");
        self.sequence += 1;
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: time,
            publish_time: time,
        };
        self.writer
            .write_to_known_channel(&header, &data)
            .map_err(|e| fail(self.path, super::failure::describe(&e)))
    }
}

fn schema_data(name: &str) -> Vec<u8> {
    let t = time_schema();
    let vec3 = json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}});
    let quat = json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}});
    let bytes = json!({"type": "string", "contentEncoding": "base64"});
    let s = json!({"type": "string"});
    let int = json!({"type": "integer"});
    let nums = json!({"type": "array", "items": {"type": "number"}});
    match name {
        "foxglove.CompressedImage" => schema(
            name,
            json!({"timestamp": t, "frame_id": s, "data": bytes, "format": s}),
        ),
        "foxglove.RawImage" => schema(
            name,
            json!({"timestamp": t, "frame_id": s, "width": int, "height": int, "encoding": s, "step": int, "data": bytes}),
        ),
        "foxglove.CameraCalibration" => schema(
            name,
            json!({"timestamp": t, "frame_id": s, "width": int, "height": int, "distortion_model": s, "D": nums, "K": nums, "R": nums, "P": nums}),
        ),
        "foxglove.FrameTransform" => schema(
            name,
            json!({"timestamp": t, "parent_frame_id": s, "child_frame_id": s, "translation": vec3, "rotation": quat}),
        ),
        "foxglove.PointCloud" => schema(
            name,
            json!({"timestamp": t, "frame_id": s, "pose": {"type": "object", "properties": {"position": vec3, "orientation": quat}},
                   "point_stride": int, "fields": {"type": "array", "items": {"type": "object", "properties": {"name": s, "offset": int, "type": int}}}, "data": bytes}),
        ),
        _ => unreachable!("the exporter writes the schemas above"),
    }
}
