//! An independent writer of ROS 2 MCAP files for the import tests: a CDR encoder written
//! from the ROS 2 message definitions (not relume's decoder run backwards) and the
//! `mcap` crate's writer.

use std::collections::BTreeMap;
use std::path::Path;

/// Plain CDR, little-endian: the header `00 01 00 00`, fields aligned to their size
/// counted from the end of the header.
pub struct Cdr(pub Vec<u8>);

impl Cdr {
    pub fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while !(self.0.len() - 4).is_multiple_of(n) {
            self.0.push(0);
        }
    }
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend(s.as_bytes());
        self.0.push(0);
        self
    }
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.0.extend(b);
        self
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for &x in v {
            self.f64(x);
        }
        self
    }
    /// std_msgs/Header: builtin_interfaces/Time stamp (int32 sec, uint32 nanosec),
    /// string frame_id.
    pub fn header(&mut self, stamp_ns: i64, frame_id: &str) -> &mut Self {
        self.i32((stamp_ns / 1_000_000_000) as i32)
            .u32((stamp_ns % 1_000_000_000) as u32)
            .string(frame_id)
    }
}

/// sensor_msgs/Image.
#[allow(clippy::too_many_arguments)]
pub fn image(
    stamp_ns: i64,
    frame: &str,
    w: u32,
    h: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, frame)
        .u32(h)
        .u32(w)
        .string(encoding)
        .u8(0)
        .u32(step)
        .bytes(data);
    c.0
}

/// sensor_msgs/CompressedImage.
pub fn compressed_image(stamp_ns: i64, frame: &str, format: &str, data: &[u8]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, frame).string(format).bytes(data);
    c.0
}

/// sensor_msgs/CameraInfo (plumb_bob, no distortion, no binning, full ROI).
#[allow(clippy::too_many_arguments)]
pub fn camera_info(
    stamp_ns: i64,
    frame: &str,
    w: u32,
    h: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
) -> Vec<u8> {
    camera_info_k(
        stamp_ns,
        frame,
        w,
        h,
        [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
    )
}

/// One sensor_msgs/CameraInfo with the row-major camera matrix `k` as given.
pub fn camera_info_k(stamp_ns: i64, frame: &str, w: u32, h: u32, k: [f64; 9]) -> Vec<u8> {
    let [fx, _, cx, _, fy, cy, _, _, _] = k;
    let mut c = Cdr::new();
    c.header(stamp_ns, frame).u32(h).u32(w).string("plumb_bob");
    c.u32(5).f64s(&[0.0; 5]);
    c.f64s(&k);
    c.f64s(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    c.f64s(&[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]);
    // binning_x, binning_y, roi (x_offset, y_offset, height, width, do_rectify).
    c.u32(0).u32(0).u32(0).u32(0).u32(0).u32(0).u8(0);
    c.0
}

/// One geometry_msgs/TransformStamped.
pub struct Tf<'a> {
    pub stamp_ns: i64,
    pub parent: &'a str,
    pub child: &'a str,
    pub t: [f64; 3],
    /// x, y, z, w
    pub q: [f64; 4],
}

/// tf2_msgs/TFMessage.
pub fn tf_message(transforms: &[Tf]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.u32(transforms.len() as u32);
    for t in transforms {
        c.header(t.stamp_ns, t.parent)
            .string(t.child)
            .f64s(&t.t)
            .f64s(&t.q);
    }
    c.0
}

/// geometry_msgs/PoseStamped (`t.child` is not sent: the message does not name the
/// frame it places).
pub fn pose_stamped(t: &Tf) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t.stamp_ns, t.parent).f64s(&t.t).f64s(&t.q);
    c.0
}

/// nav_msgs/Odometry (zero covariances and twist).
pub fn odometry(t: &Tf) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t.stamp_ns, t.parent)
        .string(t.child)
        .f64s(&t.t)
        .f64s(&t.q);
    c.f64s(&[0.0; 36]).f64s(&[0.0; 6]).f64s(&[0.0; 36]);
    c.0
}

/// An MCAP file of ROS 2 messages; channels are made as topics are first used.
pub struct Bag {
    writer: mcap::Writer<std::io::BufWriter<std::fs::File>>,
    channels: BTreeMap<String, u16>,
    sequence: u32,
}

impl Bag {
    pub fn create(path: &Path, compression: Option<mcap::Compression>) -> Bag {
        Bag::create_chunked(path, compression, None)
    }

    /// A bag whose chunks close once they pass `chunk_size` bytes (`Some(1)`: about one
    /// message each); `None` keeps the writer's default.
    pub fn create_chunked(
        path: &Path,
        compression: Option<mcap::Compression>,
        chunk_size: Option<u64>,
    ) -> Bag {
        let file = std::fs::File::create(path).unwrap();
        let options = mcap::WriteOptions::new();
        let options = match chunk_size {
            Some(size) => options.chunk_size(Some(size)),
            None => options,
        };
        let writer = options
            .compression(compression)
            .profile("ros2")
            .create(std::io::BufWriter::new(file))
            .unwrap();
        Bag {
            writer,
            channels: BTreeMap::new(),
            sequence: 0,
        }
    }

    /// Writes `data` (CDR) on `topic` of ROS 2 type `schema` (`sensor_msgs/msg/Image`),
    /// logged at `log_ns`.
    pub fn put(&mut self, topic: &str, schema: &str, log_ns: u64, data: &[u8]) {
        self.put_encoded(topic, schema, "cdr", log_ns, data)
    }

    pub fn put_encoded(
        &mut self,
        topic: &str,
        schema: &str,
        encoding: &str,
        log_ns: u64,
        data: &[u8],
    ) {
        let id = match self.channels.get(topic) {
            Some(&id) => id,
            None => {
                let schema_id = self
                    .writer
                    .add_schema(schema, "ros2msg", format!("# {schema}\n").as_bytes())
                    .unwrap();
                let id = self
                    .writer
                    .add_channel(schema_id, topic, encoding, &BTreeMap::new())
                    .unwrap();
                self.channels.insert(topic.to_string(), id);
                id
            }
        };
        self.sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: self.sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.writer.write_to_known_channel(&header, data).unwrap();
    }

    pub fn finish(mut self) {
        self.writer.finish().unwrap();
    }
}
