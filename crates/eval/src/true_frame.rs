//! The true mixed-reality frame of a synthetic recording: what the camera would have
//! recorded had the pipeline's `[[object]]`s really stood in the room, rendered by
//! [`relume_recording::synth::insert`] with the room's own lights and interreflection,
//! through the frame's own camera model (its color transform and contrast, gamma 2.2),
//! on the frames and pixel lattice of the 1024-sample references.
//!
//! Only recordings of `relume synth` with this build's generator version have one: the
//! truth re-traces the analytic room the recording was rendered from, so it must be the
//! same room, lit as it was at each frame (`relume synth --panel-off-at`, `--lamp-on-at`).
//! Where the objects change nothing the true pixel is the recorded one
//! exactly (the renderer returns the recorded radiance bit for bit, and the recorded
//! color was made from it by the same camera model).

use super::truth::FrameTruth;
use glam::{DMat3, Vec3};
use relume_base::raster::Rgb8Image;
use relume_graph::Frame;
use relume_graph::pipeline::SOURCE_PRODUCT;
use relume_recording::synth::camera::{GAMMA, camera_pixel};
use relume_recording::synth::insert::{
    InsertedHit, InsertedObjects, TrueFrameSettings, render_inserted,
};
use relume_recording::synth::lamp::SpotLamp;
use relume_recording::synth::render::View;
use relume_recording::synth::scene::Scene;
use relume_recording::synth::{GENERATOR_VERSION, LightSwitches, SYNTH_TOOL};
use relume_recording::{Header, Intrinsics};
use relume_scene::light::spot::{LightWorld, SpotLight};
use relume_scene::objects::VirtualScene;
use relume_stages::world::ObjectWorld;
use std::sync::{Arc, Mutex};

/// Paths per pixel of the truth (its error is reported with it:
/// `truth_noise_psnr_db`).
pub const TRUTH_PATHS: u32 = 256;
/// Surfaces a truth path meets at most: the objects' shadows and their light on the
/// room, the room's light on them, and one more bounce of each.
pub const TRUTH_BOUNCES: u32 = 4;

/// The true frame of one scored frame, on the reference lattice.
pub struct TrueComposite {
    pub frame: usize,
    /// Only pixels whose x and y are multiples of this were rendered; the others hold
    /// the recorded color.
    pub stride: u32,
    /// The 8-bit frame the camera would have recorded with the objects in the room.
    pub image: Rgb8Image,
    /// The 8-bit frame it did record (the truth without objects).
    pub camera: Rgb8Image,
    /// The truth's own error per pixel: one standard error, in 8-bit levels (the
    /// largest channel's); zero where the objects change nothing.
    pub noise_levels: Vec<f32>,
    /// Whether the pixel sees an object.
    pub object: Vec<bool>,
    /// The frame's contrast exponent (to linearize levels: [`linear_of_level`]).
    pub contrast: f32,
    /// Seconds the render took.
    pub render_s: f64,
    /// The room's depth at every pixel (metres, 0 where nothing is hit), without the
    /// objects: with `view`, where each pixel's real point is (the ghost's region,
    /// [`super::ghost`]).
    pub depth: Vec<f32>,
    /// The camera the frame was rendered through.
    pub view: View,
}

impl TrueComposite {
    /// Whether pixel `i` was rendered (lies on the lattice).
    pub fn has_pixel(&self, i: usize) -> bool {
        let (w, s) = (self.image.width as usize, self.stride as usize);
        w > 0 && (i % w).is_multiple_of(s) && (i / w).is_multiple_of(s)
    }
}

/// The pipeline's objects as the truth renderer sees them.
/// The pipeline's objects and its virtual lamps, as the truth inserts them.
struct Objects<'a>(&'a VirtualScene, &'a [SpotLamp]);

impl InsertedObjects for Objects<'_> {
    fn intersect(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<InsertedHit> {
        self.0
            .intersect(origin, direction, t_min, t_max)
            .map(|hit| InsertedHit {
                t: hit.t,
                position: hit.position,
                normal: hit.normal,
                albedo: hit.material.albedo,
                exponent: hit.material.exponent,
            })
    }

    fn occluded(&self, origin: Vec3, direction: Vec3, t_min: f32, t_max: f32) -> bool {
        self.0.occluded(origin, direction, t_min, t_max)
    }

    fn lamps(&self) -> &[SpotLamp] {
        self.1
    }
}

/// The pipeline's `[[light]]`s of the virtual world as lamps the truth inserts (paper
/// 002's virtual light sources: the room never had them). Its real lights are not
/// inserted: the truth's room has the lights the recording had (the synthetic room's
/// own lamp when `relume synth --lamp-on-at` switched it on), whatever the pipeline
/// believes.
fn virtual_lamps(lights: &[SpotLight]) -> Vec<SpotLamp> {
    lights
        .iter()
        .filter(|l| l.world == LightWorld::Virtual)
        .map(|l| SpotLamp {
            position: l.position,
            direction: l.direction,
            intensity: l.intensity,
            beam: l.beam,
            cutoff: l.cutoff,
        })
        .collect()
}

/// True frames computed for the frames in flight, shared by the evaluators of several
/// pipelines with the same objects (`relume compare`), keyed by frame, stride and the
/// objects' allocation; cleared with the references after each frame.
#[derive(Clone, Default)]
pub struct TruthCache(Arc<Mutex<Vec<KeyedTruth>>>);

/// A true frame and what it depends on (frame, stride, objects, settings).
type KeyedTruth = (String, Arc<TrueComposite>);

impl TruthCache {
    pub fn clear(&self) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }
}

/// Renders the true frames of a synthetic recording for one pipeline's objects.
pub struct TruthRenderer {
    /// When the room's lights switch (`relume synth --panel-off-at`, `--lamp-on-at`).
    switches: LightSwitches,
    /// The pipeline's objects (posed at each frame when they move).
    objects: ObjectWorld,
    /// Its `[[light]]`s of the virtual world ([`virtual_lamps`]).
    lamps: Vec<SpotLamp>,
    intrinsics: Intrinsics,
    settings: TrueFrameSettings,
    shared: Option<TruthCache>,
}

/// Why a recording has no true mixed-reality frame, or `None` when it has one.
pub fn unavailable(header: &Header) -> Option<String> {
    let p = &header.provenance;
    if p.tool != SYNTH_TOOL {
        return Some(format!(
            "the recording was made by `{}`, not `{SYNTH_TOOL}`: only the synthetic room can be re-rendered with the objects in it",
            p.tool
        ));
    }
    match p.settings.get("generator") {
        Some(v) if v == GENERATOR_VERSION => LightSwitches::of(p).err(),
        v => Some(format!(
            "the recording was made by generator version {}, this build renders version {GENERATOR_VERSION}'s room; make it again with `relume synth`",
            v.map_or("(none)", |v| v.as_str())
        )),
    }
}

impl TruthRenderer {
    /// The renderer for `objects` over the recording of `header`, or `None` when the
    /// recording has no true frame ([`unavailable`]) or nothing is inserted
    /// (no objects and no virtual lamps).
    pub fn new(header: &Header, objects: ObjectWorld, seed: u64) -> Option<TruthRenderer> {
        let lamps = virtual_lamps(&objects.lights);
        if unavailable(header).is_some() || (objects.scene.triangles.is_empty() && lamps.is_empty())
        {
            return None;
        }
        Some(TruthRenderer {
            // `unavailable` has checked the setting.
            switches: LightSwitches::of(&header.provenance).ok()?,
            lamps,
            objects,
            intrinsics: header.color_intrinsics,
            settings: TrueFrameSettings {
                paths: TRUTH_PATHS,
                bounces: TRUTH_BOUNCES,
                light_samples: 1,
                seed: relume_base::rng::hash(&[seed, TRUTH_SALT]),
            },
            shared: None,
        })
    }

    /// Takes true frames from `cache` when another evaluator rendered them, and leaves
    /// those it renders there.
    pub fn share(&mut self, cache: TruthCache) {
        self.shared = Some(cache);
    }

    /// The true frame of `frame` on the lattice of `stride`; `None` when the frame has
    /// no ground truth or no recorded pose.
    pub fn render(&self, frame: &Frame, stride: u32) -> Result<Option<Arc<TrueComposite>>, String> {
        let key = format!(
            "{} {stride} {:p} {:?} {:?}",
            frame.index,
            // Moving objects: their own motions, which no other pipeline shares.
            match &self.objects.moving {
                Some(moving) => Arc::as_ptr(moving) as *const (),
                None => Arc::as_ptr(&self.objects.scene) as *const (),
            },
            self.settings,
            // Pipelines with the same objects and other lamps have other truths.
            self.lamps,
        );
        if let Some(cache) = &self.shared {
            let held = cache.0.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((_, t)) = held.iter().find(|(k, _)| *k == key) {
                return Ok(Some(t.clone()));
            }
        }
        let Some(truth) = FrameTruth::of(frame)? else {
            return Ok(None);
        };
        let Some(pose) = frame
            .record(SOURCE_PRODUCT)
            .ok()
            .and_then(|r| r.pose.as_ref())
        else {
            return Ok(None);
        };
        let k = self.intrinsics;
        if (truth.width, truth.height) != (k.width, k.height) {
            return Err(format!(
                "frame {}: the ground truth is {}x{}, the color camera {}x{}",
                frame.index, truth.width, truth.height, k.width, k.height
            ));
        }
        let view = View {
            rotation: DMat3::from_quat(pose.rotation()).as_mat3(),
            position: pose.translation().as_vec3(),
            intrinsics: k,
        };
        let s = stride.max(1);
        let objects = self
            .objects
            .scene_at(frame.index as u64)
            .map_err(|e| e.to_string())?;
        let started = std::time::Instant::now();
        let scene: Scene = self.switches.scene_at(frame.index);
        let rendered = render_inserted(
            &scene,
            &view,
            &truth.radiance,
            &Objects(&objects, &self.lamps),
            frame.index as u64,
            &self.settings,
            &|x, y| x % s == 0 && y % s == 0,
        );
        let render_s = started.elapsed().as_secs_f64();
        let transform = truth.color_transform.transpose().to_cols_array();
        let encode = |l: Vec3| camera_pixel(&transform, truth.contrast, l);
        let levels = |l: Vec3| {
            let c = truth.color_transform * l;
            c.to_array().map(|v| unrounded_level(v, truth.contrast))
        };
        let noise_levels = rendered
            .radiance
            .iter()
            .zip(&rendered.standard_error)
            .map(|(&l, &e)| {
                if e == Vec3::ZERO {
                    return 0.0;
                }
                let (hi, lo) = (levels(l + e), levels((l - e).max(Vec3::ZERO)));
                (0..3).map(|c| 0.5 * (hi[c] - lo[c])).fold(0.0, f32::max)
            })
            .collect();
        let image = Rgb8Image::from_vec(
            k.width,
            k.height,
            rendered.radiance.iter().map(|&l| encode(l)).collect(),
        )
        .ok_or("truth image size")?;
        let camera = Rgb8Image::from_vec(
            k.width,
            k.height,
            truth.radiance.iter().map(|&l| encode(l)).collect(),
        )
        .ok_or("camera image size")?;
        let composite = Arc::new(TrueComposite {
            frame: frame.index,
            stride: s,
            image,
            camera,
            noise_levels,
            object: rendered.object,
            contrast: truth.contrast,
            render_s,
            depth: truth.depth,
            view,
        });
        if let Some(cache) = &self.shared {
            let mut held = cache.0.lock().unwrap_or_else(|p| p.into_inner());
            held.push((key, composite.clone()));
        }
        Ok(Some(composite))
    }
}

/// Salt of the truth's seed, apart from every stage's.
const TRUTH_SALT: u64 = 0x7472_7565;

/// The camera's 8-bit encoding of linear `v` before rounding (on the 0..255 scale).
fn unrounded_level(v: f32, contrast: f32) -> f32 {
    let v = v.max(0.0);
    let v = if contrast == 1.0 { v } else { v.powf(contrast) };
    v.powf(1.0 / GAMMA).min(1.0) * 255.0
}

/// The camera's linear value of 8-bit `level` (inverse of the encoding, without the
/// clipping).
pub fn linear_of_level(level: u8, contrast: f32) -> f32 {
    (level as f32 / 255.0).powf(GAMMA).powf(1.0 / contrast)
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_graph::Product;
    use relume_recording::codec::decode_color;
    use relume_recording::synth::{self, SynthConfig};
    use relume_recording::{FrameRecords, RECORD, Record};
    use relume_scene::objects::{Material, shapes};

    /// Frame `index` of a small synthetic recording, as the replay hands it to eval.
    fn synthetic_frame(config: &SynthConfig, index: usize) -> Frame {
        let records = synth::frame_records(
            config,
            &relume_recording::synth::interreflection::room(),
            index,
        )
        .unwrap();
        let (mut color, mut pose, mut truth) = (None, None, None);
        for record in records {
            match record {
                Record::Color(c) => color = Some(c),
                Record::Pose(p) => pose = Some(p.pose),
                Record::Truth(t) => truth = Some(t),
                Record::Depth(_) => {}
            }
        }
        let records = FrameRecords {
            index,
            stamp_ns: 0,
            color: color.unwrap(),
            depth: None,
            pose,
            truth,
        };
        let mut frame = Frame::new(index, 0);
        frame.insert(SOURCE_PRODUCT, Product::new(RECORD, Arc::new(records)));
        frame
    }

    /// A dark sphere of radius 0.3 resting on the floor at the objects' spot.
    fn ball() -> Arc<VirtualScene> {
        let mut triangles = shapes::sphere(0.3, 48);
        for t in &mut triangles {
            for v in &mut t.vertices {
                *v += Vec3::new(0.0, 0.3, 0.0);
            }
        }
        let material = Material {
            albedo: Vec3::splat(0.2),
            exponent: 0.0,
        };
        Arc::new(VirtualScene::new(triangles, vec![material]))
    }

    /// The header and frame 14 of a 64 x 48 synthetic recording of 15 frames.
    fn small_recording() -> (Header, Frame) {
        let config = SynthConfig {
            frames: 15,
            width: 64,
            height: 48,
            ..SynthConfig::default()
        };
        (synth::header(&config), synthetic_frame(&config, 14))
    }

    #[test]
    fn the_truth_keeps_the_recorded_pixels_the_objects_do_not_change() {
        let (header, frame) = small_recording();
        assert_eq!(unavailable(&header), None);
        let renderer = TruthRenderer::new(&header, ObjectWorld::still(ball()), 1).unwrap();
        let truth = renderer.render(&frame, 1).unwrap().unwrap();
        // The camera model reproduces the recorded frame exactly.
        let records = frame.record(SOURCE_PRODUCT).unwrap();
        let recorded = decode_color(&records.color.image).unwrap();
        assert_eq!(truth.camera.data, recorded.data);
        let unchanged: Vec<usize> = (0..recorded.data.len())
            .filter(|&i| !truth.object[i] && truth.noise_levels[i] == 0.0)
            .collect();
        for &i in &unchanged {
            assert_eq!(truth.image.data[i], recorded.data[i], "pixel {i}");
        }
        // In a closed room every surface sees the ball by some path, so at the truth's
        // sample count few pixels are untouched; far from the ball the change is below
        // a level and the 8-bit pixel is the recorded one.
        let off_object = (0..recorded.data.len()).filter(|&i| !truth.object[i]);
        let within_a_level = off_object
            .clone()
            .filter(|&i| (0..3).all(|c| truth.image.data[i][c].abs_diff(recorded.data[i][c]) <= 1))
            .count();
        let off_object = off_object.count();
        eprintln!(
            "{} of {} pixels untouched, {within_a_level} of {off_object} off the ball within a level",
            unchanged.len(),
            recorded.data.len()
        );
        assert!(within_a_level > off_object * 3 / 4, "{within_a_level}");
        // The ball is in view, and its shadow darkens the floor.
        assert!(truth.object.iter().filter(|o| **o).count() > 20);
        let darker = (0..recorded.data.len())
            .filter(|&i| !truth.object[i])
            .filter(|&i| {
                (0..3)
                    .all(|c| i32::from(truth.image.data[i][c]) + 2 < i32::from(recorded.data[i][c]))
            })
            .count();
        assert!(darker > 10, "{darker} pixels in the ball's shadow");
        // On a stride, pixels off the lattice keep the recorded color.
        let strided = renderer.render(&frame, 4).unwrap().unwrap();
        for i in (0..recorded.data.len()).filter(|&i| !strided.has_pixel(i)) {
            assert_eq!(strided.image.data[i], recorded.data[i]);
        }
    }

    #[test]
    fn a_virtual_lamp_is_inserted_and_a_real_one_is_not() {
        let (header, frame) = small_recording();
        let room = relume_recording::synth::lamp::room_lamp();
        let light = |world| SpotLight {
            name: "lamp".into(),
            world,
            position: room.position,
            direction: room.direction,
            intensity: room.intensity,
            beam: room.beam,
            cutoff: room.cutoff,
        };
        let lit_by = |lights: Vec<SpotLight>| ObjectWorld {
            lights,
            ..ObjectWorld::still(VirtualScene::new(Vec::new(), Vec::new()))
        };
        // A real light the recording does not have changes nothing the truth renders:
        // with no objects, nothing is inserted.
        assert!(TruthRenderer::new(&header, lit_by(vec![light(LightWorld::Real)]), 1).is_none());
        let renderer =
            TruthRenderer::new(&header, lit_by(vec![light(LightWorld::Virtual)]), 1).unwrap();
        let truth = renderer.render(&frame, 1).unwrap().unwrap();
        let recorded = truth.camera.data.clone();
        let (mut brighter, mut darker) = (0, 0);
        for (t, r) in truth.image.data.iter().zip(&recorded) {
            brighter += usize::from((0..3).all(|c| t[c] > r[c].saturating_add(2).min(254)));
            darker += usize::from((0..3).any(|c| t[c] < r[c]));
        }
        // The lamp's cone brightens the floor in view, and nothing darkens.
        assert!(brighter > 100, "{brighter} pixels brighter");
        assert_eq!(darker, 0);
        assert!(truth.object.iter().all(|o| !o));
    }

    #[test]
    fn only_the_current_synthetic_room_has_a_truth() {
        let config = SynthConfig::default();
        let mut header = synth::header(&config);
        header
            .provenance
            .settings
            .insert("generator".into(), "2".into());
        let why = unavailable(&header).unwrap();
        assert!(why.contains("generator version 2"), "{why}");
        header.provenance.tool = "relume import tum".into();
        let why = unavailable(&header).unwrap();
        assert!(why.contains("`relume import tum`"), "{why}");
        assert!(TruthRenderer::new(&header, ObjectWorld::still(ball()), 1).is_none());
    }
}
