//! `relume synth` and `relume import`: commands that produce recordings.

use super::interrupt::PartialFile;
use super::output;
use super::progress;
use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use relume::recording::association::{self, AssociationStats};
use relume::recording::importers::{
    self, ImportOptions, StoreMode, k4a, record3d, redwood, scannet, tum,
};
use relume::recording::mcap;
use relume::recording::synth::{self, LightSwitches, SynthConfig};
use relume::recording::{Recording, Replay, ReplayOptions};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Output recording (.relume).
    #[arg(short, long)]
    out: PathBuf,
    /// Number of frames. The camera's auto-exposure sweeps its whole range (0.5x to 2x)
    /// and its white balance drifts over the recording, whatever its length, so a short
    /// one changes them fast: from 15 frames on color.compensate follows (under 1 %
    /// median error at 640x480); at 10 its error is 3 % and every stage after it scores
    /// worse for it (the filter's gain: 8.4x against 12.5x); at 5 it falls back on 3
    /// approximate frames.
    #[arg(long, default_value_t = SynthConfig::default().frames)]
    frames: usize,
    /// Image size, WIDTHxHEIGHT. The camera keeps the field of view of a 640x480
    /// PrimeSense (fx = fy = 525 at that size), scaled per axis: a size that is not 4:3
    /// has non-square pixels (640x240: fx 525, fy 262.5).
    #[arg(long, default_value = "640x480", value_parser = parse_size, allow_hyphen_values = true)]
    size: (u32, u32),
    /// Seed of every random choice (noise, holes, shading samples).
    #[arg(long, default_value_t = SynthConfig::default().seed)]
    seed: u64,
    /// Frames per second of the stamps (0.001 to 1e6).
    #[arg(long, default_value_t = SynthConfig::default().fps)]
    fps: f64,
    /// Amplitude of the camera's contrast change between frames (0 = none, at most 0.9).
    #[arg(long, default_value_t = SynthConfig::default().contrast)]
    contrast: f32,
    /// Store clean depth instead of Kinect-like noisy depth with holes.
    #[arg(long)]
    no_depth_noise: bool,
    /// Focal length multiplier: `--size 320x240 --zoom 2` sees the central 320x240
    /// pixels of the full 640x480 camera (a small image as finely sampled as the full one).
    /// 0.25 to 16.
    #[arg(long, default_value_t = SynthConfig::default().zoom)]
    zoom: f64,
    /// Switch the ceiling panel off at this frame (a light that changes): the room darkens
    /// at once, the objects' shadows from the panel vanish, and every frame's truth, and
    /// `relume eval`'s true frames, are of the room as it is lit then. The `environment`
    /// attachment is frame 0's room (a probe taken at the start). `relume eval --score-frames`
    /// over the switch measures how fast a pipeline follows it.
    #[arg(long, value_name = "FRAME")]
    panel_off_at: Option<usize>,
    /// Switch the room's lamp on at this frame (0: on throughout): a real spot light on a
    /// low stand by the west wall, aimed east across the floor towards the checker block
    /// (Mitsuba 3's spot profile). Every frame's truth, and `relume eval`'s true frames,
    /// are lit by it. A pipeline models it with a `[[light]]` table `world = "real"` of
    /// the same pose and profile: pipelines/mixed-reality-dir-room-lamp.toml, paper
    /// 002's double shadow (scripts/double_shadow.py).
    #[arg(long, value_name = "FRAME")]
    lamp_on_at: Option<usize>,
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, e.g. 320x240, got {text:?}"))?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|&v| v > 0);
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!(
            "expected WIDTHxHEIGHT with positive integers, e.g. 320x240, got {text:?}"
        )),
    }
}

pub fn synth(a: SynthArgs) -> anyhow::Result<i32> {
    let config = SynthConfig {
        frames: a.frames,
        width: a.size.0,
        height: a.size.1,
        seed: a.seed,
        fps: a.fps,
        contrast: a.contrast,
        zoom: a.zoom,
        depth_noise: !a.no_depth_noise,
        switches: LightSwitches {
            panel_off_at: a.panel_off_at,
            lamp_on_at: a.lamp_on_at,
        },
        ..SynthConfig::default()
    };
    output::check_output_file("-o", &a.out)?;
    if (2..synth::camera::STEADY_COLOR_FRAMES).contains(&a.frames) {
        eprintln!(
            "warning: the camera's exposure sweeps 0.5x to 2x and back over any recording: \
             over {} frames it changes faster than color.compensate follows (3 % median \
             error at 10 frames, under 1 % from {}), and the scores of the stages after it \
             (light, sampling, the filter's gain) measure that too; give --frames {} or more \
             for scores that stand for the stages themselves",
            a.frames,
            synth::camera::STEADY_COLOR_FRAMES,
            synth::camera::STEADY_COLOR_FRAMES
        );
    }
    let start = std::time::Instant::now();
    remove_stale_partials_beside(&a.out);
    let _partial = PartialFile::watch(&a.out);
    let summary = generate(&config, &a.out)?;
    outln!(
        "wrote {} ({} frames, {}x{}, {:.1} MB) in {:.2} s",
        a.out.display(),
        summary.frames,
        config.width,
        config.height,
        summary.bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    )?;
    Ok(0)
}

/// Makes sure the built-in default recording exists and matches the current generator;
/// (re)generates it otherwise.
pub fn ensure_default_recording(path: &Path) -> anyhow::Result<()> {
    let config = SynthConfig::default();
    let existing = Recording::open(path);
    if let Ok(rec) = &existing
        && rec.damage().is_none()
        && rec.header().provenance == synth::provenance(&config)
    {
        return Ok(());
    }
    // The reason, with the damage or read error, so that a replaced file is explained.
    let why = match existing {
        Ok(rec) => match rec.damage() {
            Some(damage) => format!("the old one is damaged: {damage}"),
            None => "the old one does not match the current generator".to_string(),
        },
        Err(e) if path.exists() => format!("the old one cannot be read: {e}"),
        Err(_) => "first use".to_string(),
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the folder {}", dir.display()))?;
    }
    eprintln!(
        "generating the built-in synthetic recording into {} ({why}; {} frames at {}x{}) ...",
        path.display(),
        config.frames,
        config.width,
        config.height
    );
    let _partial = PartialFile::watch(path);
    generate(&config, path)?;
    Ok(())
}

/// Generates with a progress bar (shown on terminals only).
fn generate(config: &SynthConfig, path: &Path) -> anyhow::Result<synth::SynthSummary> {
    // The room's interreflection is solved once, before the first frame (about a
    // second), so that the frame rate the progress reports is the frames'.
    synth::interreflection::room();
    let bar = progress::bar(config.frames as u64, "rendering", "frames");
    let summary =
        synth::generate_with_progress(config, path, &mut |done, _| bar.set_position(done as u64));
    bar.finish_and_clear();
    Ok(summary?)
}

#[derive(Subcommand, Debug)]
pub enum ImportCommand {
    /// TUM RGB-D layout: rgb.txt, depth.txt (PNG16, 5000 per metre), groundtruth.txt.
    Tum {
        /// The dataset directory.
        dir: PathBuf,
        #[command(flatten)]
        common: CommonImportArgs,
    },
    /// Redwood / Open3D layout: color/ or image/, depth/ (PNG16, mm), a .log trajectory
    /// (optional: without one the recording has no poses; track them with
    /// pipelines/*-tracked.toml), and Open3D's camera_intrinsic.json or intrinsic.json
    /// (its RealSense recorder's and bag reader's; used unless --intrinsics is given,
    /// with intrinsic.json's depth_scale).
    Redwood {
        /// The dataset directory.
        dir: PathBuf,
        /// Frames per second (the layout has no stamps: frame k is at k / fps).
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// The trajectory file (default: the directory's .log file).
        #[arg(long)]
        trajectory: Option<PathBuf>,
        #[command(flatten)]
        common: CommonImportArgs,
    },
    /// ScanNet .sens file: intrinsics, depth scale, poses and stamps from the file;
    /// frames without a valid pose (lost tracking) are skipped and counted.
    Scannet {
        /// The .sens file.
        file: PathBuf,
        /// Frames per second for files without stamps (frame k is then at k / fps).
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        #[command(flatten)]
        common: CommonImportArgs,
    },
    /// Record3D .r3d export (iPhone / iPad LiDAR): JPEG color, LZFSE depth registered to
    /// the color size, intrinsics and ARKit poses from its metadata; frame k at k / fps.
    Record3d {
        /// The .r3d file.
        file: PathBuf,
        /// Output recording (.relume).
        #[arg(short, long)]
        out: PathBuf,
        /// Keep color compressed as found (decoded on replay) or store raw pixels.
        #[arg(long, value_enum, default_value_t = StoreMode::Compressed)]
        store: StoreMode,
    },
    /// Azure Kinect recording (.mkv from k4arecorder, the SDK, Open3D or pyk4a; Orbbec's
    /// Kinect-compatible cameras too): MJPG or BGRA color, 16-bit depth registered to the
    /// color camera with the calibration.json it carries (both lenses' distortion and the
    /// extrinsic), the device's stamps. No poses: track them with pipelines/*-tracked.toml.
    /// `--list` shows the tracks, attachments and tags.
    K4a {
        /// The .mkv file.
        file: PathBuf,
        /// List the tracks, attachments and tags, and what an import takes; write nothing.
        #[arg(long)]
        list: bool,
        /// Output recording (.relume).
        #[arg(short, long, required_unless_present = "list")]
        out: Option<PathBuf>,
        /// The color track by name or number (default: the one named COLOR).
        #[arg(long)]
        color_track: Option<String>,
        /// The depth track by name or number (default: the one named DEPTH).
        #[arg(long)]
        depth_track: Option<String>,
        /// Keep color compressed as found (decoded on replay) or store raw pixels.
        #[arg(long, value_enum, default_value_t = StoreMode::Compressed)]
        store: StoreMode,
    },
    /// ROS 2, ROS 1 or Foxglove MCAP log: color and depth images (sensor_msgs/Image,
    /// CompressedImage incl. compressedDepth, foxglove.RawImage/CompressedImage),
    /// intrinsics from CameraInfo, poses from /tf + /tf_static or a pose topic. Topics
    /// and frames are detected when unambiguous; `--list` shows what the file holds.
    Mcap(McapArgs),
    /// ROS 1 bag (rosbag record, RealSense Viewer / librealsense up to 2.55, TUM RGB-D's
    /// bags): the same messages, options and detection as `import mcap`. A RealSense
    /// recording's depth unit comes from its "Depth Units" option and its depth is
    /// registered to the color camera with the recorded extrinsics.
    #[command(visible_alias = "rosbag")]
    Bag(McapArgs),
}

#[derive(Args, Debug)]
pub struct McapArgs {
    /// The MCAP file (chunks uncompressed, zstd or lz4) or ROS 1 bag (chunks
    /// uncompressed, bz2 or lz4); either command reads either.
    file: PathBuf,
    /// List the topics, what each holds, and the transform tree; write nothing.
    #[arg(long)]
    list: bool,
    /// Output recording (.relume).
    #[arg(short, long, required_unless_present = "list")]
    out: Option<PathBuf>,
    /// The color image topic (default: the only one).
    #[arg(long)]
    color_topic: Option<String>,
    /// The depth image topic (default: the only one). Depth from a camera of its own
    /// (other intrinsics, or another frame) is registered into the color view: with a
    /// RealSense recording's extrinsics, a static transform between the two frames, or
    /// else as one camera centre.
    #[arg(long)]
    depth_topic: Option<String>,
    /// The CameraInfo / CameraCalibration topic of the color images (default: the one
    /// beside the color topic, or in its frame, or the only one).
    #[arg(long)]
    info_topic: Option<String>,
    /// A PoseStamped, Odometry or PoseInFrame topic for the camera poses (default: the
    /// TF tree when it holds the camera frame, else the only pose topic). A PoseStamped
    /// gives the camera's own pose; an Odometry's child frame is linked to the camera
    /// through the TF tree.
    #[arg(long)]
    pose_topic: Option<String>,
    /// The frame the camera poses are expressed in (default: the root of the camera's
    /// transform tree, e.g. map or odom).
    #[arg(long)]
    world_frame: Option<String>,
    /// The camera's optical frame (z forward, x right, y down; default: the color
    /// images' frame_id).
    #[arg(long)]
    camera_frame: Option<String>,
    /// Camera intrinsics, overriding the camera info: fx,fy,cx,cy in pixels of the
    /// images' own size, or a preset (primesense, tum-fr1, tum-fr2, tum-fr3).
    #[arg(long, value_parser = importers::parse_intrinsics)]
    intrinsics: Option<importers::CameraIntrinsics>,
    /// Keep images compressed as found (decoded on replay) or store raw pixels.
    #[arg(long, value_enum, default_value_t = StoreMode::Compressed)]
    store: StoreMode,
    /// Pass over a damaged chunk (its CRC, size or compression does not check out),
    /// naming it and counting what it cost, instead of stopping. Damage outside the
    /// chunks still stops the import.
    #[arg(long)]
    skip_corrupt: bool,
}

impl McapArgs {
    fn options(&self) -> mcap::McapOptions {
        mcap::McapOptions {
            common: ImportOptions {
                intrinsics: self.intrinsics.unwrap_or_default(),
                store: self.store,
            },
            intrinsics: self.intrinsics,
            color_topic: self.color_topic.clone(),
            depth_topic: self.depth_topic.clone(),
            info_topic: self.info_topic.clone(),
            pose_topic: self.pose_topic.clone(),
            world_frame: self.world_frame.clone(),
            camera_frame: self.camera_frame.clone(),
            skip_corrupt: self.skip_corrupt,
        }
    }
}

impl ImportCommand {
    /// The output recording (`None`: `import mcap --list` writes none).
    fn out(&self) -> Option<&PathBuf> {
        match self {
            ImportCommand::Tum { common, .. }
            | ImportCommand::Redwood { common, .. }
            | ImportCommand::Scannet { common, .. } => Some(&common.out),
            ImportCommand::Record3d { out, .. } => Some(out),
            ImportCommand::K4a { out, .. } => out.as_ref(),
            ImportCommand::Mcap(a) | ImportCommand::Bag(a) => a.out.as_ref(),
        }
    }

    /// `--intrinsics` as given, for the notes on rescaled presets.
    fn intrinsics(&self) -> Option<importers::CameraIntrinsics> {
        match self {
            ImportCommand::Tum { common, .. } | ImportCommand::Redwood { common, .. } => {
                Some(common.intrinsics.unwrap_or_default())
            }
            // ScanNet: the file's own unless given, needing neither note nor warning.
            ImportCommand::Scannet { common, .. } => common.intrinsics,
            ImportCommand::Record3d { .. } | ImportCommand::K4a { .. } => None,
            ImportCommand::Mcap(a) | ImportCommand::Bag(a) => a.intrinsics,
        }
    }
}

#[derive(Args, Debug)]
pub struct CommonImportArgs {
    /// Output recording (.relume).
    #[arg(short, long)]
    out: PathBuf,
    /// Camera intrinsics: fx,fy,cx,cy in pixels of the images' own size, or a preset for
    /// 640x480 images (rescaled, with a note, to other sizes): primesense, tum-fr1,
    /// tum-fr2, tum-fr3. Default: primesense; for scannet, the file's own.
    #[arg(long, value_parser = importers::parse_intrinsics)]
    intrinsics: Option<importers::CameraIntrinsics>,
    /// Keep images compressed as found (decoded on replay) or store raw pixels.
    #[arg(long, value_enum, default_value_t = StoreMode::Compressed)]
    store: StoreMode,
}

impl CommonImportArgs {
    fn options(&self) -> ImportOptions {
        ImportOptions {
            intrinsics: self.intrinsics.unwrap_or_default(),
            store: self.store,
        }
    }
}

pub fn import(command: ImportCommand) -> anyhow::Result<i32> {
    let start = std::time::Instant::now();
    if let ImportCommand::Mcap(a) | ImportCommand::Bag(a) = &command
        && a.list
    {
        let read = mcap::read::ReadOptions {
            skip_corrupt: a.skip_corrupt,
        };
        let scan = mcap::Scan::read(&a.file, read)?;
        outln!("{}", scan.listing().trim_end())?;
        return Ok(0);
    }
    if let ImportCommand::K4a {
        file, list: true, ..
    } = &command
    {
        outln!("{}", k4a::listing(file)?.trim_end())?;
        return Ok(0);
    }
    let out = command.out().expect("clap requires -o unless --list");
    output::check_output_file("-o", out)?;
    match &command {
        ImportCommand::Mcap(a) | ImportCommand::Bag(a) => output::check_not_input(out, &a.file)?,
        ImportCommand::Scannet { file, .. }
        | ImportCommand::Record3d { file, .. }
        | ImportCommand::K4a { file, .. } => output::check_not_input(out, file)?,
        _ => {}
    }
    remove_stale_partials_beside(out);
    let _partial = PartialFile::watch(out);
    let bar = progress::bar(0, "importing", "frames");
    let mut tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let summary = match &command {
        ImportCommand::Tum { dir, common } => {
            tum::import(dir, &common.out, &common.options(), &mut tick)?
        }
        ImportCommand::Mcap(a) | ImportCommand::Bag(a) => {
            mcap::import(&a.file, out, &a.options(), &mut tick)?
        }
        ImportCommand::Redwood {
            dir,
            fps,
            trajectory,
            common,
        } => {
            let options = redwood::RedwoodOptions {
                common: common.options(),
                fps: *fps,
                trajectory: trajectory.clone(),
                override_intrinsics: common.intrinsics.is_some(),
            };
            redwood::import(dir, &common.out, &options, &mut tick)?
        }
        ImportCommand::Record3d { file, out, store } => {
            let options = ImportOptions {
                store: *store,
                ..ImportOptions::default()
            };
            record3d::import(file, out, &options, &mut tick)?
        }
        ImportCommand::K4a {
            file,
            color_track,
            depth_track,
            store,
            ..
        } => {
            let options = k4a::K4aOptions {
                common: ImportOptions {
                    store: *store,
                    ..ImportOptions::default()
                },
                color_track: color_track.clone(),
                depth_track: depth_track.clone(),
            };
            k4a::import(file, out, &options, &mut tick)?
        }
        ImportCommand::Scannet { file, fps, common } => {
            let options = scannet::ScannetOptions {
                common: common.options(),
                fps: *fps,
                override_intrinsics: common.intrinsics.is_some(),
            };
            scannet::import(file, &common.out, &options, &mut tick)?
        }
    };
    bar.finish_and_clear();
    for warning in &summary.warnings {
        eprintln!("warning: {warning}");
    }
    // A recording where no color image has a depth image near it replays nothing: an
    // error naming how far apart the streams' stamps are, and no file.
    let replay = Replay::open(out, ReplayOptions::default())?;
    if replay.stats.frames == 0 && replay.stats.depth_records > 0 {
        let offsets = association::depth_offsets(replay.recording.index());
        let _ = std::fs::remove_file(out);
        bail!("{}", no_association(&replay.stats, &offsets));
    }
    let header = replay.recording.header();
    // Intrinsics from the folder's own file need no note on presets.
    let intrinsics = match header.provenance.settings.contains_key("intrinsics_file") {
        true => None,
        false => command.intrinsics(),
    };
    let sizes = [
        ("color", &header.color_intrinsics),
        ("depth", &header.depth_intrinsics),
    ];
    let (c, d) = (&header.color_intrinsics, &header.depth_intrinsics);
    if matches!(intrinsics, Some(importers::CameraIntrinsics::Given { .. }))
        && (c.width, c.height) != (d.width, d.height)
    {
        eprintln!(
            "warning: {}: the given intrinsics apply to both the color ({}x{}) and the depth \
             ({}x{}) images, as given: one of the two streams needs other values",
            out.display(),
            c.width,
            c.height,
            d.width,
            d.height
        );
    }
    let mut noted = Vec::new();
    for (stream, k) in sizes {
        let size = (k.width, k.height);
        if !noted.contains(&size)
            && let Some(note) = intrinsics.and_then(|k| k.rescale_note(stream, size))
        {
            eprintln!("note: {note}");
            noted.push(size);
        }
    }
    let skipped = match summary.skipped_frames {
        0 => String::new(),
        n => format!(", {n} frames skipped"),
    };
    let counts = (summary.color, summary.depth, summary.poses);
    output::print_wrote(out, counts, &skipped, start)?;
    // What the recording lacks that most pipelines need, from its frames as replay
    // builds them. A dataset may lack it, so this warns rather than fails.
    let mut warnings = missing_streams(&replay.stats);
    let header = replay.recording.header();
    let (color, depth) = (&header.color_intrinsics, &header.depth_intrinsics);
    if replay.stats.frames > 0 && (color.width, color.height) != (depth.width, depth.height) {
        warnings.push(format!(
            "the color images are {}x{} and the depth images {}x{}: stages that combine \
             them, such as cloud.samples (in the acquisition and mixed-reality pipelines), \
             stop at the first frame",
            color.width, color.height, depth.width, depth.height
        ));
    }
    for warning in warnings {
        eprintln!("warning: {}: {warning}", out.display());
    }
    Ok(0)
}

/// Removes the half-written files that interrupted runs left beside `out`.
fn remove_stale_partials_beside(out: &Path) {
    let folder = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    super::out_dir::remove_stale_partials(folder, 0);
}

/// Why an import built no frame, with the offsets (ns, depth minus color) from each
/// color stamp to the nearest depth stamp: their range and median say whether the two
/// streams' clocks differ by a constant.
fn no_association(stats: &AssociationStats, offsets: &[i64]) -> String {
    let mut sorted = offsets.to_vec();
    sorted.sort_unstable();
    let s = |ns: i64| format!("{:+.3} s", ns as f64 * 1e-9);
    let seen = match (sorted.first(), sorted.last()) {
        (Some(&lo), Some(&hi)) => format!(
            "; from each color image the nearest depth image is {} to {} away (median {}, \
             positive: depth later)",
            s(lo),
            s(hi),
            s(sorted[sorted.len() / 2])
        ),
        _ => String::new(),
    };
    format!(
        "no frames: none of the {} color images has one of the {} depth images within {} ms{seen}; \
         if the streams' clocks differ by a constant, fix the stamps in the dataset's \
         lists; nothing was written",
        stats.color_records,
        stats.depth_records,
        relume::recording::association::DEFAULT_TOLERANCE_NS / 1_000_000
    )
}

/// Warnings for frames without depth (every stage after `decode` but the color ones
/// reads it) or without a camera pose (`depth.fuse`, `cloud.samples` and what follows
/// them read it).
fn missing_streams(stats: &AssociationStats) -> Vec<String> {
    let mut warnings = Vec::new();
    if stats.frames == 0 {
        // Every color image lacks depth near its stamp: nothing else matters.
        warnings.push(format!(
            "no frames: none of the {} color images has a depth image within {} ms",
            stats.color_records,
            relume::recording::association::DEFAULT_TOLERANCE_NS / 1_000_000
        ));
        return warnings;
    }
    if stats.depth_records == 0 {
        warnings.push("no depth images: pipelines that read `depth` will not run".to_string());
    }
    if stats.frames_with_pose == 0 {
        warnings.push(
            "no camera poses: pipelines that read `pose` (the default one does) run only with \
             the tracker giving it (pipelines/*-tracked.toml)"
                .to_string(),
        );
    } else if stats.frames_with_pose < stats.frames {
        warnings.push(format!(
            "only {} of {} frames have a camera pose: pipelines that read `pose` stop at \
             the first frame without one",
            stats.frames_with_pose, stats.frames
        ));
    }
    warnings
}
