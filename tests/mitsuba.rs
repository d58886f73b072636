//! An independent check of `relume synth`'s renderer against Mitsuba 3: the synthetic
//! room is exported (`relume::recording::synth::mitsuba`), rendered by
//! `scripts/mitsuba_render.py` (PyPI's `mitsuba`, variant `scalar_rgb`, CPU) and compared
//! with relume's own rendering of the same views, region by region.
//!
//! Mitsuba box-filters each pixel (its samples spread over the pixel's square) while
//! relume shoots one ray through its centre. Point samples of the room's sharp textures
//! (10 cm checkers, 2 cm drawer gaps, 1.6 cm grout) alias: one ray per centre put a
//! block's mean 12 % off Mitsuba's. So relume's images here are box-filtered too: the
//! mean of 4 x 4 renders whose principal point moves the pixel-centre rays over a
//! regular grid inside each pixel ([`box_filtered`]). Pixels whose 3 x 3 neighbourhood
//! sees more than one thing (geometric edges where depth jumps, room corners, the
//! emitters' borders) are still left out ([`interior`]), and the figures are means over
//! whole regions: "room" (floor, ceiling and walls, not the emitters) and "ball+blocks".
//! Interior emitter pixels must give the light's radiance within 0.1 %.
//!
//! The last test checks the true mixed-reality frame (`synth::insert::render_inserted`:
//! the recorded radiance plus a path-traced differential) against Mitsuba's path tracing
//! of the room with the same triangle meshes inserted, box-filtered the same way, per
//! region: the room the objects leave as it was, the objects, and their shadows.
//!
//! The Python side runs in a virtual environment made once under the target folder by
//! `pip install mitsuba==3.9.1`.

mod common;

use glam::{DMat3, Vec3};
use relume::objects::{Bvh, Triangle, shapes, tri_normal};
use relume::recording::Intrinsics;
use relume::recording::synth::camera::camera_pose;
use relume::recording::synth::geometry::{AxisBox, ray_box_entry};
use relume::recording::synth::insert::{
    InsertedHit, InsertedObjects, TrueFrameSettings, render_inserted,
};
use relume::recording::synth::lamp::room_lamp;
use relume::recording::synth::mitsuba::{MitsubaObject, export_scene, read_radiance};
use relume::recording::synth::render::{View, pixel_direction, purpose, render_view, shade};
use relume::recording::synth::scene::{Hit, OBJECT_POSITION, Ray, Scene, Surface};
use relume::rng::Counter;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Instant;

/// Image size of the compared views: PrimeSense scaled down.
const W: u32 = 64;
const H: u32 = 48;
/// Texture resolution of the exported room: 1 cm texels (a pixel covers about 5 cm
/// of the nearest wall).
const TEXELS_PER_METRE: f32 = 100.0;
/// Seed of relume's shadow rays and of Mitsuba's sampler.
const SEED: u64 = 7;
/// Stratified shadow rays per light and sub-pixel of relume's direct light (the
/// renderer's own grid is 4 x 2): with 16 sub-pixels, 256 per light and pixel.
const DIRECT_GRID: (u32, u32) = (4, 4);
/// Mitsuba's samples per pixel with direct light only (`max_depth` 2): two seeds'
/// region means differ by 0.25 % at most (3.4 s for the three views on two cores).
const DIRECT_SPP: u32 = 1024;
/// Mitsuba's samples per pixel with full path tracing (`max_depth` -1): at 1024, two
/// seeds' region means differed by 0.25 % (room) and 0.7 % (blue of ball+blocks, a
/// dim channel), in 11 s; twice the samples halve the variance.
const GI_SPP: u32 = 2048;
/// The largest relative error of a region's mean, per channel.
const TOLERANCE: f64 = 0.02;

/// The python3 of a virtual environment with Mitsuba 3 installed.
fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let made = PYTHON.get_or_init(|| {
        common::venv::make(
            "mitsuba-venv",
            &["mitsuba==3.9.1"],
            "import mitsuba; mitsuba.set_variant('scalar_rgb')",
        )
        .map(|venv| venv.join("bin/python3"))
    });
    match made {
        Ok(python) => python,
        Err(why) => panic!(
            "the Mitsuba comparison needs Python 3 with venv and pip, and Mitsuba 3 from PyPI \
             (`pip install mitsuba==3.9.1`): {why}"
        ),
    }
}

/// Runs `scripts/mitsuba_render.py` on `dir/scene.xml` into `dir/out`; prints its
/// report (per-view times) and returns the seconds it took.
fn mitsuba_render(dir: &Path, spp: u32, max_depth: i32, extra: &[&str]) -> f64 {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/mitsuba_render.py");
    let started = Instant::now();
    let out = Command::new(python())
        .arg(script)
        .arg(dir.join("scene.xml"))
        .arg(dir.join("out"))
        .args(["--spp", &spp.to_string()])
        .args(["--max-depth", &max_depth.to_string()])
        .args(["--seed", &SEED.to_string()])
        .args(extra)
        .output()
        .expect("run python");
    let seconds = started.elapsed().as_secs_f64();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "mitsuba_render.py failed: {}\n{}{}",
        out.status,
        text,
        String::from_utf8_lossy(&out.stderr)
    );
    for line in text.lines() {
        eprintln!("  mitsuba: {line}");
    }
    seconds
}

/// A view of camera path time `t` through `intrinsics`, built as `relume synth` does.
fn view_at(t: f64, intrinsics: Intrinsics) -> View {
    let pose = camera_pose(t);
    View {
        rotation: DMat3::from_quat(pose.rotation()).as_mat3(),
        position: pose.translation().as_vec3(),
        intrinsics,
    }
}

/// The compared views: from the orbit's start (the ball, drawers and fabric bench), from
/// the west looking at the window, and from the north looking south.
fn views() -> Vec<View> {
    let k = Intrinsics::PRIMESENSE.scaled_to(W, H);
    [0.0, 1.9, 4.5].map(|t| view_at(t, k)).to_vec()
}

/// What a pixel's centre ray sees, for the region masks.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seen {
    Emitter(usize),
    Room(Surface),
    Object(Surface),
    /// The check object of the camera test.
    Cube,
    /// Inserted object `k` of the mixed-reality test.
    Inserted(usize),
}

/// The first hit through each pixel centre of `view`, with what it is.
fn centre_hits(scene: &Scene, view: &View) -> Vec<(Hit, Seen)> {
    let k = view.intrinsics;
    let mut hits = Vec::new();
    for y in 0..k.height {
        for x in 0..k.width {
            let ray = Ray {
                origin: view.position,
                direction: view.rotation * pixel_direction(&k, x, y),
            };
            let hit = scene.intersect(&ray, 0.0).expect("every ray hits the room");
            let seen = match hit.surface {
                _ if scene.material(&hit).emission != Vec3::ZERO => Seen::Emitter(
                    scene
                        .lights
                        .iter()
                        .position(|l| l.surface == hit.surface && l.contains(hit.position))
                        .unwrap(),
                ),
                Surface::Ball | Surface::Block(_) => Seen::Object(hit.surface),
                other => Seen::Room(other),
            };
            hits.push((hit, seen));
        }
    }
    hits
}

/// True for pixels whose 3 x 3 neighbourhood sees one thing only: away from
/// geometric edges (where depth jumps), room corners and emitter borders.
fn interior(seen: &[Seen], width: u32, height: u32) -> Vec<bool> {
    let (w, h) = (width as i64, height as i64);
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let centre = seen[(y * w + x) as usize];
            (-1..=1).all(|dy| {
                (-1..=1).all(|dx| {
                    let (nx, ny) = (x + dx, y + dy);
                    !(0..w).contains(&nx)
                        || !(0..h).contains(&ny)
                        || seen[(ny * w + nx) as usize] == centre
                })
            })
        })
        .collect()
}

/// The regions compared: "room" (floor, ceiling, walls, not the emitters) and "objects"
/// (the ball and the blocks).
fn region_of(seen: Seen) -> Option<usize> {
    match seen {
        Seen::Room(_) => Some(0),
        Seen::Object(_) => Some(1),
        Seen::Emitter(_) | Seen::Cube | Seen::Inserted(_) => None,
    }
}
const REGIONS: [&str; 2] = ["room", "ball+blocks"];

/// Sums of a set of pixels: count, relume's and Mitsuba's radiance.
#[derive(Clone, Copy, Default)]
struct Sums {
    pixels: usize,
    relume: glam::DVec3,
    mitsuba: glam::DVec3,
}

impl Sums {
    fn add(&mut self, relume: Vec3, mitsuba: Vec3) {
        self.pixels += 1;
        self.relume += relume.as_dvec3();
        self.mitsuba += mitsuba.as_dvec3();
    }

    /// Mitsuba's mean over relume's, less 1, per channel.
    fn errors(&self) -> glam::DVec3 {
        self.mitsuba / self.relume - 1.0
    }
}

fn percent(v: glam::DVec3) -> String {
    format!(
        "{:+.2} %, {:+.2} %, {:+.2} %",
        100.0 * v.x,
        100.0 * v.y,
        100.0 * v.z
    )
}

/// Compares Mitsuba's renders in `out` with relume's images of `views`, over the
/// interior pixels (see [`interior`]) of each region: prints, per view and region, the
/// pixel count, both means and the relative error per channel (then, for information,
/// per surface), and returns the worst region error over views, regions of at least 50
/// pixels and channels. Checks that interior emitter pixels give the light's radiance in
/// Mitsuba within 0.1 %.
fn compare(label: &str, scene: &Scene, views: &[View], relume: &[Vec<Vec3>], out: &Path) -> f64 {
    let mut worst: f64 = 0.0;
    eprintln!("{label}: relative error of region means (Mitsuba / relume - 1; R, G, B)");
    for (index, view) in views.iter().enumerate() {
        let k = view.intrinsics;
        let (width, height, mitsuba) =
            read_radiance(&out.join(format!("view_{index}.pfm"))).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((width, height), (k.width, k.height));
        let seen: Vec<Seen> = centre_hits(scene, view).iter().map(|h| h.1).collect();
        let keep = interior(&seen, width, height);
        let mut regions = [Sums::default(); 2];
        let mut surfaces: Vec<(Seen, Sums)> = Vec::new();
        let (mut emitter_pixels, mut emitter_error) = (0, 0f64);
        for i in (0..seen.len()).filter(|&i| keep[i]) {
            let (a, b) = (relume[index][i], mitsuba[i]);
            if let Seen::Emitter(l) = seen[i] {
                let want = scene.lights[l].radiance;
                emitter_error = emitter_error.max(((b - want).abs() / want).max_element() as f64);
                emitter_pixels += 1;
            } else if let Some(r) = region_of(seen[i]) {
                regions[r].add(a, b);
                match surfaces.iter_mut().find(|s| s.0 == seen[i]) {
                    Some(s) => s.1.add(a, b),
                    None => {
                        let mut s = Sums::default();
                        s.add(a, b);
                        surfaces.push((seen[i], s));
                    }
                }
            }
        }
        eprintln!(
            "  view {index}: {} of {} pixels interior; {emitter_pixels} emitter pixels, off \
             the lights' radiance by {:.4} % at most",
            keep.iter().filter(|k| **k).count(),
            seen.len(),
            100.0 * emitter_error,
        );
        assert!(
            emitter_error < 1e-3,
            "{label}, view {index}: Mitsuba's emitter pixels differ from the lights' \
             radiance by up to {:.3} %",
            100.0 * emitter_error
        );
        for (name, s) in REGIONS.iter().zip(&regions) {
            if s.pixels == 0 {
                continue;
            }
            let n = s.pixels as f64;
            let (a, b) = (s.relume / n, s.mitsuba / n);
            eprintln!(
                "    {name:<12} {:>5} px  relume ({:.4}, {:.4}, {:.4})  mitsuba ({:.4}, {:.4}, \
                 {:.4})  error ({})",
                s.pixels,
                a.x,
                a.y,
                a.z,
                b.x,
                b.y,
                b.z,
                percent(s.errors()),
            );
            if s.pixels >= 50 {
                worst = worst.max(s.errors().abs().max_element());
            }
        }
        surfaces.sort_by_key(|s| format!("{:?}", s.0));
        for (surface, s) in &surfaces {
            let name = match surface {
                Seen::Room(s) | Seen::Object(s) => format!("{s:?}"),
                other => format!("{other:?}"),
            };
            eprintln!(
                "      {name:<10} {:>5} px  error ({})",
                s.pixels,
                percent(s.errors())
            );
        }
    }
    worst
}

/// Sub-pixel positions per axis of relume's box-filtered images (`SUBPIXELS^2` per
/// pixel, on a regular grid).
const SUBPIXELS: u32 = 4;

/// Relume's image of `view` box-filtered as Mitsuba's are: the mean of `render` over
/// copies of the view whose principal point moves each pixel centre's ray to one of
/// `SUBPIXELS^2` regular positions inside the pixel; `render` gets the moved view and
/// the sub-pixel's number (a frame number for its random numbers).
fn box_filtered(view: &View, render: impl Fn(&View, u64) -> Vec<Vec3>) -> Vec<Vec3> {
    let n = SUBPIXELS;
    let mut sum = vec![Vec3::ZERO; (view.intrinsics.width * view.intrinsics.height) as usize];
    for (moved, frame) in subpixel_views(view) {
        for (s, v) in sum.iter_mut().zip(render(&moved, frame)) {
            *s += v;
        }
    }
    sum.iter().map(|s| *s / (n * n) as f32).collect()
}

/// The `SUBPIXELS^2` copies of `view` of [`box_filtered`], each with its sub-pixel's
/// number.
fn subpixel_views(view: &View) -> Vec<(View, u64)> {
    let n = SUBPIXELS;
    let mut out = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let mut moved = *view;
            // Pixel (x, y)'s ray then passes through image point (x + dx, y + dy).
            moved.intrinsics.cx -= (i as f64 + 0.5) / n as f64 - 0.5;
            moved.intrinsics.cy -= (j as f64 + 0.5) / n as f64 - 0.5;
            out.push((moved, (j * n + i) as u64));
        }
    }
    out
}

/// Relume's direct light through each pixel centre of `view`: `shade` on the room
/// without its interreflection, with `DIRECT_GRID` shadow rays per light.
fn relume_direct(scene: &Scene, view: &View, frame: u64) -> Vec<Vec3> {
    centre_hits(scene, view)
        .iter()
        .enumerate()
        .map(|(i, (hit, _))| {
            let mut rng = Counter::new(&[SEED, frame, purpose::SHADOW, i as u64]);
            shade(scene, hit, &mut rng, DIRECT_GRID)
        })
        .collect()
}

/// The axis-aligned cube of the camera check, as triangles facing out.
fn cube_triangles(b: &AxisBox) -> Vec<[Vec3; 3]> {
    let corner = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    };
    let centre = (b.min + b.max) * 0.5;
    let quads = [
        [0, 2, 6, 4],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 3, 7, 6],
        [0, 1, 3, 2],
        [4, 5, 7, 6],
    ];
    let mut out = Vec::new();
    for q in quads {
        let [a, b, c, d] = q.map(corner);
        for mut t in [[a, b, c], [a, c, d]] {
            // Counter-clockwise seen from outside.
            if (t[1] - t[0]).cross(t[2] - t[0]).dot(t[0] - centre) < 0.0 {
                t.swap(1, 2);
            }
            out.push(t);
        }
    }
    out
}

#[test]
fn mitsuba_sees_the_room_where_relume_does() {
    // An off-centre, non-4:3 pinhole besides the compared views, and a cube the room
    // does not hold: Mitsuba's first hits (averaged over each pixel) must be relume's
    // pixel-centre hits.
    let scene = Scene::room_without_interreflection();
    let cube = AxisBox {
        min: Vec3::new(-0.2, 0.0, -0.2),
        max: Vec3::new(0.2, 0.4, 0.2),
    };
    let mut views = views();
    views.push(view_at(
        3.0,
        Intrinsics {
            width: 50,
            height: 30,
            fx: 45.0,
            fy: 45.0,
            cx: 20.7,
            cy: 18.2,
        },
    ));
    let dir = tempfile::tempdir().unwrap();
    let object = MitsubaObject {
        triangles: cube_triangles(&cube),
        normals: None,
        albedo: Vec3::splat(0.5),
    };
    export_scene(dir.path(), &scene, &views, &[object], 1.0).unwrap();
    mitsuba_render(dir.path(), 64, 1, &["--positions"]);
    let mut cube_pixels = 0;
    for (index, view) in views.iter().enumerate() {
        let k = view.intrinsics;
        let (width, height, positions) =
            read_radiance(&dir.path().join(format!("out/view_{index}_position.pfm"))).unwrap();
        assert_eq!((width, height), (k.width, k.height));
        let mut hits = centre_hits(&scene, view);
        for (i, (hit, seen)) in hits.iter_mut().enumerate() {
            let (x, y) = (i as u32 % k.width, i as u32 / k.width);
            let ray = Ray {
                origin: view.position,
                direction: view.rotation * pixel_direction(&k, x, y),
            };
            if let Some((t, _)) = ray_box_entry(&ray, &cube, 0.0, hit.t) {
                hit.t = t;
                hit.position = ray.at(t);
                *seen = Seen::Cube;
            }
        }
        let seen: Vec<Seen> = hits.iter().map(|h| h.1).collect();
        let keep = interior(&seen, width, height);
        // Mitsuba's first hit of each pixel projected into relume's camera, less the
        // pixel's centre: its image offset in pixels.
        let world_to_camera = view.rotation.transpose();
        let mut offsets: Vec<(f64, f64)> = Vec::new();
        let mut depth_errors: Vec<f32> = Vec::new();
        for (i, (_, s)) in hits.iter().enumerate() {
            if keep[i] {
                let c = world_to_camera * (positions[i] - view.position);
                let u = k.fx * (c.x / c.z) as f64 + k.cx - (i as u32 % k.width) as f64;
                let v = k.fy * (c.y / c.z) as f64 + k.cy - (i as u32 / k.width) as f64;
                offsets.push((u, v));
                depth_errors.push((c.z / hits[i].0.t - 1.0).abs());
                cube_pixels += (*s == Seen::Cube) as usize;
            }
        }
        let n = offsets.len() as f64;
        let mean = offsets
            .iter()
            .fold((0.0, 0.0), |m, o| (m.0 + o.0 / n, m.1 + o.1 / n));
        let worst = offsets.iter().fold(0f64, |m, o| m.max(o.0.hypot(o.1)));
        depth_errors.sort_by(f32::total_cmp);
        let depth_median = depth_errors[depth_errors.len() / 2];
        let depth_worst = depth_errors[depth_errors.len() - 1];
        eprintln!(
            "view {index}: {n} interior pixels; Mitsuba's first hits projected into relume's \
             camera lie off the pixel centres by ({:+.4}, {:+.4}) px on average, {worst:.4} px \
             at most; their depth differs by {:.3} % (median), {:.3} % at most",
            mean.0,
            mean.1,
            100.0 * depth_median,
            100.0 * depth_worst
        );
        assert!(
            mean.0.hypot(mean.1) < 0.01
                && worst < 0.25
                && depth_median < 2e-3
                && depth_worst < 0.03,
            "view {index}: Mitsuba's first hits lie off relume's pixel centres by \
             ({:+.4}, {:+.4}) px on average, {worst:.4} px at most, depth by {depth_median} \
             (median), {depth_worst} at most",
            mean.0,
            mean.1
        );
    }
    assert!(cube_pixels > 50, "the cube is seen by {cube_pixels} pixels");
}

#[test]
fn mitsuba_direct_light_matches_relume_direct_light() {
    // Direct light only: Mitsuba's path tracer stopped after one bounce (max_depth 2)
    // against relume's shade() without interreflection.
    direct_light_matches(&Scene::room_without_interreflection(), "direct light");
}

#[test]
fn mitsuba_direct_light_matches_relume_with_the_lamp_on() {
    // The same with the room's lamp switched on (`relume synth --lamp-on-at`): Mitsuba's
    // `spot` emitter against relume's own profile and shadow ray. The lamp brings a third
    // of the direct light in view (view 1's room: 0.147 red without it, 0.225 with it).
    let scene = Scene {
        lamp: Some(room_lamp()),
        ..Scene::room_without_interreflection()
    };
    direct_light_matches(&scene, "direct light, lamp on");
}

/// Exports `scene` with the compared views, renders its direct light in Mitsuba and
/// relume, and requires every region's mean to agree within `TOLERANCE`.
fn direct_light_matches(scene: &Scene, label: &str) {
    let views = views();
    let dir = tempfile::tempdir().unwrap();
    let started = Instant::now();
    export_scene(dir.path(), scene, &views, &[], TEXELS_PER_METRE).unwrap();
    let export_s = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let relume: Vec<Vec<Vec3>> = views
        .iter()
        .map(|v| box_filtered(v, |v, frame| relume_direct(scene, v, frame)))
        .collect();
    let relume_s = started.elapsed().as_secs_f64();
    let mitsuba_s = mitsuba_render(dir.path(), DIRECT_SPP, 2, &[]);
    eprintln!(
        "{label}: export {export_s:.2} s, relume {relume_s:.2} s ({} sub-pixels x {}x{} \
         shadow rays per light), mitsuba {mitsuba_s:.2} s ({DIRECT_SPP} spp, max depth 2)",
        SUBPIXELS * SUBPIXELS,
        DIRECT_GRID.0,
        DIRECT_GRID.1
    );
    let worst = compare(label, scene, &views, &relume, &dir.path().join("out"));
    assert!(
        worst < TOLERANCE,
        "{label}: a region's mean differs by {:.2} % (tolerance {:.0} %)",
        100.0 * worst,
        100.0 * TOLERANCE
    );
}

#[test]
fn mitsuba_path_tracing_matches_relume_global_illumination() {
    // The full light transport: Mitsuba without a depth limit against the renderer
    // `relume synth` uses, one ray per pixel centre.
    let scene = relume::recording::synth::interreflection::room();
    let views = views();
    let dir = tempfile::tempdir().unwrap();
    export_scene(dir.path(), &scene, &views, &[], TEXELS_PER_METRE).unwrap();
    let started = Instant::now();
    let relume: Vec<Vec<Vec3>> = views
        .iter()
        .map(|v| box_filtered(v, |v, frame| render_view(&scene, v, SEED, frame).radiance))
        .collect();
    let relume_s = started.elapsed().as_secs_f64();
    let mitsuba_s = mitsuba_render(dir.path(), GI_SPP, -1, &[]);
    eprintln!(
        "relume {relume_s:.2} s ({} sub-pixels), mitsuba {mitsuba_s:.2} s ({GI_SPP} spp, no \
         depth limit)",
        SUBPIXELS * SUBPIXELS
    );
    let worst = compare(
        "global illumination",
        &scene,
        &views,
        &relume,
        &dir.path().join("out"),
    );
    assert!(
        worst < TOLERANCE,
        "a region's mean differs by {:.2} % (tolerance {:.0} %)",
        100.0 * worst,
        100.0 * TOLERANCE
    );
}

/// Segments around the inserted sphere's axis (`shapes::sphere`): 64 segments and 32
/// rings, 3968 flat triangles, within 0.8 mm of the sphere.
const SPHERE_SEGMENTS: u32 = 64;
/// The inserted box: edge lengths and the centre of its bottom face, on the floor beside
/// the sphere (views 0 and 1 see it).
const BOX_SIZE: Vec3 = Vec3::new(0.25, 0.2, 0.25);
const BOX_AT: Vec3 = Vec3::new(-0.1, 0.0, 0.6);
/// Paths per pixel of each of the truth's 16 sub-pixel renders (512 per pixel): the
/// region means' standard error is 0.22 % at most (objects, blue), 0.01 % on the room.
const TRUTH_PATHS: u32 = 32;
/// Surfaces a truth path meets at most: with 5, region means moved by up to 0.3 % (within
/// their noise) against 8.
const TRUTH_BOUNCES: u32 = 8;
/// Paths per pixel centre of the independent truth render that picks the regions.
const SELECTION_PATHS: u32 = 64;
/// A room pixel belongs to the shadow region when the objects darken it by more than this
/// fraction (sum of the channels)...
const SHADOW_DARKENING: f32 = 0.05;
/// ... and to the room the objects leave as it was when they change it by less than this
/// fraction either way. (At the truth's path counts every room pixel is `changed`: some
/// path of the 512 meets an object, however little that changes the pixel.)
const ROOM_CHANGE: f32 = 0.01;
/// Mitsuba's samples per pixel for the mixed-reality frame (no depth limit): two seeds'
/// region means differed by 0.23 % at most (at 1024: 0.8 %).
const MIXED_SPP: u32 = 2048;
/// The largest relative standard error of the truth's region means that lets the
/// comparison speak for the truth.
const TRUTH_NOISE: f64 = 0.005;

/// The inserted objects as exported to Mitsuba: a diffuse sphere of radius 0.3 m resting
/// on the floor at the object position, and a small diffuse box beside it; flat faces
/// (Mitsuba's `face_normals`).
fn inserted_objects() -> Vec<MitsubaObject> {
    let place = |triangles: Vec<Triangle>, at: Vec3| -> Vec<[Vec3; 3]> {
        triangles
            .iter()
            .map(|t| t.vertices.map(|v| v + at))
            .collect()
    };
    vec![
        MitsubaObject {
            triangles: place(shapes::sphere(0.3, SPHERE_SEGMENTS), OBJECT_POSITION),
            normals: None,
            albedo: Vec3::new(0.7, 0.5, 0.3),
        },
        MitsubaObject {
            triangles: place(
                shapes::cuboid(BOX_SIZE),
                BOX_AT + Vec3::Y * (BOX_SIZE.y / 2.0),
            ),
            normals: None,
            albedo: Vec3::new(0.3, 0.5, 0.7),
        },
    ]
}

/// The same triangles for relume's truth: a BVH over them (its hits equal the brute-force
/// Moller-Trumbore loop's bit for bit), flat shading with the triangle's geometric normal
/// turned towards the ray's origin, Lambertian with the object's albedo.
struct Inserted {
    triangles: Vec<Triangle>,
    albedo: Vec<Vec3>,
    bvh: Bvh,
}

impl Inserted {
    fn new(objects: &[MitsubaObject]) -> Inserted {
        let triangles: Vec<Triangle> = objects
            .iter()
            .enumerate()
            .flat_map(|(k, o)| {
                o.triangles.iter().map(move |v| Triangle {
                    vertices: *v,
                    normals: [tri_normal(v); 3],
                    material: k as u32,
                })
            })
            .collect();
        let bvh = Bvh::build(&triangles);
        Inserted {
            albedo: objects.iter().map(|o| o.albedo).collect(),
            triangles,
            bvh,
        }
    }

    /// The object a ray meets first within `t_max`: its index and distance.
    fn first(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<(usize, f32)> {
        self.bvh
            .nearest(origin, direction, 0.0, t_max)
            .map(|(t, id, _, _)| (self.triangles[id as usize].material as usize, t))
    }
}

impl InsertedObjects for Inserted {
    fn intersect(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<InsertedHit> {
        let (t, id, _, _) = self.bvh.nearest(origin, direction, t_min, t_max)?;
        let triangle = &self.triangles[id as usize];
        let mut normal = tri_normal(&triangle.vertices);
        if normal.dot(direction) > 0.0 {
            normal = -normal;
        }
        Some(InsertedHit {
            t,
            position: origin + direction * t,
            normal,
            albedo: self.albedo[triangle.material as usize],
            exponent: 0.0,
        })
    }

    fn occluded(&self, origin: Vec3, direction: Vec3, t_min: f32, t_max: f32) -> bool {
        self.bvh.any_hit(origin, direction, t_min, t_max)
    }
}

/// relume's true mixed-reality frame of a view, box-filtered as Mitsuba's pixels are
/// ([`box_filtered`]): per pixel the means over the sub-pixel views.
struct FilteredTruth {
    radiance: Vec<Vec3>,
    recorded: Vec<Vec3>,
    /// Variance of the mean radiance, from each sub-pixel render's standard error.
    variance: Vec<Vec3>,
    /// Whether any sub-pixel's truth changed.
    changed: Vec<bool>,
}

/// The truth of `view` with `objects`: for each sub-pixel view, the recorded radiance
/// (`render_view`, as the global-illumination test renders relume's side) and
/// `render_inserted` on it.
fn filtered_truth(
    scene: &Scene,
    view: &View,
    objects: &Inserted,
    settings: &TrueFrameSettings,
) -> FilteredTruth {
    let size = (view.intrinsics.width * view.intrinsics.height) as usize;
    let count = (SUBPIXELS * SUBPIXELS) as f32;
    let mut out = FilteredTruth {
        radiance: vec![Vec3::ZERO; size],
        recorded: vec![Vec3::ZERO; size],
        variance: vec![Vec3::ZERO; size],
        changed: vec![false; size],
    };
    for (moved, frame) in subpixel_views(view) {
        let recorded = render_view(scene, &moved, SEED, frame).radiance;
        let truth = render_inserted(
            scene,
            &moved,
            &recorded,
            objects,
            frame,
            settings,
            &|_, _| true,
        );
        for (i, r) in recorded.iter().enumerate() {
            out.radiance[i] += truth.radiance[i] / count;
            out.recorded[i] += *r / count;
            let e = truth.standard_error[i] / count;
            out.variance[i] += e * e;
            out.changed[i] |= truth.changed[i];
        }
    }
    out
}

/// Sums of a region of the mixed-reality frame.
#[derive(Clone, Copy, Default)]
struct MixedSums {
    pixels: usize,
    truth: glam::DVec3,
    mitsuba: glam::DVec3,
    recorded: glam::DVec3,
    variance: glam::DVec3,
}

impl MixedSums {
    fn add(&mut self, truth: &FilteredTruth, mitsuba: Vec3, i: usize) {
        self.pixels += 1;
        self.truth += truth.radiance[i].as_dvec3();
        self.mitsuba += mitsuba.as_dvec3();
        self.recorded += truth.recorded[i].as_dvec3();
        self.variance += truth.variance[i].as_dvec3();
    }

    /// Mitsuba's mean over the truth's, less 1, per channel.
    fn errors(&self) -> glam::DVec3 {
        self.mitsuba / self.truth - 1.0
    }

    /// The truth's standard error of the region mean, relative to the mean.
    fn truth_error(&self) -> glam::DVec3 {
        self.variance.powf(0.5) / self.truth
    }
}

#[test]
fn mitsuba_agrees_with_the_true_mixed_reality_frame() {
    // The true frame of `insert::render_inserted` (recorded radiance plus a path-traced
    // differential) against Mitsuba's path tracing of the room with the same triangles
    // in it, region by region over interior pixels: "room" (room pixels the objects
    // change by less than 1 %), "objects", "shadow" (room pixels they darken by more
    // than 5 %) and "partly changed" (the other room pixels: penumbrae, light the
    // objects reflect). Each region of at least 50 pixels must agree within 2 % per
    // channel; the first three must each have one somewhere.
    let started = Instant::now();
    let scene = relume::recording::synth::interreflection::room();
    let views = views();
    let objects = inserted_objects();
    let inserted = Inserted::new(&objects);
    let settings = TrueFrameSettings {
        paths: TRUTH_PATHS,
        bounces: TRUTH_BOUNCES,
        light_samples: 1,
        seed: SEED,
    };
    let truths: Vec<FilteredTruth> = views
        .iter()
        .map(|v| filtered_truth(&scene, v, &inserted, &settings))
        .collect();
    let truth_s = started.elapsed().as_secs_f64();
    // The regions are picked by an independent render (another seed, pixel centres), so
    // that they do not favour pixels whose truth came out dark or bright by chance: per
    // pixel, the change the objects make relative to the recorded radiance (sum of the
    // channels), and whether it changed at all.
    let selecting = Instant::now();
    let selection_settings = TrueFrameSettings {
        paths: SELECTION_PATHS,
        seed: SEED + 1,
        ..settings
    };
    let selection: Vec<Vec<(f32, bool)>> = views
        .iter()
        .map(|v| {
            let frame = 1000;
            let recorded = render_view(&scene, v, SEED + 1, frame).radiance;
            let t = render_inserted(
                &scene,
                v,
                &recorded,
                &inserted,
                frame,
                &selection_settings,
                &|_, _| true,
            );
            (0..recorded.len())
                .map(|i| {
                    let change = (t.radiance[i] - recorded[i]).element_sum()
                        / recorded[i].element_sum().max(1e-6);
                    (change, t.changed[i])
                })
                .collect()
        })
        .collect();
    let selection_s = selecting.elapsed().as_secs_f64();
    let dir = tempfile::tempdir().unwrap();
    export_scene(dir.path(), &scene, &views, &objects, TEXELS_PER_METRE).unwrap();
    let mitsuba_s = mitsuba_render(dir.path(), MIXED_SPP, -1, &[]);
    eprintln!(
        "truth {truth_s:.2} s ({} sub-pixels x {TRUTH_PATHS} paths, {TRUTH_BOUNCES} bounces, \
         1 light sample), shadow selection {selection_s:.2} s ({SELECTION_PATHS} paths per \
         pixel centre), mitsuba {mitsuba_s:.2} s ({MIXED_SPP} spp, no depth limit); {} + {} \
         triangles",
        SUBPIXELS * SUBPIXELS,
        objects[0].triangles.len(),
        objects[1].triangles.len(),
    );
    const REGIONS: [&str; 4] = ["room", "objects", "shadow", "partly changed"];
    let (mut worst, mut noisiest): (f64, f64) = (0.0, 0.0);
    let mut largest = [0usize; 3];
    eprintln!(
        "mixed reality: relative error of region means (Mitsuba / truth - 1; R, G, B), and \
         the truth's relative standard error"
    );
    for (index, view) in views.iter().enumerate() {
        let k = view.intrinsics;
        let (width, height, mitsuba) =
            read_radiance(&dir.path().join(format!("out/view_{index}.pfm"))).unwrap();
        assert_eq!((width, height), (k.width, k.height));
        let seen: Vec<Seen> = centre_hits(&scene, view)
            .iter()
            .enumerate()
            .map(|(i, (hit, seen))| {
                let (x, y) = (i as u32 % k.width, i as u32 / k.width);
                let ray = view.rotation * pixel_direction(&k, x, y);
                match inserted.first(view.position, ray.normalize(), hit.t * ray.length()) {
                    Some((object, _)) => Seen::Inserted(object),
                    None => *seen,
                }
            })
            .collect();
        let keep = interior(&seen, width, height);
        let truth = &truths[index];
        let mut regions = [MixedSums::default(); 4];
        let mut per_object = [MixedSums::default(); 2];
        let (mut room_pixels, mut unchanged, mut unchanged_selection) = (0, 0, 0);
        for i in (0..seen.len()).filter(|&i| keep[i]) {
            let (change, changed) = selection[index][i];
            let region = match seen[i] {
                Seen::Emitter(_) | Seen::Cube => continue,
                Seen::Inserted(k) => {
                    per_object[k].add(truth, mitsuba[i], i);
                    1
                }
                Seen::Room(_) | Seen::Object(_) => {
                    room_pixels += 1;
                    unchanged += !truth.changed[i] as usize;
                    unchanged_selection += !changed as usize;
                    if change < -SHADOW_DARKENING {
                        2
                    } else if change.abs() < ROOM_CHANGE {
                        0
                    } else {
                        3
                    }
                }
            };
            regions[region].add(truth, mitsuba[i], i);
        }
        eprintln!(
            "  view {index}: {} of {} pixels interior; of their {room_pixels} room pixels, the \
             truth left {unchanged} unchanged ({unchanged_selection} in the selection render)",
            keep.iter().filter(|k| **k).count(),
            seen.len()
        );
        let row = |name: &str, s: &MixedSums| {
            let n = s.pixels as f64;
            let (a, b, r) = (s.truth / n, s.mitsuba / n, s.recorded / n);
            eprintln!(
                "    {name:<14} {:>5} px  truth ({:.4}, {:.4}, {:.4})  mitsuba ({:.4}, {:.4}, \
                 {:.4})  recorded ({:.4}, {:.4}, {:.4})  error ({})  truth s.e. ({})",
                s.pixels,
                a.x,
                a.y,
                a.z,
                b.x,
                b.y,
                b.z,
                r.x,
                r.y,
                r.z,
                percent(s.errors()),
                percent(s.truth_error()),
            );
        };
        for (r, (name, s)) in REGIONS.iter().zip(&regions).enumerate() {
            if s.pixels == 0 {
                continue;
            }
            row(name, s);
            if r < largest.len() {
                largest[r] = largest[r].max(s.pixels);
            }
            if s.pixels >= 50 {
                worst = worst.max(s.errors().abs().max_element());
                noisiest = noisiest.max(s.truth_error().max_element());
            }
        }
        for (name, s) in ["  sphere", "  box"].iter().zip(&per_object) {
            if s.pixels > 0 {
                row(name, s);
            }
        }
    }
    eprintln!("total {:.2} s", started.elapsed().as_secs_f64());
    for (name, n) in REGIONS.iter().zip(largest) {
        assert!(n >= 50, "the {name} region has {n} interior pixels at most");
    }
    assert!(
        noisiest < TRUTH_NOISE,
        "the truth's standard error reaches {:.2} % of a region's mean",
        100.0 * noisiest
    );
    assert!(
        worst < TOLERANCE,
        "a region's mean differs by {:.2} % (tolerance {:.0} %)",
        100.0 * worst,
        100.0 * TOLERANCE
    );
}
