//! Color conversions of `color.compensate` (paper 000 Sec. 4.1): linearization of the
//! camera's 8-bit values by a gamma curve, HSV, and the distances the pair filters and
//! the weights of eq. (1) use.
//!
//! **The hue-saturation plane.** Paper 000 compares pairs "in the hue-saturation plane"
//! after mapping hue and saturation into [0, 1]. Relume takes that plane to be the
//! cross-section of the HSV hexcone: a color of hue `h` and saturation `s` sits at
//! `s * hexagon(h)`, where `hexagon(h)` runs along a regular hexagon of circumradius 1
//! (red at (1, 0), then yellow, green, cyan, blue, magenta every sixth of a turn), so hue
//! wraps around by construction. Subtracting hue and saturation as Cartesian
//! coordinates instead would call two near-grey colors far apart because their (then
//! meaningless) hues differ; in the hexcone plane they are close, as they should be.
//! The point is computed without trigonometry: `(R - (G + B) / 2, sqrt(3) / 2 (G - B)) / V`
//! lies exactly on that hexagon at radius `S`. Distances: 1 between neighbouring
//! primaries and secondaries (red-yellow) or between a fully saturated color and grey,
//! 2 between complements.
//!
//! **Brightness of HDR values.** `V = max(R, G, B)`, not clamped (reference radiance and
//! compensated colors exceed 1). The strict HSV distance compares brightness
//! relatively, `dv = |V_a - V_b| / max(V_a, V_b)` in [0, 1] (0 when both are black), so it
//! means the same at every exposure: `dv = 0.1` is a 10 % brightness mismatch.

use glam::{Vec2, Vec3};

/// Gamma assumed for the camera's 8-bit values (paper 000 Sec. 4.1, after \[45\]).
pub const DEFAULT_INPUT_GAMMA: f32 = 2.2;

/// The camera's 8-bit levels mapped to linear values in [0, 1] by a 256-entry table,
/// `(v / 255)^gamma` (paper 000 Sec. 4.1: "a default gamma curve of 2.2").
#[derive(Clone, Debug, PartialEq)]
pub struct Linearize {
    table: [f32; 256],
}

impl Linearize {
    /// The table for display gamma `gamma` (2.2 in the paper).
    pub fn new(gamma: f32) -> Linearize {
        Linearize {
            table: std::array::from_fn(|v| (v as f64 / 255.0).powf(gamma as f64) as f32),
        }
    }

    /// The 256 linear values, indexed by level.
    #[inline]
    pub fn table(&self) -> &[f32; 256] {
        &self.table
    }

    /// The linear RGB of an 8-bit pixel.
    #[inline]
    pub fn rgb(&self, c: [u8; 3]) -> Vec3 {
        Vec3::new(
            self.table[c[0] as usize],
            self.table[c[1] as usize],
            self.table[c[2] as usize],
        )
    }
}

impl Default for Linearize {
    fn default() -> Self {
        Linearize::new(DEFAULT_INPUT_GAMMA)
    }
}

/// HSV of a linear RGB value: hue in [0, 1) (red 0, green 1/3, blue 2/3), saturation
/// `(max - min) / max` (in [0, 1] for non-negative input), value `max` (not clamped, so
/// HDR values keep V > 1). Black and greys have hue 0 and saturation 0.
pub fn hsv(rgb: Vec3) -> Vec3 {
    let (r, g, b) = (rgb.x, rgb.y, rgb.z);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let chroma = max - min;
    if !(max > 0.0 && chroma > 0.0) {
        return Vec3::new(0.0, 0.0, max.max(0.0));
    }
    let sector = if max == r {
        ((g - b) / chroma).rem_euclid(6.0)
    } else if max == g {
        (b - r) / chroma + 2.0
    } else {
        (r - g) / chroma + 4.0
    };
    let hue = sector / 6.0;
    // rem_euclid of a tiny negative value can round up to exactly 6.
    let hue = if hue >= 1.0 { 0.0 } else { hue };
    Vec3::new(hue, chroma / max, max)
}

/// The point of hue `hue` and saturation `saturation` in the hexcone's hue-saturation
/// plane (see the module doc): `saturation` times the point of the unit hexagon at
/// `hue`, interpolated linearly between the six vertices.
pub fn hexagon_point(hue: f32, saturation: f32) -> Vec2 {
    let vertex = |k: u32| {
        let angle = (k % 6) as f32 * std::f32::consts::FRAC_PI_3;
        Vec2::new(angle.cos(), angle.sin())
    };
    let sector = hue.rem_euclid(1.0) * 6.0;
    let k = (sector.floor() as u32).min(5);
    let t = sector - k as f32;
    saturation * vertex(k).lerp(vertex(k + 1), t)
}

/// `sqrt(3) / 2`.
const HALF_SQRT3: f32 = 0.866_025_4;

/// The position of a linear RGB value in the hexcone's hue-saturation plane and its
/// value V: the same point as `hexagon_point(h, s)` for `(h, s, V) = hsv(rgb)`, found
/// without trigonometry. Black gives the origin.
#[inline]
pub fn hs_point(rgb: Vec3) -> (Vec2, f32) {
    let v = rgb.x.max(rgb.y).max(rgb.z);
    let inv = if v > 0.0 { 1.0 / v } else { 0.0 };
    let point = Vec2::new(
        (rgb.x - 0.5 * (rgb.y + rgb.z)) * inv,
        HALF_SQRT3 * (rgb.y - rgb.z) * inv,
    );
    (point, v)
}

/// Relative brightness difference `|a - b| / max(a, b)`, 0 when both are 0 or less.
#[inline]
pub fn value_distance(a: f32, b: f32) -> f32 {
    let m = a.max(b);
    if m > 0.0 { (a - b).abs() / m } else { 0.0 }
}

/// Euclidean distance in the hue-saturation plane, `||hsv(a)_hs - hsv(b)_hs||` of
/// paper 000 Sec. 4.1 and eq. (1).
pub fn hs_distance(a: Vec3, b: Vec3) -> f32 {
    hs_point(a).0.distance(hs_point(b).0)
}

/// Euclidean distance in HSV including brightness (paper 000 Sec. 4.1, second pass):
/// `sqrt(d_hs^2 + dv^2)` with the relative brightness difference [`value_distance`].
pub fn hsv_distance(a: Vec3, b: Vec3) -> f32 {
    let ((pa, va), (pb, vb)) = (hs_point(a), hs_point(b));
    let dv = value_distance(va, vb);
    (pa.distance_squared(pb) + dv * dv).sqrt()
}

/// The weight of eq. (1), `(1 - min(1, d))^beta`, for an integer exponent (2 for A_t
/// and 8 for C_t in paper 000), by repeated squaring. A NaN distance gives weight 0.
#[inline]
pub fn pair_weight(hs_distance: f32, beta: u32) -> f32 {
    let mut base = if hs_distance < 1.0 {
        1.0 - hs_distance.max(0.0)
    } else {
        0.0
    };
    let (mut result, mut n) = (1.0f32, beta);
    while n > 0 {
        if n & 1 == 1 {
            result *= base;
        }
        base *= base;
        n >>= 1;
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-6
    }

    #[test]
    fn linearization_is_gamma_2_2() {
        let lin = Linearize::default();
        assert_eq!(lin.table()[0], 0.0);
        assert_eq!(lin.table()[255], 1.0);
        // 186 / 255 = 0.729412; ^2.2 = 0.499505 (the synthetic camera maps 0.5 to 186).
        assert!((lin.table()[186] - 0.499_505).abs() < 1e-6);
        assert_eq!(
            lin.rgb([0, 186, 255]),
            Vec3::new(0.0, lin.table()[186], 1.0)
        );
        assert!(lin.table().windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn hsv_of_known_colors() {
        let third = 1.0 / 3.0;
        assert!(close(
            hsv(Vec3::new(1.0, 0.0, 0.0)),
            Vec3::new(0.0, 1.0, 1.0)
        ));
        assert!(close(
            hsv(Vec3::new(1.0, 1.0, 0.0)),
            Vec3::new(1.0 / 6.0, 1.0, 1.0)
        ));
        assert!(close(
            hsv(Vec3::new(0.0, 0.5, 0.0)),
            Vec3::new(third, 1.0, 0.5)
        ));
        assert!(close(
            hsv(Vec3::new(0.0, 0.2, 0.4)),
            Vec3::new(7.0 / 12.0, 1.0, 0.4)
        ));
        assert!(close(
            hsv(Vec3::new(0.0, 0.0, 1.0)),
            Vec3::new(2.0 * third, 1.0, 1.0)
        ));
        assert!(close(
            hsv(Vec3::new(1.0, 0.0, 1.0)),
            Vec3::new(5.0 / 6.0, 1.0, 1.0)
        ));
        // Red with a little blue: just below hue 1, wrapping to red.
        assert!(close(
            hsv(Vec3::new(1.0, 0.0, 0.25)),
            Vec3::new(23.0 / 24.0, 1.0, 1.0)
        ));
        // (0.8, 0.4, 0.2): chroma 0.6, hue (0.4 - 0.2) / 0.6 / 6 = 1/18, s = 0.75.
        assert!(close(
            hsv(Vec3::new(0.8, 0.4, 0.2)),
            Vec3::new(1.0 / 18.0, 0.75, 0.8)
        ));
        // HDR: V keeps its value above 1; hue and saturation are scale-invariant.
        assert!(close(
            hsv(Vec3::new(3.2, 1.6, 0.8)),
            Vec3::new(1.0 / 18.0, 0.75, 3.2)
        ));
        assert_eq!(hsv(Vec3::splat(0.3)), Vec3::new(0.0, 0.0, 0.3));
        assert_eq!(hsv(Vec3::ZERO), Vec3::ZERO);
    }

    #[test]
    fn hs_point_lies_on_the_hexcone_at_hue_and_saturation() {
        let red = hs_point(Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(red, (Vec2::new(1.0, 0.0), 2.0));
        assert_eq!(hs_point(Vec3::splat(0.7)).0, Vec2::ZERO);
        assert_eq!(hs_point(Vec3::ZERO), (Vec2::ZERO, 0.0));
        let mut state = 7u64;
        for _ in 0..2000 {
            let mut next = || {
                state = relume_base::rng::mix64(state);
                relume_base::rng::unit_f32(state) * 3.0
            };
            let c = Vec3::new(next(), next(), next());
            let h = hsv(c);
            let expected = hexagon_point(h.x, h.y);
            let (p, v) = hs_point(c);
            assert!(p.distance(expected) < 1e-5, "{c:?}: {p:?} vs {expected:?}");
            assert_eq!(v, h.z);
        }
    }

    #[test]
    fn distances_of_known_pairs() {
        let (red, yellow, cyan) = (
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
        );
        assert!((hs_distance(red, yellow) - 1.0).abs() < 1e-6);
        assert!((hs_distance(red, cyan) - 2.0).abs() < 1e-6);
        assert!((hs_distance(red, Vec3::splat(0.2)) - 1.0).abs() < 1e-6);
        // Greys of any brightness coincide in the hs plane; hue wraps around red.
        assert_eq!(hs_distance(Vec3::splat(0.1), Vec3::splat(5.0)), 0.0);
        let (below, above) = (Vec3::new(1.0, 0.0, 0.1), Vec3::new(1.0, 0.1, 0.0));
        assert!((hs_distance(below, above) - 0.1 * 3f32.sqrt()).abs() < 1e-6);
        // Brightness counts relatively: 2.0 vs 2.5 is a 20 % mismatch.
        assert!((hsv_distance(Vec3::splat(2.0), Vec3::splat(2.5)) - 0.2).abs() < 1e-6);
        assert!((hsv_distance(red, 0.5 * yellow) - 1.25f32.sqrt()).abs() < 1e-6);
        assert_eq!(value_distance(0.0, 0.0), 0.0);
        assert_eq!(value_distance(0.0, 1.0), 1.0);
    }

    #[test]
    fn weights_follow_eq_1() {
        assert_eq!(pair_weight(0.0, 8), 1.0);
        assert_eq!(pair_weight(0.5, 2), 0.25);
        assert_eq!(pair_weight(0.5, 8), 0.5f32.powi(8));
        assert!((pair_weight(0.1, 8) - 0.9f32.powi(8)).abs() < 1e-7);
        assert_eq!(pair_weight(0.3, 0), 1.0);
        assert_eq!(pair_weight(1.0, 2), 0.0);
        assert_eq!(pair_weight(1.7, 2), 0.0);
        assert_eq!(pair_weight(f32::NAN, 2), 0.0);
    }
}
