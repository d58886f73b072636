//! The sampling stages: Monte Carlo estimates of the irradiance real surfaces and
//! virtual objects receive, without (E_R) and with (E_RV) the virtual objects.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `sample.path` | [`path`] | two-mode path sampling (paper 001 Sec. 5) |
//! | `sample.val` | [`val`] | shading from virtual area lights and SH9 (paper 004 Sec. 5) |
//! | `sample.dir` | [`instant_radiosity`] | Differential Instant Radiosity: VPLs, imperfect shadow maps (paper 002 Sec. 3) |
//!
//! [`query`] is the radiance query the renderers ask about the real scene (paper 000
//! Fig. 5): screen-space marching, Environment Mapping, Distance Impostor Tracing or
//! Voxel Cone Tracing.
//!
//! The seams a new renderer plugs into: it implements [`renderer::Renderer`] (what it
//! reads, how it builds, how it renders a frame; the one stage wrapper
//! [`renderer::RendererStage`] does the rest), writes [`layers::IrradianceLayers`]
//! (the roles of [`layers::LAYER_OUTPUTS`]), may fill its rows through
//! [`layers::shade_rows`] (rayon's pool, per-worker state, any stride), takes one line
//! in [`RENDERERS`] (the registry and `relume eval` find it there) and one in the
//! contract test (`contract_tests`: pi L under a constant environment, E_RV == E_R
//! without objects, the same bits at any thread count and on every SIMD path).

pub mod instant_radiosity;
pub mod layers;
pub mod path;
pub mod pyramid;
pub mod query;
pub mod renderer;
pub mod ssrt;
pub mod val;

use renderer::RendererKind;

/// Every built-in renderer, in registry order.
pub const RENDERERS: &[RendererKind] = &[
    RendererKind::of::<path::SamplePath>(),
    RendererKind::of::<val::SampleVal>(),
    RendererKind::of::<instant_radiosity::SampleDir>(),
];

/// The built-in renderer of stage kind `kind`, if it is one.
pub fn renderer_kind(kind: &str) -> Option<&'static RendererKind> {
    RENDERERS.iter().find(|r| r.info.kind == kind)
}

#[cfg(test)]
mod contract_tests;

#[cfg(test)]
mod tests {
    use relume_graph::{Params, Port};

    fn outputs(info: &relume_graph::StageInfo) -> Vec<Port> {
        (info.ports)(&Params::defaults(info.params)).outputs
    }

    /// The renderers write the layers of [`layers::LAYER_OUTPUTS`], under the roles'
    /// own names: one stands in for another with a one-line change (`sample.val`
    /// writes all but `touched`).
    #[test]
    fn every_renderer_writes_the_shared_layers() {
        let roles = |ports: Vec<Port>| -> Vec<(String, String)> {
            ports
                .into_iter()
                .map(|p| (p.role.to_string(), p.default_product.to_string()))
                .collect()
        };
        let layers: Vec<(String, String)> = super::layers::LAYER_OUTPUTS
            .iter()
            .map(|(r, _)| (r.to_string(), r.to_string()))
            .collect();
        assert_eq!(roles(outputs(&super::path::INFO)), layers);
        assert_eq!(roles(outputs(&super::val::INFO)), layers[..11]);
        assert_eq!(roles(outputs(&super::instant_radiosity::INFO)), layers);
    }

    #[test]
    fn every_built_in_renderer_is_found_by_kind_and_only_sample_path_references_itself() {
        let kinds: Vec<(&str, bool)> = super::RENDERERS
            .iter()
            .map(|r| (r.info.kind, r.references_itself))
            .collect();
        assert_eq!(
            kinds,
            [
                ("sample.path", true),
                ("sample.val", false),
                ("sample.dir", false)
            ]
        );
        for r in super::RENDERERS {
            assert!(super::renderer_kind(r.info.kind).is_some());
        }
        assert!(super::renderer_kind("filter.axis_aligned").is_none());
    }
}
