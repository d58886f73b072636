//! The light model of one update as a compact binary record (paper 004 Secs. 3.2, 4.3
//! and 4.4: what the server sends the mobile clients, 32 bytes per area light plus 108
//! bytes of SH), written by `write` as `<frame>.val` and readable by any program.
//!
//! Layout, little-endian, no padding (8 + 32 M + 108 bytes for M lights):
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 4 | magic `RVAL` |
//! | 4 | 2 | version, 1 (u16) |
//! | 6 | 2 | M, the number of lights (u16) |
//! | 8 + 32 j | 12 | light j's position, world metres (3 x f32) |
//! | 20 + 32 j | 4 | its unit normal, octahedral-encoded: 2 x i16 snorm (below) |
//! | 24 + 32 j | 12 | its radiant intensity I_j, R G B (3 x f32; eq. 7) |
//! | 36 + 32 j | 4 | its area A_j, square metres (f32) |
//! | 8 + 32 M | 108 | the radiance SH coefficients C_k of the indirect light, k = 0..9 in [`super::sh`]'s order, R G B each (27 x f32) |
//!
//! The normal (x, y, z) is stored as the octahedral map of Meyer et al. ("On floating-point
//! normal vectors", 2010): p = (x, z) / (|x| + |y| + |z|); where y < 0, p = ((1 - |p.y|)
//! sign(p.x), (1 - |p.x|) sign(p.y)) (sign(0) = +1); each component as
//! round(clamp(c, -1, 1) * 32767). Decoding: (u, v) = stored / 32767, y = 1 - |u| - |v|;
//! where y < 0, (u, v) = ((1 - |v|) sign(u), (1 - |u|) sign(v)); normalize (u, y, v).
//! The angle between a unit normal and its decoded value is below 1e-4 rad.

use super::{AreaLight, AreaLights};
use glam::{Vec2, Vec3};

/// The record's magic bytes.
pub const MAGIC: &[u8; 4] = b"RVAL";
/// The layout version this code writes and reads.
pub const VERSION: u16 = 1;
/// Bytes per light.
pub const LIGHT_BYTES: usize = 32;
/// Bytes of the SH block.
pub const SH_BYTES: usize = 108;
const HEADER_BYTES: usize = 8;

/// Why bytes are not a light-model record.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RecordError {
    #[error("not a light-model record (its first bytes are not `RVAL`)")]
    Magic,
    #[error("light-model record version {0}; this build reads version 1")]
    Version(u16),
    #[error("light-model record of {lights} lights must be {expected} bytes, not {len}")]
    Length {
        lights: usize,
        expected: usize,
        len: usize,
    },
    #[error("light-model record: light {0} has a non-finite value")]
    NonFinite(usize),
    #[error("light-model record: its SH coefficients have a non-finite value")]
    NonFiniteSh,
    #[error("a light model of {0} lights does not fit a record (at most 65535)")]
    TooManyLights(usize),
}

/// The octahedral encoding of unit `n` (see the module docs); zero encodes as +y.
pub fn encode_normal(n: Vec3) -> [i16; 2] {
    let sign = |c: f32| if c >= 0.0 { 1.0 } else { -1.0 };
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    let mut p = if l1 > 0.0 && l1.is_finite() {
        Vec2::new(n.x, n.z) / l1
    } else {
        Vec2::ZERO
    };
    if n.y < 0.0 {
        p = Vec2::new((1.0 - p.y.abs()) * sign(p.x), (1.0 - p.x.abs()) * sign(p.y));
    }
    [p.x, p.y].map(|c| (c.clamp(-1.0, 1.0) * 32767.0).round() as i16)
}

/// The unit normal of an octahedral encoding (see the module docs).
pub fn decode_normal(e: [i16; 2]) -> Vec3 {
    let sign = |c: f32| if c >= 0.0 { 1.0 } else { -1.0 };
    let (mut u, mut v) = (e[0] as f32 / 32767.0, e[1] as f32 / 32767.0);
    let y = 1.0 - u.abs() - v.abs();
    if y < 0.0 {
        (u, v) = ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v));
    }
    Vec3::new(u, y, v).normalize_or(Vec3::Y)
}

/// The record of `model` (see the module docs).
pub fn encode(model: &AreaLights) -> Result<Vec<u8>, RecordError> {
    let m = model.lights.len();
    let count = u16::try_from(m).map_err(|_| RecordError::TooManyLights(m))?;
    let mut bytes = Vec::with_capacity(HEADER_BYTES + LIGHT_BYTES * m + SH_BYTES);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    bytes.extend_from_slice(&count.to_le_bytes());
    let floats = |bytes: &mut Vec<u8>, values: &[f32]| {
        for v in values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    };
    for light in &model.lights {
        floats(&mut bytes, &light.position.to_array());
        for c in encode_normal(light.normal) {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        floats(&mut bytes, &light.intensity.to_array());
        floats(&mut bytes, &[light.area]);
    }
    for c in &model.sh9 {
        floats(&mut bytes, &c.to_array());
    }
    Ok(bytes)
}

/// The light model in a record (normals as decoded; every other value exact).
pub fn decode(bytes: &[u8]) -> Result<AreaLights, RecordError> {
    if bytes.len() < HEADER_BYTES || &bytes[..4] != MAGIC {
        return Err(RecordError::Magic);
    }
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != VERSION {
        return Err(RecordError::Version(version));
    }
    let m = u16::from_le_bytes([bytes[6], bytes[7]]) as usize;
    let expected = HEADER_BYTES + LIGHT_BYTES * m + SH_BYTES;
    if bytes.len() != expected {
        return Err(RecordError::Length {
            lights: m,
            expected,
            len: bytes.len(),
        });
    }
    let f = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let v3 = |at: usize| Vec3::new(f(at), f(at + 4), f(at + 8));
    let i16_at = |at: usize| i16::from_le_bytes([bytes[at], bytes[at + 1]]);
    let mut lights = Vec::with_capacity(m);
    for j in 0..m {
        let at = HEADER_BYTES + LIGHT_BYTES * j;
        let light = AreaLight {
            position: v3(at),
            normal: decode_normal([i16_at(at + 12), i16_at(at + 14)]),
            intensity: v3(at + 16),
            area: f(at + 28),
        };
        let finite = light.position.is_finite() && light.intensity.is_finite();
        if !(finite && light.area.is_finite()) {
            return Err(RecordError::NonFinite(j));
        }
        lights.push(light);
    }
    let sh_at = HEADER_BYTES + LIGHT_BYTES * m;
    let sh9: [Vec3; 9] = std::array::from_fn(|k| v3(sh_at + 12 * k));
    if sh9.iter().any(|c| !c.is_finite()) {
        return Err(RecordError::NonFiniteSh);
    }
    Ok(AreaLights { lights, sh9 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> AreaLights {
        AreaLights {
            lights: vec![
                AreaLight {
                    position: Vec3::new(0.5, 2.4, -1.0),
                    normal: Vec3::new(0.0, -1.0, 0.0),
                    intensity: Vec3::new(3.0, 2.5, 2.0),
                    area: 0.25,
                },
                AreaLight {
                    position: Vec3::new(-1.5, 1.0, 2.0),
                    normal: Vec3::new(0.6, 0.0, -0.8),
                    intensity: Vec3::new(0.5, 0.75, 1.0),
                    area: 1.5,
                },
            ],
            sh9: std::array::from_fn(|k| Vec3::new(k as f32, 0.5 * k as f32, -0.25)),
        }
    }

    /// The angle between two unit vectors, exact near 0 (acos of the dot is not in f32).
    fn angle(a: Vec3, b: Vec3) -> f32 {
        a.cross(b).length().atan2(a.dot(b))
    }

    fn floats(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    fn snorm(values: [f32; 2]) -> Vec<u8> {
        values
            .iter()
            .flat_map(|c| ((c * 32767.0).round() as i16).to_le_bytes())
            .collect()
    }

    #[test]
    fn the_record_is_the_documented_bytes() {
        // The bytes written from the module's table alone.
        let sh: Vec<f32> = (0..9)
            .flat_map(|k| [k as f32, 0.5 * k as f32, -0.25])
            .collect();
        let expected = [
            b"RVAL".to_vec(),
            1u16.to_le_bytes().to_vec(),
            2u16.to_le_bytes().to_vec(),
            floats(&[0.5, 2.4, -1.0]),
            // (0, -1, 0): p = (0, 0), folded to (1, 1) (sign(0) = +1).
            snorm([1.0, 1.0]),
            floats(&[3.0, 2.5, 2.0, 0.25]),
            floats(&[-1.5, 1.0, 2.0]),
            // (0.6, 0, -0.8): p = (x, z) / 1.4, not folded (y = 0).
            snorm([0.6 / 1.4, -0.8 / 1.4]),
            floats(&[0.5, 0.75, 1.0, 1.5]),
            floats(&sh),
        ]
        .concat();
        let bytes = encode(&model()).unwrap();
        assert_eq!(bytes.len(), 8 + 2 * 32 + 108);
        assert_eq!(bytes, expected);
    }

    #[test]
    fn decoding_gives_the_model_back() {
        let model = model();
        let back = decode(&encode(&model).unwrap()).unwrap();
        assert_eq!(back.sh9, model.sh9);
        for (a, b) in back.lights.iter().zip(&model.lights) {
            assert_eq!(
                (a.position, a.intensity, a.area),
                (b.position, b.intensity, b.area)
            );
            assert!(
                angle(a.normal, b.normal) < 1e-4,
                "{} {}",
                a.normal,
                b.normal
            );
        }
    }

    #[test]
    fn normals_survive_the_octahedral_encoding_everywhere() {
        let mut worst = 0.0f32;
        for i in 0..2000u32 {
            // A Fibonacci sphere: every octant and both hemispheres.
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / 2000.0;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - y * y).sqrt();
            let n = Vec3::new(r * phi.cos(), y, r * phi.sin());
            worst = worst.max(angle(decode_normal(encode_normal(n)), n));
        }
        for n in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            worst = worst.max(angle(decode_normal(encode_normal(n)), n));
        }
        assert!(worst < 1e-4, "{worst}");
    }

    #[test]
    fn damaged_records_are_errors_that_say_what_is_wrong() {
        let bytes = encode(&model()).unwrap();
        assert_eq!(decode(b"PNG\0xxxx"), Err(RecordError::Magic));
        let mut v2 = bytes.clone();
        v2[4] = 2;
        assert_eq!(
            decode(&v2).unwrap_err().to_string(),
            "light-model record version 2; this build reads version 1"
        );
        let short = &bytes[..bytes.len() - 1];
        assert_eq!(
            decode(short).unwrap_err().to_string(),
            "light-model record of 2 lights must be 180 bytes, not 179"
        );
        let mut nan = bytes.clone();
        nan[8 + 32 + 28..8 + 32 + 32].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(decode(&nan), Err(RecordError::NonFinite(1)));
        let mut nan_sh = bytes;
        let last = nan_sh.len() - 4;
        nan_sh[last..].copy_from_slice(&f32::INFINITY.to_le_bytes());
        assert_eq!(decode(&nan_sh), Err(RecordError::NonFiniteSh));
    }
}
