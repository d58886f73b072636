use super::cache::{self, CacheOutcome};
use super::*;
use crate::light::sh::sh9_irradiance;
use crate::objects::{Material, VirtualScene, ray_triangle, shapes};

/// A sky-like low-frequency light: brighter above (+y), warmer towards +x.
fn light() -> [Vec3; 9] {
    let mut c = [Vec3::ZERO; 9];
    c[0] = Vec3::new(1.0, 0.9, 0.8);
    c[1] = Vec3::new(0.6, 0.6, 0.7);
    c[3] = Vec3::new(0.25, 0.1, 0.0);
    c[6] = Vec3::splat(0.1);
    c[8] = Vec3::new(0.05, 0.0, 0.05);
    c
}

fn scene(triangles: Vec<crate::objects::Triangle>) -> VirtualScene {
    VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY])
}

/// The paper's torus: it shadows itself through its hole and on its inner side.
fn torus() -> VirtualScene {
    scene(shapes::torus(0.25, 0.09, 32, 16))
}

/// The occluded irradiance of radiance `sh` at a vertex by brute force: `side^2`
/// stratified uniform-hemisphere directions (another distribution and another seed than
/// the transfer's), L(w) V(w) cos(theta) summed directly.
fn brute_force(scene: &VirtualScene, p: Vec3, n: Vec3, sh: &[Vec3; 9], side: u64) -> DVec3 {
    let n = n.normalize().as_dvec3();
    let (t1, t2) = n.any_orthonormal_pair();
    let bounds = scene.bounds();
    let origin = p + n.as_vec3() * ((bounds.max - bounds.min).length() * 1e-4).max(1e-5);
    let mut sum = DVec3::ZERO;
    for cell in 0..side * side {
        let h = rng::hash(&[99, cell]);
        let z = ((cell / side) as f64 + rng::unit_f64(h)) / side as f64;
        let phi =
            std::f64::consts::TAU * ((cell % side) as f64 + rng::unit_f64(h >> 7)) / side as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let d = (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * z).normalize();
        if scene.occluded(origin, d.as_vec3(), 0.0, f32::INFINITY) {
            continue;
        }
        let radiance = sh
            .iter()
            .zip(sh9_basis(d))
            .fold(DVec3::ZERO, |l, (c, y)| l + c.as_dvec3() * y);
        sum += radiance * z;
    }
    // Uniform hemisphere: pdf 1 / (2 pi).
    sum * std::f64::consts::TAU / (side * side) as f64
}

#[test]
fn an_unoccluded_vertex_gets_the_clamped_cosine_irradiance() {
    // Every vertex of a sphere sees its whole hemisphere.
    let sphere = scene(shapes::sphere(0.2, 16));
    let transfer = Transfer::compute(&sphere, TransferParams::default()).unwrap();
    let (vertices, _) = scene_vertices(&sphere);
    let sh = light();
    for (vector, &(_, normal)) in transfer.vectors.iter().zip(&vertices) {
        let prt = Transfer::irradiance(vector, &sh);
        let exact = sh9_irradiance(&sh, normal.normalize());
        let err = (prt - exact).length() / exact.length();
        assert!(err < 0.01, "normal {normal}: {prt} vs {exact} ({err})");
    }
}

#[test]
fn transfer_is_within_two_percent_of_brute_force_occluded_irradiance() {
    let torus = torus();
    let transfer = Transfer::compute(&torus, TransferParams::default()).unwrap();
    let (vertices, _) = scene_vertices(&torus);
    let sh = light();
    let (mut worst, mut occluded) = (0.0f64, 0);
    // Every 7th vertex: all around the tube, inner and outer sides, top and bottom.
    for (v, &(p, n)) in vertices.iter().enumerate().step_by(7) {
        let prt = Transfer::irradiance(&transfer.vectors[v], &sh).as_dvec3();
        let reference = brute_force(&torus, p, n, &sh, 256);
        let unoccluded = sh9_irradiance(&sh, n.normalize()).as_dvec3();
        if reference.length() < 0.97 * unoccluded.length() {
            occluded += 1;
        }
        let err = (prt - reference).length() / reference.length();
        worst = worst.max(err);
    }
    assert!(worst < 0.02, "worst relative error {worst}");
    // The test means something: many of these vertices are shadowed by the torus.
    assert!(occluded > 20, "only {occluded} occluded vertices");
}

#[test]
fn transfer_is_the_same_on_one_and_three_threads() {
    let torus = torus();
    let params = TransferParams {
        samples: 64,
        seed: 5,
    };
    let on = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| Transfer::compute(&torus, params))
    };
    assert_eq!(on(1), on(3));
}

#[test]
fn barycentrics_of_a_hit_are_the_ray_tests() {
    let tri = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.1, 0.0),
        Vec3::new(0.2, 0.0, 1.0),
    ];
    let origin = Vec3::new(0.3, 2.0, 0.25);
    let dir = (Vec3::new(0.35, 0.05, 0.3) - origin).normalize();
    let (t, u, v) = ray_triangle(origin, dir, &tri, 0.0, f32::INFINITY).unwrap();
    let (bu, bv) = barycentrics(&tri, origin + dir * t);
    assert!(
        (bu - u).abs() < 1e-5 && (bv - v).abs() < 1e-5,
        "{bu} {bv} vs {u} {v}"
    );
}

#[test]
fn interpolation_weights_the_corners() {
    let torus = torus();
    let transfer = Transfer::compute(&torus, TransferParams::default()).unwrap();
    let corner = |c: usize| transfer.vectors[transfer.corner_vertex[3 * 10 + c] as usize];
    assert_eq!(transfer.at(10, 0.0, 0.0), corner(0));
    assert_eq!(transfer.at(10, 1.0, 0.0), corner(1));
    let mid = transfer.at(10, 0.5, 0.5);
    for (k, m) in mid.iter().enumerate() {
        assert!((m - 0.5 * (corner(1)[k] + corner(2)[k])).abs() < 1e-6);
    }
}

/// Few directions: the cache tests need vectors, not accurate ones.
const FEW: TransferParams = TransferParams {
    samples: 16,
    seed: 1,
};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("relume-prt-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn the_cache_writes_once_then_loads_the_same_vectors() {
    let dir = temp_dir("roundtrip");
    let torus = torus();
    let params = FEW;
    let (computed, outcome) = cache::load_or_compute(&torus, params, Some(&dir)).unwrap();
    let CacheOutcome::Written { path, replaced } = outcome else {
        panic!("{outcome:?}")
    };
    assert!(!replaced);
    let name = path.file_name().unwrap().to_str().unwrap();
    assert_eq!(name, format!("prt-{}.bin", cache::digest(&torus, params)));
    // Only the file: no temporary left behind.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    let (loaded, outcome) = cache::load_or_compute(&torus, params, Some(&dir)).unwrap();
    assert!(
        matches!(outcome, CacheOutcome::Loaded(ref p) if *p == path),
        "{outcome:?}"
    );
    assert_eq!(loaded, computed);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_digest_follows_the_geometry_and_the_settings() {
    let torus = torus();
    let params = FEW;
    let base = cache::digest(&torus, params);
    assert_eq!(base.len(), 32);
    let mut moved = torus.clone();
    moved.triangles[5].vertices[1].x += 1e-6;
    assert_ne!(cache::digest(&moved, params), base);
    let more = TransferParams {
        samples: 25,
        ..params
    };
    assert_ne!(cache::digest(&torus, more), base);
    let reseeded = TransferParams { seed: 2, ..params };
    assert_ne!(cache::digest(&torus, reseeded), base);
    assert_eq!(cache::digest(&torus.clone(), params), base);
}

#[test]
fn a_damaged_cache_file_is_recomputed_and_replaced() {
    let dir = temp_dir("damaged");
    let torus = torus();
    let params = FEW;
    let (good, _) = cache::load_or_compute(&torus, params, Some(&dir)).unwrap();
    let digest = cache::digest(&torus, params);
    let path = cache::cache_path(&dir, &digest);
    let bytes = std::fs::read(&path).unwrap();
    let n = torus.triangles.len();

    let truncated = &bytes[..bytes.len() - 4];
    let expected = format!(
        "{} bytes where {} were expected",
        bytes.len() - 4,
        bytes.len()
    );
    assert_eq!(cache::decode(truncated, &digest, n).unwrap_err(), expected);
    let mut nan = bytes.clone();
    let last = nan.len() - 4;
    nan[last..].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(
        cache::decode(&nan, &digest, n).unwrap_err(),
        "it holds non-finite coefficients"
    );
    let mut index = bytes.clone();
    index[36..40].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(
        cache::decode(&index, &digest, n).unwrap_err(),
        "a corner's vertex index is out of range"
    );
    let vertices = good.vectors.len();
    let mut bounce_count = bytes.clone();
    bounce_count[32..36].copy_from_slice(&7u32.to_le_bytes());
    assert_eq!(
        cache::decode(&bounce_count, &digest, n).unwrap_err(),
        format!("it holds 7 bounce vectors for {vertices} vertices")
    );
    let other = cache::digest(
        &torus,
        TransferParams {
            samples: 4,
            seed: 1,
        },
    );
    assert_eq!(
        cache::decode(&bytes, &other, n).unwrap_err(),
        "its digest is not the scene's"
    );
    assert_eq!(
        cache::decode(b"hello", &digest, n).unwrap_err(),
        "not a relume transfer file"
    );

    std::fs::write(&path, truncated).unwrap();
    let (again, outcome) = cache::load_or_compute(&torus, params, Some(&dir)).unwrap();
    assert!(
        matches!(outcome, CacheOutcome::Written { replaced: true, .. }),
        "{outcome:?}"
    );
    assert_eq!(again, good);
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two unit-radius-apart spheres, objects 0 and 1 (materials 0 and 1).
fn two_spheres(radius: f32, gap: f32) -> VirtualScene {
    let mut triangles = shapes::sphere(radius, 24);
    let mut other = shapes::sphere(radius, 24);
    for t in &mut other {
        t.material = 1;
        for v in &mut t.vertices {
            v.x += 2.0 * radius + gap;
        }
    }
    triangles.extend(other);
    VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY; 2])
}

#[test]
fn one_object_has_no_bounce_transfer() {
    let transfer = Transfer::compute(&torus(), FEW).unwrap();
    assert!(transfer.bounce.is_empty());
    assert_eq!(transfer.bounce_at(0, 0.2, 0.3), None);
}

#[test]
fn the_bounce_transfer_leaves_out_only_the_objects_own_occlusion() {
    // Two convex spheres: the bounce transfer (self-occlusion only) is the whole
    // clamped-cosine lobe at every vertex, E = pi for a constant radiance 1, while the
    // room's transfer leaves out the other sphere: a point facing a sphere of radius R
    // whose centre lies d away along its normal loses its view factor (R / d)^2.
    let (radius, gap) = (0.2f32, 0.1f32);
    let scene = two_spheres(radius, gap);
    let transfer = Transfer::compute(&scene, TransferParams::default()).unwrap();
    assert_eq!(transfer.bounce.len(), transfer.vectors.len());
    let (vertices, _) = scene_vertices(&scene);
    let constant = {
        let mut c = [Vec3::ZERO; 9];
        // L = 1: C_0 = sqrt(4 pi).
        c[0] = Vec3::splat((4.0 * std::f32::consts::PI).sqrt());
        c
    };
    let pi = std::f32::consts::PI;
    let (mut facing_checked, mut hidden_checked) = (0, 0);
    for (v, &(p, n)) in vertices.iter().enumerate() {
        let other_centre = Vec3::new(2.0 * radius + gap, 0.0, 0.0);
        let from_p = other_centre - p;
        let facing = n.normalize().dot(from_p.normalize());
        let e_bounce = Transfer::irradiance(&transfer.bounce[v], &constant).x;
        let e_open = Transfer::irradiance(&transfer.vectors[v], &constant).x;
        assert!((e_bounce - pi).abs() < 0.01 * pi, "{p}: {e_bounce}");
        if p.x > radius * 0.999 && facing > 0.999 {
            // The first sphere's point nearest the second, facing it squarely.
            let exact = pi * (1.0 - (radius / from_p.length()).powi(2));
            assert!((e_open - exact).abs() < 0.02 * exact, "{e_open} vs {exact}");
            facing_checked += 1;
        }
        let half_angle = (radius / from_p.length()).asin();
        if facing < -half_angle.sin() && p.x < radius {
            // The other sphere lies wholly below this point's horizon: the same
            // directions, so the same bits.
            assert_eq!(transfer.vectors[v], transfer.bounce[v], "{p}");
            hidden_checked += 1;
        }
    }
    assert!(
        facing_checked >= 1 && hidden_checked > 100,
        "{facing_checked} {hidden_checked}"
    );
}

#[test]
fn the_cache_keeps_the_bounce_transfer() {
    let dir = temp_dir("bounce");
    let scene = two_spheres(0.2, 0.1);
    let (computed, _) = cache::load_or_compute(&scene, FEW, Some(&dir)).unwrap();
    assert!(!computed.bounce.is_empty());
    let (loaded, outcome) = cache::load_or_compute(&scene, FEW, Some(&dir)).unwrap();
    assert!(matches!(outcome, CacheOutcome::Loaded(_)), "{outcome:?}");
    assert_eq!(loaded, computed);
    std::fs::remove_dir_all(&dir).unwrap();
}
