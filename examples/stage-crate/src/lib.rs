//! A stage crate: `example.depth_edges`, a stage that lives outside relume's own
//! stages, registered with the library beside the built-in ones. Copy this crate to
//! start your own: the op is a plain function over preallocated buffers, the stage a
//! thin wrapper that reads its input from the frame and inserts its output, and
//! [`INFO`] tells the registry its parameters and ports, so that pipelines using it are
//! checked (kinds, bindings, parameter types and bounds) like any other.
//!
//! `src/main.rs` runs a pipeline file through it; `tests/run.rs` checks the stage's
//! output against the op.

use relume::graph::{
    BuildContext, Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError,
    StageInfo,
};
use relume::raster::{DepthImage, LabelImage};
use relume::stages::kind;

/// Why the op cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EdgeError {
    #[error("the edge map is {0}x{1}, the depth {2}x{3}")]
    SizeMismatch(u32, u32, u32, u32),
}

/// Marks depth discontinuities: 255 where a pixel's depth differs from its right or
/// lower neighbour's by more than `threshold` metres (both valid, > 0), else 0.
pub fn depth_edges(
    depth: &DepthImage,
    threshold: f32,
    edges: &mut LabelImage,
) -> Result<(), EdgeError> {
    if !depth.same_size(edges) {
        return Err(EdgeError::SizeMismatch(
            edges.width,
            edges.height,
            depth.width,
            depth.height,
        ));
    }
    let (w, h) = (depth.width as usize, depth.height as usize);
    let z = &depth.data;
    let jump = |a: f32, b: f32| a > 0.0 && b > 0.0 && (a - b).abs() > threshold;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let right = x + 1 < w && jump(z[i], z[i + 1]);
            let down = y + 1 < h && jump(z[i], z[i + w]);
            edges.data[i] = if right || down { 255 } else { 0 };
        }
    }
    Ok(())
}

/// The stage: depth in, edge labels out.
struct DepthEdges {
    threshold: f32,
    depth: String,
    edges: String,
}

impl Stage for DepthEdges {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let depth = frame.depth(&self.depth)?;
        let mut edges = LabelImage::zeroed(depth.width, depth.height);
        depth_edges(depth, self.threshold, &mut edges)
            .map_err(|e| StageError::Failed(e.to_string()))?;
        frame.insert(&self.edges, Product::new(kind::LABELS, edges));
        Ok(())
    }
}

/// `example.depth_edges`: register it with `registry.register(INFO)`.
pub const INFO: StageInfo = StageInfo {
    kind: "example.depth_edges",
    summary: "depth discontinuities as a label map (a stage from a crate of its own)",
    params: &[ParamSpec::new(
        "threshold",
        ParamDefault::Float(0.1),
        "metres of depth difference between neighbours that make an edge",
    )
    .range(0.001, 100.0)],
    ports: |_| Ports {
        inputs: vec![Port::new("depth", "depth", &[kind::DEPTH])],
        outputs: vec![Port::new("edges", "edges", &[kind::LABELS])],
    },
    build: |ctx: &BuildContext| {
        Ok(Box::new(DepthEdges {
            threshold: ctx.params.float("threshold") as f32,
            depth: ctx.input("depth"),
            edges: ctx.output("edges"),
        }))
    },
};

/// relume's built-in stages and this crate's.
pub fn registry() -> relume::graph::Registry {
    let mut registry = relume::stages::registry();
    registry.register(INFO);
    registry
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_in_depth_is_an_edge_and_holes_are_not() {
        // 1 m | 2 m, with a hole (0) at the bottom right.
        let depth = DepthImage::from_vec(3, 2, vec![1.0, 1.0, 2.0, 1.0, 1.0, 0.0]).unwrap();
        let mut edges = LabelImage::zeroed(3, 2);
        depth_edges(&depth, 0.5, &mut edges).unwrap();
        assert_eq!(edges.data, vec![0, 255, 0, 0, 0, 0]);
        let mut small = LabelImage::zeroed(2, 2);
        assert_eq!(
            depth_edges(&depth, 0.5, &mut small),
            Err(EdgeError::SizeMismatch(2, 2, 3, 2))
        );
    }
}
