//! Building one checked stage into the stage that runs: the check that the world is ready, the
//! registry's builder with its [`BuildContext`], then the `every` and `lag` wrappers
//! ([`super::every`], [`super::lag`]). Both ways of building a run go through it, one
//! stage at a time: a lone pipeline's chain ([`super::pipeline::Pipeline::build`]) and
//! the nodes of a stage tree ([`super::tree::StageGraph::build`]).

use super::registry::Registry;
use super::resolved::ResolvedStage;
use super::stage::{BuildContext, Stage, StageError};
use super::world::World;
use relume_recording::Header;
use std::path::Path;
use std::sync::Arc;

/// Builds `stage` for a run over a recording with `header`, with the world of its
/// pipeline; files it writes go under `out_dir`. Fails, before building anything, with
/// `waiting`: why the world cannot run yet ([`World::waiting`]).
pub(super) fn build_stage(
    stage: &ResolvedStage,
    world: &Arc<dyn World>,
    waiting: Option<&str>,
    registry: &Registry,
    header: &Header,
    out_dir: &Path,
    seed: u64,
) -> Result<Box<dyn Stage>, StageError> {
    if let Some(why) = waiting {
        return Err(StageError::Failed(why.to_string()));
    }
    let info = registry.get(stage.kind).ok_or_else(|| {
        let message = format!("stage kind `{}` is not registered", stage.kind);
        StageError::Failed(message)
    })?;
    let ctx = BuildContext {
        stage_name: &stage.name,
        params: &stage.params,
        inputs: &stage.inputs,
        outputs: &stage.outputs,
        header,
        out_dir,
        seed,
        world,
    };
    let built = (info.build)(&ctx)?;
    let inputs = stage.inputs.values().cloned().collect();
    let outputs = stage.outputs.values().cloned().collect();
    let paced = super::every::every_k(built, stage);
    super::lag::lag_n(paced, stage.lag, inputs, outputs)
}
