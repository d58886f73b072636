//! The sampling stages: Monte Carlo estimates of the irradiance real surfaces and
//! virtual objects receive, without (E_R) and with (E_RV) the virtual objects.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `sample.path` | [`path`] | two-mode path sampling (paper 001 Sec. 5) |
//! | `sample.val` | [`val`] | shading from virtual area lights and SH9 (paper 004 Sec. 5) |
//!
//! [`query`] is the radiance query the renderers ask about the real scene (paper 000
//! Fig. 5): screen-space marching, Environment Mapping or Distance Impostor Tracing.

pub mod layers;
pub mod path;
pub mod pyramid;
pub mod query;
pub mod ssrt;
pub mod val;

#[cfg(test)]
mod tests {
    use crate::graph::{Params, Port};

    fn outputs(info: &crate::graph::StageInfo) -> Vec<Port> {
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
    }
}
