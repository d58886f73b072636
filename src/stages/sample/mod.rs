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

    /// `sample.val` stands in for `sample.path` with a one-line change only if it writes
    /// the same roles, under the same default names and kinds (all but `touched`).
    #[test]
    fn sample_val_writes_the_roles_of_sample_path() {
        let path = outputs(&super::path::INFO);
        let val = outputs(&super::val::INFO);
        let shared: Vec<&Port> = path.iter().filter(|p| p.role != "touched").collect();
        assert_eq!(shared.len(), 11);
        assert_eq!(shared, val.iter().collect::<Vec<_>>());
    }
}
