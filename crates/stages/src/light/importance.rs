//! `light.importance` (paper 001 Sec. 5.2): the precomputed table of environment
//! importance samples that the sampling stages index per pixel with stratification,
//! instead of inverting the CDFs 16 times per pixel. Built by [`LightTable::build`]
//! from a 2D piecewise-constant distribution weighted by luminance x sin(theta)
//! ([`relume_scene::light::distribution`]). The table is rebuilt only when the environment
//! changes (a new `Arc`); otherwise the same `Arc<LightTable>` is passed on.

use crate::kind;
use crate::kind::FrameProducts;
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
use relume_scene::light::{EnvMap, LightTable};
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[ParamSpec::new(
    "samples",
    ParamDefault::Int(4096),
    "importance samples in the table (paper 001: 4096); pixels draw stratified subsets of it",
)
.range(16.0, 1_000_000.0)];

pub const INFO: StageInfo = StageInfo {
    kind: "light.importance",
    summary: "the table of environment importance samples, luminance x sin(theta) weighted, stratified (paper 001 Sec. 5.2)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[("environment", &[kind::ENVIRONMENT])],
            &[("light_table", &[kind::LIGHT_TABLE])],
        )
    },
    build: |ctx| {
        Ok(Box::new(Importance {
            environment: ctx.input("environment"),
            light_table: ctx.output("light_table"),
            samples: ctx.params.int("samples") as usize,
            seed: ctx.seed,
            last: None,
        }))
    },
};

struct Importance {
    environment: String,
    light_table: String,
    samples: usize,
    seed: u64,
    /// The environment the last table was built from, and the table.
    last: Option<(Arc<EnvMap>, Arc<LightTable>)>,
}

impl Stage for Importance {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let env = frame.environment(&self.environment)?;
        let table = match &self.last {
            Some((last, table)) if Arc::ptr_eq(last, env) => Arc::clone(table),
            _ => {
                let table = Arc::new(LightTable::build(env, self.samples, self.seed));
                self.last = Some((Arc::clone(env), Arc::clone(&table)));
                table
            }
        };
        frame.insert(&self.light_table, Product::new(kind::LIGHT_TABLE, table));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_graph::{BuildContext, ParamValue, Params};
    use relume_recording::{Header, Intrinsics};
    use std::collections::BTreeMap;

    fn stage(samples: i64) -> Box<dyn Stage> {
        let mut params = Params::defaults(PARAMS);
        params.set("samples", ParamValue::Int(samples));
        let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let ctx = BuildContext {
            stage_name: "importance",
            params: &params,
            inputs: &BTreeMap::new(),
            outputs: &BTreeMap::new(),
            header: &header,
            out_dir: std::path::Path::new("."),
            seed: 4,
            world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
        };
        (INFO.build)(&ctx).unwrap()
    }

    fn table(stage: &mut Box<dyn Stage>, env: &Arc<EnvMap>) -> Arc<LightTable> {
        let mut frame = Frame::new(0, 0);
        frame.insert(
            "environment",
            Product::new(kind::ENVIRONMENT, Arc::clone(env)),
        );
        stage.process(&mut frame).unwrap();
        Arc::clone(frame.light_table("light_table").unwrap())
    }

    #[test]
    fn table_is_rebuilt_only_for_a_new_environment() {
        let mut stage = stage(64);
        let env = Arc::new(EnvMap::from_fn(32, 16, |d| {
            Vec3::splat(1.0 + d.y.max(0.0) * 10.0)
        }));
        let first = table(&mut stage, &env);
        assert_eq!(first.samples.len(), 64);
        assert_eq!(*first, LightTable::build(&env, 64, 4), "the run's seed");
        assert!(Arc::ptr_eq(&first, &table(&mut stage, &env)));
        let copy = Arc::new((*env).clone());
        let second = table(&mut stage, &copy);
        assert!(!Arc::ptr_eq(&first, &second));
        assert_eq!(*first, *second, "same map, same table");
    }

    #[test]
    fn a_frame_without_the_environment_is_an_error_naming_it() {
        let mut frame = Frame::new(0, 0);
        let message = stage(16).process(&mut frame).unwrap_err().to_string();
        assert!(message.contains("environment"), "{message}");
    }
}
