//! The products a checked stage reads and writes: its input and output roles as the
//! config bound them, for the evaluator and every scorer to find them in a frame.

use relume_graph::ResolvedStage;

/// The product a stage writes for output `role` (the role itself unless renamed).
pub(crate) fn output(stage: &ResolvedStage, role: &str) -> String {
    stage
        .outputs
        .get(role)
        .cloned()
        .unwrap_or_else(|| role.into())
}

/// The product a stage reads for input `role` (the role itself unless renamed).
pub(crate) fn input(stage: &ResolvedStage, role: &str) -> String {
    stage
        .inputs
        .get(role)
        .cloned()
        .unwrap_or_else(|| role.into())
}
