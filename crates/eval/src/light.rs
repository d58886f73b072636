//! Scores of the light stages, against brute-force integration of the maps they were
//! given (no recording ground truth needed).
//!
//! - `light.importance`: `pdf_integral` (the sampling pdf integrated over the sphere: 1
//!   for a correct pdf; the value farthest from 1 over the maps seen) and
//!   `irradiance_rel_error` (irradiance estimated from the whole sample table against the
//!   sum over every texel, mean over 26 normals and the maps seen).
//! - `light.val`: `sh_irradiance_rel_error` (irradiance from the nine SH coefficients of
//!   the indirect part against brute force over that part, mean over 26 normals and
//!   frames) and `val_center_drift_m` (mean distance the light centres moved between
//!   consecutive frames; it measures flicker when the light is static, which
//!   `environment_static` reports).

use glam::Vec3;
use relume_graph::Frame;
use relume_scene::light::distribution::{Distribution2D, pdf_integral};
use relume_scene::light::table::irradiance_rel_error;
use relume_scene::light::{AreaLights, EnvMap};
use relume_stages::kind::FrameProducts;
use serde_json::{Value, json};
use std::sync::Arc;

/// The 26 directions of the cube's faces, edges and corners: receivers' normals.
fn test_normals() -> Vec<Vec3> {
    let mut normals = Vec::new();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    normals.push(Vec3::new(x as f32, y as f32, z as f32).normalize());
                }
            }
        }
    }
    normals
}

fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        f64::NAN
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

/// True when `next` is the same map as `last` (the same allocation: the stages re-insert
/// the same `Arc` while the light is unchanged).
fn same(last: &Option<Arc<EnvMap>>, next: &Arc<EnvMap>) -> bool {
    last.as_ref().is_some_and(|l| Arc::ptr_eq(l, next))
}

/// Scores a `light.importance` stage once per distinct environment map.
pub struct ImportanceScorer {
    environment: String,
    table: String,
    last: Option<Arc<EnvMap>>,
    pdf_integrals: Vec<f64>,
    irradiance_errors: Vec<f64>,
}

impl ImportanceScorer {
    pub fn new(environment: String, table: String) -> Self {
        ImportanceScorer {
            environment,
            table,
            last: None,
            pdf_integrals: Vec::new(),
            irradiance_errors: Vec::new(),
        }
    }

    pub fn observe(&mut self, frame: &Frame) {
        let (Ok(env), Ok(table)) = (
            frame.environment(&self.environment),
            frame.light_table(&self.table),
        ) else {
            return;
        };
        if same(&self.last, env) {
            return;
        }
        self.last = Some(env.clone());
        self.pdf_integrals
            .push(pdf_integral(&Distribution2D::from_env(env)));
        self.irradiance_errors
            .push(irradiance_rel_error(env, table, &test_normals()));
    }

    pub fn report(&self) -> Value {
        let worst = self
            .pdf_integrals
            .iter()
            .copied()
            .max_by(|a, b| (a - 1.0).abs().total_cmp(&(b - 1.0).abs()))
            .unwrap_or(f64::NAN);
        json!({
            "maps_scored": self.pdf_integrals.len(),
            "pdf_integral": worst,
            "irradiance_rel_error": mean(&self.irradiance_errors),
        })
    }
}

/// Scores a `light.val` stage.
pub struct ValScorer {
    indirect: String,
    lights: String,
    last_indirect: Option<Arc<EnvMap>>,
    last_lights: Option<Arc<AreaLights>>,
    sh_errors: Vec<f64>,
    drifts: Vec<f64>,
    maps: usize,
}

impl ValScorer {
    pub fn new(indirect: String, lights: String) -> Self {
        ValScorer {
            indirect,
            lights,
            last_indirect: None,
            last_lights: None,
            sh_errors: Vec::new(),
            drifts: Vec::new(),
            maps: 0,
        }
    }

    pub fn observe(&mut self, frame: &Frame) {
        let (Ok(indirect), Ok(lights)) = (
            frame.environment(&self.indirect),
            frame.area_lights(&self.lights),
        ) else {
            return;
        };
        if !same(&self.last_indirect, indirect) {
            self.maps += 1;
            self.sh_errors
                .push(relume_scene::light::sh::sh_irradiance_rel_error(
                    indirect,
                    &test_normals(),
                ));
            self.last_indirect = Some(indirect.clone());
        }
        if let Some(prev) = &self.last_lights {
            self.drifts
                .push(relume_scene::light::val::val_center_drift(prev, lights) as f64);
        }
        self.last_lights = Some(lights.clone());
    }

    pub fn report(&self) -> Value {
        json!({
            "sh_irradiance_rel_error": mean(&self.sh_errors),
            "val_center_drift_m": mean(&self.drifts),
            "environment_static": self.maps == 1,
            "lights": self.last_lights.as_ref().map_or(0, |l| l.lights.len()),
        })
    }
}
