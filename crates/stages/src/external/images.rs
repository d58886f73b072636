//! Frame products as the protocol's image bytes and back, without a copy on the way
//! out (the image's own samples are written) and read straight into the product's
//! buffer on the way in. Samples travel in the machine's byte order, which the protocol
//! fixes as little-endian: relume builds for little-endian targets only here.

use super::protocol::{Dtype, ImageMeta, Layout, ReadError, read_all};
use crate::kind;
use glam::Vec3;
use relume_base::raster::Image;
use relume_graph::{Product, ProductKind};

#[cfg(not(target_endian = "little"))]
compile_error!("external stages send samples little-endian, as the machine holds them");

/// The product kind a protocol kind name stands for.
pub fn product_kind(layout: &Layout) -> &'static [ProductKind] {
    match layout.name {
        "color" => &[kind::COLOR],
        "depth" => &[kind::DEPTH],
        "points" => &[kind::POINTS],
        "normals" => &[kind::NORMALS],
        "radiance" => &[kind::RADIANCE],
        "scalar" => &[kind::SCALAR],
        "labels" => &[kind::LABELS],
        other => unreachable!("a layout without a product kind: {other}"),
    }
}

/// The meta and bytes of `product` sent as the port `role` of kind `layout`, or `None`
/// when the product is not of that kind.
pub fn to_bytes<'p>(
    product: &'p Product,
    role: &str,
    layout: &Layout,
) -> Option<(ImageMeta, &'p [u8])> {
    let kind = product_kind(layout)[0];
    let (width, height, bytes): (u32, u32, &[u8]) = match (layout.channels, layout.dtype) {
        (3, Dtype::U8) => {
            let image = product.get::<Image<[u8; 3]>>(kind)?;
            (image.width, image.height, bytemuck::cast_slice(&image.data))
        }
        (3, Dtype::F32) => {
            let image = product.get::<Image<Vec3>>(kind)?;
            (image.width, image.height, bytemuck::cast_slice(&image.data))
        }
        (1, Dtype::F32) => {
            let image = product.get::<Image<f32>>(kind)?;
            (image.width, image.height, bytemuck::cast_slice(&image.data))
        }
        (1, Dtype::U8) => {
            let image = product.get::<Image<u8>>(kind)?;
            (image.width, image.height, &image.data[..])
        }
        _ => unreachable!(
            "no layout has {} {:?} channels",
            layout.channels, layout.dtype
        ),
    };
    let meta = ImageMeta {
        role: role.to_string(),
        kind: layout.name.to_string(),
        width,
        height,
        channels: layout.channels,
        dtype: layout.dtype,
        offset: None,
    };
    Some((meta, bytes))
}

/// Reads the bytes `meta` announces into a product of kind `layout`. The caller has
/// checked that the meta's channels and type are the layout's.
pub fn from_reader(
    meta: &ImageMeta,
    layout: &Layout,
    input: &mut impl std::io::Read,
) -> Result<Product, ReadError> {
    let kind = product_kind(layout)[0];
    let (w, h) = (meta.width, meta.height);
    let n = w as usize * h as usize;
    fn read<T: bytemuck::Pod + Default>(
        input: &mut impl std::io::Read,
        w: u32,
        h: u32,
        n: usize,
    ) -> Result<Image<T>, ReadError> {
        let mut data = vec![T::default(); n];
        read_all(input, bytemuck::cast_slice_mut(&mut data))?;
        Ok(Image::from_vec(w, h, data).expect("n = w * h"))
    }
    Ok(match (layout.channels, layout.dtype) {
        (3, Dtype::U8) => Product::new(kind, read::<[u8; 3]>(input, w, h, n)?),
        (3, Dtype::F32) => Product::new(kind, read::<Vec3>(input, w, h, n)?),
        (1, Dtype::F32) => Product::new(kind, read::<f32>(input, w, h, n)?),
        (1, Dtype::U8) => Product::new(kind, read::<u8>(input, w, h, n)?),
        _ => unreachable!(
            "no layout has {} {:?} channels",
            layout.channels, layout.dtype
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_layout_round_trips_bit_for_bit() {
        let values = [0.5f32, -0.0, f32::MIN_POSITIVE, 1e30, 3.25, f32::NAN];
        for layout in super::super::protocol::LAYOUTS {
            let kind = product_kind(layout)[0];
            let product = match (layout.channels, layout.dtype) {
                (3, Dtype::U8) => Product::new(
                    kind,
                    Image::from_vec(2, 1, vec![[1u8, 2, 3], [250, 251, 252]]).unwrap(),
                ),
                (3, Dtype::F32) => Product::new(
                    kind,
                    Image::from_vec(
                        2,
                        1,
                        vec![
                            Vec3::new(values[0], values[1], values[2]),
                            Vec3::new(values[3], values[4], values[5]),
                        ],
                    )
                    .unwrap(),
                ),
                (1, Dtype::F32) => {
                    Product::new(kind, Image::from_vec(3, 2, values.to_vec()).unwrap())
                }
                _ => Product::new(kind, Image::from_vec(3, 1, vec![0u8, 7, 255]).unwrap()),
            };
            let (meta, bytes) = to_bytes(&product, "port", layout).unwrap();
            assert_eq!(meta.byte_len(), Ok(bytes.len()), "{}", layout.name);
            let back = from_reader(&meta, layout, &mut &bytes[..]).unwrap();
            assert_eq!(back.digest(), product.digest(), "{}", layout.name);
        }
    }

    #[test]
    fn a_product_of_another_kind_is_not_sent() {
        let depth = Product::new(kind::DEPTH, Image::from_vec(1, 1, vec![1.0f32]).unwrap());
        assert!(to_bytes(&depth, "image", &Layout::of("scalar").unwrap()).is_none());
    }
}
