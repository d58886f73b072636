use super::*;

/// Samples on the six walls of a box room [-2, 2] x [0, 3] x [-2.5, 2.5], `spacing`
/// apart, each wall its own radiance: (wall + 1) / 6 in red, 1 in green.
fn box_room(spacing: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let (lo, hi) = (Vec3::new(-2.0, 0.0, -2.5), Vec3::new(2.0, 3.0, 2.5));
    let (mut positions, mut radiances) = (Vec::new(), Vec::new());
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let nu = ((hi[u] - lo[u]) / spacing) as u32;
        let nv = ((hi[v] - lo[v]) / spacing) as u32;
        for side in 0..2 {
            let wall = 2 * axis + side;
            for i in 0..=nu {
                for j in 0..=nv {
                    let mut p = Vec3::ZERO;
                    p[axis] = if side == 0 { lo[axis] } else { hi[axis] };
                    p[u] = lo[u] + i as f32 * spacing;
                    p[v] = lo[v] + j as f32 * spacing;
                    positions.push(p);
                    radiances.push(Vec3::new((wall + 1) as f32 / 6.0, 1.0, 0.0));
                }
            }
        }
    }
    (positions, radiances)
}

/// The exact distance to the room's walls from `o` along `d`, and the wall's radiance.
fn exact_hit(o: Vec3, d: Vec3) -> (f32, Vec3) {
    let (lo, hi) = (Vec3::new(-2.0, 0.0, -2.5), Vec3::new(2.0, 3.0, 2.5));
    let mut best = (f32::INFINITY, Vec3::ZERO);
    for axis in 0..3 {
        for side in 0..2 {
            let plane = if side == 0 { lo[axis] } else { hi[axis] };
            let t = (plane - o[axis]) / d[axis];
            if t > 0.0 && t < best.0 {
                best = (t, Vec3::new((2 * axis + side + 1) as f32 / 6.0, 1.0, 0.0));
            }
        }
    }
    best
}

fn directions(n: u32) -> Vec<Vec3> {
    // A Fibonacci sphere.
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f32 * 2.399_963;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

/// Mean |t_half - t| and the share of cones whose radiance is the wall's own, for
/// cones of `spread` from an off-centre point through a room voxelized at `voxel`.
fn cone_errors(voxel: f32, spread: f32) -> (f32, f32) {
    let (positions, radiances) = box_room(voxel * 0.5);
    let volume = VoxelVolume::from_points(&positions, &radiances, voxel).unwrap();
    let origin = Vec3::new(0.7, 1.1, -0.9);
    let dirs = directions(400);
    let (mut error, mut right) = (0.0, 0);
    for &d in &dirs {
        let (t, radiance) = exact_hit(origin, d);
        let m = volume.march(origin, d, spread, 0.0, f32::INFINITY);
        error += (m.t_half - t).abs();
        let seen = m.radiance / m.opacity;
        if (seen - radiance).abs().max_element() < 0.02 {
            right += 1;
        }
    }
    (error / dirs.len() as f32, right as f32 / dirs.len() as f32)
}

#[test]
fn a_narrow_cone_in_a_fine_volume_approaches_the_ray() {
    let (coarse_error, coarse_right) = cone_errors(0.1, 0.05);
    let (fine_error, fine_right) = cone_errors(0.025, 0.005);
    assert!(
        fine_error < 0.02,
        "fine: mean distance error {fine_error} m"
    );
    assert!(
        fine_error < coarse_error,
        "fine {fine_error} m, coarse {coarse_error} m"
    );
    assert!(
        fine_right > 0.95,
        "fine: {fine_right} of the cones see their wall"
    );
    assert!(fine_right >= coarse_right);
}

#[test]
fn a_wide_cone_averages_what_it_covers() {
    // Looking straight at the floor from 1 m, a 45-degree cone sees only floor.
    let (positions, radiances) = box_room(0.05);
    let volume = VoxelVolume::from_points(&positions, &radiances, 0.1).unwrap();
    let m = volume.march(Vec3::new(0.0, 1.0, 0.0), -Vec3::Y, 0.4, 0.0, f32::INFINITY);
    assert!(m.opacity > 0.9, "opacity {}", m.opacity);
    let floor = Vec3::new(3.0 / 6.0, 1.0, 0.0);
    let seen = m.radiance / m.opacity;
    assert!((seen - floor).abs().max_element() < 0.02, "saw {seen}");
    // Within the cone's radius there (0.4 m): the coarse level blurs the floor by it.
    assert!((m.t_half - 1.0).abs() < 0.25, "t_half {}", m.t_half);
}

#[test]
fn coarse_levels_keep_walls_opaque_seen_head_on() {
    let (positions, radiances) = box_room(0.1);
    let volume = VoxelVolume::from_points(&positions, &radiances, 0.2).unwrap();
    let top = volume.levels.last().unwrap();
    assert_eq!(top.dims, [1, 1, 1]);
    let finest = &volume.levels[0];
    assert_eq!(finest.axes, 1);
    assert!(volume.levels[1..].iter().all(|l| l.axes == 3));
    // Seen head-on, a wall stays opaque at every level: a coarse voxel holding a
    // stretch of the floor is opaque seen along y.
    for (l, level) in volume.levels.iter().enumerate().skip(1) {
        let size = volume.voxel_size * (1u32 << l) as f32;
        if size > 1.0 {
            break; // Coarser voxels reach past the room's walls.
        }
        let on_floor = Vec3::new(0.0, 1e-3, 0.0);
        let local = (on_floor - volume.origin) / size;
        let i = level.index(local.x as u32, local.y as u32, local.z as u32) * 3;
        assert!(
            level.voxels[i + 1].w > 0.99,
            "level {l}: {}",
            level.voxels[i + 1]
        );
    }
}

#[test]
fn empty_and_malformed_inputs() {
    let empty = VoxelVolume::from_points(&[], &[], 0.05).unwrap();
    assert!(empty.is_empty());
    assert_eq!(
        empty.march(Vec3::ZERO, Vec3::X, 0.1, 0.0, 10.0),
        ConeMarch::CLEAR
    );
    let nan_only = VoxelVolume::from_points(&[Vec3::NAN], &[Vec3::ONE], 0.05).unwrap();
    assert!(nan_only.is_empty());
    assert_eq!(
        VoxelVolume::from_points(&[Vec3::ZERO], &[], 0.05),
        Err(VoxelError::Lengths(1, 0))
    );
    assert_eq!(
        VoxelVolume::from_points(&[Vec3::ZERO], &[Vec3::ONE], 0.0),
        Err(VoxelError::VoxelSize(0.0))
    );
    // A single sample: a one-voxel volume, opaque at the sample.
    let one = VoxelVolume::from_points(&[Vec3::ONE], &[Vec3::X], 0.05).unwrap();
    assert_eq!(one.dims(), [1, 1, 1]);
    let at_sample = one.sample(Vec3::ONE, 0.0, Vec3::X);
    assert!(
        (at_sample - Vec4::new(1.0, 0.0, 0.0, 1.0))
            .abs()
            .max_element()
            < 1e-5
    );
}

#[test]
fn a_huge_extent_grows_the_voxels_not_the_memory() {
    let positions = [Vec3::ZERO, Vec3::new(1000.0, 1.0, 1.0)];
    let volume = VoxelVolume::from_points(&positions, &[Vec3::ONE; 2], 0.05).unwrap();
    assert!(volume.dims().iter().all(|&d| d <= MAX_DIM));
    assert!(volume.voxel_size > 3.9);
}
