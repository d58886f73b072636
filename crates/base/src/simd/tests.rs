use super::*;

fn rows<V: Lanes>() -> [V; LANES] {
    std::array::from_fn(|r| V::from_array(std::array::from_fn(|l| (10 * r + l) as f32)))
}

fn check_transpose<V: Lanes>(name: &str) {
    let columns = V::transpose(rows::<V>());
    for (l, column) in columns.iter().enumerate() {
        let expected: [f32; LANES] = std::array::from_fn(|r| (10 * r + l) as f32);
        assert_eq!(column.to_array(), expected, "{name}, column {l}");
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_transpose_avx2() {
    check_transpose::<Avx2>("Avx2");
}

#[test]
fn transpose_moves_lane_l_of_row_r_to_lane_r_of_row_l() {
    check_transpose::<Portable>("Portable");
    #[cfg(target_arch = "x86_64")]
    if Kernel::detect() == Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_transpose_avx2() };
    }
}

fn check_rotate_up<V: Lanes>(name: &str) {
    let v = rows::<V>()[3];
    for r in 0..LANES {
        let expected: [f32; LANES] = std::array::from_fn(|l| (30 + (l + LANES - r) % LANES) as f32);
        assert_eq!(v.rotate_up(r).to_array(), expected, "{name}, r = {r}");
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_rotate_up_avx2() {
    check_rotate_up::<Avx2>("Avx2");
}

fn check_permute<V: Lanes>(name: &str) {
    let v = rows::<V>()[3];
    for index in [
        [0, 1, 2, 3, 4, 5, 6, 7],
        [7, 6, 5, 4, 3, 2, 1, 0],
        [3, 3, 0, 9, 15, 8, 1, 2],
    ] {
        let expected: [f32; LANES] = std::array::from_fn(|l| (30 + index[l] % 8) as f32);
        let got = v.permute(V::lane_indices(index)).to_array();
        assert_eq!(got, expected, "{name}, {index:?}");
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_permute_avx2() {
    check_permute::<Avx2>("Avx2");
}

#[test]
fn permute_picks_lane_index_mod_8() {
    check_permute::<Portable>("Portable");
    #[cfg(target_arch = "x86_64")]
    if Kernel::detect() == Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_permute_avx2() };
    }
}

#[test]
fn rotate_up_moves_lane_l_to_lane_l_plus_r() {
    check_rotate_up::<Portable>("Portable");
    #[cfg(target_arch = "x86_64")]
    if Kernel::detect() == Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_rotate_up_avx2() };
    }
}

/// `trunc` as `f32::trunc` (negative, halves, just below whole numbers, large,
/// infinite, NaN), and `gather_at` reading at whole-number float indices up to
/// just below 2^24.
fn check_trunc_and_gather_at<V: Lanes>(name: &str) {
    let values = [
        [-2.5, -0.7, -0.0, 0.0, 0.49, 0.99999994, 1.0, 127.99999],
        [
            4095.5,
            8_388_607.5,
            16_777_215.0,
            1e10,
            -1e10,
            f32::INFINITY,
            f32::NEG_INFINITY,
            3.5,
        ],
    ];
    for v in values {
        let got = V::from_array(v).trunc().to_array();
        for (g, x) in got.iter().zip(v) {
            assert_eq!(g.to_bits(), x.trunc().to_bits(), "{name}: trunc({x})");
        }
    }
    assert!(V::splat(f32::NAN).trunc().to_array()[0].is_nan(), "{name}");
    let data: Vec<f32> = (0..1 << 16).map(|i| i as f32 * 0.5).collect();
    let index = [0.0, 1.0, 65535.0, 17.0, 17.0, 4096.0, 3.0, 60000.0];
    // SAFETY: every index is inside `data`.
    let got = unsafe { V::gather_at(data.as_ptr(), V::from_array(index)) }.to_array();
    assert_eq!(got, index.map(|i| data[i as usize]), "{name}");
    // The largest index the contract allows.
    let mut far = vec![1.0f32; 1 << 24];
    far[(1 << 24) - 1] = 7.0;
    let at = [16_777_215.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    // SAFETY: every index is inside `far`.
    let got = unsafe { V::gather_at(far.as_ptr(), V::from_array(at)) }.to_array();
    assert_eq!(got[0], 7.0, "{name}");
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_trunc_and_gather_at_avx2() {
    check_trunc_and_gather_at::<Avx2>("Avx2");
}

#[test]
fn trunc_rounds_toward_zero_and_gather_at_reads_at_float_indices() {
    check_trunc_and_gather_at::<Portable>("Portable");
    #[cfg(target_arch = "x86_64")]
    if Kernel::detect() == Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_trunc_and_gather_at_avx2() };
    }
}

fn check_interleave3<V: Lanes>(name: &str) {
    let planes: [V; 3] =
        std::array::from_fn(|c| V::from_array(std::array::from_fn(|l| (10 * l + c) as f32)));
    let triples: Vec<f32> = V::interleave3(planes)
        .iter()
        .flat_map(|v| v.to_array())
        .collect();
    let expected: Vec<f32> = (0..LANES)
        .flat_map(|l| (0..3).map(move |c| (10 * l + c) as f32))
        .collect();
    assert_eq!(triples, expected, "{name}");
    let back = V::deinterleave3(V::interleave3(planes));
    for (c, (got, plane)) in back.iter().zip(&planes).enumerate() {
        assert_eq!(
            got.to_array(),
            plane.to_array(),
            "{name}: deinterleave3 plane {c}"
        );
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_interleave3_avx2() {
    check_interleave3::<Avx2>("Avx2");
}

#[test]
fn interleave3_makes_eight_triples_from_three_planes_and_deinterleave3_undoes_it() {
    check_interleave3::<Portable>("Portable");
    #[cfg(target_arch = "x86_64")]
    if Kernel::detect() == Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_interleave3_avx2() };
    }
}
