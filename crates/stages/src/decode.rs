//! `decode`: turns a frame's encoded records into color (8-bit sRGB), depth (metres)
//! and pose products. Color and depth decode in parallel.

use crate::kind;
use relume_graph::{
    BuildContext, Frame, ParamDefault, ParamSpec, Params, Ports, Product, Stage, StageError,
    StageInfo,
};
use relume_recording::codec::{decode_color, decode_depth};

pub const INFO: StageInfo = StageInfo {
    kind: "decode",
    summary: "decode the recording's color (sRGB 8-bit), depth (metres) and pose",
    params: &[ParamSpec::new(
        "parallel",
        ParamDefault::Bool(true),
        "decode color and depth at the same time on two threads",
    )],
    ports: |_| {
        Ports::fixed(
            &[("record", &[kind::RECORD])],
            &[
                ("color", &[kind::COLOR]),
                ("depth", &[kind::DEPTH]),
                ("pose", &[kind::POSE]),
            ],
        )
    },
    build: |ctx| Ok(Box::new(Decode::new(ctx, ctx.params))),
};

/// The `decode` stage.
pub struct Decode {
    record: String,
    color: String,
    depth: String,
    pose: String,
    depth_unit_m: f64,
    parallel: bool,
}

impl Decode {
    fn new(ctx: &BuildContext, params: &Params) -> Decode {
        Decode {
            record: ctx.input("record"),
            color: ctx.output("color"),
            depth: ctx.output("depth"),
            pose: ctx.output("pose"),
            depth_unit_m: ctx.header.depth_unit_m,
            parallel: params.bool("parallel"),
        }
    }
}

impl Stage for Decode {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let records = frame.record(&self.record)?.clone();
        let decode_c = || {
            decode_color(&records.color.image).map_err(|e| {
                StageError::Failed(format!(
                    "color image at stamp {} ns: {e}",
                    records.color.stamp_ns
                ))
            })
        };
        let decode_d = || {
            records
                .depth
                .as_ref()
                .map(|d| {
                    decode_depth(&d.image, self.depth_unit_m).map_err(|e| {
                        StageError::Failed(format!("depth image at stamp {} ns: {e}", d.stamp_ns))
                    })
                })
                .transpose()
        };
        let (color, depth) = if self.parallel {
            rayon::join(decode_c, decode_d)
        } else {
            (decode_c(), decode_d())
        };
        frame.insert(&self.color, Product::new(kind::COLOR, color?));
        if let Some(depth) = depth? {
            frame.insert(&self.depth, Product::new(kind::DEPTH, depth));
        }
        if let Some(pose) = records.pose {
            frame.insert(&self.pose, Product::new(kind::POSE, pose));
        }
        Ok(())
    }
}
