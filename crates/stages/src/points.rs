//! `depth.to_points`: back-projection of a depth map through the pinhole intrinsics to a
//! camera-space position map, X = (u - cx) z / fx, Y = (v - cy) z / fy, Z = z.

use crate::{OpError, kind};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{DepthImage, Image, Vec3Image, depth_is_valid};
use relume_graph::{Frame, Ports, Product, Stage, StageError, StageInfo};
use relume_recording::Intrinsics;

pub const INFO: StageInfo = StageInfo {
    kind: "depth.to_points",
    summary: "back-project depth (metres) to camera-space positions with the depth intrinsics",
    params: &[],
    ports: |_| Ports::fixed(&[("depth", &[kind::DEPTH])], &[("points", &[kind::POINTS])]),
    build: |ctx| {
        Ok(Box::new(DepthToPoints {
            depth: ctx.input("depth"),
            points: ctx.output("points"),
            intrinsics: ctx.header.depth_intrinsics,
        }))
    },
};

/// Back-projects `depth` into `points` (same size); missing depth gives a NaN position.
/// The intrinsics are rescaled when the image is not the size they were given for.
pub fn depth_to_points(
    depth: &DepthImage,
    intrinsics: &Intrinsics,
    points: &mut Vec3Image,
) -> Result<(), OpError> {
    if !depth.same_size(points) {
        return Err(OpError::SizeMismatch(format!(
            "point map is {}x{}, depth is {}x{}",
            points.width, points.height, depth.width, depth.height
        )));
    }
    let k = intrinsics.scaled_to(depth.width, depth.height);
    let (fx, fy, cx, cy) = (
        (1.0 / k.fx) as f32,
        (1.0 / k.fy) as f32,
        k.cx as f32,
        k.cy as f32,
    );
    let width = depth.width as usize;
    points
        .data
        .par_chunks_mut(width)
        .zip(depth.data.par_chunks(width))
        .enumerate()
        .for_each(|(v, (out, row))| {
            let y = (v as f32 - cy) * fy;
            for (u, (p, &z)) in out.iter_mut().zip(row).enumerate() {
                *p = if depth_is_valid(z) {
                    Vec3::new((u as f32 - cx) * fx * z, y * z, z)
                } else {
                    Vec3::NAN
                };
            }
        });
    Ok(())
}

struct DepthToPoints {
    depth: String,
    points: String,
    intrinsics: Intrinsics,
}

impl Stage for DepthToPoints {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let depth = frame.depth(&self.depth)?;
        let mut points = Image::filled(depth.width, depth.height, Vec3::NAN);
        depth_to_points(depth, &self.intrinsics, &mut points)?;
        frame.insert(&self.points, Product::new(kind::POINTS, points));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_projection_matches_the_pinhole_model() {
        let k = Intrinsics {
            width: 4,
            height: 3,
            fx: 2.0,
            fy: 4.0,
            cx: 1.5,
            cy: 1.0,
        };
        let mut depth = Image::filled(4, 3, 2.0f32);
        depth.data[5] = 0.0;
        let mut pts = Image::filled(4, 3, Vec3::ZERO);
        depth_to_points(&depth, &k, &mut pts).unwrap();
        // pixel (3, 2): X = (3 - 1.5) * 2 / 2, Y = (2 - 1) * 2 / 4
        assert_eq!(*pts.at(3, 2), Vec3::new(1.5, 0.5, 2.0));
        assert!(pts.at(1, 1).is_nan());
    }
}
