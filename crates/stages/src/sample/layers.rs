//! The irradiance layers every renderer writes (`sample.path`, `sample.val`,
//! `sample.dir`), so that `filter.axis_aligned` and `composite.differential` run on
//! any of them unchanged: one type, one list of output roles, one way into the frame,
//! one pixel result and one row writer ([`PixelLayers`], [`LayerRow`]), and one
//! driver that hands a renderer the rows to fill in parallel ([`shade_rows`]).

use crate::OpError;
use crate::kind;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{Image, LabelImage, ScalarImage, Vec3Image};
use relume_graph::{Frame, Port, Product, ProductKind};

/// The output roles of a renderer, in [`IrradianceLayers`] order, with their kinds.
/// A renderer that cannot say which pixels its objects touched writes all but the
/// last.
pub const LAYER_OUTPUTS: [(&str, &[ProductKind]); 12] = [
    ("e_r_dir", &[kind::RADIANCE]),
    ("e_r_ind", &[kind::RADIANCE]),
    ("e_rv_dir", &[kind::RADIANCE]),
    ("e_rv_ind", &[kind::RADIANCE]),
    ("mask", &[kind::SCALAR]),
    ("k_v", &[kind::RADIANCE]),
    ("exponent", &[kind::SCALAR]),
    ("world_position", &[kind::POINTS]),
    ("world_normal", &[kind::NORMALS]),
    ("direct_min_distance", &[kind::SCALAR]),
    ("indirect_min_distance", &[kind::SCALAR]),
    ("touched", &[kind::LABELS]),
];

/// The inputs `sample.path` and `sample.dir` both read, in order: (role, default
/// product, kinds). The same roles let one stand in for the other, and let `relume
/// eval` run the path references on either's inputs.
pub const RENDERER_INPUTS: [(&str, &str, &[ProductKind]); 5] = [
    ("depth", "refined_depth", &[kind::DEPTH]),
    ("normals", "normals", &[kind::NORMALS]),
    ("pose", "pose", &[kind::POSE]),
    ("radiance", "compensated", &[kind::RADIANCE]),
    ("light_table", "light_table", &[kind::LIGHT_TABLE]),
];

/// [`RENDERER_INPUTS`] as ports.
pub fn renderer_input_ports() -> impl Iterator<Item = Port> {
    RENDERER_INPUTS
        .iter()
        .map(|(role, product, kinds)| Port::new(role, product, kinds))
}

/// [`LAYER_OUTPUTS`] as ports, each writing the product of its role's name.
pub fn layer_output_ports() -> Vec<Port> {
    LAYER_OUTPUTS
        .iter()
        .map(|(role, kinds)| Port::new(role, role, kinds))
        .collect()
}

/// Refuses ([`OpError::SizeMismatch`]) a renderer's inputs whose sizes differ from the depth map's (`w` x `h`):
/// `sizes` are (what, width, height); the error names `stage` and the first that
/// differs.
pub fn check_sizes(
    stage: &str,
    (w, h): (u32, u32),
    sizes: &[(&str, u32, u32)],
) -> Result<(), OpError> {
    for &(what, ww, hh) in sizes {
        if (ww, hh) != (w, h) {
            return Err(OpError::SizeMismatch(format!(
                "{stage}: {what} is {ww}x{hh}, depth is {w}x{h}"
            )));
        }
    }
    Ok(())
}

/// One value per pixel of each layer a renderer writes.
#[derive(Clone, Debug, PartialEq)]
pub struct IrradianceLayers {
    /// Irradiance, real geometry only, direct / indirect.
    pub e_r_dir: Vec3Image,
    pub e_r_ind: Vec3Image,
    /// Irradiance with the virtual objects.
    pub e_rv_dir: Vec3Image,
    pub e_rv_ind: Vec3Image,
    /// Fraction of the pixel that shows real geometry (M of paper 001 eq. 2).
    pub mask: ScalarImage,
    /// Albedo of the virtual surface the pixel shows (0 where none).
    pub k_v: Vec3Image,
    /// Phong exponent of that surface (0 where none, or diffuse): the filter's B_rho
    /// (paper 001 eq. 17) and B_h (eq. 18).
    pub exponent: ScalarImage,
    /// World position / unit normal of the visible surface (NaN / zero: none).
    pub world_position: Vec3Image,
    pub world_normal: Vec3Image,
    /// Metres to the nearest blocker of a direct sample / hit of an indirect ray.
    pub direct_min_distance: ScalarImage,
    pub indirect_min_distance: ScalarImage,
    /// 1 where some path met a virtual object (E_RV may differ from E_R), else 0.
    pub touched: LabelImage,
}

impl IrradianceLayers {
    /// Layers for a `width` x `height` frame whose irradiance is NaN until written
    /// (a pixel no renderer shades has no estimate).
    pub fn new(width: u32, height: u32) -> IrradianceLayers {
        Self::filled(width, height, Vec3::NAN)
    }

    /// Layers whose irradiance starts at `irradiance`; every other layer starts at
    /// "nothing there": mask 1, no albedo or exponent, NaN position, zero normal,
    /// infinite distances, untouched. About 30 MB at 640x480: filled on two threads.
    pub fn filled(width: u32, height: u32, irradiance: Vec3) -> IrradianceLayers {
        let v = |x| Image::filled(width, height, x);
        let s = |x| Image::filled(width, height, x);
        let ((e_r_dir, e_r_ind, e_rv_dir, e_rv_ind, mask, exponent), rest) = rayon::join(
            || {
                let e = irradiance;
                (v(e), v(e), v(e), v(e), s(1.0), s(0.0))
            },
            || {
                let (zero, nan, infinity) = (Vec3::ZERO, Vec3::NAN, f32::INFINITY);
                let touched = Image::filled(width, height, 0u8);
                (v(zero), v(nan), v(zero), s(infinity), s(infinity), touched)
            },
        );
        let (
            k_v,
            world_position,
            world_normal,
            direct_min_distance,
            indirect_min_distance,
            touched,
        ) = rest;
        IrradianceLayers {
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask,
            k_v,
            exponent,
            world_position,
            world_normal,
            direct_min_distance,
            indirect_min_distance,
            touched,
        }
    }

    /// The width and height of every layer, if they agree.
    pub fn size(&self) -> Option<(u32, u32)> {
        let s = &self.e_r_dir;
        let all = [
            self.e_r_ind.same_size(s),
            self.e_rv_dir.same_size(s),
            self.e_rv_ind.same_size(s),
            self.mask.same_size(s),
            self.k_v.same_size(s),
            self.exponent.same_size(s),
            self.world_position.same_size(s),
            self.world_normal.same_size(s),
            self.direct_min_distance.same_size(s),
            self.indirect_min_distance.same_size(s),
            self.touched.same_size(s),
        ];
        all.iter().all(|&b| b).then_some((s.width, s.height))
    }

    /// The layers as products, in [`LAYER_OUTPUTS`] order.
    pub fn into_products(self) -> [Product; 12] {
        [
            Product::new(kind::RADIANCE, self.e_r_dir),
            Product::new(kind::RADIANCE, self.e_r_ind),
            Product::new(kind::RADIANCE, self.e_rv_dir),
            Product::new(kind::RADIANCE, self.e_rv_ind),
            Product::new(kind::SCALAR, self.mask),
            Product::new(kind::RADIANCE, self.k_v),
            Product::new(kind::SCALAR, self.exponent),
            Product::new(kind::POINTS, self.world_position),
            Product::new(kind::NORMALS, self.world_normal),
            Product::new(kind::SCALAR, self.direct_min_distance),
            Product::new(kind::SCALAR, self.indirect_min_distance),
            Product::new(kind::LABELS, self.touched),
        ]
    }

    /// Puts the layers into `frame` under `names`, one per role of [`LAYER_OUTPUTS`]
    /// in order; layers past the end of `names` are not written.
    pub fn insert_into(self, frame: &mut Frame, names: &[String]) {
        for (name, product) in names.iter().zip(self.into_products()) {
            frame.insert(name, product);
        }
    }
}

/// What a renderer estimates at one pixel, one value per layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelLayers {
    pub e_r_dir: Vec3,
    pub e_r_ind: Vec3,
    pub e_rv_dir: Vec3,
    pub e_rv_ind: Vec3,
    pub mask: f32,
    pub k_v: Vec3,
    pub exponent: f32,
    pub world_position: Vec3,
    pub world_normal: Vec3,
    pub direct_min_distance: f32,
    pub indirect_min_distance: f32,
    pub touched: bool,
}

/// One row of every layer.
pub struct LayerRow<'a> {
    pub e_r_dir: &'a mut [Vec3],
    pub e_r_ind: &'a mut [Vec3],
    pub e_rv_dir: &'a mut [Vec3],
    pub e_rv_ind: &'a mut [Vec3],
    pub mask: &'a mut [f32],
    pub k_v: &'a mut [Vec3],
    pub exponent: &'a mut [f32],
    pub world_position: &'a mut [Vec3],
    pub world_normal: &'a mut [Vec3],
    pub direct_min_distance: &'a mut [f32],
    pub indirect_min_distance: &'a mut [f32],
    pub touched: &'a mut [u8],
}

impl LayerRow<'_> {
    /// Writes pixel `x` of the row.
    #[inline(always)]
    pub fn set(&mut self, x: usize, r: &PixelLayers) {
        self.e_r_dir[x] = r.e_r_dir;
        self.e_r_ind[x] = r.e_r_ind;
        self.e_rv_dir[x] = r.e_rv_dir;
        self.e_rv_ind[x] = r.e_rv_ind;
        self.mask[x] = r.mask;
        self.k_v[x] = r.k_v;
        self.exponent[x] = r.exponent;
        self.world_position[x] = r.world_position;
        self.world_normal[x] = r.world_normal;
        self.direct_min_distance[x] = r.direct_min_distance;
        self.indirect_min_distance[x] = r.indirect_min_distance;
        self.touched[x] = r.touched as u8;
    }
}

/// The renderers' driver: shades the rows of `out` (`width` pixels each) whose index
/// is a multiple of `stride`, in parallel on rayon's pool. `shade` gets the state
/// `init` made for its worker (buffers reused from row to row), the row's index and
/// the row to write. Each row is written by one call alone, so the layers do not
/// depend on the thread count.
pub fn shade_rows<S>(
    out: &mut IrradianceLayers,
    width: usize,
    stride: usize,
    init: impl Fn() -> S + Sync + Send,
    shade: impl Fn(&mut S, usize, LayerRow<'_>) + Sync + Send,
) {
    let stride = stride.max(1);
    rows(out, width)
        .into_par_iter()
        .enumerate()
        .filter(|(y, _)| y % stride == 0)
        .for_each_init(init, |state, (y, row)| shade(state, y, row));
}

/// The rows of every layer of `out` (rows of `width` pixels), top to bottom.
fn rows(out: &mut IrradianceLayers, width: usize) -> Vec<LayerRow<'_>> {
    let width = width.max(1);
    let mut e_r_dir = out.e_r_dir.data.chunks_mut(width);
    let mut e_r_ind = out.e_r_ind.data.chunks_mut(width);
    let mut e_rv_dir = out.e_rv_dir.data.chunks_mut(width);
    let mut e_rv_ind = out.e_rv_ind.data.chunks_mut(width);
    let mut mask = out.mask.data.chunks_mut(width);
    let mut k_v = out.k_v.data.chunks_mut(width);
    let mut exponent = out.exponent.data.chunks_mut(width);
    let mut world_position = out.world_position.data.chunks_mut(width);
    let mut world_normal = out.world_normal.data.chunks_mut(width);
    let mut direct_min = out.direct_min_distance.data.chunks_mut(width);
    let mut indirect_min = out.indirect_min_distance.data.chunks_mut(width);
    let mut touched = out.touched.data.chunks_mut(width);
    let mut rows = Vec::new();
    while let (Some(a), Some(b), Some(c), Some(d), Some(e), Some(f)) = (
        e_r_dir.next(),
        e_r_ind.next(),
        e_rv_dir.next(),
        e_rv_ind.next(),
        mask.next(),
        k_v.next(),
    ) {
        let (Some(exponent), Some(g), Some(h), Some(i), Some(j), Some(k)) = (
            exponent.next(),
            world_position.next(),
            world_normal.next(),
            direct_min.next(),
            indirect_min.next(),
            touched.next(),
        ) else {
            break;
        };
        rows.push(LayerRow {
            e_r_dir: a,
            e_r_ind: b,
            e_rv_dir: c,
            e_rv_ind: d,
            mask: e,
            k_v: f,
            exponent,
            world_position: g,
            world_normal: h,
            direct_min_distance: i,
            indirect_min_distance: j,
            touched: k,
        });
    }
    rows
}
