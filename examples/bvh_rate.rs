//! The objects' BVH alone, for a peer to trace the same triangles and rays
//! (`scripts/bvh_peer.py` runs it beside Embree 4):
//!
//! ```text
//! cargo run --release --example bvh_rate -- dump PIPELINE.toml TRIANGLES
//! cargo run --release --example bvh_rate -- trace TRIANGLES RAYS HITS [--repeat N]
//! ```
//!
//! `dump` writes the triangles of a pipeline's `[[object]]` tables (at frame 0) as
//! little-endian f32, nine per triangle (three vertices). `trace` builds relume's BVH
//! over such a file ([`relume::objects::Bvh::build`], as `sample.path` does), traces
//! each ray of RAYS (six f32 each: origin, direction) for its nearest hit with t in
//! (0, inf) on one thread ([`relume::objects::Bvh::nearest`]), `--repeat` times (5 by
//! default), and prints one JSON line: the build's seconds, each pass's seconds and the
//! median pass's rays per second. HITS gets per ray its t (f32, +inf for a miss) and
//! the triangle hit (i32, -1 for a miss), in that order: the rays' t first, then their
//! triangles.

use anyhow::{Context, Result, bail, ensure};
use glam::Vec3;
use relume::graph::Pipeline;
use relume::objects::{Bvh, Triangle};
use relume::stages::world::object_world;
use std::path::Path;
use std::time::Instant;

/// Files larger than this are refused before they are read (about 14 million
/// triangles or 22 million rays).
const MAX_FILE_BYTES: u64 = 512 << 20;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["dump", pipeline, out] => dump(Path::new(pipeline), Path::new(out)),
        ["trace", triangles, rays, hits, rest @ ..] => {
            let repeat = match rest {
                [] => 5,
                ["--repeat", n] => n.parse().context("--repeat takes a count")?,
                _ => bail!("trace: unexpected arguments {rest:?}"),
            };
            ensure!(repeat >= 1, "--repeat must be at least 1");
            trace(
                Path::new(triangles),
                Path::new(rays),
                Path::new(hits),
                repeat,
            )
        }
        _ => bail!(
            "usage: bvh_rate dump PIPELINE.toml TRIANGLES\n       \
             bvh_rate trace TRIANGLES RAYS HITS [--repeat N]"
        ),
    }
}

/// Writes the triangles of `pipeline`'s objects to `out`.
fn dump(pipeline: &Path, out: &Path) -> Result<()> {
    let pipeline = Pipeline::load(pipeline, &relume::stages::registry())?;
    let scene = object_world(&pipeline.world).scene_at(0)?;
    ensure!(
        !scene.triangles.is_empty(),
        "{} has no [[object]] triangles",
        pipeline.name
    );
    let floats: Vec<f32> = scene
        .triangles
        .iter()
        .flat_map(|t| t.vertices.iter().flat_map(|v| v.to_array()))
        .collect();
    std::fs::write(out, bytemuck::cast_slice(&floats))
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("{} triangles -> {}", scene.triangles.len(), out.display());
    Ok(())
}

/// The little-endian f32 values of `path`, in records of `record` values.
fn read_floats(path: &Path, record: usize) -> Result<Vec<f32>> {
    let size = std::fs::metadata(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .len();
    ensure!(
        size <= MAX_FILE_BYTES,
        "{}: {size} bytes, more than the {MAX_FILE_BYTES} this tool reads",
        path.display()
    );
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    ensure!(
        bytes.len() % (4 * record) == 0,
        "{}: {} bytes is not a whole number of {record}-float records",
        path.display(),
        bytes.len()
    );
    let floats: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(k) = floats.iter().position(|v| !v.is_finite()) {
        bail!(
            "{}: value {k} (record {}) is not a finite number",
            path.display(),
            k / record
        );
    }
    Ok(floats)
}

fn trace(triangles: &Path, rays: &Path, hits: &Path, repeat: usize) -> Result<()> {
    let triangles: Vec<Triangle> = read_floats(triangles, 9)?
        .chunks_exact(9)
        .map(|t| {
            let v = |k: usize| Vec3::new(t[3 * k], t[3 * k + 1], t[3 * k + 2]);
            let vertices = [v(0), v(1), v(2)];
            let n = relume::objects::tri_normal(&vertices);
            Triangle {
                vertices,
                normals: [n; 3],
                material: 0,
            }
        })
        .collect();
    let rays: Vec<(Vec3, Vec3)> = read_floats(rays, 6)?
        .chunks_exact(6)
        .map(|r| (Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5])))
        .collect();
    ensure!(!triangles.is_empty(), "no triangles");
    let start = Instant::now();
    let bvh = Bvh::build(&triangles);
    let build_s = start.elapsed().as_secs_f64();
    let mut found = vec![(f32::INFINITY, -1i32); rays.len()];
    let mut passes = Vec::with_capacity(repeat);
    for _ in 0..repeat {
        let start = Instant::now();
        for (slot, &(origin, dir)) in found.iter_mut().zip(&rays) {
            *slot = match bvh.nearest(origin, dir, 0.0, f32::INFINITY) {
                Some((t, id, _, _)) => (t, id as i32),
                None => (f32::INFINITY, -1),
            };
        }
        passes.push(start.elapsed().as_secs_f64());
    }
    let mut sorted = passes.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut out: Vec<u8> = Vec::with_capacity(rays.len() * 8);
    out.extend(found.iter().flat_map(|h| h.0.to_le_bytes()));
    out.extend(found.iter().flat_map(|h| h.1.to_le_bytes()));
    std::fs::write(hits, out).with_context(|| format!("cannot write {}", hits.display()))?;
    println!(
        "{{\"triangles\": {}, \"rays\": {}, \"build_s\": {build_s:.6}, \"pass_s\": {passes:?}, \
         \"rays_per_s\": {:.1}}}",
        triangles.len(),
        rays.len(),
        rays.len() as f64 / median
    );
    Ok(())
}
