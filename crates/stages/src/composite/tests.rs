use super::*;
use crate::compensate::{apply_compensation, hsv::Linearize};
use relume_base::rng;
use relume_base::threads::with_threads;
use std::f32::consts::PI;

const W: u32 = 64;
const H: u32 = 48;

/// A camera image of hashed levels over the whole range, and a compensation that
/// mixes channels (as C_t of paper 000 eq. 2 does).
fn camera() -> (Rgb8Image, Mat3) {
    let data = (0..W * H)
        .map(|i| std::array::from_fn(|c| rng::hash(&[7, i as u64, c as u64]) as u8))
        .collect();
    let matrix = Mat3::from_cols(
        Vec3::new(1.3, 0.05, -0.02),
        Vec3::new(0.04, 0.9, 0.03),
        Vec3::new(-0.03, 0.06, 1.6),
    );
    (Image::from_vec(W, H, data).unwrap(), matrix)
}

/// Noisy irradiance layers: E_RV == E_R everywhere.
fn layer(salt: u64) -> Vec3Image {
    let data = (0..W * H)
        .map(|i| {
            let u = |c: u64| rng::unit_f32(rng::hash(&[salt, i as u64, c])) * 3.0;
            Vec3::new(u(0), u(1), u(2))
        })
        .collect();
    Image::from_vec(W, H, data).unwrap()
}

struct Scene {
    color: Rgb8Image,
    compensation: Mat3,
    radiance: Vec3Image,
    e_dir: Vec3Image,
    e_ind: Vec3Image,
    mask: ScalarImage,
    k_v: Vec3Image,
}

fn scene() -> Scene {
    let (color, compensation) = camera();
    let mut radiance = Image::filled(0, 0, Vec3::ZERO);
    apply_compensation(&color, &Linearize::new(2.2), &compensation, &mut radiance);
    Scene {
        color,
        compensation,
        radiance,
        e_dir: layer(1),
        e_ind: layer(2),
        mask: Image::filled(W, H, 1.0),
        k_v: Image::filled(W, H, Vec3::ZERO),
    }
}

fn run(s: &Scene, e_rv_dir: &Vec3Image, e_rv_ind: &Vec3Image) -> CompositeOutputs {
    let inputs = CompositeInputs {
        e_r_dir: &s.e_dir,
        e_r_ind: &s.e_ind,
        e_rv_dir,
        e_rv_ind,
        mask: &s.mask,
        k_v: &s.k_v,
        radiance: &s.radiance,
        inverse_compensation: s.compensation.inverse(),
    };
    let mut out = CompositeOutputs::new(W, H);
    composite(
        &inputs,
        &CompositeParams::default(),
        &GammaEncoder::new(2.2),
        &mut out,
    )
    .unwrap();
    out
}

#[test]
fn without_objects_the_frame_is_the_camera_image() {
    // Compensation, ratio 1, inverse compensation and gamma: the camera's own levels.
    let s = scene();
    let out = run(&s, &s.e_dir, &s.e_ind);
    assert_eq!(out.final_color.data, s.color.data);
    assert!(out.differential.data.iter().all(|&r| r == Vec3::ONE));
    let linear = Linearize::new(2.2);
    for (hdr, c) in out.final_hdr.data.iter().zip(&s.color.data) {
        assert!((*hdr - linear.rgb(*c)).abs().max_element() < 1e-5);
    }
}

#[test]
fn a_shadow_scales_the_camera_light_and_a_virtual_pixel_shows_the_object() {
    let mut s = scene();
    let mut e_rv_dir = s.e_dir.clone();
    // Pixel 10: the object blocks 3/4 of the light in every channel (E_RV = E_R / 4).
    let e_r = s.e_dir.data[10] + s.e_ind.data[10];
    e_rv_dir.data[10] = e_r / 4.0 - s.e_ind.data[10];
    // Pixel 20: fully virtual, albedo k_V; pixel 30: half real, half virtual.
    let k_v = Vec3::new(0.8, 0.4, 0.2);
    for i in [20, 30] {
        s.k_v.data[i] = k_v;
    }
    s.mask.data[20] = 0.0;
    s.mask.data[30] = 0.5;
    let out = run(&s, &e_rv_dir, &s.e_ind);
    let linear = Linearize::new(2.2);
    let camera = |i: usize| linear.rgb(s.color.data[i]);
    let c_inv = s.compensation.inverse();
    assert!(
        (out.differential.data[10] - Vec3::splat(0.25))
            .abs()
            .max_element()
            < 1e-6
    );
    assert!(
        (out.final_hdr.data[10] - camera(10) * 0.25)
            .abs()
            .max_element()
            < 1e-5
    );
    let e_rv = s.e_dir.data[20] + s.e_ind.data[20];
    let virtual_20 = c_inv * (k_v * e_rv / std::f32::consts::PI);
    assert!((out.final_hdr.data[20] - virtual_20).abs().max_element() < 1e-5);
    let e_rv = s.e_dir.data[30] + s.e_ind.data[30];
    let mixed = c_inv * (0.5 * k_v * e_rv / std::f32::consts::PI) + 0.5 * camera(30);
    assert!((out.final_hdr.data[30] - mixed).abs().max_element() < 1e-5);
    // Everywhere else: the camera's levels.
    for i in (0..s.color.data.len()).filter(|i| ![10, 20, 30].contains(i)) {
        assert_eq!(out.final_color.data[i], s.color.data[i], "pixel {i}");
    }
}

#[test]
fn the_ratio_is_one_where_an_estimate_is_missing_and_bounded_where_e_r_vanishes() {
    let p = CompositeParams::default();
    assert_eq!(differential_ratio(f32::NAN, 2.0, &p), 1.0);
    assert_eq!(differential_ratio(2.0, f32::NAN, &p), 1.0);
    assert_eq!(differential_ratio(0.0, 0.0, &p), 1.0);
    assert_eq!(differential_ratio(0.0, 1.0, &p), p.max_ratio);
    // E_R = -0 is no irradiance, as +0 is, even with min_irradiance 0.
    let no_floor = CompositeParams {
        min_irradiance: 0.0,
        ..p
    };
    assert_eq!(differential_ratio(-0.0, 1.0, &no_floor), p.max_ratio);
    assert_eq!(differential_ratio(2.0, -1.0, &p), 0.0);
    assert_eq!(differential_ratio(2.0, 1.0, &p), 0.5);
    assert_eq!(differential_ratio(1e-6, 2e-6, &p), 2e-6 / p.min_irradiance);
    // The three-channel form gives the scalar form's bits, edge cases included.
    let values = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        -0.0,
        0.0,
        1e-6,
        2e-6,
        0.5,
        1.0,
        2.0,
        1e30,
    ];
    for p in [
        p,
        CompositeParams {
            min_irradiance: 0.0,
            ..p
        },
    ] {
        for &a in &values {
            for &b in &values {
                let (e_r, e_rv) = (Vec3::new(a, b, 0.25), Vec3::new(b, a, 0.5));
                let three = differential_ratio3(e_r, e_rv, &p).to_array();
                let one = [0, 1, 2].map(|c| differential_ratio(e_r[c], e_rv[c], &p));
                assert_eq!(
                    three.map(f32::to_bits),
                    one.map(f32::to_bits),
                    "{e_r} {e_rv}"
                );
            }
        }
    }
}

#[test]
fn size_mismatches_are_errors_naming_the_product() {
    let s = scene();
    let small = Image::filled(W - 1, H, Vec3::ONE);
    let inputs = CompositeInputs {
        e_r_dir: &s.e_dir,
        e_r_ind: &s.e_ind,
        e_rv_dir: &s.e_dir,
        e_rv_ind: &small,
        mask: &s.mask,
        k_v: &s.k_v,
        radiance: &s.radiance,
        inverse_compensation: Mat3::IDENTITY,
    };
    let mut out = CompositeOutputs::new(W, H);
    let err = composite(
        &inputs,
        &CompositeParams::default(),
        &GammaEncoder::new(2.2),
        &mut out,
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "composite.differential: e_rv_ind is 63x48, the camera image is 64x48"
    );
    assert!(matches!(err, OpError::SizeMismatch(_)), "{err:?}");
}

#[test]
fn the_same_bits_with_one_and_three_threads() {
    let mut s = scene();
    for i in (0..s.mask.data.len()).step_by(7) {
        s.mask.data[i] = (i % 5) as f32 / 4.0;
        s.k_v.data[i] = Vec3::new(0.3, 0.5, 0.7);
    }
    let e_rv = layer(3);
    let one = with_threads(1, || run(&s, &e_rv, &s.e_ind));
    let three = with_threads(3, || run(&s, &e_rv, &s.e_ind));
    assert_eq!(one.final_color.data, three.final_color.data);
    let bits = |img: &Vec3Image| {
        img.data
            .iter()
            .flat_map(|v| v.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&one.final_hdr), bits(&three.final_hdr));
    assert_eq!(bits(&one.differential), bits(&three.differential));
}

fn run_with(s: &Scene, e_rv_dir: &Vec3Image, params: &CompositeParams) -> CompositeOutputs {
    let inputs = CompositeInputs {
        e_r_dir: &s.e_dir,
        e_r_ind: &s.e_ind,
        e_rv_dir,
        e_rv_ind: &s.e_ind,
        mask: &s.mask,
        k_v: &s.k_v,
        radiance: &s.radiance,
        inverse_compensation: s.compensation.inverse(),
    };
    let mut out = CompositeOutputs::new(W, H);
    composite(&inputs, params, &GammaEncoder::new(params.gamma), &mut out).unwrap();
    out
}

/// Paper 002's tone-mapped difference: the camera's levels where the objects change
/// nothing; TM(cam) + TM(a E_RV / pi) - TM(a E_R / pi) in a shadow, which equals the
/// ratio form when the camera shows albedo times E_R / pi, and departs from it by an
/// absolute amount where it does not.
#[test]
fn the_difference_form_adds_the_tone_mapped_difference_to_the_camera() {
    let mut s = scene();
    // Identity compensation, so that TM is the gamma alone.
    s.compensation = Mat3::IDENTITY;
    s.radiance = Image::from_vec(
        W,
        H,
        s.color
            .data
            .iter()
            .map(|&c| Linearize::new(2.2).rgb(c))
            .collect(),
    )
    .unwrap();
    let difference = CompositeParams {
        difference: true,
        ..CompositeParams::default()
    };
    let untouched = run_with(&s, &s.e_dir, &difference);
    assert_eq!(untouched.final_color.data, s.color.data);
    // Pixel 10: the camera shows albedo a = 0.4 lit by E_R = pi (L = a E_R / pi = a:
    // the camera's color is the albedo, as the form assumes); the objects leave a
    // quarter of the light.
    let e_r = Vec3::splat(PI);
    s.e_dir.data[10] = e_r - s.e_ind.data[10];
    s.radiance.data[10] = 0.4 * e_r / PI;
    let mut e_rv_dir = s.e_dir.clone();
    e_rv_dir.data[10] = e_r / 4.0 - s.e_ind.data[10];
    let by_difference = run_with(&s, &e_rv_dir, &difference);
    let by_ratio = run_with(&s, &e_rv_dir, &CompositeParams::default());
    let expected = 0.4 * e_r.x / 4.0 / PI;
    for out in [&by_difference, &by_ratio] {
        assert!(
            (out.final_hdr.data[10].x - expected).abs() < 1e-4,
            "{}",
            out.final_hdr.data[10]
        );
    }
    // A saturated camera pixel (its albedo clamps at 1): the difference form darkens it
    // by TM(1 E_R / pi) - TM(E_R / 4 pi), not by the factor 4.
    s.radiance.data[10] = Vec3::splat(1.5);
    let by_difference = run_with(&s, &e_rv_dir, &difference);
    let tm = |x: f32| x.powf(1.0 / 2.2);
    let display = (tm(1.5).min(1.0) + tm(e_r.x / 4.0 / PI) - tm(e_r.x / PI)).clamp(0.0, 1.0);
    assert!((by_difference.final_hdr.data[10].x - display.powf(2.2)).abs() < 1e-4);
    assert!((by_difference.final_hdr.data[10].x - 1.5 / 4.0).abs() > 0.05);
    // A virtual pixel shows the object, k_V E_RV / pi, whatever the camera saw there,
    // also with no real point behind it (E_R NaN).
    s.mask.data[20] = 0.0;
    s.k_v.data[20] = Vec3::new(0.8, 0.4, 0.2);
    s.e_dir.data[20] = Vec3::NAN;
    let by_difference = run_with(&s, &e_rv_dir, &difference);
    let e_rv = e_rv_dir.data[20] + s.e_ind.data[20];
    let object = s.k_v.data[20] * e_rv / PI;
    assert!(
        (by_difference.final_hdr.data[20] - object)
            .abs()
            .max_element()
            < 1e-4
    );
    // Untouched real pixels keep the camera's linear values exactly.
    assert_eq!(
        by_difference.final_hdr.data[11],
        untouched.final_hdr.data[11]
    );
}
