//! `normals.cross` (paper 002, Sec. 4.2): normals from the cross product of neighbouring
//! positions, N(u, v) = (V(u+1, v) - V(u, v)) x (V(u, v+1) - V(u, v)) with forward
//! differences as in the paper, or central differences; normalized and turned to face
//! the camera. Invalid (zero) where a neighbour is missing or lies across a depth jump.
//!
//! It also writes `refined_depth`, as `normals.plane_fit` does, so that either stage
//! drops into a pipeline whose later stages read it: here it is the depth of the
//! points themselves (their z; 0 where a point is missing), nothing refined.

use crate::{OpError, kind};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{Image, Vec3Image};
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "step",
        ParamDefault::Int(1),
        "pixel distance to the neighbours",
    )
    .range(1.0, 16.0),
    ParamSpec::new(
        "difference",
        ParamDefault::Str("forward"),
        "forward: V(u+s) - V(u) as in paper 002; central: V(u+s) - V(u-s)",
    )
    .choices(&["forward", "central"]),
    ParamSpec::new(
        "max_depth_jump",
        ParamDefault::Float(0.1),
        "neighbours farther than this in depth (metres) from the centre make the normal invalid",
    )
    .range(0.0, 100.0),
];

pub const CROSS_INFO: StageInfo = StageInfo {
    kind: "normals.cross",
    summary: "normals from the cross product of neighbouring positions (paper 002 Sec. 4.2)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[("points", &[kind::POINTS])],
            &[
                ("normals", &[kind::NORMALS]),
                ("refined_depth", &[kind::DEPTH]),
            ],
        )
    },
    build: |ctx| {
        let p = ctx.params;
        Ok(Box::new(CrossNormals {
            points: ctx.input("points"),
            normals: ctx.output("normals"),
            refined_depth: ctx.output("refined_depth"),
            params: CrossParams {
                step: p.int("step") as usize,
                central: p.str("difference") == "central",
                max_depth_jump: p.float("max_depth_jump") as f32,
            },
        }))
    },
};

/// Parameters of [`cross_normals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CrossParams {
    pub step: usize,
    pub central: bool,
    pub max_depth_jump: f32,
}

impl Default for CrossParams {
    fn default() -> Self {
        CrossParams {
            step: 1,
            central: false,
            max_depth_jump: 0.1,
        }
    }
}

/// Computes unit normals facing the camera from a camera-space position map; zero where
/// invalid (missing neighbours, borders, depth jumps, degenerate cross products).
pub fn cross_normals(
    points: &Vec3Image,
    params: &CrossParams,
    normals: &mut Vec3Image,
) -> Result<(), OpError> {
    if !points.same_size(normals) {
        return Err(OpError::SizeMismatch(format!(
            "normal map is {}x{}, points are {}x{}",
            normals.width, normals.height, points.width, points.height
        )));
    }
    let (w, h, s) = (points.width as usize, points.height as usize, params.step);
    let at = |x: usize, y: usize| points.data[y * w + x];
    normals
        .data
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, n) in row.iter_mut().enumerate() {
                *n = Vec3::ZERO;
                let (x0, y0) = if params.central {
                    (x.wrapping_sub(s), y.wrapping_sub(s))
                } else {
                    (x, y)
                };
                if x0 >= w || y0 >= h || x + s >= w || y + s >= h {
                    continue;
                }
                let c = at(x, y);
                let (l, r, u, d) = (at(x0, y), at(x + s, y), at(x, y0), at(x, y + s));
                let all_valid = [c, l, r, u, d].iter().all(|p| p.is_finite());
                if !all_valid
                    || [l, r, u, d]
                        .iter()
                        .any(|p| (p.z - c.z).abs() > params.max_depth_jump)
                {
                    continue;
                }
                let cross = (r - l).cross(d - u);
                let len = cross.length();
                if len.is_nan() || len <= 1e-12 {
                    continue;
                }
                let unit = cross / len;
                *n = if unit.dot(c) > 0.0 { -unit } else { unit };
            }
        });
    Ok(())
}

struct CrossNormals {
    points: String,
    normals: String,
    refined_depth: String,
    params: CrossParams,
}

/// The depth of each point (its camera-space z), 0 where it is missing: what
/// `normals.cross` writes as `refined_depth`.
pub fn point_depth(points: &Vec3Image) -> Image<f32> {
    let data = points
        .data
        .iter()
        .map(|p| {
            let z = p.z;
            if p.is_finite() && relume_base::raster::depth_is_valid(z) {
                z
            } else {
                0.0
            }
        })
        .collect();
    Image::from_vec(points.width, points.height, data).expect("one depth per point")
}

impl Stage for CrossNormals {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let points = frame.points(&self.points)?;
        let mut normals = Image::filled(points.width, points.height, Vec3::ZERO);
        cross_normals(points, &self.params, &mut normals)?;
        let depth = point_depth(points);
        frame.insert(&self.normals, Product::new(kind::NORMALS, normals));
        frame.insert(&self.refined_depth, Product::new(kind::DEPTH, depth));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions of the plane z = 2 + 0.5 x seen by a pinhole camera, 0.01 rad per pixel.
    fn tilted_plane() -> Vec3Image {
        let (w, h) = (8u32, 6u32);
        let data = (0..h)
            .flat_map(|v| {
                (0..w).map(move |u| {
                    let (dx, dy) = (u as f32 * 0.01 - 0.04, v as f32 * 0.01 - 0.03);
                    // ray (dx, dy, 1) * t meets z = 2 + 0.5 x at t = 2 / (1 - 0.5 dx)
                    let t = 2.0 / (1.0 - 0.5 * dx);
                    Vec3::new(dx * t, dy * t, t)
                })
            })
            .collect();
        Image::from_vec(w, h, data).unwrap()
    }

    #[test]
    fn plane_normals_are_exact_and_face_the_camera() {
        let pts = tilted_plane();
        let expected = Vec3::new(0.5, 0.0, -1.0).normalize();
        for central in [false, true] {
            let mut n = Image::filled(8, 6, Vec3::ZERO);
            cross_normals(
                &pts,
                &CrossParams {
                    central,
                    ..Default::default()
                },
                &mut n,
            )
            .unwrap();
            let inner = n.at(3, 3);
            assert!((*inner - expected).length() < 1e-5, "{inner:?}");
            assert_eq!(*n.at(7, 3), Vec3::ZERO, "no right neighbour at the border");
        }
    }

    #[test]
    fn missing_neighbours_and_jumps_invalidate() {
        let mut pts = tilted_plane();
        pts.data[3 * 8 + 4] = Vec3::NAN;
        pts.data[2 * 8 + 1].z += 1.0;
        let mut n = Image::filled(8, 6, Vec3::ONE);
        cross_normals(&pts, &CrossParams::default(), &mut n).unwrap();
        assert_eq!(*n.at(3, 3), Vec3::ZERO, "right neighbour missing");
        assert_eq!(*n.at(1, 1), Vec3::ZERO, "lower neighbour across a jump");
        assert_ne!(*n.at(5, 4), Vec3::ZERO);
    }
}
