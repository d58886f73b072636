//! `light.split` (paper 004 Sec. 4.2): splits the environment light into its direct part
//! (light sources and strong indirect light, which `light.val` turns into area lights)
//! and its indirect part (low-frequency, compressed to SH9), per color channel by an
//! energy ratio. See [`relume_scene::light::split`] for the math.

use crate::kind::FrameProducts;
use crate::{OpError, kind};
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
use relume_scene::light::EnvMap;
use relume_scene::light::split::{map_is_consistent, split_direct_indirect};
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[ParamSpec::new(
    "ratio",
    ParamDefault::Float(0.9),
    "share of each channel's total radiant intensity (L dA) that goes to the direct part, brightest texels first (paper 004 used 0.75-0.98)",
)
.range(0.0, 1.0)];

pub const INFO: StageInfo = StageInfo {
    kind: "light.split",
    summary: "direct and indirect parts of the environment light by an energy ratio per channel (paper 004 Sec. 4.2)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[("environment", &[kind::ENVIRONMENT])],
            &[
                ("direct_light", &[kind::ENVIRONMENT]),
                ("indirect_light", &[kind::ENVIRONMENT]),
            ],
        )
    },
    build: |ctx| {
        Ok(Box::new(Split {
            environment: ctx.input("environment"),
            direct: ctx.output("direct_light"),
            indirect: ctx.output("indirect_light"),
            ratio: ctx.params.float("ratio"),
            last: None,
        }))
    },
};

/// The last input and its parts.
type Cached = (Arc<EnvMap>, Arc<EnvMap>, Arc<EnvMap>);

struct Split {
    environment: String,
    direct: String,
    indirect: String,
    ratio: f64,
    last: Option<Cached>,
}

/// True when `a` and `b` hold the same map (the same Arc, or equal contents).
pub(crate) fn same_map(a: &Arc<EnvMap>, b: &Arc<EnvMap>) -> bool {
    Arc::ptr_eq(a, b) || **a == **b
}

/// The error for a map whose buffers do not match its size.
pub(crate) fn check_map(name: &str, map: &EnvMap) -> Result<(), OpError> {
    if map_is_consistent(map) {
        return Ok(());
    }
    Err(OpError::SizeMismatch(format!(
        "environment map `{name}` is {}x{} but has {} radiance and {} distance texels",
        map.width,
        map.height,
        map.radiance.len(),
        map.distance.len()
    )))
}

impl Stage for Split {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let env = frame.environment(&self.environment)?.clone();
        let reuse = matches!(&self.last, Some((last, _, _)) if same_map(last, &env));
        if !reuse {
            check_map(&self.environment, &env)?;
            let (direct, indirect) = split_direct_indirect(&env, self.ratio);
            self.last = Some((env, Arc::new(direct), Arc::new(indirect)));
        }
        let (_, direct, indirect) = self.last.as_ref().expect("set above");
        frame.insert(
            &self.direct,
            Product::new(kind::ENVIRONMENT, direct.clone()),
        );
        frame.insert(
            &self.indirect,
            Product::new(kind::ENVIRONMENT, indirect.clone()),
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_graph::{BuildContext, Params};
    use relume_recording::{Header, Intrinsics};
    use std::collections::BTreeMap;

    fn stage() -> Box<dyn Stage> {
        let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let params = Params::defaults(PARAMS);
        let ctx = BuildContext {
            stage_name: "split",
            params: &params,
            inputs: &BTreeMap::new(),
            outputs: &BTreeMap::new(),
            header: &header,
            out_dir: std::path::Path::new("."),
            seed: 1,
            world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
        };
        (INFO.build)(&ctx).unwrap()
    }

    fn frame(env: &Arc<EnvMap>) -> Frame {
        let mut f = Frame::new(0, 0);
        f.insert("environment", Product::new(kind::ENVIRONMENT, env.clone()));
        f
    }

    #[test]
    fn splits_once_and_reuses_the_parts_while_the_input_is_unchanged() {
        let env = Arc::new(EnvMap::from_fn(32, 16, |d| {
            Vec3::splat(0.1) + Vec3::splat(50.0) * (d.y > 0.95) as u8 as f32
        }));
        let mut s = stage();
        let mut a = frame(&env);
        s.process(&mut a).unwrap();
        let direct = a.environment("direct_light").unwrap().clone();
        let indirect = a.environment("indirect_light").unwrap().clone();
        assert!(direct.radiance.iter().any(|&l| l.x > 1.0));
        let (d, i) = split_direct_indirect(&env, 0.9);
        assert_eq!((&*direct, &*indirect), (&d, &i));
        // The same map again, even in a new Arc: the same parts, not recomputed.
        let mut b = frame(&Arc::new((*env).clone()));
        s.process(&mut b).unwrap();
        assert!(Arc::ptr_eq(&direct, b.environment("direct_light").unwrap()));
        // A changed map: new parts.
        let other = Arc::new(EnvMap::constant(32, 16, Vec3::ONE));
        let mut c = frame(&other);
        s.process(&mut c).unwrap();
        assert!(!Arc::ptr_eq(
            &direct,
            c.environment("direct_light").unwrap()
        ));
    }

    #[test]
    fn inconsistent_maps_are_refused_by_name() {
        let mut env = EnvMap::constant(4, 2, Vec3::ONE);
        env.distance.pop();
        let err = stage().process(&mut frame(&Arc::new(env))).unwrap_err();
        assert_eq!(
            err.to_string(),
            "environment map `environment` is 4x2 but has 8 radiance and 7 distance texels"
        );
    }
}
