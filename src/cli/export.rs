//! `relume export`: a recording (and a replay's saved products) in another format.

use super::interrupt::PartialFile;
use super::output;
use super::progress;
use clap::{Args, Subcommand};
use relume::recording::mcap;
use std::path::PathBuf;

#[derive(Subcommand, Debug)]
pub enum ExportCommand {
    /// MCAP with Foxglove's well-known schemas (JSON), for Foxglove and Lichtblick:
    /// color (CompressedImage or RawImage), depth (RawImage 16UC1), calibrations
    /// (CameraCalibration), poses (FrameTransform world -> camera on /tf), and with
    /// --products the PNGs (CompressedImage) and environment clouds (PointCloud) a
    /// replay saved. `relume import mcap` reads it back to the same frames.
    Mcap(McapExportArgs),
}

#[derive(Args, Debug)]
pub struct McapExportArgs {
    /// The recording (.relume).
    recording: PathBuf,
    /// Output MCAP file.
    #[arg(short, long)]
    out: PathBuf,
    /// A folder of saved products (`relume replay REC --save color,cloud --out OUT` writes
    /// OUT/<product>/<frame>.png|ply): each product becomes a topic /relume/<product>
    /// at its frames' stamps.
    #[arg(long, value_name = "DIR")]
    products: Option<PathBuf>,
}

pub fn export(command: ExportCommand) -> anyhow::Result<i32> {
    let ExportCommand::Mcap(a) = command;
    let start = std::time::Instant::now();
    output::check_output_file("-o", &a.out)?;
    output::check_not_input(&a.out, &a.recording)?;
    if let Some(dir) = &a.products
        && !dir.is_dir()
    {
        anyhow::bail!("--products {}: not a folder", dir.display());
    }
    let _partial = PartialFile::watch(&a.out);
    let bar = progress::bar(0, "exporting", "records");
    let mut tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let options = mcap::ExportOptions {
        products: a.products.clone(),
    };
    let summary = mcap::export(&a.recording, &a.out, &options, &mut tick)?;
    bar.finish_and_clear();
    for warning in &summary.warnings {
        eprintln!("warning: {warning}");
    }
    let products: Vec<String> = summary
        .products
        .iter()
        .map(|(name, n)| format!("{n} {name}"))
        .collect();
    let products = match products.is_empty() {
        true => String::new(),
        false => format!(", products: {}", products.join(", ")),
    };
    let counts = (summary.color, summary.depth, summary.poses);
    output::print_wrote(&a.out, counts, &products, start)?;
    Ok(0)
}
