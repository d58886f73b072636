//! A minimal ROS 1 bag writer for the import benchmark: uncompressed chunks of one frame
//! each, the connections in the first chunk, no index section (relume reads in file
//! order). tests/rosbag.rs checks the reader against an independent writer (Python's
//! rosbags); this one only makes a large input quickly.

use std::io::Write;

fn field(name: &str, value: &[u8]) -> Vec<u8> {
    let mut out = ((name.len() + 1 + value.len()) as u32)
        .to_le_bytes()
        .to_vec();
    out.extend(name.as_bytes());
    out.push(b'=');
    out.extend(value);
    out
}

fn record(fields: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
    let header = fields.concat();
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend(header);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
    out
}

fn time(ns: i64) -> [u8; 8] {
    let mut t = [0u8; 8];
    t[..4].copy_from_slice(&((ns / 1_000_000_000) as u32).to_le_bytes());
    t[4..].copy_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    t
}

/// ROS 1 serialization helpers.
pub struct Msg(pub Vec<u8>);

impl Msg {
    pub fn header(stamp_ns: i64, frame: &str) -> Msg {
        let mut m = Msg(0u32.to_le_bytes().to_vec());
        m.0.extend(time(stamp_ns));
        m.string(frame)
    }
    pub fn u32(mut self, v: u32) -> Msg {
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn u8(mut self, v: u8) -> Msg {
        self.0.push(v);
        self
    }
    pub fn f32(mut self, v: f32) -> Msg {
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn f64s(mut self, v: &[f64]) -> Msg {
        for x in v {
            self.0.extend(x.to_le_bytes());
        }
        self
    }
    pub fn string(self, s: &str) -> Msg {
        self.bytes(s.as_bytes())
    }
    pub fn bytes(mut self, b: &[u8]) -> Msg {
        self.0.extend((b.len() as u32).to_le_bytes());
        self.0.extend(b);
        self
    }
}

pub struct BagWriter {
    out: std::io::BufWriter<std::fs::File>,
    topics: Vec<(String, String)>,
    pending: Vec<u8>,
    wrote_connections: bool,
}

impl BagWriter {
    pub fn create(path: &std::path::Path) -> BagWriter {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        out.write_all(b"#ROSBAG V2.0\n").unwrap();
        let fields = [
            field("op", &[3]),
            field("index_pos", &0u64.to_le_bytes()),
            field("conn_count", &0u32.to_le_bytes()),
            field("chunk_count", &0u32.to_le_bytes()),
        ];
        let head = fields.concat().len() + 8;
        out.write_all(&record(&fields, &vec![b' '; 4096 - head]))
            .unwrap();
        BagWriter {
            out,
            topics: Vec::new(),
            pending: Vec::new(),
            wrote_connections: false,
        }
    }

    /// The connection id of `topic`, added on first use.
    pub fn connection(&mut self, topic: &str, ty: &str) -> u32 {
        if let Some(i) = self.topics.iter().position(|(t, _)| t == topic) {
            return i as u32;
        }
        self.topics.push((topic.into(), ty.into()));
        (self.topics.len() - 1) as u32
    }

    pub fn put(&mut self, topic: &str, ty: &str, stamp_ns: i64, msg: Msg) {
        let conn = self.connection(topic, ty);
        let fields = [
            field("op", &[2]),
            field("conn", &conn.to_le_bytes()),
            field("time", &time(stamp_ns)),
        ];
        self.pending.extend(record(&fields, &msg.0));
    }

    /// Closes the current chunk.
    pub fn flush_chunk(&mut self) {
        let mut chunk = Vec::new();
        if !self.wrote_connections {
            for (i, (topic, ty)) in self.topics.iter().enumerate() {
                let fields = [
                    field("op", &[7]),
                    field("conn", &(i as u32).to_le_bytes()),
                    field("topic", topic.as_bytes()),
                ];
                let data = [
                    field("topic", topic.as_bytes()),
                    field("type", ty.as_bytes()),
                    field("md5sum", b"*"),
                    field("message_definition", b""),
                ]
                .concat();
                chunk.extend(record(&fields, &data));
            }
            self.wrote_connections = true;
        }
        chunk.append(&mut self.pending);
        let fields = [
            field("op", &[5]),
            field("compression", b"none"),
            field("size", &(chunk.len() as u32).to_le_bytes()),
        ];
        self.out.write_all(&record(&fields, &chunk)).unwrap();
    }

    pub fn finish(mut self) {
        self.out.flush().unwrap();
    }
}
