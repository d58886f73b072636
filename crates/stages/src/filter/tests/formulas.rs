//! The filter's formulas: bandwidths against paper 001's numbers and hand computations
//! (eqs. 17-18), screen-space curvature against analytic surfaces (eq. 20), the fast
//! exp of the Gaussian weights, and B_e against maps of known spectra.

use super::*;
use crate::filter::gaussian::{self, exp_neg};
use relume_base::simd::{self as lanes, Lanes, Portable};

#[test]
fn bandwidths_match_paper_figure_4_and_hand_computed_cases() {
    // Paper 001 Fig. 4 / eq. 13: kappa 0.5, occluder at z = 2, B_e = 3, B_f = 1: 2.5.
    assert_eq!(direct_bandwidth(0.5, 2.0, 1.0, 0.0, 3.0), 2.5);
    // Glossy, m = 64: B_rho = 1.25 * 8 = 10; 0.5 (1 + 20) + (1 + 20 + 3) / 2 = 22.5.
    assert_eq!(bandwidth::brdf_bandwidth(64.0), 10.0);
    assert_eq!(direct_bandwidth(0.5, 2.0, 1.0, 10.0, 3.0), 22.5);
    // No occluder: only the curvature term, 0.5 * 1.
    assert_eq!(direct_bandwidth(0.5, f32::INFINITY, 1.0, 0.0, 3.0), 0.5);
    // Eq. 18: 2.8 / 0.5 (diffuse), (4.27 + 0.15 * 40) / 0.5 = 20.54, none: 0.
    assert_eq!(indirect_bandwidth(0.5, 0.0), 5.6);
    assert!((indirect_bandwidth(0.5, 40.0) - 20.54).abs() < 1e-5);
    assert_eq!(indirect_bandwidth(f32::INFINITY, 0.0), 0.0);
    // Degenerate distances stay finite.
    assert!((indirect_bandwidth(0.0, 0.0) - 2800.0).abs() < 1e-3);
    assert_eq!(direct_bandwidth(0.0, f32::NAN, 1.0, 0.0, 3.0), 0.0);
}

#[test]
fn sphere_curvature_is_one_over_radius_and_a_plane_has_none() {
    let radius = 0.5;
    let scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), radius, 4.0), 1.0, 1.0);
    let mut kx = Image::filled(W, H, f32::NAN);
    let mut ky = Image::filled(W, H, f32::NAN);
    screen_curvature(&scene.position, &scene.normal, &mut kx, &mut ky).unwrap();
    let center = Vec3::new(0.0, 0.0, 2.0);
    let mut checked = 0;
    let mut worst = 0.0f32;
    for y in 1..H - 1 {
        for x in 1..W - 1 {
            // Pixels whose 3 x 3 neighbourhood is all on the sphere.
            let on_sphere = (0..9).all(|k| {
                let p = *scene.position.at(x + k % 3 - 1, y + k / 3 - 1);
                ((p - center).length() - radius).abs() < 1e-4
            });
            if on_sphere {
                for k in [*kx.at(x, y), *ky.at(x, y)] {
                    worst = worst.max((k * radius - 1.0).abs());
                }
                checked += 1;
            }
        }
    }
    eprintln!("sphere: {checked} pixels, worst |kappa r - 1| = {worst}");
    assert!(checked > 500, "{checked} sphere pixels");
    assert!(worst < 0.01, "curvature off by {worst} of 1/r");
    let flat = Scene::new(plane(2.0), 1.0, 1.0);
    screen_curvature(&flat.position, &flat.normal, &mut kx, &mut ky).unwrap();
    assert!(kx.data.iter().chain(&ky.data).all(|&k| k == 0.0));
}

#[test]
fn curvature_falls_back_to_the_backward_neighbour() {
    let mut scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.5, 4.0), 1.0, 1.0);
    let (x, y) = (W / 2, H / 2);
    scene.normal.data[(y * W + x + 1) as usize] = Vec3::ZERO;
    scene.position.data[((y + 1) * W + x) as usize] = Vec3::NAN;
    let mut kx = Image::filled(W, H, f32::NAN);
    let mut ky = Image::filled(W, H, f32::NAN);
    screen_curvature(&scene.position, &scene.normal, &mut kx, &mut ky).unwrap();
    assert!((kx.at(x, y) * 0.5 - 1.0).abs() < 0.01, "{}", kx.at(x, y));
    assert!((ky.at(x, y) * 0.5 - 1.0).abs() < 0.01, "{}", ky.at(x, y));
    assert_eq!(*kx.at(x + 1, y), 0.0, "no normal: no curvature");
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn exp_avx2(a: f32) -> [f32; lanes::LANES] {
    use lanes::Avx2;
    gaussian::exp_neg_lanes(Avx2::splat(a), Avx2::splat(gaussian::EXP_CUTOFF)).to_array()
}

#[test]
fn fast_exp_accuracy() {
    assert_eq!(exp_neg(0.0), 1.0);
    assert_eq!(exp_neg(40.0), 0.0);
    assert!(exp_neg(39.9) > 0.0);
    assert_eq!(exp_neg(1e30), 0.0);
    assert_eq!(exp_neg(f32::NAN), 0.0);
    let rel = |a: f32| ((exp_neg(a) as f64) / (-(a as f64)).exp() - 1.0).abs();
    let worst = |lo: f32, hi: f32| {
        (0..=200_000)
            .map(|k| rel(lo + (hi - lo) * k as f32 / 200_000.0))
            .fold(0.0f64, f64::max)
    };
    // The lane versions compute the same bits.
    let cutoff = gaussian::EXP_CUTOFF;
    for a in [0.0f32, 1e-3, 0.5, 3.7, 20.0, 39.99, 40.0, 1e30, f32::NAN] {
        let expected = [exp_neg(a).to_bits(); lanes::LANES];
        let portable = gaussian::exp_neg_lanes(Portable::splat(a), Portable::splat(cutoff));
        assert_eq!(portable.to_array().map(f32::to_bits), expected, "{a}");
        #[cfg(target_arch = "x86_64")]
        if lanes::Kernel::detect() == lanes::Kernel::Avx2Fma {
            // SAFETY: the CPU has AVX2 and FMA.
            let avx2 = unsafe { exp_avx2(a) };
            assert_eq!(avx2.map(f32::to_bits), expected, "{a}");
        }
    }
    let (small, large) = (worst(0.0, 1.0), worst(0.0, 39.99));
    eprintln!("exp_neg: max relative error {small:e} on [0, 1], {large:e} on [0, 40)");
    assert!(small < 4e-6, "max relative error {small} on [0, 1]");
    assert!(large < 8e-6, "max relative error {large} on [0, 40)");
}

#[test]
fn environment_bandwidth_of_known_maps() {
    use std::f32::consts::PI;
    let constant = EnvMap::constant(128, 64, Vec3::splat(2.0));
    assert_eq!(environment_bandwidth(&constant), 0.0);
    // 1 + 0.5 cos(3 phi): energy 1 at DC, 0.0625 at k = +-3: DC holds 1 / 1.125 < 99 %,
    // so B_e is the radius of k = 3: Omega_phi = 3.
    let phi_wave = EnvMap::from_fn(128, 64, |d| {
        let phi = d.z.atan2(d.x);
        Vec3::splat(1.0 + 0.5 * (3.0 * phi).cos())
    });
    assert!((environment_bandwidth(&phi_wave) - 3.0).abs() < 1e-6);
    // 1 + 0.5 cos(2 theta): one cycle over the rows, l = 1: Omega_theta = 2.
    let theta_wave = EnvMap::from_fn(128, 64, |d| {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        Vec3::splat(1.0 + 0.5 * (2.0 * theta).cos())
    });
    assert!((environment_bandwidth(&theta_wave) - 2.0).abs() < 1e-6);
    // A single bright texel has a flat spectrum: B_e near the largest radius.
    let mut spot = EnvMap::constant(64, 32, Vec3::ZERO);
    spot.radiance[10 * 64 + 20] = Vec3::splat(1000.0);
    let b = environment_bandwidth(&spot);
    eprintln!("B_e: point light {b}");
    assert!(b > 30.0, "B_e of a point light is {b}");
    assert_eq!(
        environment_bandwidth(&EnvMap::constant(64, 32, Vec3::ZERO)),
        0.0
    );
    let _ = PI;
}

#[test]
fn curvature_angle_of_two_normals() {
    // Neighbours 0.1 m apart whose normals differ by `angle`: kappa = angle / 0.1.
    for angle in [1e-3f32, 0.1, 0.5, 1.0, std::f32::consts::FRAC_PI_2] {
        let normals = Image::from_vec(
            2,
            1,
            vec![Vec3::Z, Vec3::new(angle.sin(), 0.0, angle.cos()) * 3.0],
        )
        .unwrap();
        let positions = Image::from_vec(2, 1, vec![Vec3::ZERO, Vec3::new(0.1, 0.0, 0.0)]).unwrap();
        let mut kx = Image::filled(2, 1, 0.0);
        let mut ky = Image::filled(2, 1, 0.0);
        screen_curvature(&positions, &normals, &mut kx, &mut ky).unwrap();
        let relative = (kx.data[0] * 0.1 / angle - 1.0).abs();
        eprintln!("angle {angle}: relative error {relative}");
        assert!(
            relative < if angle < 0.6 { 2e-4 } else { 8e-3 },
            "{angle}: {relative}"
        );
        assert_eq!(
            kx.data[0], kx.data[1],
            "backward neighbour of the last pixel"
        );
        assert_eq!(ky.data, vec![0.0, 0.0], "no vertical neighbour");
    }
}
