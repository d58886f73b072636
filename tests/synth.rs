//! The synthetic recording generator: determinism, structure, and ground truth that is
//! consistent with the sensor streams.

use relume::recording::synth::*;
use relume::recording::{Record, Recording, Replay, ReplayOptions, StreamKind, codec};
use std::path::{Path, PathBuf};

fn small(width: u32, height: u32, frames: usize) -> SynthConfig {
    SynthConfig {
        frames,
        width,
        height,
        ..SynthConfig::default()
    }
}

fn generate_in(dir: &Path, name: &str, config: &SynthConfig) -> PathBuf {
    let path = dir.join(name);
    let summary = generate(config, &path).expect("generate");
    assert_eq!(summary.path, path);
    assert_eq!(summary.frames, config.frames);
    assert_eq!(summary.bytes, std::fs::metadata(&path).unwrap().len());
    path
}

/// The camera-space ray through the centre of pixel (x, y), with z = 1.
fn pixel_ray(k: &relume::recording::Intrinsics, x: u32, y: u32) -> [f64; 3] {
    [(x as f64 - k.cx) / k.fx, (y as f64 - k.cy) / k.fy, 1.0]
}

#[test]
fn same_config_gives_identical_bytes_for_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        seed: 9,
        contrast: 0.2,
        ..small(80, 60, 3)
    };
    let a = generate_in(dir.path(), "a.relume", &config);
    let b = generate_in(dir.path(), "b.relume", &config);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let c = pool.install(|| generate_in(dir.path(), "c.relume", &config));
    let bytes = std::fs::read(&a).unwrap();
    assert_eq!(bytes, std::fs::read(&b).unwrap());
    assert_eq!(
        bytes,
        std::fs::read(&c).unwrap(),
        "one thread differs from the default pool"
    );
    // Another seed changes the noise, not the file's structure.
    let d = generate_in(dir.path(), "d.relume", &SynthConfig { seed: 10, ..config });
    assert_ne!(bytes, std::fs::read(&d).unwrap());
}

#[test]
fn recording_has_every_stream_and_the_scene_truth() {
    let dir = tempfile::tempdir().unwrap();
    let config = small(64, 48, 4);
    let path = generate_in(dir.path(), "s.relume", &config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    assert!(replay.recording.damage().is_none());
    assert_eq!(replay.len(), config.frames);
    assert_eq!(replay.stats.frames_with_pose, config.frames);
    assert_eq!(replay.stats.frames_with_truth, config.frames);
    let header = replay.recording.header();
    assert_eq!(header.name, "synthetic-room");
    assert_eq!(header.streams, StreamKind::ALL.to_vec());
    assert_eq!(header.depth_unit_m, 0.0002);
    assert_eq!(header.color_intrinsics, config.intrinsics());
    assert_eq!(header.depth_intrinsics, config.intrinsics());
    assert_eq!(header.provenance, provenance(&config));
    assert_eq!(header.provenance.settings["generator"], GENERATOR_VERSION);
    let truth = header.ground_truth.as_ref().expect("scene truth");
    assert_eq!(truth.object_position, [0.0, 0.3, 0.0]);
    let env = header.attachment("environment").expect("environment map");
    assert_eq!(env.kind, "envmap/latlong");
    assert_eq!(
        (env.image.width, env.image.height, env.image.channels),
        (256, 128, 3)
    );
    let texels = codec::decode_floats(&env.image).unwrap();
    assert!(texels.iter().all(|v| v.is_finite() && *v >= 0.0));
    // The brightest texels are the window's: towards +x (phi near 0), above the horizon.
    let luminance = |i: usize| texels[3 * i] + texels[3 * i + 1] + texels[3 * i + 2];
    let brightest = (0..256 * 128)
        .max_by(|&a, &b| luminance(a).total_cmp(&luminance(b)))
        .unwrap();
    assert!(luminance(brightest) > 20.0);
    let (row, column) = (brightest / 256, brightest % 256);
    let phi = (column as f64 + 0.5) / 256.0 * 360.0;
    assert!(
        row < 64 && !(25.0..=335.0).contains(&phi),
        "row {row} phi {phi}"
    );

    let mut previous_stamp = -1;
    for n in 0..replay.len() {
        let frame = replay.read_frame(n).unwrap();
        assert_eq!(frame.stamp_ns, (n as f64 / config.fps * 1e9).round() as i64);
        assert!(frame.stamp_ns > previous_stamp);
        previous_stamp = frame.stamp_ns;
        let depth = frame.depth.expect("depth");
        assert!(depth.stamp_ns > frame.stamp_ns && depth.stamp_ns - frame.stamp_ns <= 5_000_000);
        let truth = frame.truth.expect("truth");
        assert_eq!(truth.stamp_ns, frame.stamp_ns);
        assert!(frame.pose.is_some());
    }
    // Pose records lie exactly at the color stamps.
    let recording = Recording::open(&path).unwrap();
    let pose_stamps: Vec<i64> = (0..recording.index().len())
        .filter_map(|i| match recording.read_record(i).unwrap() {
            Record::Pose(p) => Some(p.stamp_ns),
            _ => None,
        })
        .collect();
    let color_stamps: Vec<i64> = replay.frames.iter().map(|f| f.stamp_ns).collect();
    assert_eq!(pose_stamps, color_stamps);
}

#[test]
fn noisy_depth_has_holes_and_errors_that_grow_with_depth() {
    let dir = tempfile::tempdir().unwrap();
    let config = small(160, 120, 2);
    let path = generate_in(dir.path(), "d.relume", &config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let unit = replay.recording.header().depth_unit_m;
    let (mut near, mut far) = (Vec::new(), Vec::new());
    for n in 0..replay.len() {
        let frame = replay.read_frame(n).unwrap();
        let noisy = codec::decode_depth(&frame.depth.unwrap().image, unit).unwrap();
        let clean = codec::decode_floats(&frame.truth.unwrap().depth).unwrap();
        assert_eq!(clean.len(), noisy.data.len());
        assert!(
            clean.iter().all(|&z| z > 0.3 && z < 7.5),
            "the room is closed: every pixel hits"
        );
        let holes = noisy.data.iter().filter(|&&z| z == 0.0).count() as f64 / clean.len() as f64;
        assert!((0.01..0.25).contains(&holes), "hole fraction {holes}");
        let mut sorted = clean.clone();
        sorted.sort_by(f32::total_cmp);
        let median = sorted[sorted.len() / 2];
        for (&z, &m) in clean.iter().zip(&noisy.data) {
            if m > 0.0 {
                let error = (m - z).abs() as f64;
                assert!(error < 0.5, "a valid pixel is off by {error} m at {z} m");
                if z < median {
                    near.push(error)
                } else {
                    far.push(error)
                }
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (near, far) = (mean(&near), mean(&far));
    assert!(
        near > 0.0 && near < 0.02 && far > 1.5 * near,
        "near {near} far {far}"
    );

    // Without noise, depth is the clean depth rounded to the storage unit.
    let clean_config = SynthConfig {
        depth_noise: false,
        ..small(64, 48, 1)
    };
    let path = generate_in(dir.path(), "c.relume", &clean_config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let frame = replay.read_frame(0).unwrap();
    let units = codec::decode_depth_units(&frame.depth.unwrap().image).unwrap();
    let clean = codec::decode_floats(&frame.truth.unwrap().depth).unwrap();
    for (&u, &z) in units.data.iter().zip(&clean) {
        assert_eq!(u, (z as f64 / unit).round() as u16);
    }
}

#[test]
fn color_is_the_stored_camera_model_applied_to_the_stored_radiance() {
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        contrast: 0.3,
        ..small(96, 72, 4)
    };
    let path = generate_in(dir.path(), "c.relume", &config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let mut contrasts = Vec::new();
    for n in 0..replay.len() {
        let frame = replay.read_frame(n).unwrap();
        let color = codec::decode_color(&frame.color.image).unwrap();
        let truth = frame.truth.unwrap();
        let radiance = codec::decode_floats(&truth.radiance).unwrap();
        let m = truth.color_transform;
        contrasts.push(truth.contrast);
        let (mut compared, mut off_by_one) = (0, 0);
        for (pixel, l) in color.data.iter().zip(radiance.chunks_exact(3)) {
            if pixel.contains(&255) {
                continue;
            }
            compared += 1;
            for c in 0..3 {
                let linear = m[3 * c] * l[0] + m[3 * c + 1] * l[1] + m[3 * c + 2] * l[2];
                let v = linear
                    .max(0.0)
                    .powf(truth.contrast)
                    .powf(1.0 / 2.2)
                    .min(1.0);
                let expected = (v * 255.0).round() as i32;
                let diff = (expected - pixel[c] as i32).abs();
                assert!(
                    diff <= 1,
                    "frame {n}: level {} expected {expected}",
                    pixel[c]
                );
                off_by_one += diff as usize;
            }
        }
        assert!(
            compared > color.data.len() / 2,
            "frame {n} is mostly clipped"
        );
        assert!(
            off_by_one * 100 < compared,
            "frame {n}: {off_by_one} levels off by one"
        );
    }
    assert!(
        contrasts.iter().any(|&c| (c - 1.0).abs() > 0.05),
        "{contrasts:?}"
    );
    assert!(
        contrasts
            .iter()
            .all(|&c| (0.7 - 1e-6..=1.3 + 1e-6).contains(&c))
    );
}

#[test]
fn normals_are_unit_and_face_the_camera() {
    let dir = tempfile::tempdir().unwrap();
    let config = small(64, 48, 2);
    let path = generate_in(dir.path(), "n.relume", &config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let k = replay.recording.header().color_intrinsics;
    for n in 0..replay.len() {
        let truth = replay.read_frame(n).unwrap().truth.unwrap();
        let normals = codec::decode_floats(&truth.normals).unwrap();
        assert_eq!(normals.len(), 64 * 48 * 3);
        for (i, nrm) in normals.chunks_exact(3).enumerate() {
            let length = nrm.iter().map(|v| (v * v) as f64).sum::<f64>().sqrt();
            assert!((length - 1.0).abs() < 2e-3, "pixel {i}: length {length}");
            let ray = pixel_ray(&k, (i % 64) as u32, (i / 64) as u32);
            let dot: f64 = (0..3).map(|c| nrm[c] as f64 * ray[c]).sum();
            assert!(dot < 0.0, "pixel {i} faces away");
        }
    }
}

#[test]
fn exposure_spans_the_configured_range_and_frames_are_well_exposed() {
    let dir = tempfile::tempdir().unwrap();
    // Without white balance the rows of the transform sum to the exposure (the fixed
    // color mix keeps grey grey).
    let config = SynthConfig {
        white_balance: 0.0,
        exposure_range: (0.6, 1.8),
        ..small(64, 48, 5)
    };
    let path = generate_in(dir.path(), "e.relume", &config);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let mut exposures = Vec::new();
    for n in 0..replay.len() {
        let frame = replay.read_frame(n).unwrap();
        let m = frame.truth.unwrap().color_transform;
        let rows: Vec<f32> = m.chunks(3).map(|r| r.iter().sum()).collect();
        assert!(rows.iter().all(|r| (r - rows[0]).abs() < 1e-5), "{rows:?}");
        exposures.push(rows[0]);
        let color = codec::decode_color(&frame.color.image).unwrap();
        let count = color.data.len() as f64;
        let mean = color.data.iter().flatten().map(|&v| v as f64).sum::<f64>() / (3.0 * count);
        let clipped = color.data.iter().filter(|p| p.contains(&255)).count() as f64 / count;
        assert!(
            (50.0..200.0).contains(&mean) && clipped < 0.15,
            "frame {n}: mean {mean} clipped {clipped}"
        );
    }
    let min = exposures.iter().cloned().fold(f32::INFINITY, f32::min);
    let max = exposures.iter().cloned().fold(0.0, f32::max);
    assert!(
        (min - 0.6).abs() < 1e-4 && (max - 1.8).abs() < 1e-4,
        "{exposures:?}"
    );

    // White balance: per-channel gains within +-20 percent that differ between channels.
    let wb = SynthConfig {
        white_balance: 0.2,
        ..config
    };
    let path = generate_in(dir.path(), "w.relume", &wb);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let mut gains_seen = Vec::new();
    for (n, exposure) in exposures.iter().enumerate() {
        let m = replay.read_frame(n).unwrap().truth.unwrap().color_transform;
        // M = exposure * MIX * diag(gains): the gains are the diagonal of MIX^-1 M / e.
        let mix = glam::Mat3::from_cols_array(&camera::MIX).transpose();
        let unmixed = mix.inverse() * glam::Mat3::from_cols_array(&m).transpose() / *exposure;
        let gains: Vec<f32> = (0..3).map(|i| unmixed.col(i)[i]).collect();
        let off_diagonal = (0..3)
            .flat_map(|c| (0..3).filter(move |&r| r != c).map(move |r| (r, c)))
            .map(|(r, c)| unmixed.col(c)[r].abs())
            .fold(0.0, f32::max);
        assert!(off_diagonal < 1e-4, "{unmixed:?}");
        assert!(
            gains.iter().all(|g| (0.8 - 1e-4..=1.2 + 1e-4).contains(g)),
            "{gains:?}"
        );
        gains_seen.push(gains);
    }
    assert!(
        gains_seen.iter().any(|g| (g[0] - g[2]).abs() > 0.05),
        "{gains_seen:?}"
    );
}

#[test]
fn bad_settings_are_errors_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.relume");
    for config in [
        SynthConfig {
            frames: 0,
            ..small(64, 48, 1)
        },
        SynthConfig {
            width: 0,
            ..small(64, 48, 1)
        },
        SynthConfig {
            fps: -1.0,
            ..small(64, 48, 1)
        },
        SynthConfig {
            fps: 1e10,
            ..small(64, 48, 1)
        },
        SynthConfig {
            exposure_range: (1.0, 0.5),
            ..small(64, 48, 1)
        },
    ] {
        let err = generate(&config, &path).unwrap_err();
        assert!(err.to_string().contains("bad.relume"), "{err}");
        assert!(!path.exists());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}
