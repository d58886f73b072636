//! Tests of the splat: footprints, depth tests, ties, culling, thread counts.

use super::*;
use glam::{DQuat, DVec3};
use relume_recording::Intrinsics;

fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, 160, 120)
}

/// Samples on a 5 cm grid over the plane n . X = n . X0 around X0 (camera space of
/// `pose`), returned in world space.
fn plane_cloud(pose: &Pose, centre: Vec3, normal: Vec3, half_extent: f32) -> EnvCloud {
    let m = pose.matrix().as_mat4();
    let tangent = normal.any_orthonormal_vector();
    let bitangent = normal.cross(tangent);
    let steps = (half_extent / 0.05) as i32;
    let mut cloud = EnvCloud::default();
    for i in -steps..=steps {
        for j in -steps..=steps {
            let p = centre + tangent * (i as f32 * 0.05) + bitangent * (j as f32 * 0.05);
            cloud.positions.push(m.transform_point3(p));
            cloud.colors.push(Vec3::new(0.25, 0.5, (i + j) as f32));
            cloud.normals.push(m.transform_vector3(-normal));
        }
    }
    cloud
}

fn splat_all(cloud: &EnvCloud, pose: &Pose, params: &SplatParams) -> GBuffer {
    let cam = camera();
    let mut out = GBuffer::new(cam.width, cam.height);
    splat(
        cloud,
        pose,
        &cam,
        params,
        &mut SplatBuffer::default(),
        &mut out,
    )
    .unwrap();
    out
}

#[test]
fn a_tilted_plane_splats_to_its_exact_depth_and_normal() {
    let pose = Pose::from_parts(DVec3::new(1.0, 2.0, -0.5), DQuat::from_rotation_y(0.4));
    // The plane z = 2 + 0.4 x (camera space): normal (0.4, 0, -1) facing the camera.
    let normal = Vec3::new(-0.4, 0.0, 1.0).normalize();
    let cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), normal, 2.0);
    let out = splat_all(&cloud, &pose, &SplatParams::default());
    let cam = camera();
    let facing = -normal;
    let mut hits = 0;
    for y in 30..90 {
        for x in 40..120 {
            let i = y * 160 + x;
            if out.coverage.data[i] != COVERAGE_SPLAT {
                continue;
            }
            hits += 1;
            let ray = cam.ray(x as f32, y as f32);
            let expected = 2.0 / (1.0 - 0.4 * ray.x);
            assert!((out.depth.data[i] - expected).abs() < 1e-4, "({x}, {y})");
            assert!((out.normals.data[i] - facing).length() < 1e-5);
            assert_eq!(out.color.data[i].x, 0.25);
        }
    }
    assert!(hits > 60 * 80 * 9 / 10, "most pixels are hit: {hits}");
}

#[test]
fn the_nearest_sample_wins_and_covers_its_footprint() {
    let pose = Pose::IDENTITY;
    let mut cloud = EnvCloud::default();
    // Far sample first, near sample second, both on the optical axis; a third one
    // exactly as near as the second (tie: the lower index wins).
    for (z, tag) in [(3.0, 0.0), (1.0, 1.0), (1.0, 2.0)] {
        cloud.positions.push(Vec3::new(0.0, 0.0, z));
        cloud.colors.push(Vec3::splat(tag));
        cloud.normals.push(Vec3::Z);
    }
    let params = SplatParams {
        radius: 0.01,
        max_radius_px: 64.0,
        ..SplatParams::default()
    };
    let out = splat_all(&cloud, &pose, &params);
    // Both project to (79.5, 59.5). Near: radius 0.01 * 131.25 / 1 = 1.3 px; far:
    // 0.44 px, raised to 0.75. The 4 nearest centres lie at 0.71 px, the next 8 at
    // 1.58 px: both cover the same 4 pixels and the near one wins them all.
    for (x, y) in [(79, 59), (80, 59), (79, 60), (80, 60)] {
        let i = y * 160 + x;
        assert_eq!(out.depth.data[i], 1.0);
        assert_eq!(out.color.data[i], Vec3::splat(1.0), "tie: lower index");
        assert_eq!(
            out.normals.data[i],
            Vec3::NEG_Z,
            "turned towards the camera"
        );
    }
    let covered = out
        .coverage
        .data
        .iter()
        .filter(|&&c| c == COVERAGE_SPLAT)
        .count();
    assert_eq!(covered, 4);
    assert!(out.color.data[0].is_nan() && out.depth.data[0] == 0.0);
    assert_eq!(out.normals.data[0], Vec3::ZERO);
}

#[test]
fn deterministic_for_any_thread_count() {
    let pose = Pose::from_parts(DVec3::new(0.1, 0.0, 0.0), DQuat::from_rotation_x(0.1));
    let mut cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), Vec3::NEG_Z, 1.5);
    // A second, interpenetrating plane makes many exact and near ties.
    let other = plane_cloud(
        &pose,
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(0.3, 0.1, -1.0).normalize(),
        1.5,
    );
    cloud.positions.extend(&other.positions);
    cloud.colors.extend(&other.colors);
    cloud.normals.extend(&other.normals);
    let run = || splat_all(&cloud, &pose, &SplatParams::default());
    let a = relume_base::threads::with_threads(1, run);
    let b = relume_base::threads::with_threads(3, run);
    assert_eq!(a.bits(), b.bits());
}

#[test]
fn empty_cloud_and_samples_behind_the_camera_leave_no_data() {
    let pose = Pose::IDENTITY;
    let mut cloud = EnvCloud::default();
    let out = splat_all(&cloud, &pose, &SplatParams::default());
    assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
    cloud.positions.push(Vec3::new(0.0, 0.0, -1.0));
    cloud.colors.push(Vec3::ONE);
    cloud.normals.push(Vec3::Z);
    cloud.positions.push(Vec3::new(0.0, 0.0, 1.0));
    cloud.colors.push(Vec3::NAN);
    cloud.normals.push(Vec3::Z);
    let out = splat_all(&cloud, &pose, &SplatParams::default());
    assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
    assert!(out.depth.data.iter().all(|&d| d == 0.0));
}

/// Occlusion culling drops a sample whose centre lies more than the margin behind the
/// nearest centre of the 3x3 pixels around its own centre pixel, and only such samples:
/// a sample beside a nearer one is culled (its pixel stays uncovered, since the nearer
/// sample's footprint does not reach it), one two pixels away is not, nor one within
/// the margin, nor one exactly the margin behind; an infinite margin culls nothing.
#[test]
fn occlusion_culling_drops_samples_behind_a_nearer_centre_only() {
    let cam = camera();
    // Footprints of 0.75 px (the minimum): each sample covers its centre pixel alone.
    // `apart` is two rows below the others: outside both their 3x3 neighbourhoods.
    let (front, beside, apart) = ((40, 60), (41, 60), (40, 62));
    let cloud_with = |beside_z: f32| {
        let mut cloud = EnvCloud::default();
        for (tag, ((x, y), z)) in [(front, 1.0), (beside, beside_z), (apart, 2.0)]
            .into_iter()
            .enumerate()
        {
            cloud
                .positions
                .push(cam.back_project(x as f32, y as f32, z));
            cloud.colors.push(Vec3::splat(tag as f32));
            cloud.normals.push(Vec3::Z);
        }
        cloud
    };
    let params = |margin: f32| SplatParams {
        radius: 0.001,
        max_radius_px: 64.0,
        occlusion_margin: margin,
    };
    let drawn = |out: &GBuffer, (x, y): (usize, usize)| {
        let i = y * 160 + x;
        (out.coverage.data[i] == COVERAGE_SPLAT).then(|| out.color.data[i].x)
    };
    for (beside_z, margin, beside_drawn) in [
        (2.0, 0.1, false),
        (2.0, 1.0, true),
        (2.0, f32::INFINITY, true),
        (1.05, 0.1, true),
    ] {
        let out = splat_all(&cloud_with(beside_z), &Pose::IDENTITY, &params(margin));
        let case = format!("beside at z = {beside_z}, margin {margin}");
        assert_eq!(drawn(&out, front), Some(0.0), "{case}");
        assert_eq!(drawn(&out, beside), beside_drawn.then_some(1.0), "{case}");
        assert_eq!(drawn(&out, apart), Some(2.0), "{case}");
        let covered = out.coverage.data.iter().filter(|&&c| c == COVERAGE_SPLAT);
        assert_eq!(covered.count(), 2 + beside_drawn as usize, "{case}");
    }
}
