//! Binary PLY export of the environment-sample cloud: little-endian float x, y, z,
//! uchar red, green, blue (the compensated linear color tone-mapped for viewing),
//! float nx, ny, nz and float r_linear, g_linear, b_linear (the HDR value itself).
//! MeshLab and CloudCompare read the standard properties and keep the extra ones.

use crate::composite::GammaEncoder;
use relume_scene::light::EnvCloud;
use std::io::Write;
use std::sync::OnceLock;

/// The 8-bit display value of a linear color channel: clamp to [0, 1], gamma 1/2.2,
/// rounded to the nearest level (0 for NaN). By table lookup ([`GammaEncoder`]): a
/// `powf` per channel was more than half of the default pipeline's `write` stage.
pub fn display_level(linear: f32) -> u8 {
    static DISPLAY: OnceLock<GammaEncoder> = OnceLock::new();
    DISPLAY.get_or_init(|| GammaEncoder::new(2.2)).level(linear)
}

/// Encodes `cloud` as a binary little-endian PLY file.
pub fn ply_bytes(cloud: &EnvCloud) -> Vec<u8> {
    let n = cloud.len();
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment relume environment samples (paper 000 Sec. 5)\n\
         element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float r_linear\nproperty float g_linear\nproperty float b_linear\nend_header\n"
    );
    let mut out = Vec::with_capacity(header.len() + n * 39);
    out.extend_from_slice(header.as_bytes());
    for i in 0..n {
        let (p, c, nrm) = (cloud.positions[i], cloud.colors[i], cloud.normals[i]);
        for v in p.to_array() {
            out.write_all(&v.to_le_bytes()).expect("writing to a Vec");
        }
        out.extend(c.to_array().map(display_level));
        for v in nrm.to_array().into_iter().chain(c.to_array()) {
            out.write_all(&v.to_le_bytes()).expect("writing to a Vec");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn ply_has_a_standard_header_and_39_bytes_per_vertex() {
        let cloud = EnvCloud {
            positions: vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 0.0)],
            colors: vec![Vec3::new(1.0, 0.0, 4.0), Vec3::splat(0.5)],
            normals: vec![Vec3::Z, Vec3::X],
        };
        let bytes = ply_bytes(&cloud);
        let text = String::from_utf8_lossy(&bytes);
        let end = text.find("end_header\n").unwrap() + "end_header\n".len();
        assert!(text.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(text.contains("element vertex 2\n"));
        assert_eq!(bytes.len(), end + 2 * 39);
        let body = &bytes[end..];
        assert_eq!(f32::from_le_bytes(body[8..12].try_into().unwrap()), 3.0);
        assert_eq!(&body[12..15], &[255, 0, 255]);
        assert_eq!(f32::from_le_bytes(body[23..27].try_into().unwrap()), 1.0);
        assert_eq!(f32::from_le_bytes(body[35..39].try_into().unwrap()), 4.0);
        assert_eq!(&body[39 + 12..39 + 15], &[186, 186, 186]);
    }
}
