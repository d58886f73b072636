//! Where a pipeline's poses come from: the recording's (`decode`'s `pose` output) or a
//! tracker's. A recording without poses can feed a stage that needs one only through
//! [`pose.track`](super::INFO); [`reads_recorded_pose`] finds the stage that would stop
//! such a run, so that it is refused before it starts, with the swap that fixes it.

use relume_graph::pipeline::PREVIOUS_SUFFIX;
use relume_graph::{Registry, ResolvedStage};

/// A stage that cannot run without the recording's poses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PoseReader {
    /// The stage's name and line in its file.
    pub stage: String,
    pub line: usize,
    /// The input that reads the pose, and the product it names.
    pub role: String,
    pub product: String,
}

/// The first stage of `stages` whose required input reads the pose a `decode` stage
/// takes from the recording (an optional input, such as `pose.track`'s `recorded`,
/// does not count): the stage a recording without poses stops.
pub fn reads_recorded_pose(stages: &[ResolvedStage], registry: &Registry) -> Option<PoseReader> {
    let recorded: Vec<&String> = stages
        .iter()
        .filter(|s| s.kind == crate::decode::INFO.kind)
        .filter_map(|s| s.outputs.get("pose"))
        .collect();
    stages.iter().find_map(|s| {
        let ports = (registry.get(s.kind)?.ports)(&s.params);
        s.inputs.iter().find_map(|(role, product)| {
            let current = product.strip_suffix(PREVIOUS_SUFFIX).unwrap_or(product);
            let required = ports.inputs.iter().any(|p| &p.role == role && !p.optional);
            (required && recorded.iter().any(|r| r.as_str() == current)).then(|| PoseReader {
                stage: s.name.clone(),
                line: s.line,
                role: role.clone(),
                product: product.clone(),
            })
        })
    })
}
