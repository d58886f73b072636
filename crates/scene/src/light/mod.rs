//! Environment light: the HDR lat-long map a pipeline lights with ([`EnvMap`]), its
//! importance-sampling table ([`LightTable`], paper 001 Sec. 5.2), and the virtual area
//! lights plus spherical harmonics of its direct and indirect parts ([`AreaLights`],
//! paper 004 Secs. 4.2-4.4); the spot lights a pipeline knows of, real or virtual ([`spot`],
//! paper 002 Sec. 3.7). Maps come from files or the recording ([`loaders`]) or
//! from the environment-sample cloud as a distance impostor ([`impostor`], paper 000
//! Sec. 6.1); [`distribution`] importance-samples them.
//!
//! Direction convention (shared with the synthetic recording's `environment`
//! attachment): texel row r, column c of a W x H map looks along theta = (r + 0.5) / H *
//! pi from world +y and phi = (c + 0.5) / W * 2 pi, d = (sin theta cos phi, cos theta,
//! sin theta sin phi).

pub mod cloud;
pub mod distribution;
pub mod envmap;
pub mod impostor;
pub mod kmeans;
pub mod loaders;
pub mod products;
pub mod prt;
pub mod record;
pub mod sh;
pub mod split;
pub mod spot;
pub mod table;
pub mod val;
pub mod voxels;

pub use cloud::EnvCloud;
pub use distribution::{Distribution2D, pdf_integral};
pub use envmap::EnvMap;
pub use impostor::{CubeImpostor, ImpostorBuilder, ImpostorParams};
pub use loaders::{LightError, envmap_from_attachment, load_envmap};
pub use products::{AREA_LIGHTS, CLOUD, ENVIRONMENT, LIGHT_TABLE, VOXELS};
pub use spot::{LightWorld, SpotLight};
pub use table::{LightSample, LightTable, irradiance_rel_error};
pub use val::{AreaLight, AreaLights, LightMethod, ValBuilder, ValParams};
