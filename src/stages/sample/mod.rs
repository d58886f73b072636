//! The sampling stages: Monte Carlo estimates of the irradiance real surfaces and
//! virtual objects receive, without (E_R) and with (E_RV) the virtual objects.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `sample.path` | [`path`] | two-mode path sampling (paper 001 Sec. 5) |
//! | `sample.val` | [`val`] | shading from virtual area lights and SH9 (paper 004 Sec. 5) |

pub mod path;
pub mod pyramid;
pub mod ssrt;
pub mod val;
