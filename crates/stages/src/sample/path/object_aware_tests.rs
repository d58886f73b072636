//! Object-aware sampling of direct light (paper 000 Sec. 7): the same mean as the
//! correlated direct samples, with less noise in the shadow.

use super::tests::{
    SPHERE_CENTER, SPHERE_RADIUS, block_around, floor_scene, mean, run, sphere, uniform_table,
    variance,
};
use super::*;
use glam::Vec3;
use relume_scene::objects::Material;

#[test]
fn object_aware_direct_light_is_unbiased_and_lowers_the_variance_in_the_shadow() {
    let scene = floor_scene();
    let table = uniform_table(4096);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    // Floor pixels under the sphere (a quarter of the cosine-weighted sky blocked) and
    // at the edge of its shadow.
    let blocks = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.3, 0.0, 0.8)].map(block_around);
    const SEEDS: usize = 40;
    let mut block_means = [[[0f64; SEEDS]; 2]; 2];
    let mut pooled_variance = [0f64; 2];
    for (mode, object_aware_direct) in [false, true].into_iter().enumerate() {
        let mut values = vec![[0f64; SEEDS]; 18];
        for seed in 0..SEEDS {
            let params = PathParams {
                seed: seed as u64,
                object_aware_direct,
                ..Default::default()
            };
            let out = run(&scene, &objects, &table, &params);
            for (b, block) in blocks.iter().enumerate() {
                for (k, &p) in block.iter().enumerate() {
                    assert_eq!(out.mask.data[p], 1.0, "a floor pixel");
                    let v = out.e_rv_dir.data[p].x as f64;
                    values[b * 9 + k][seed] = v;
                    block_means[mode][b][seed] += v / 9.0;
                }
            }
        }
        pooled_variance[mode] = values.iter().map(|xs| variance(xs)).sum::<f64>() / 18.0;
    }
    for (b, (correlated, aware)) in block_means[0].iter().zip(&block_means[1]).enumerate() {
        let (m0, m1) = (mean(correlated), mean(aware));
        let se = ((variance(correlated) + variance(aware)) / SEEDS as f64).sqrt();
        println!("block {b}: mean E_RV^dir correlated {m0:.5}, object-aware {m1:.5} (se {se:.5})");
        assert!(m0 > 0.0 && m1 > 0.0);
        assert!((m0 - m1).abs() < 4.0 * se, "biased: {m0} vs {m1} (se {se})");
    }
    let [v0, v1] = pooled_variance;
    println!(
        "per-pixel sd of E_RV^dir: correlated {:.5}, object-aware {:.5}",
        v0.sqrt(),
        v1.sqrt()
    );
    assert!(
        v1 < 0.8 * v0,
        "object-aware direct light should lower the variance: {v1} vs {v0}"
    );
}

#[test]
fn object_aware_direct_light_changes_nothing_where_no_candidate_meets_an_object() {
    let scene = floor_scene();
    let table = uniform_table(1024);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let params = PathParams {
        object_aware_direct: true,
        ..Default::default()
    };
    let out = run(&scene, &objects, &table, &params);
    let mut touched = 0;
    for i in 0..out.touched.data.len() {
        if out.touched.data[i] != 0 {
            touched += 1;
        } else {
            let (r, rv) = (out.e_r_dir.data[i], out.e_rv_dir.data[i]);
            assert!(
                r.to_array().map(f32::to_bits) == rv.to_array().map(f32::to_bits),
                "{i}"
            );
        }
    }
    assert!(touched > 200, "{touched}");
    // E_R is the same estimate with the differential on or off.
    let plain = run(&scene, &objects, &table, &PathParams::default());
    assert!(
        plain
            .e_r_dir
            .data
            .iter()
            .zip(&out.e_r_dir.data)
            .all(|(a, b)| { a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits) })
    );
}
