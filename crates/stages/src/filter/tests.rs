//! Tests of `filter.axis_aligned`'s behaviour: constancy, edges, noise, temporal reuse,
//! NaNs, E_RV == E_R bits, determinism. Its formulas (bandwidths, curvature, the fast
//! exp, B_e) are tested in `tests/formulas.rs`, paper 001 Fig. 4's flatland bandwidth in
//! `tests/flatland.rs`, the passes against eqs. 21-23
//! evaluated directly in `tests/reference.rs`, the reprojection in `tests/temporal.rs`.

use super::temporal::find_previous;
use super::*;
use relume_base::rng::{hash, unit_f32};
use relume_base::simd::{self as lanes, Lanes};

mod flatland;
mod formulas;
mod reference;
mod temporal;

const W: u32 = 96;
const H: u32 = 72;

fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
}

/// Inputs of one frame, owned.
#[derive(Clone)]
struct Scene {
    layers: [Vec3Image; 4],
    position: Vec3Image,
    normal: Vec3Image,
    zd: ScalarImage,
    zi: ScalarImage,
    exponent: ScalarImage,
}

impl Scene {
    /// Camera at the world origin looking down +z; `surface(ray)` gives the world
    /// position and normal along the view ray (z = 1) or `None`. Layers constant 1,
    /// distances `zd` / `zi`, diffuse.
    fn new(surface: impl Fn(Vec3) -> Option<(Vec3, Vec3)>, zd: f32, zi: f32) -> Scene {
        let cam = camera();
        let mut position = Image::filled(W, H, Vec3::NAN);
        let mut normal = Image::filled(W, H, Vec3::ZERO);
        for v in 0..H {
            for u in 0..W {
                if let Some((p, n)) = surface(cam.ray(u as f32, v as f32)) {
                    let i = (v * W + u) as usize;
                    position.data[i] = p;
                    normal.data[i] = n;
                }
            }
        }
        let layer = Image::filled(W, H, Vec3::ONE);
        Scene {
            layers: [layer.clone(), layer.clone(), layer.clone(), layer],
            position,
            normal,
            zd: Image::filled(W, H, zd),
            zi: Image::filled(W, H, zi),
            exponent: Image::filled(W, H, 0.0),
        }
    }

    fn inputs(&self, view: Option<(Pose, Pinhole)>) -> FilterInputs<'_> {
        FilterInputs {
            layers: [
                &self.layers[0],
                &self.layers[1],
                &self.layers[2],
                &self.layers[3],
            ],
            world_position: &self.position,
            world_normal: &self.normal,
            direct_min_distance: &self.zd,
            indirect_min_distance: &self.zi,
            exponent: &self.exponent,
            environment: None,
            view,
        }
    }

    /// The top-left `w` x `h` pixels of every image.
    fn crop(&self, w: u32, h: u32) -> Scene {
        fn crop<T: Copy>(image: &Image<T>, w: u32, h: u32) -> Image<T> {
            let data = (0..h)
                .flat_map(|y| (0..w).map(move |x| *image.at(x, y)))
                .collect();
            Image::from_vec(w, h, data).unwrap()
        }
        Scene {
            layers: self.layers.each_ref().map(|l| crop(l, w, h)),
            position: crop(&self.position, w, h),
            normal: crop(&self.normal, w, h),
            zd: crop(&self.zd, w, h),
            zi: crop(&self.zi, w, h),
            exponent: crop(&self.exponent, w, h),
        }
    }

    /// Sets every layer to `f(pixel index)`.
    fn set_layers(&mut self, f: impl Fn(usize) -> Vec3) {
        for layer in &mut self.layers {
            for (i, v) in layer.data.iter_mut().enumerate() {
                *v = f(i);
            }
        }
    }
}

/// A fronto-parallel plane at depth `z`.
fn plane(z: f32) -> impl Fn(Vec3) -> Option<(Vec3, Vec3)> {
    move |ray| Some((ray * z, Vec3::NEG_Z))
}

/// A sphere of `radius` at `center` in front of a plane at depth `back`.
fn sphere(center: Vec3, radius: f32, back: f32) -> impl Fn(Vec3) -> Option<(Vec3, Vec3)> {
    move |ray: Vec3| {
        let d = ray.normalize();
        let b = d.dot(center);
        let disc = b * b - (center.length_squared() - radius * radius);
        if disc >= 0.0 {
            let p = d * (b - disc.sqrt());
            Some((p, (p - center) / radius))
        } else {
            Some((ray * back, Vec3::NEG_Z))
        }
    }
}

fn filter_frames(
    scenes: &[&Scene],
    params: FilterParams,
    view: Option<(Pose, Pinhole)>,
) -> FilterOutputs {
    let mut filter = AxisAlignedFilter::new(params);
    let mut out = FilterOutputs::new(W, H);
    for scene in scenes {
        out = FilterOutputs::new(W, H);
        filter.filter(&scene.inputs(view), &mut out).unwrap();
    }
    out
}

fn params(temporal: bool) -> FilterParams {
    FilterParams {
        environment_bandwidth: 3.0,
        temporal,
        ..Default::default()
    }
}

fn noise(seed: u64, i: usize) -> f32 {
    unit_f32(hash(&[seed, i as u64])) - 0.5
}

/// `first` seen from the identity pose, then `second` from `moved`: the outputs of the
/// second frame.
fn filter_still_then_moved(
    filter: &mut AxisAlignedFilter,
    first: &Scene,
    second: &Scene,
    moved: Pose,
) -> FilterOutputs {
    let mut out = FilterOutputs::new(W, H);
    filter
        .filter(&first.inputs(Some((Pose::IDENTITY, camera()))), &mut out)
        .unwrap();
    filter
        .filter(&second.inputs(Some((moved, camera()))), &mut out)
        .unwrap();
    out
}

/// Variance of channel x of `image` over pixels at least `margin` from the border.
fn interior_variance(image: &Vec3Image, margin: u32) -> f64 {
    let values: Vec<f64> = (margin..H - margin)
        .flat_map(|y| (margin..W - margin).map(move |x| (x, y)))
        .map(|(x, y)| image.at(x, y).x as f64)
        .collect();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64
}

fn same_bits(a: &Vec3Image, b: &Vec3Image) -> bool {
    a.data
        .iter()
        .zip(&b.data)
        .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits))
}

#[test]
fn a_constant_layer_stays_constant() {
    let mut scene = Scene::new(sphere(Vec3::new(0.1, 0.0, 2.0), 0.4, 3.0), 0.8, 0.5);
    scene.set_layers(|_| Vec3::new(0.7, 1.3, 42.0));
    let out = filter_frames(
        &[&scene, &scene],
        params(true),
        Some((Pose::IDENTITY, camera())),
    );
    for layer in &out.layers {
        for v in &layer.data {
            assert!(
                (*v - Vec3::new(0.7, 1.3, 42.0)).abs().max_element() < 4e-5,
                "{v}"
            );
        }
    }
}

#[test]
fn an_edge_in_world_position_does_not_leak() {
    // Left half at 2 m, right half at 3 m; the layer is 1 on the near plane, 0 behind.
    let split = |ray: Vec3| Some((ray * if ray.x < 0.0 { 2.0 } else { 3.0 }, Vec3::NEG_Z));
    // Direct: kappa 0, z = 1, B_e = 3: B = 4; indirect: 2.8 / 0.25 = 11.2.
    let mut scene = Scene::new(split, 1.0, 0.25);
    let near: Vec<bool> = scene.position.data.iter().map(|p| p.z < 2.5).collect();
    scene.set_layers(|i| if near[i] { Vec3::ONE } else { Vec3::ZERO });
    let out = filter_frames(&[&scene], params(false), None);
    for layer in &out.layers {
        for (v, &is_near) in layer.data.iter().zip(&near) {
            let expected = if is_near { 1.0 } else { 0.0 };
            assert!((v.x - expected).abs() < 1e-3, "{v} near {is_near}");
        }
    }
    // The widths: sigma = 1 / 4 and 1 / 11.2.
    assert_eq!(out.width_dir.data[0], 0.25);
    assert!((out.width_ind.data[0] - 1.0 / 11.2).abs() < 1e-7);
}

#[test]
fn noise_loses_most_of_its_variance_under_a_wide_kernel() {
    let mut scene = Scene::new(plane(2.0), 100.0, 100.0);
    scene.set_layers(|i| Vec3::splat(1.0 + noise(1, i)));
    let before = interior_variance(&scene.layers[0], 15);
    let out = filter_frames(&[&scene], params(false), None);
    for layer in &out.layers {
        let after = interior_variance(layer, 15);
        eprintln!("noise: variance {before} -> {after}");
        assert!(after < 0.1 * before, "variance {before} -> {after}");
    }
    assert!((before - 1.0 / 12.0).abs() < 0.01);
}

#[test]
fn temporal_reuse_finds_the_same_pixel_and_lowers_the_variance() {
    // Narrow kernel (sigma 5 cm) so that the spatial filter leaves noise to remove.
    let mut first = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.5, 3.0), 0.2, 0.2);
    first.set_layers(|i| Vec3::splat(1.0 + noise(2, i)));
    let mut second = first.clone();
    second.set_layers(|i| Vec3::splat(1.0 + noise(3, i)));
    let view = Some((Pose::IDENTITY, camera()));
    // Each pixel finds itself.
    let mut filter = AxisAlignedFilter::new(params(true));
    let mut out = FilterOutputs::new(W, H);
    filter.filter(&first.inputs(view), &mut out).unwrap();
    let previous_view = filter.previous_view.unwrap();
    for y in 0..H as usize {
        for x in 0..W as usize {
            let p = first.position.data[y * W as usize + x];
            assert_eq!(
                find_previous(p, &previous_view, filter.previous_x_set.planes()),
                Some((x, y))
            );
        }
    }
    let with = filter_frames(&[&first, &second], params(true), view);
    let without = filter_frames(&[&first, &second], params(false), view);
    for k in 0..4 {
        let (a, b) = (
            interior_variance(&with.layers[k], 15),
            interior_variance(&without.layers[k], 15),
        );
        eprintln!("temporal layer {k}: variance {a} with, {b} without");
        assert!(a < 0.75 * b, "layer {k}: temporal {a}, spatial {b}");
    }
}

/// A frame of another size (and an empty one) drops the previous frame: the output is
/// that of a fresh filter, bit for bit.
#[test]
fn a_size_change_drops_the_previous_frame() {
    let mut first = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.5, 3.0), 0.3, 0.3);
    first.set_layers(|i| Vec3::splat(1.0 + noise(40, i)));
    let small = first.crop(93, 70);
    let view = Some((Pose::IDENTITY, camera()));
    let mut filter = AxisAlignedFilter::new(params(true));
    let mut out = FilterOutputs::new(W, H);
    filter.filter(&first.inputs(view), &mut out).unwrap();
    let mut after = FilterOutputs::new(93, 70);
    filter.filter(&small.inputs(view), &mut after).unwrap();
    let mut fresh = FilterOutputs::new(93, 70);
    AxisAlignedFilter::new(params(true))
        .filter(&small.inputs(view), &mut fresh)
        .unwrap();
    for k in 0..4 {
        assert!(same_bits(&after.layers[k], &fresh.layers[k]), "layer {k}");
    }
    let empty = first.crop(0, 0);
    let mut none = FilterOutputs::new(0, 0);
    filter.filter(&empty.inputs(view), &mut none).unwrap();
    AxisAlignedFilter::new(params(true))
        .filter(&empty.inputs(view), &mut none)
        .unwrap();
}

#[test]
fn e_rv_equal_to_e_r_filters_to_the_same_bits() {
    let mut scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.3, 2.5), 0.5, 0.3);
    scene.set_layers(|i| Vec3::new(1.0 + noise(4, i), 0.5 + noise(5, i), 2.0));
    // E_RV differs (darker) in a small patch at (20..24, 10..14).
    let in_patch = |x: u32, y: u32| (20..24).contains(&x) && (10..14).contains(&y);
    for y in 0..H {
        for x in 0..W {
            if in_patch(x, y) {
                let i = (y * W + x) as usize;
                scene.layers[2].data[i] *= 0.3;
                scene.layers[3].data[i] *= 0.3;
            }
        }
    }
    let out = filter_frames(
        &[&scene, &scene],
        params(true),
        Some((Pose::IDENTITY, camera())),
    );
    let (mut equal, mut differ) = (0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            // Outside the 31 x 31 footprint of the patch (same pose: the previous frame's
            // footprint is the same).
            let far = x + 15 < 20 || x >= 24 + 15 || y + 15 < 10 || y >= 14 + 15;
            for (r, rv) in [(0, 2), (1, 3)] {
                let (a, b) = (out.layers[r].data[i], out.layers[rv].data[i]);
                if far {
                    assert_eq!(
                        a.to_array().map(f32::to_bits),
                        b.to_array().map(f32::to_bits)
                    );
                    equal += 1;
                } else if a != b {
                    differ += 1;
                }
            }
        }
    }
    eprintln!("E_RV vs E_R: {equal} equal, {differ} differ");
    assert!(
        equal > 5000 && differ > 100,
        "{equal} equal, {differ} differ"
    );
}

/// E_R's outputs do not depend on E_RV's inputs (the two share weights, not sums), and
/// where E_RV == E_R everywhere the outputs are equal bit for bit.
#[test]
fn e_r_does_not_depend_on_e_rv() {
    let mut same = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.3, 2.5), 0.5, 0.3);
    same.set_layers(|i| Vec3::new(1.0 + noise(6, i), 0.5 + noise(7, i), 2.0));
    let mut differs = same.clone();
    for layer in &mut differs.layers[2..] {
        for (i, v) in layer.data.iter_mut().enumerate() {
            *v *= 0.5 + noise(8, i);
        }
    }
    let view = Some((Pose::IDENTITY, camera()));
    let reused = filter_frames(&[&same, &same], params(true), view);
    let full = filter_frames(&[&differs, &differs], params(true), view);
    for layer in 0..2 {
        let bits = |out: &FilterOutputs| -> Vec<[u32; 3]> {
            let data = &out.layers[layer].data;
            data.iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect()
        };
        assert_eq!(bits(&reused), bits(&full), "layer {layer}");
        assert_eq!(
            bits(&reused),
            reused.layers[layer + 2]
                .data
                .iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        );
    }
}

#[test]
fn missing_values_stay_nan_and_do_not_spread() {
    let mut scene = Scene::new(plane(2.0), 1.0, 1.0);
    scene.set_layers(|_| Vec3::splat(0.25));
    let holes = [(10u32, 10u32), (11, 10), (50, 40), (0, 0), (95, 71)];
    for &(x, y) in &holes {
        scene.layers[0].data[(y * W + x) as usize] = Vec3::new(f32::NAN, 1.0, 1.0);
    }
    // A pixel without a position: every layer is missing there.
    scene.position.data[(30 * W + 30) as usize] = Vec3::NAN;
    scene.layers[3].data[(5 * W + 60) as usize] = Vec3::INFINITY;
    let out = filter_frames(
        &[&scene, &scene],
        params(true),
        Some((Pose::IDENTITY, camera())),
    );
    for (k, layer) in out.layers.iter().enumerate() {
        for y in 0..H {
            for x in 0..W {
                let v = *layer.at(x, y);
                let missing = (k == 0 && holes.contains(&(x, y)))
                    || (x, y) == (30, 30)
                    || (k == 3 && (x, y) == (60, 5));
                if missing {
                    assert!(v.is_nan(), "layer {k} ({x}, {y}) {v}");
                } else {
                    assert!(
                        (v - Vec3::splat(0.25)).abs().max_element() < 1e-6,
                        "layer {k} ({x}, {y}) {v}"
                    );
                }
            }
        }
    }
    assert!(out.width_dir.at(30, 30).is_nan());
}

#[test]
fn outputs_are_the_same_bits_for_any_thread_count() {
    let mut first = Scene::new(sphere(Vec3::new(0.1, -0.05, 2.0), 0.4, 3.0), 0.7, 0.4);
    first.set_layers(|i| Vec3::new(1.0 + noise(6, i), noise(7, i), 3.0 * noise(8, i)));
    first.layers[2].data[100] = Vec3::NAN;
    first
        .exponent
        .data
        .iter_mut()
        .step_by(3)
        .for_each(|m| *m = 64.0);
    let mut second = first.clone();
    second.set_layers(|i| Vec3::new(1.0 + noise(9, i), noise(10, i), noise(11, i)));
    let moved = Pose::from_parts(
        glam::DVec3::new(0.02, 0.0, 0.01),
        glam::DQuat::from_rotation_y(0.01),
    );
    let run = |threads| {
        relume_base::threads::with_threads(threads, || {
            let mut filter = AxisAlignedFilter::new(params(true));
            filter_still_then_moved(&mut filter, &first, &second, moved)
        })
    };
    let (one, three) = (run(1), run(3));
    for k in 0..4 {
        assert!(same_bits(&one.layers[k], &three.layers[k]), "layer {k}");
    }
    assert_eq!(
        one.width_dir
            .data
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>(),
        three
            .width_dir
            .data
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    );
}
