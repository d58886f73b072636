//! The [`Stage`] abstraction and what the registry needs to build one (its error,
//! [`StageError`], is re-exported here from the leaf that frames use too).

pub use super::error::StageError;
use super::frame::{Frame, ProductKind};
use super::params::{ParamSpec, Params};
use super::timing::Parts;
use relume_recording::Header;
use std::collections::BTreeMap;
use std::path::Path;

/// One step of a pipeline. It runs on its own thread, one frame at a time, reading its
/// inputs from the frame and adding its outputs; it may keep state across frames.
pub trait Stage: Send {
    /// Processes one frame.
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError>;

    /// How much of the last [`Stage::process`] call was spent by a program outside
    /// relume on its own work, as it reported (an external stage's `compute_ms`): the
    /// timing table reports it apart from the rest, the transport.
    fn program_ns(&self) -> Option<u64> {
        None
    }

    /// How the last [`Stage::process`] call's time splits into named parts, as the
    /// stage measured them (`sample.path`: material, object, differential, setup):
    /// the timing table reports each part's median under the stage.
    fn parts(&self) -> Option<Parts> {
        None
    }

    /// Called once after the last frame (e.g. to flush a summary file).
    fn finish(&mut self) -> Result<(), StageError> {
        Ok(())
    }
}

/// A named input or output of a stage kind.
#[derive(Clone, Debug, PartialEq)]
pub struct Port {
    /// The role the stage reads or writes, e.g. `points`.
    pub role: String,
    /// The product name used when the config does not map the role.
    pub default_product: String,
    /// Accepted kinds (inputs) or the one produced kind (outputs).
    pub kinds: &'static [ProductKind],
    /// An input the stage can run without. Only such an input may read the previous
    /// frame (`product@prev`): the first frame of a run has none.
    pub optional: bool,
    /// An input read only where some stage makes it: a pipeline in which no stage
    /// does (and whose config does not bind it) still loads, and the stage finds no
    /// such product in its frames (it must then do without, or say what is missing).
    pub when_made: bool,
}

impl Port {
    pub fn new(role: &str, default_product: &str, kinds: &'static [ProductKind]) -> Port {
        Port {
            role: role.to_string(),
            default_product: default_product.to_string(),
            kinds,
            optional: false,
            when_made: false,
        }
    }

    /// The same input, which the stage can run without (see [`Port::optional`]).
    pub fn optional(self) -> Port {
        Port {
            optional: true,
            ..self
        }
    }

    /// The same input, read only where a stage makes it (see [`Port::when_made`]).
    pub fn when_made(self) -> Port {
        Port {
            when_made: true,
            ..self
        }
    }
}

/// A stage kind's inputs and outputs for given parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Ports {
    pub inputs: Vec<Port>,
    pub outputs: Vec<Port>,
}

impl Ports {
    /// Ports of a stage with fixed inputs and outputs, each `(role, kinds)` with the role
    /// as its default product name.
    pub fn fixed(
        inputs: &[(&str, &'static [ProductKind])],
        outputs: &[(&str, &'static [ProductKind])],
    ) -> Ports {
        Ports {
            inputs: inputs.iter().map(|(r, k)| Port::new(r, r, k)).collect(),
            outputs: outputs.iter().map(|(r, k)| Port::new(r, r, k)).collect(),
        }
    }
}

/// What a stage kind's builder receives.
pub struct BuildContext<'a> {
    pub stage_name: &'a str,
    pub params: &'a Params,
    /// Role -> product name; previous-frame inputs carry the `@prev` suffix, which is
    /// also the name under which the runtime places them in the frame.
    pub inputs: &'a BTreeMap<String, String>,
    pub outputs: &'a BTreeMap<String, String>,
    /// The recording's header (intrinsics, depth unit, ground truth).
    pub header: &'a Header,
    /// Root directory for files the stage writes.
    pub out_dir: &'a Path,
    /// The run's seed for counter-based random numbers.
    pub seed: u64,
    /// The pipeline's world: what its `[[object]]` tables declare (see [`super::world`]).
    pub world: &'a std::sync::Arc<dyn super::world::World>,
}

impl BuildContext<'_> {
    /// The product name bound to input `role`.
    pub fn input(&self, role: &str) -> String {
        self.inputs
            .get(role)
            .cloned()
            .unwrap_or_else(|| role.to_string())
    }

    /// The product name bound to output `role`.
    pub fn output(&self, role: &str) -> String {
        self.outputs
            .get(role)
            .cloned()
            .unwrap_or_else(|| role.to_string())
    }
}

/// A stage kind in the registry.
#[derive(Clone, Copy)]
pub struct StageInfo {
    /// The name configs use, e.g. `normals.cross`.
    pub kind: &'static str,
    /// One line for `relume stages`.
    pub summary: &'static str,
    pub params: &'static [ParamSpec],
    /// The stage's inputs and outputs given its (checked) parameters.
    pub ports: fn(&Params) -> Ports,
    pub build: fn(&BuildContext) -> Result<Box<dyn Stage>, StageError>,
}
