//! The stage families. Each module holds the math as plain functions over buffers
//! (`op(&src, &mut dst, params) -> Result`) and a thin [`Stage`](crate::graph::Stage)
//! type that the registry builds from config.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `decode` | [`decode`] | decodes color, depth and pose from the recording's records |
//! | `depth.fuse` | [`fuse`] | warps the previous fused depth into the view and merges it with the new depth |
//! | `depth.to_points` | [`points`] | back-projects depth to a camera-space position map |
//! | `normals.cross` | [`normals`] | normals from the cross product of neighbouring positions |
//! | `write` | [`write`] | saves chosen products per frame as PNG or EXR |
//! | `debug.noop`, `debug.sleep`, `debug.fail` | [`debug`] | runtime overhead, back-pressure and failure handling |

pub mod debug;
pub mod decode;
pub mod fuse;
pub mod normals;
pub mod points;
pub mod write;

use crate::graph::{Port, Ports, ProductKind, StageInfo};

/// Every built-in stage kind.
pub fn builtin() -> Vec<StageInfo> {
    vec![
        decode::INFO,
        fuse::INFO,
        points::INFO,
        normals::CROSS_INFO,
        write::INFO,
        debug::NOOP_INFO,
        debug::SLEEP_INFO,
        debug::FAIL_INFO,
    ]
}

/// Ports of a stage with fixed inputs and outputs: (role, default product, kinds).
pub(crate) fn fixed_ports(
    inputs: &[(&str, &'static [ProductKind])],
    outputs: &[(&str, &'static [ProductKind])],
) -> Ports {
    Ports {
        inputs: inputs.iter().map(|(r, k)| Port::new(r, r, k)).collect(),
        outputs: outputs.iter().map(|(r, k)| Port::new(r, r, k)).collect(),
    }
}
