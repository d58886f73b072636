//! Protocol 1 of external stages, as `docs/external-stages.md` specifies it: every
//! message is the magic `RLX1`, a little-endian `u32` length, a MessagePack map of that
//! length (the meta) and then the raw bytes of the images the meta lists, in its order.
//! This module is the encoding alone (no process, no frame), so it is tested on bytes.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::{Read, Write};

/// The protocol version relume speaks.
pub const VERSION: u32 = 1;

/// Every message starts with these four bytes: a program that prints to its standard
/// output by mistake is told so instead of being misread.
pub const MAGIC: &[u8; 4] = b"RLX1";

/// The largest meta accepted from a program (a meta lists images; it holds no pixels).
pub const MAX_META: usize = 1 << 20;

/// The largest image side and pixel count accepted from a program, as for image files.
pub const MAX_SIDE: u32 = 16_384;
pub const MAX_PIXELS: u64 = 64 << 20;

/// How an image kind travels: its name in pipeline files and the protocol, its channel
/// count and its element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub name: &'static str,
    pub channels: u32,
    pub dtype: Dtype,
}

/// The element type of an image's samples, little-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    U8,
    F32,
}

impl Dtype {
    pub fn size(self) -> u64 {
        match self {
            Dtype::U8 => 1,
            Dtype::F32 => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Dtype::U8 => "u8",
            Dtype::F32 => "f32",
        }
    }
}

/// The image kinds an external stage may read and write, by their protocol names.
pub const LAYOUTS: &[Layout] = &[
    Layout::new("color", 3, Dtype::U8),
    Layout::new("depth", 1, Dtype::F32),
    Layout::new("points", 3, Dtype::F32),
    Layout::new("normals", 3, Dtype::F32),
    Layout::new("radiance", 3, Dtype::F32),
    Layout::new("scalar", 1, Dtype::F32),
    Layout::new("labels", 1, Dtype::U8),
];

impl Layout {
    const fn new(name: &'static str, channels: u32, dtype: Dtype) -> Layout {
        Layout {
            name,
            channels,
            dtype,
        }
    }

    /// The layout of the kind called `name`.
    pub fn of(name: &str) -> Option<Layout> {
        LAYOUTS.iter().copied().find(|l| l.name == name)
    }
}

/// One image in a message: which port, its size and layout. Its bytes follow the meta,
/// `width * height * channels * size(dtype)` of them, rows top to bottom, channels
/// interleaved.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageMeta {
    pub role: String,
    pub kind: String,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub dtype: Dtype,
    /// Where the bytes lie in the shared memory, when that transport is in use; without
    /// it they follow the meta on the pipe.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<u64>,
}

/// A value that is not an image, carried in the meta itself. Protocol 1 knows one kind,
/// `pose`: the camera-to-world transform, `translation` in metres and `rotation` a unit
/// quaternion (x, y, z, w), as the recording holds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Value {
    pub role: String,
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f64; 4]>,
}

/// The kind name of a pose value.
pub const POSE: &str = "pose";

/// The shared memory relume offers in `hello`: a file the program maps whole. Inputs
/// lie before `output_offset`; the program writes its outputs from there on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShmOffer {
    pub path: String,
    pub size: u64,
    pub output_offset: u64,
}

impl ImageMeta {
    /// The byte count of the image, or why its size is not one relume accepts.
    pub fn byte_len(&self) -> Result<usize, String> {
        if self.width > MAX_SIDE
            || self.height > MAX_SIDE
            || u64::from(self.width) * u64::from(self.height) > MAX_PIXELS
        {
            return Err(format!(
                "`{}` is {}x{}: over {MAX_SIDE} a side or {MAX_PIXELS} pixels",
                self.role, self.width, self.height
            ));
        }
        if !(1..=4).contains(&self.channels) {
            return Err(format!(
                "`{}` has {} channels: 1 to 4 travel",
                self.role, self.channels
            ));
        }
        let n = u64::from(self.width)
            * u64::from(self.height)
            * u64::from(self.channels)
            * self.dtype.size();
        Ok(n as usize)
    }
}

/// What relume sends.
#[derive(Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Request {
    /// First, once: who the program is in the pipeline and what it is asked for.
    Hello {
        protocol: u32,
        stage: String,
        /// The stage's `settings`, `name = value` as written (the program types them).
        settings: BTreeMap<String, String>,
        /// Role -> kind name, of the images each frame request carries.
        inputs: BTreeMap<String, String>,
        /// Role -> kind name, of the images each reply must carry.
        outputs: BTreeMap<String, String>,
        /// The run's seed.
        seed: u64,
        /// Shared memory the program may use instead of the pipe for image bytes.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        shm: Option<ShmOffer>,
    },
    /// One frame: its images follow the meta.
    Frame {
        index: u64,
        stamp_ns: i64,
        /// hash(run seed, frame index, stage name): a deterministic program seeds its
        /// random numbers with it and gives the same bytes on every run.
        seed: u64,
        inputs: Vec<ImageMeta>,
        /// The inputs that are not images (poses).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        values: Vec<Value>,
    },
    /// No more frames: the program exits with status 0.
    End,
}

/// What a program answers.
#[derive(Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Reply {
    /// To `hello`: the protocol it speaks, and `"shm"` when it mapped the offered
    /// shared memory (absent: everything over the pipe).
    Ready {
        protocol: u32,
        #[serde(default)]
        transport: Option<String>,
    },
    /// To `frame`: its images follow the meta. `compute_ms` is the program's own time
    /// on the frame, apart from transport.
    Frame {
        index: u64,
        outputs: Vec<ImageMeta>,
        /// The outputs that are not images (poses).
        #[serde(default)]
        values: Vec<Value>,
        #[serde(default)]
        compute_ms: Option<f64>,
    },
    /// The program cannot go on: the run stops with this message.
    Error { message: String },
}

/// Writes the header of a message (magic, length, meta); the caller writes the image
/// bytes after it.
pub fn write_meta(out: &mut impl Write, meta: &impl Serialize) -> std::io::Result<()> {
    let bytes = rmp_serde::to_vec_named(meta).map_err(std::io::Error::other)?;
    out.write_all(MAGIC)?;
    out.write_all(&(bytes.len() as u32).to_le_bytes())?;
    out.write_all(&bytes)
}

/// Why a message could not be read.
#[derive(Debug)]
pub enum ReadError {
    /// The stream ended (the program exited or closed its output), after `got` bytes
    /// of the message.
    Closed {
        got: usize,
    },
    Io(std::io::Error),
    /// Not a protocol-1 message: what was found instead.
    Malformed(String),
}

/// Reads a message's magic, length and meta.
pub fn read_meta<T: for<'de> Deserialize<'de>>(input: &mut impl Read) -> Result<T, ReadError> {
    let mut head = [0u8; 8];
    read_all(input, &mut head)?;
    if &head[..4] != MAGIC {
        return Err(ReadError::Malformed(format!(
            "a message starts with {:?}, not \"RLX1\" (does the program print to its standard \
             output? Only the protocol may go there; print to standard error)",
            String::from_utf8_lossy(&head)
        )));
    }
    let len = u32::from_le_bytes(head[4..].try_into().expect("4 bytes")) as usize;
    if len > MAX_META {
        return Err(ReadError::Malformed(format!(
            "a meta of {len} bytes, over the {MAX_META} allowed"
        )));
    }
    let mut meta = vec![0u8; len];
    read_all(input, &mut meta)?;
    rmp_serde::from_slice(&meta)
        .map_err(|e| ReadError::Malformed(format!("a meta that is not a protocol-1 map: {e}")))
}

/// Fills `buf` from `input`; the end of the stream is [`ReadError::Closed`].
pub fn read_all(input: &mut impl Read, buf: &mut [u8]) -> Result<(), ReadError> {
    let mut got = 0;
    while got < buf.len() {
        match input.read(&mut buf[got..]) {
            Ok(0) => return Err(ReadError::Closed { got }),
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(ReadError::Io(e)),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_request_round_trips_as_a_named_map() {
        let request = Request::Frame {
            index: 3,
            stamp_ns: -5,
            seed: 7,
            inputs: vec![ImageMeta {
                role: "image".into(),
                kind: "radiance".into(),
                width: 2,
                height: 1,
                channels: 3,
                dtype: Dtype::F32,
                offset: None,
            }],
            values: vec![],
        };
        let mut bytes = Vec::new();
        write_meta(&mut bytes, &request).unwrap();
        assert_eq!(&bytes[..4], b"RLX1");
        let len = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
        assert_eq!(bytes.len(), 8 + len);
        // A map with the field names, as Python's msgpack gives a dict.
        assert_eq!(bytes[8] & 0xF0, 0x80, "a fixmap");
        let back: Request = read_meta(&mut &bytes[..]).unwrap();
        assert_eq!(back, request);
    }

    #[test]
    fn a_reply_without_compute_time_reads() {
        // {"type": "frame", "index": 0, "outputs": []} as Python's msgpack writes it.
        let meta = [
            0x83, 0xA4, b't', b'y', b'p', b'e', 0xA5, b'f', b'r', b'a', b'm', b'e', 0xA5, b'i',
            b'n', b'd', b'e', b'x', 0x00, 0xA7, b'o', b'u', b't', b'p', b'u', b't', b's', 0x90,
        ];
        let mut bytes = b"RLX1".to_vec();
        bytes.extend((meta.len() as u32).to_le_bytes());
        bytes.extend(meta);
        let reply: Reply = read_meta(&mut &bytes[..]).unwrap();
        assert_eq!(
            reply,
            Reply::Frame {
                index: 0,
                outputs: vec![],
                values: vec![],
                compute_ms: None
            }
        );
    }

    #[test]
    fn what_is_not_a_message_is_named() {
        let err = read_meta::<Reply>(&mut &b"hello world\n"[..]).unwrap_err();
        let ReadError::Malformed(why) = err else {
            panic!("{err:?}")
        };
        assert!(
            why.starts_with("a message starts with \"hello wo\""),
            "{why}"
        );
        let mut huge = b"RLX1".to_vec();
        huge.extend(u32::MAX.to_le_bytes());
        let err = read_meta::<Reply>(&mut &huge[..]).unwrap_err();
        assert!(
            matches!(&err, ReadError::Malformed(w) if w == "a meta of 4294967295 bytes, over the 1048576 allowed"),
            "{err:?}"
        );
        let err = read_meta::<Reply>(&mut &b"RLX1\x05\0\0\0ab"[..]).unwrap_err();
        assert!(matches!(err, ReadError::Closed { got: 2 }), "{err:?}");
    }

    #[test]
    fn image_sizes_are_bounded_before_anything_is_allocated() {
        let meta = |width, height, channels| ImageMeta {
            role: "out".into(),
            kind: "radiance".into(),
            width,
            height,
            channels,
            dtype: Dtype::F32,
            offset: None,
        };
        assert_eq!(meta(640, 480, 3).byte_len(), Ok(640 * 480 * 12));
        assert_eq!(
            meta(20_000, 1, 3).byte_len(),
            Err("`out` is 20000x1: over 16384 a side or 67108864 pixels".into())
        );
        assert_eq!(
            meta(1, 1, 9).byte_len(),
            Err("`out` has 9 channels: 1 to 4 travel".into())
        );
    }
}
