//! `material.estimate`: the diffuse reflectance rho of the real surfaces (paper 000
//! eq. 5 in its Monte Carlo form, Sec. 7): with the incident light sampled by
//! `sample.*` as irradiance E_R = E_R^dir + E_R^ind, and the compensated camera radiance
//! L(x) of a Lambertian surface, L = rho / pi * E, so rho = pi L / E per channel. With
//! cosine-weighted samples, E = pi * mean(L_i) and this is the paper's
//! rho = L / mean(L_i).

use crate::{OpError, kind};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{Image, ScalarImage, Vec3Image};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError, StageInfo,
};
use std::f32::consts::PI;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "min_irradiance",
        ParamDefault::Float(1e-4),
        "pixels whose sampled irradiance (any channel) is below this get no estimate (NaN): \
         rho = pi L / E is meaningless where almost no light was found",
    )
    .range(0.0, 1e9),
    ParamSpec::new(
        "max_albedo",
        ParamDefault::Float(1.0),
        "estimates are clamped to [0, max_albedo] per channel; a Lambertian surface reflects \
         at most what it receives, so values above 1 are sampling noise or light the \
         samples missed",
    )
    .range(0.0, 1e3),
];

pub const INFO: StageInfo = StageInfo {
    kind: "material.estimate",
    summary: "diffuse reflectance of real surfaces, rho = pi L / E_R (paper 000 eq. 5, Monte Carlo form)",
    params: PARAMS,
    ports: |_| Ports {
        inputs: vec![
            Port::new("radiance", "compensated", &[kind::RADIANCE]),
            Port::new("e_r_dir", "e_r_dir", &[kind::RADIANCE]),
            Port::new("e_r_ind", "e_r_ind", &[kind::RADIANCE]),
            Port::new("mask", "mask", &[kind::SCALAR]),
        ],
        outputs: vec![Port::new("real_albedo", "real_albedo", &[kind::RADIANCE])],
    },
    build: |ctx| {
        Ok(Box::new(MaterialEstimate {
            radiance: ctx.input("radiance"),
            e_r_dir: ctx.input("e_r_dir"),
            e_r_ind: ctx.input("e_r_ind"),
            mask: ctx.input("mask"),
            albedo: ctx.output("real_albedo"),
            params: AlbedoParams {
                min_irradiance: ctx.params.float("min_irradiance") as f32,
                max_albedo: ctx.params.float("max_albedo") as f32,
            },
        }))
    },
};

/// Settings of [`estimate_albedo`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlbedoParams {
    pub min_irradiance: f32,
    pub max_albedo: f32,
}

/// rho = pi L / (E^dir + E^ind) per channel and pixel (paper 000 eq. 5), clamped to
/// [0, max_albedo]; NaN where no real surface is visible (`mask` 0), where the camera
/// radiance is missing, or where the irradiance is below `min_irradiance`.
pub fn estimate_albedo(
    radiance: &Vec3Image,
    e_dir: &Vec3Image,
    e_ind: &Vec3Image,
    mask: &ScalarImage,
    params: &AlbedoParams,
    albedo: &mut Vec3Image,
) -> Result<(), OpError> {
    for (name, w, h) in [
        ("e_r_dir", e_dir.width, e_dir.height),
        ("e_r_ind", e_ind.width, e_ind.height),
        ("mask", mask.width, mask.height),
        ("albedo", albedo.width, albedo.height),
    ] {
        if (w, h) != (radiance.width, radiance.height) {
            return Err(OpError::SizeMismatch(format!(
                "{name} is {w}x{h}, the camera radiance is {}x{}",
                radiance.width, radiance.height
            )));
        }
    }
    let width = radiance.width as usize;
    if width == 0 {
        return Ok(());
    }
    albedo
        .data
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(row, out)| {
            let at = row * width;
            for (i, rho) in out.iter_mut().enumerate() {
                let p = at + i;
                let l = radiance.data[p];
                let e = e_dir.data[p] + e_ind.data[p];
                *rho = if mask.data[p] > 0.0
                    && l.is_finite()
                    && e.is_finite()
                    && e.min_element() >= params.min_irradiance
                    && e.min_element() > 0.0
                {
                    (PI * l / e).clamp(Vec3::ZERO, Vec3::splat(params.max_albedo))
                } else {
                    Vec3::NAN
                };
            }
        });
    Ok(())
}

struct MaterialEstimate {
    radiance: String,
    e_r_dir: String,
    e_r_ind: String,
    mask: String,
    albedo: String,
    params: AlbedoParams,
}

impl Stage for MaterialEstimate {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let radiance = frame.radiance(&self.radiance)?;
        let mut albedo = Image::filled(radiance.width, radiance.height, Vec3::NAN);
        estimate_albedo(
            radiance,
            frame.radiance(&self.e_r_dir)?,
            frame.radiance(&self.e_r_ind)?,
            frame.scalar(&self.mask)?,
            &self.params,
            &mut albedo,
        )?;
        frame.insert(&self.albedo, Product::new(kind::RADIANCE, albedo));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_the_albedo_of_a_lambertian_surface_and_refuses_where_it_cannot() {
        // A surface of albedo rho under irradiance E reflects L = rho / pi * E.
        let rho = Vec3::new(0.6, 0.3, 0.1);
        let e_dir = Image::filled(3, 1, Vec3::new(2.0, 2.0, 2.0));
        let e_ind = Image::filled(3, 1, Vec3::new(1.0, 0.5, 0.25));
        let e = Vec3::new(3.0, 2.5, 2.25);
        let mut radiance = Image::filled(3, 1, rho / PI * e);
        radiance.data[2] = Vec3::NAN;
        let mut mask = Image::filled(3, 1, 1.0f32);
        mask.data[1] = 0.0;
        let mut albedo = Image::filled(3, 1, Vec3::ZERO);
        let params = AlbedoParams {
            min_irradiance: 1e-4,
            max_albedo: 1.0,
        };
        estimate_albedo(&radiance, &e_dir, &e_ind, &mask, &params, &mut albedo).unwrap();
        assert!(
            (albedo.data[0] - rho).abs().max_element() < 1e-6,
            "{}",
            albedo.data[0]
        );
        assert!(albedo.data[1].is_nan(), "virtual pixel");
        assert!(albedo.data[2].is_nan(), "no camera radiance");
        // No light found: no estimate rather than infinity.
        let dark = Image::filled(3, 1, Vec3::ZERO);
        estimate_albedo(&radiance, &dark, &dark, &mask, &params, &mut albedo).unwrap();
        assert!(albedo.data[0].is_nan());
    }

    #[test]
    fn size_mismatches_are_errors_naming_the_product() {
        let img = Image::filled(2, 2, Vec3::ONE);
        let small = Image::filled(1, 2, Vec3::ONE);
        let mask = Image::filled(2, 2, 1.0f32);
        let mut out = Image::filled(2, 2, Vec3::ZERO);
        let params = AlbedoParams {
            min_irradiance: 0.0,
            max_albedo: 1.0,
        };
        let err = estimate_albedo(&img, &small, &img, &mask, &params, &mut out).unwrap_err();
        assert_eq!(
            err.to_string(),
            "e_r_dir is 1x2, the camera radiance is 2x2"
        );
        assert!(matches!(err, OpError::SizeMismatch(_)), "{err:?}");
    }
}
