//! The graph runtime, for a lone pipeline and for several sharing their first stages.

mod graph;
mod linear;
mod rates;
mod stages;
