//! Reading the framing of a `.sens` file: its header, and per frame the pose, stamps
//! and where the images lie (see the layout in [`super`]). Every size is checked
//! against the file's length before it is used.

use crate::types::{Intrinsics, Pose};
use glam::{DMat3, DMat4, DQuat};
use std::fs::File;
use std::io::{BufReader, Read};

/// The `.sens` version this importer reads.
pub const SENS_VERSION: u32 = 4;
/// Bytes of a frame before its images: a 4x4 f32 pose, two stamps, two sizes.
pub const FRAME_HEADER_BYTES: u64 = 64 + 4 * 8;
/// The longest sensor name accepted (ScanNet's are a few bytes).
const MAX_NAME_BYTES: u64 = 1 << 16;

/// Color compression types of the header (`color_compression_type`).
fn color_compression(code: i32) -> Result<i32, String> {
    match code {
        0..=2 => Ok(code),
        -1 => Err("color compression type -1 (unknown) cannot be read: \
                   raw (0), PNG (1) and JPEG (2) can"
            .into()),
        _ => Err(format!(
            "unknown color compression type {code}: raw (0), PNG (1) and JPEG (2) can be read"
        )),
    }
}

/// Depth compression types of the header (`depth_compression_type`).
fn depth_compression(code: i32) -> Result<i32, String> {
    let name = match code {
        0 | 1 => return Ok(code),
        -1 => "(unknown) ",
        2 => "(occi_ushort) ",
        _ => "",
    };
    let known = if name.is_empty() { "unknown " } else { "" };
    Err(format!(
        "{known}depth compression type {code} {name}cannot be read: raw_ushort (0) and \
         zlib_ushort (1) can"
    ))
}

/// The intrinsics in a row-major 4x4 matrix, for images of `width` x `height`.
pub fn intrinsics_from(m: &[f32; 16], width: u32, height: u32) -> Intrinsics {
    Intrinsics {
        width,
        height,
        fx: m[0] as f64,
        fy: m[5] as f64,
        cx: m[2] as f64,
        cy: m[6] as f64,
    }
}

/// The pose of a row-major camera-to-world matrix, or `None` when it is not a rigid
/// transform: a non-finite entry (ScanNet writes -inf where tracking was lost), a
/// rotation that is not orthonormal with determinant +1 (within 1e-3: f32 entries), or
/// a last row other than 0 0 0 1 (within 1e-5).
pub fn rigid_pose(m: &[f32; 16]) -> Option<Pose> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let values: Vec<f64> = m.iter().map(|&v| v as f64).collect();
    let m = DMat4::from_cols_slice(&values).transpose();
    let rotation = DMat3::from_mat4(m);
    let orthonormal = (rotation * rotation.transpose() - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|x| x.abs() < 1e-3);
    let last_row = m.row(3) - glam::DVec4::W;
    if !orthonormal || rotation.determinant() < 0.0 || last_row.abs().max_element() > 1e-5 {
        return None;
    }
    Some(Pose::from_parts(
        m.w_axis.truncate(),
        DQuat::from_mat3(&rotation),
    ))
}

/// A `.sens` file being read, with its position and length for the checks.
pub(super) struct Sens {
    pub(super) file: BufReader<File>,
    pub(super) len: u64,
    pub(super) pos: u64,
}

impl Sens {
    /// Fills `buf`, or says where the file ends (`what` is being read).
    pub(super) fn fill(&mut self, buf: &mut [u8], what: &str) -> Result<(), String> {
        if self.len - self.pos < buf.len() as u64 {
            return Err(format!(
                "truncated: the file ends at byte {}, in the {what}",
                self.len
            ));
        }
        self.file
            .read_exact(buf)
            .map_err(|e| format!("cannot read the {what}: {e}"))?;
        self.pos += buf.len() as u64;
        Ok(())
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], String> {
        let mut buf = [0; N];
        self.fill(&mut buf, what)?;
        Ok(buf)
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        self.array(what).map(u32::from_le_bytes)
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        self.array(what).map(u64::from_le_bytes)
    }

    fn matrix(&mut self, what: &str) -> Result<[f32; 16], String> {
        let bytes: [u8; 64] = self.array(what)?;
        Ok(std::array::from_fn(|i| {
            f32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap())
        }))
    }

    /// Skips `n` bytes of `what`, which must lie within the file.
    fn skip(&mut self, n: u64, what: &str) -> Result<(), String> {
        let left = self.len - self.pos;
        if n > left {
            return Err(format!(
                "{what} of {n} bytes is larger than the {left} bytes left in the file"
            ));
        }
        self.seek_to(self.pos + n, what)
    }

    pub(super) fn seek_to(&mut self, offset: u64, what: &str) -> Result<(), String> {
        self.file
            .seek_relative(offset as i64 - self.pos as i64)
            .map_err(|e| format!("cannot read the {what}: {e}"))?;
        self.pos = offset;
        Ok(())
    }
}

/// What the header says.
pub(super) struct SensHeader {
    pub(super) sensor: String,
    pub(super) color: Intrinsics,
    pub(super) depth: Intrinsics,
    pub(super) identity_extrinsics: bool,
    pub(super) color_type: i32,
    pub(super) depth_type: i32,
    pub(super) depth_shift: f32,
    pub(super) frames: u64,
}

pub(super) fn read_header(sens: &mut Sens) -> Result<SensHeader, String> {
    let truncated =
        |e: String| format!("truncated header: {}", e.trim_start_matches("truncated: "));
    let version = sens.u32("version").map_err(truncated)?;
    if version != SENS_VERSION {
        return Err(format!(
            "not a ScanNet .sens file of version {SENS_VERSION}: its version field is {version}"
        ));
    }
    let name_len = sens.u64("sensor name's length").map_err(truncated)?;
    if name_len > MAX_NAME_BYTES {
        return Err(format!(
            "the sensor name's length is {name_len} bytes, over {MAX_NAME_BYTES}: not a .sens header"
        ));
    }
    let mut name = vec![0; name_len as usize];
    sens.fill(&mut name, "sensor name").map_err(truncated)?;
    let mut matrices = [[0f32; 16]; 4];
    for (m, what) in matrices.iter_mut().zip([
        "color intrinsics",
        "color extrinsics",
        "depth intrinsics",
        "depth extrinsics",
    ]) {
        *m = sens.matrix(what).map_err(truncated)?;
    }
    let mut i32_field = |what: &str| sens.u32(what).map(|v| v as i32).map_err(truncated);
    let color_type = i32_field("color compression type")?;
    let depth_type = i32_field("depth compression type")?;
    let mut size = [0u32; 4];
    for (s, what) in
        size.iter_mut()
            .zip(["color width", "color height", "depth width", "depth height"])
    {
        *s = sens.u32(what).map_err(truncated)?;
    }
    let depth_shift = f32::from_bits(sens.u32("depth shift").map_err(truncated)?);
    let frames = sens.u64("frame count").map_err(truncated)?;
    color_compression(color_type)?;
    depth_compression(depth_type)?;
    let color = intrinsics_from(&matrices[0], size[0], size[1]);
    let depth = intrinsics_from(&matrices[2], size[2], size[3]);
    color
        .check()
        .map_err(|e| format!("color intrinsics: {e}"))?;
    depth
        .check()
        .map_err(|e| format!("depth intrinsics: {e}"))?;
    if !(depth_shift.is_finite() && depth_shift > 0.0) {
        return Err(format!(
            "depth shift {depth_shift} is not a finite positive number of units per metre"
        ));
    }
    // The depth unit is 1 / shift metres: bounded as a recording's (DEPTH_UNIT_RANGE_M).
    let (finest, coarsest) = crate::types::DEPTH_UNIT_RANGE_M;
    let (fewest, most) = (1.0 / coarsest, 1.0 / finest);
    if !(fewest..=most).contains(&(depth_shift as f64)) {
        return Err(format!(
            "depth shift {} units per metre is not a depth sensor's: it must lie between \
             {fewest} and {most} (a stored unit of {} m to {coarsest} m)",
            relume_base::pinhole::readable(depth_shift as f64),
            relume_base::pinhole::readable(finest)
        ));
    }
    let identity = glam::Mat4::IDENTITY.to_cols_array();
    let left = sens.len - sens.pos;
    if frames == 0 || frames > left / FRAME_HEADER_BYTES {
        return Err(format!(
            "the header says {frames} frames, but the {left} bytes after it hold {} \
             (each frame takes at least {FRAME_HEADER_BYTES} bytes)",
            if frames == 0 {
                "none to import".to_string()
            } else {
                format!("at most {}", left / FRAME_HEADER_BYTES)
            }
        ));
    }
    Ok(SensHeader {
        sensor: String::from_utf8_lossy(&name).into_owned(),
        color,
        depth,
        identity_extrinsics: matrices[1] == identity && matrices[3] == identity,
        color_type,
        depth_type,
        depth_shift,
        frames,
    })
}

/// Where a frame's images lie, and its pose.
pub(super) struct FrameInfo {
    pub(super) index: usize,
    pub(super) pose: Pose,
    pub(super) color_us: u64,
    pub(super) depth_us: u64,
    pub(super) color: (u64, u64),
    pub(super) depth: (u64, u64),
}

/// The most bytes a compressed image of `raw` bytes may take (or exactly `raw`).
fn size_limit(raw: u64, compressed: bool) -> u64 {
    if compressed { 2 * raw + (1 << 20) } else { raw }
}

/// Reads frame `k`'s header and skips its images; `None` when its pose is not rigid.
pub(super) fn scan_frame(
    sens: &mut Sens,
    k: usize,
    h: &SensHeader,
) -> Result<Option<FrameInfo>, String> {
    let pose = rigid_pose(&sens.matrix("camera-to-world matrix")?);
    let color_us = sens.u64("color timestamp")?;
    let depth_us = sens.u64("depth timestamp")?;
    let color_len = sens.u64("color size")?;
    let depth_len = sens.u64("depth size")?;
    let raw_color = h.color.width as u64 * h.color.height as u64 * 3;
    let raw_depth = h.depth.width as u64 * h.depth.height as u64 * 2;
    for (name, len, raw, compressed) in [
        ("color", color_len, raw_color, h.color_type != 0),
        ("depth", depth_len, raw_depth, h.depth_type != 0),
    ] {
        let limit = size_limit(raw, compressed);
        if len > limit || (!compressed && len != raw) {
            let (w, h) = if name == "color" {
                (h.color.width, h.color.height)
            } else {
                (h.depth.width, h.depth.height)
            };
            let bound = if compressed { "at most" } else { "exactly" };
            return Err(format!(
                "{name} size of {len} bytes is not what a {w}x{h} {name} image takes \
                 ({bound} {limit} bytes)"
            ));
        }
    }
    let color = (sens.pos, color_len);
    sens.skip(color_len, "color image")?;
    let depth = (sens.pos, depth_len);
    sens.skip(depth_len, "depth image")?;
    Ok(pose.map(|pose| FrameInfo {
        index: k,
        pose,
        color_us,
        depth_us,
        color,
        depth,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDENTITY: [f32; 16] = [
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];

    #[test]
    fn scannet_poses_must_be_finite_and_rigid() {
        let mut m = IDENTITY;
        m[3] = 2.0; // row-major: x translation
        let pose = rigid_pose(&m).unwrap();
        assert_eq!(pose.translation, [2.0, 0.0, 0.0]);
        assert_eq!(pose.rotation, [0.0, 0.0, 0.0, 1.0]);
        // Lost tracking: -inf everywhere, or any non-finite entry.
        assert!(rigid_pose(&[f32::NEG_INFINITY; 16]).is_none());
        let mut nan = IDENTITY;
        nan[7] = f32::NAN;
        assert!(rigid_pose(&nan).is_none());
        let mut scaled = IDENTITY;
        scaled[0] = 2.0;
        assert!(rigid_pose(&scaled).is_none());
        let mut mirrored = IDENTITY;
        mirrored[0] = -1.0;
        assert!(rigid_pose(&mirrored).is_none());
        let mut projective = IDENTITY;
        projective[12] = 0.5;
        assert!(rigid_pose(&projective).is_none());
        // A rotation about z by 90 degrees, in f32.
        let r = [
            0.0, -1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 1.0, 3.0, 0.0, 0.0, 0.0, 1.0,
        ];
        let pose = rigid_pose(&r).unwrap();
        let back = pose.matrix().transpose().to_cols_array();
        for (a, b) in back.iter().zip(r) {
            assert!((a - b as f64).abs() < 1e-12, "{back:?}");
        }
    }

    #[test]
    fn scannet_intrinsics_are_read_row_major() {
        let m = [
            525.0, 0.0, 319.5, 0.0, 0.0, 524.0, 239.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        let k = intrinsics_from(&m, 640, 480);
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (640, 480, 525.0, 524.0, 319.5, 239.5)
        );
    }

    #[test]
    fn scannet_compression_types_are_named() {
        assert_eq!(color_compression(2), Ok(2));
        assert_eq!(depth_compression(1), Ok(1));
        assert_eq!(
            color_compression(-1).unwrap_err(),
            "color compression type -1 (unknown) cannot be read: raw (0), PNG (1) and JPEG (2) can"
        );
        assert_eq!(
            depth_compression(-1).unwrap_err(),
            "depth compression type -1 (unknown) cannot be read: raw_ushort (0) and \
             zlib_ushort (1) can"
        );
        assert_eq!(
            depth_compression(9).unwrap_err(),
            "unknown depth compression type 9 cannot be read: raw_ushort (0) and \
             zlib_ushort (1) can"
        );
    }
}
