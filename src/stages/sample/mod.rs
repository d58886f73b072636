//! Monte Carlo sampling of irradiance with and without the virtual objects.

pub mod ssrt;
