//! Stages for measuring and testing the runtime: `debug.noop` passes frames on (its
//! cost is the runtime's own overhead per stage hop), `debug.sleep` is a slow stage
//! (back-pressure), `debug.fail` fails or panics at a chosen frame (clean shutdown).

use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Stage, StageError, StageInfo};
use std::time::Duration;

pub const NOOP_INFO: StageInfo = StageInfo {
    kind: "debug.noop",
    summary: "pass frames on untouched (measures the runtime's overhead per stage)",
    params: &[],
    ports: |_| Ports::default(),
    build: |_| Ok(Box::new(Noop)),
};

pub const SLEEP_INFO: StageInfo = StageInfo {
    kind: "debug.sleep",
    summary: "sleep a fixed time per frame (a slow stage, to see back-pressure)",
    params: &[ParamSpec::new(
        "ms",
        ParamDefault::Float(10.0),
        "milliseconds to sleep per frame",
    )
    .range(0.0, 60_000.0)],
    ports: |_| Ports::default(),
    build: |ctx| {
        Ok(Box::new(Sleep(Duration::from_secs_f64(
            ctx.params.float("ms") * 1e-3,
        ))))
    },
};

pub const FAIL_INFO: StageInfo = StageInfo {
    kind: "debug.fail",
    summary: "fail (or panic) at a chosen frame, to check that a pipeline stops cleanly",
    params: &[
        ParamSpec::new(
            "frame",
            ParamDefault::Int(0),
            "index of the frame to fail at",
        )
        .range(0.0, 1e12),
        ParamSpec::new(
            "mode",
            ParamDefault::Str("error"),
            "return an error or panic",
        )
        .choices(&["error", "panic"]),
    ],
    ports: |_| Ports::default(),
    build: |ctx| {
        Ok(Box::new(Fail {
            frame: ctx.params.int("frame") as usize,
            panic: ctx.params.str("mode") == "panic",
        }))
    },
};

struct Noop;

impl Stage for Noop {
    fn process(&mut self, _frame: &mut Frame) -> Result<(), StageError> {
        Ok(())
    }
}

struct Sleep(Duration);

impl Stage for Sleep {
    fn process(&mut self, _frame: &mut Frame) -> Result<(), StageError> {
        std::thread::sleep(self.0);
        Ok(())
    }
}

struct Fail {
    frame: usize,
    panic: bool,
}

impl Stage for Fail {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        if frame.index == self.frame {
            if self.panic {
                panic!("debug.fail was asked to panic at frame {}", frame.index);
            }
            return Err(StageError::Failed(format!(
                "debug.fail was asked to fail at frame {}",
                frame.index
            )));
        }
        Ok(())
    }
}
