//! Test stages and a counting frame source for the runtime tests.

use relume::graph::{
    BuildContext, Frame, FrameSource, ParamDefault, ParamSpec, Pipeline, Ports, Product, Registry,
    SourceFile, Stage, StageError, StageInfo,
};
use relume::raster::Image;
use relume::recording::{Header, Intrinsics, RecordingError};
use relume::stages::kind;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

/// Frames with no products, counting how many were read; the frames in `corrupt` fail
/// to read.
pub struct CountingSource {
    pub frames: usize,
    pub read: AtomicUsize,
    pub corrupt: Vec<usize>,
}

impl CountingSource {
    pub fn new(frames: usize) -> Self {
        CountingSource {
            frames,
            read: AtomicUsize::new(0),
            corrupt: Vec::new(),
        }
    }
}

impl FrameSource for CountingSource {
    fn len(&self) -> usize {
        self.frames
    }

    fn read(&self, n: usize) -> Result<Frame, RecordingError> {
        if self.corrupt.contains(&n) {
            return Err(RecordingError::Corrupt {
                path: "test".into(),
                offset: n as u64,
                reason: "made corrupt by the test".into(),
            });
        }
        self.read.fetch_add(1, Ordering::SeqCst);
        Ok(Frame::new(n, n as i64 * 1_000_000))
    }
}

/// `test.index`: writes the frame index as a 1x1 depth map into its output.
pub const INDEX_INFO: StageInfo = StageInfo {
    kind: "test.index",
    summary: "frame index as a product",
    params: &[],
    ports: |_| Ports {
        inputs: vec![],
        outputs: vec![relume::graph::Port::new("value", "value", &[kind::DEPTH])],
    },
    build: |ctx| Ok(Box::new(IndexStage(ctx.output("value")))),
};

struct IndexStage(String);

impl Stage for IndexStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        frame.insert(
            &self.0,
            Product::new(kind::DEPTH, Image::filled(1, 1, frame.index as f32)),
        );
        Ok(())
    }
}

/// `test.copy`: copies its (possibly previous-frame) input to its output; writes -1
/// when the input is absent (the first frame of a feedback edge).
pub const COPY_INFO: StageInfo = StageInfo {
    kind: "test.copy",
    summary: "copy a product",
    params: &[ParamSpec::new(
        "sleep_ms",
        ParamDefault::Float(0.0),
        "delay",
    )],
    ports: |_| Ports {
        // Without the input (the first frame under `@prev`) the copy is -1.
        inputs: vec![relume::graph::Port::new("input", "input", &[kind::DEPTH]).optional()],
        outputs: vec![relume::graph::Port::new("output", "output", &[kind::DEPTH])],
    },
    build: |ctx: &BuildContext| {
        Ok(Box::new(CopyStage {
            input: ctx.input("input"),
            output: ctx.output("output"),
            sleep: ctx.params.float("sleep_ms"),
        }))
    },
};

struct CopyStage {
    input: String,
    output: String,
    sleep: f64,
}

impl Stage for CopyStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        std::thread::sleep(Duration::from_secs_f64(self.sleep * 1e-3));
        let value = match frame.get(&self.input) {
            Some(_) => frame.depth(&self.input)?.data[0],
            None => -1.0,
        };
        frame.insert(
            &self.output,
            Product::new(kind::DEPTH, Image::filled(1, 1, value)),
        );
        Ok(())
    }
}

pub fn registry() -> Registry {
    let mut r = relume::stages::registry();
    r.register(INDEX_INFO);
    r.register(COPY_INFO);
    r
}

pub fn pipeline(text: &str) -> Pipeline {
    Pipeline::parse(
        &SourceFile {
            name: "test.toml".into(),
            text: text.into(),
        },
        &registry(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

pub fn header() -> Header {
    Header::new("test", Intrinsics::PRIMESENSE, 0.001)
}
