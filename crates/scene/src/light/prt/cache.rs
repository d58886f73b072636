//! The on-disk cache of [`Transfer`] vectors, keyed by the digest of the scene's
//! triangles and the transfer's settings, so a pipeline's objects are precomputed once
//! and later runs load them.
//!
//! File `prt-<digest>.bin` in the cache folder, little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `RLPRT002` |
//! | 16 | digest (two 64-bit hashes of the triangles, the sample count and the seed) |
//! | 4 | triangles T (u32) |
//! | 4 | vertices V (u32) |
//! | 4 | bounce vectors B (u32): 0, or V for a scene of several objects |
//! | 12 T | per triangle corner, its vertex index (u32) |
//! | 36 V | per vertex, the nine C_vk (f32) |
//! | 36 B | per vertex, the nine bounce coefficients B_vk (f32) |
//!
//! A file is written to a temporary name in the same folder and renamed, so a reader
//! never sees half of one. A file that does not match (size, magic, digest, an index out
//! of range, a non-finite value) is not used: the vectors are recomputed and the file
//! replaced. The folder is `RELUME_CACHE` when set (`off` disables the cache), else
//! `$XDG_CACHE_HOME/relume`, else `$HOME/.cache/relume`.

use super::{Transfer, TransferParams};
use crate::objects::VirtualScene;
use relume_base::cancel::Cancelled;
use relume_base::rng;
use relume_recording::writer::write_file_atomic;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"RLPRT002";
/// The version of [`Transfer::compute`]'s estimator, in the digest: bump it when the
/// directions, the ray offset or the estimate change, so old files are not used.
const ESTIMATOR_VERSION: u64 = 2;
const HEADER_BYTES: usize = 8 + 16 + 4 + 4 + 4;

/// What [`load_or_compute`] did.
#[derive(Debug)]
pub enum CacheOutcome {
    /// The vectors came from this file.
    Loaded(PathBuf),
    /// Computed and written to this file (`replaced`: an unusable file was there).
    Written { path: PathBuf, replaced: bool },
    /// Computed; the file could not be written (the reason).
    NotWritten { path: PathBuf, reason: String },
    /// Computed; no cache folder (`RELUME_CACHE=off`, or no home).
    Disabled,
}

/// The cache folder from the environment (see the module docs), or `None` when the
/// cache is off.
pub fn cache_dir_from_env() -> Option<PathBuf> {
    let non_empty = |name| std::env::var_os(name).filter(|v| !v.is_empty());
    if let Some(dir) = non_empty("RELUME_CACHE") {
        return (dir != "off").then(|| PathBuf::from(dir));
    }
    if let Some(xdg) = non_empty("XDG_CACHE_HOME") {
        return Some(PathBuf::from(xdg).join("relume"));
    }
    non_empty("HOME").map(|home| PathBuf::from(home).join(".cache").join("relume"))
}

/// The digest of `scene`'s triangles (corners and normals, bit for bit) and of the
/// settings that change the vectors, as 32 hex digits.
pub fn digest(scene: &VirtualScene, params: TransferParams) -> String {
    let mut words = vec![ESTIMATOR_VERSION, params.samples.max(1) as u64, params.seed];
    words.push(scene.triangles.len() as u64);
    for tri in &scene.triangles {
        for c in 0..3 {
            let (p, n) = (tri.vertices[c], tri.normals[c]);
            let bits = [p.x, p.y, p.z, n.x, n.y, n.z].map(|x| x.to_bits() as u64);
            words.extend([bits[0] << 32 | bits[1], bits[2] << 32 | bits[3]]);
            words.push(bits[4] << 32 | bits[5]);
        }
    }
    let fold = |salt: u64| {
        words
            .iter()
            .fold(salt, |acc, &w| rng::mix64(acc ^ rng::mix64(w)))
    };
    format!("{:016x}{:016x}", fold(0x5052_5431), fold(0x5052_5432))
}

/// The file of `digest` in `dir`.
pub fn cache_path(dir: &Path, digest: &str) -> PathBuf {
    dir.join(format!("prt-{digest}.bin"))
}

/// The file's bytes for `transfer` under `digest`.
pub fn encode(transfer: &Transfer, digest: &str) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(
        HEADER_BYTES
            + 4 * transfer.corner_vertex.len()
            + 36 * (transfer.vectors.len() + transfer.bounce.len()),
    );
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&digest_bytes(digest));
    bytes.extend_from_slice(&((transfer.corner_vertex.len() / 3) as u32).to_le_bytes());
    bytes.extend_from_slice(&(transfer.vectors.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&(transfer.bounce.len() as u32).to_le_bytes());
    for v in &transfer.corner_vertex {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    for vector in transfer.vectors.iter().chain(&transfer.bounce) {
        for c in vector {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    bytes
}

/// The 16 bytes of a 32-hex-digit digest (zeros for anything else).
fn digest_bytes(digest: &str) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = digest
            .get(2 * i..2 * i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0);
    }
    out
}

/// The transfer in `bytes` when they are a valid file for `digest` and a scene of
/// `triangles` triangles, else why not.
pub fn decode(bytes: &[u8], digest: &str, triangles: usize) -> Result<Transfer, String> {
    if bytes.len() < HEADER_BYTES || &bytes[..8] != MAGIC {
        return Err("not a relume transfer file".into());
    }
    if bytes[8..24] != digest_bytes(digest) {
        return Err("its digest is not the scene's".into());
    }
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let (t, v, b) = (word(24) as usize, word(28) as usize, word(32) as usize);
    if t != triangles {
        return Err(format!("it holds {t} triangles, the scene {triangles}"));
    }
    if b != 0 && b != v {
        return Err(format!("it holds {b} bounce vectors for {v} vertices"));
    }
    let expected = HEADER_BYTES as u128 + 12 * t as u128 + 36 * (v + b) as u128;
    if bytes.len() as u128 != expected {
        return Err(format!(
            "{} bytes where {expected} were expected",
            bytes.len()
        ));
    }
    let corners = &bytes[HEADER_BYTES..HEADER_BYTES + 12 * t];
    let corner_vertex: Vec<u32> = corners
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    let floats = &bytes[HEADER_BYTES + 12 * t..];
    let mut vectors: Vec<[f32; 9]> = floats
        .chunks_exact(36)
        .map(|chunk| {
            std::array::from_fn(|k| {
                f32::from_le_bytes(chunk[4 * k..4 * k + 4].try_into().expect("4 bytes"))
            })
        })
        .collect();
    if vectors.iter().flatten().any(|c| !c.is_finite()) {
        return Err("it holds non-finite coefficients".into());
    }
    let bounce = vectors.split_off(v);
    let transfer = Transfer {
        corner_vertex,
        vectors,
        bounce,
    };
    if !transfer.fits(triangles) {
        return Err("a corner's vertex index is out of range".into());
    }
    Ok(transfer)
}

/// The transfer of `scene` from the cache in `dir` when a valid file is there, else
/// computed (and written there when `dir` is given); [`Cancelled`] when the computation
/// was asked to stop (nothing is written then).
pub fn load_or_compute(
    scene: &VirtualScene,
    params: TransferParams,
    dir: Option<&Path>,
) -> Result<(Transfer, CacheOutcome), Cancelled> {
    let Some(dir) = dir else {
        return Ok((Transfer::compute(scene, params)?, CacheOutcome::Disabled));
    };
    let digest = digest(scene, params);
    let path = cache_path(dir, &digest);
    // A file larger than any for this scene (at most 3 vertices per triangle) is not
    // read at all.
    let largest = HEADER_BYTES as u64 + (12 + 2 * 36 * 3) * scene.triangles.len() as u64;
    let fits = std::fs::metadata(&path).is_ok_and(|m| m.len() <= largest);
    let existing = fits
        .then(|| relume_base::files::read_regular(&path).ok())
        .flatten();
    if let Some(bytes) = &existing
        && let Ok(transfer) = decode(bytes, &digest, scene.triangles.len())
    {
        return Ok((transfer, CacheOutcome::Loaded(path)));
    }
    let transfer = Transfer::compute(scene, params)?;
    let written = std::fs::create_dir_all(dir)
        .and_then(|_| write_file_atomic(&path, &encode(&transfer, &digest)));
    let outcome = match written {
        Ok(()) => CacheOutcome::Written {
            path,
            replaced: existing.is_some(),
        },
        Err(e) => CacheOutcome::NotWritten {
            path,
            reason: e.to_string(),
        },
    };
    Ok((transfer, outcome))
}
