//! Tests of the full windows: which windows the Y pass finds full, and that their sums
//! are the bits of the general ones.

use super::super::gaussian::{
    Contiguous, MAX_TAPS, VALUE_PLANES, Window, accumulate, accumulate_full,
};
use super::super::lane_planes::{LaneLayout, LanePlanes};
use super::super::layout::{X_B2_IND, X_B2Y_DIR, X_DIR, X_IND, X_PLANES, X_PX};
use super::super::temporal::PreviousView;
use super::sets::*;
use super::*;
use glam::Vec3;
use relume_base::raster::{Image, Vec3Image};
use relume_base::rng::{hash, unit_f32};
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// An X set of `width` x `height` with every value present except at `gaps` (pixel x,
/// line, plane), positions on a plane 2 m away and random values.
fn x_set(width: usize, height: usize, radius: usize, gaps: &[(usize, usize, usize)]) -> XSet {
    let mut set = LanePlanes::new(LaneLayout::blocks(X_PLANES, width, height, radius));
    let s = set.plane_stride();
    for line in 0..height {
        for x in 0..width {
            let i = set.pixel_index(x as isize, line as isize);
            let data = set.data_mut();
            data[i + X_PX * s] = 0.01 * x as f32;
            data[i + (X_PX + 1) * s] = 0.01 * line as f32;
            data[i + (X_PX + 2) * s] = 2.0;
            data[i + X_B2Y_DIR * s] = 100.0;
            data[i + X_B2_IND * s] = 50.0;
            for first in [X_DIR, X_IND] {
                for q in 0..6 {
                    data[i + (first + q) * s] = unit_f32(hash(&[x as u64, line as u64, q as u64]));
                }
                data[i + (first + 6) * s] = 1.0;
                data[i + (first + 7) * s] = 1.0;
            }
        }
    }
    for &(x, line, plane) in gaps {
        let i = set.pixel_index(x as isize, line as isize);
        set.data_mut()[i + plane * s] = 0.0;
    }
    XSet::from_planes(set)
}

/// The Y pass marks a window of a kind full exactly when all its taps, eight lanes by
/// 2 R + 1 lines inside the image, have both valid planes 1: gaps in either layer of
/// a kind empty that kind's windows around them, and the lines within R of the image's
/// top and bottom (whose windows reach the padding) are never full.
#[test]
fn full_windows_are_the_windows_without_a_gap() {
    // Width 21: the last block's lanes 5..8 lie past the image, with no values, so its
    // windows are never full.
    let (width, height, radius) = (21, 30, 3);
    let gaps = [(5, 10, X_DIR + 6), (12, 2, X_IND + 7), (15, 26, X_DIR + 7)];
    let set = x_set(width, height, radius, &gaps);
    let expected: Vec<u8> = (0..width.div_ceil(LANES))
        .flat_map(|n| (0..height).map(move |y| (n, y)))
        .map(|(n, y)| {
            let mut bits = 0;
            for (k, first) in [X_DIR, X_IND].into_iter().enumerate() {
                let inside = y >= radius && y + radius < height && (n + 1) * LANES <= width;
                let gap = gaps.iter().any(|&(x, line, plane)| {
                    x / LANES == n
                        && line.abs_diff(y) <= radius
                        && plane >= first
                        && plane < first + 8
                });
                if inside && !gap {
                    bits |= 1 << k;
                }
            }
            bits
        })
        .collect();
    for kernel in [Kernel::Portable, Kernel::detect()] {
        let mut out: [Vec3Image; 4] =
            std::array::from_fn(|_| Image::filled(width as u32, height as u32, Vec3::ZERO));
        let mut set = set.clone();
        y_pass(kernel, &mut set, None, radius, &mut out);
        assert_eq!(set.full_windows().bits, expected, "{kernel:?}");
        // Writing the planes forgets the windows.
        set.planes_mut();
        assert_eq!(set.full_windows(), &FullWindows::default());
    }
    for k in 0..2 {
        let count = expected.iter().filter(|&&b| b & (1 << k) != 0).count();
        assert!(
            count > 0 && count < expected.len(),
            "kind {k}: {count} full"
        );
    }
}

/// Over windows whose valid planes are all 1, the full sums are the general sums bit
/// for bit, from any starting sums, with either kernel's lanes.
#[test]
fn full_sums_are_the_bits_of_the_general_sums() {
    let set = x_set(16, 12, 5, &[]);
    let set = set.planes();
    let s = set.plane_stride();
    for case in 0..200u64 {
        let random = |k: u64| unit_f32(hash(&[case, k]));
        let weights: Vec<Portable> = (0..MAX_TAPS as u64)
            .map(|i| {
                let w: [f32; LANES] = std::array::from_fn(|l| {
                    // Some exact zeros and ones, as the cutoff and the target give.
                    match hash(&[case, i, l as u64]) % 8 {
                        0 => 0.0,
                        1 => 1.0,
                        _ => random(100 + i * 8 + l as u64),
                    }
                });
                Portable::from_array(w)
            })
            .collect();
        let start: [Portable; VALUE_PLANES] = std::array::from_fn(|q| {
            Portable::splat(if case % 2 == 0 { 0.0 } else { random(q as u64) })
        });
        let line = (case % 3) as isize;
        let window = Window {
            planes: set.data()[set.slot_index((case % 2) as isize, line)..].as_ptr(),
            plane_stride: s,
            tap_step: set.line_step(),
            taps: 2 * (case as usize % 5) + 1,
        };
        let first = if case % 4 < 2 { X_DIR } else { X_IND };
        let (mut general, mut full) = (start, start);
        // SAFETY: lines line..line + 9 <= 11 of blocks 0 and 1 lie inside the set, and
        // inside the image: every valid plane read is 1.
        unsafe {
            accumulate(&Contiguous, &window, first, &weights, &mut general);
            accumulate_full(&Contiguous, &window, first, &weights, &mut full);
        }
        for q in 0..VALUE_PLANES {
            let (g, f) = (general[q].to_array(), full[q].to_array());
            assert_eq!(
                g.map(f32::to_bits),
                f.map(f32::to_bits),
                "case {case}, plane {q}"
            );
        }
    }
}

/// The Y pass with the previous frame's full windows gives the bits it gives without
/// them (every window read the general way), for both kernels, under a still camera
/// (contiguous temporal reads), one moved by 3 pixels (rotated reads) and one rolled
/// two ways (permuted reads over two lines, of one block or two), with gaps in both
/// sets and a partial last block.
#[test]
fn temporal_taps_over_full_windows_give_the_general_bits() {
    use glam::Affine3A;
    use relume_base::pinhole::Pinhole;
    use relume_recording::Intrinsics;
    let (width, height, radius) = (37, 40, 4);
    let current = x_set(
        width,
        height,
        radius,
        &[(9, 20, X_DIR + 6), (30, 5, X_IND + 7)],
    );
    let previous = x_set(
        width,
        height,
        radius,
        // Read by permuted groups of the camera rolled by 0.12: (26, 14) in the second
        // block (3) of those at pixels 24.. of lines 12-16, whose first block (2) is
        // full there; (21, 26) in the window of the second line (22) but not the first
        // of the group at pixels 16.. of line 20.
        &[
            (3, 12, X_IND + 6),
            (20, 33, X_DIR + 7),
            (26, 14, X_DIR + 6),
            (21, 26, X_IND + 6),
        ],
    );
    // Positions (0.01 x, 0.01 y, 2) project to pixel (x, y): f = 200, c = 0.
    let intrinsics = Intrinsics {
        width: width as u32,
        height: height as u32,
        fx: 200.0,
        fy: 200.0,
        cx: 0.0,
        cy: 0.0,
    };
    let camera = Pinhole::new(&intrinsics, width as u32, height as u32);
    let mut previous = previous;
    let mut scratch: [Vec3Image; 4] =
        std::array::from_fn(|_| Image::filled(width as u32, height as u32, Vec3::ZERO));
    y_pass(Kernel::Portable, &mut previous, None, radius, &mut scratch);
    assert!(previous.full_windows().bits.contains(&3));
    // The same planes with no window known to be full.
    let previous_general = XSet::from_planes(previous.planes().clone());
    // The move the gaps of `previous` are placed for.
    let rolled_more = Affine3A::from_rotation_z(0.12);
    let moves = [
        ("still", Affine3A::IDENTITY),
        (
            "3 px sideways",
            Affine3A::from_translation(glam::Vec3::new(0.03, 0.0, 0.0)),
        ),
        ("rolled", Affine3A::from_rotation_z(0.05)),
        ("rolled more", rolled_more),
    ];
    for (shift, world_to_camera) in moves {
        let view = PreviousView {
            world_to_camera,
            camera,
        };
        for kernel in [Kernel::Portable, Kernel::detect()] {
            let run = |previous: &XSet| {
                let mut out: [Vec3Image; 4] =
                    std::array::from_fn(|_| Image::filled(width as u32, height as u32, Vec3::ZERO));
                let previous = Previous {
                    x_set: previous,
                    view: &view,
                };
                let mut current = current.clone();
                y_pass(kernel, &mut current, Some(previous), radius, &mut out);
                out.map(|layer| {
                    layer
                        .data
                        .iter()
                        .flat_map(|v| v.to_array().map(f32::to_bits))
                        .collect::<Vec<u32>>()
                })
            };
            assert_eq!(
                run(&previous),
                run(&previous_general),
                "{kernel:?}, shift {shift}"
            );
        }
    }
    // The rolled-more groups that the gaps are placed for read their taps permuted,
    // from windows full in one kind only: the sums above went both ways.
    let view = PreviousView {
        world_to_camera: rolled_more,
        camera,
    };
    let previous = Previous {
        x_set: &previous,
        view: &view,
    };
    let valid = [[Portable::splat(1.0); 2]; 2];
    for (x0, y, expected_full) in [(16, 20, 0b01), (24, 14, 0b10)] {
        let position = [
            Portable::from_array(std::array::from_fn(|l| 0.01 * (x0 + l) as f32)),
            Portable::splat(0.01 * y as f32),
            Portable::splat(2.0),
        ];
        let taps = super::taps::temporal_taps(previous, position, &valid, x0, y, radius);
        let full = match taps {
            super::taps::TemporalTaps::Permuted(_, permuted, _, full) => {
                assert_eq!(permuted.count(), 2, "group ({x0}, {y})");
                full
            }
            _ => panic!("group ({x0}, {y}) does not read permuted"),
        };
        assert_eq!(full, expected_full, "group ({x0}, {y})");
    }
}
