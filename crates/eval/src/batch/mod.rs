//! Batch runs of a dataset: a manifest lists recordings and pipelines, each pair is an
//! *item* with a stable id, items are split into shards by a hash of their id (so a
//! Slurm job array or a Kubernetes Indexed Job runs one shard per task), and each
//! finished item leaves a completion marker so that a rerun skips it.
//!
//! - [`manifest`]: the manifest file (TOML, errors with file, line and column) and
//!   [`item_id`].
//! - [`shard`]: `--shard I/N`, `--shard auto` from the scheduler's variables, and which
//!   items a shard runs.
//! - [`marker`]: an item's output folder, its `DONE` marker and the digest it holds.
//! - [`summary`]: the status of every item of an output folder, for `--summary`.
//! - [`BatchError`]: what each of them fails with.
//!
//! The command itself (running the items through the replay code) is `relume batch`,
//! in the binary's `cli::batch`.

mod error;
pub mod manifest;
pub mod marker;
pub mod shard;
pub mod summary;

pub use error::BatchError;
pub use manifest::{Item, Manifest, Settings, item_id};
pub use marker::{Marker, MarkerState};
pub use shard::{Shard, ShardSpec};
pub use summary::{ItemStatus, ItemSummary};
