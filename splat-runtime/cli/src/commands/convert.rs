//! `splat convert IN OUT`: a scene from one format to another, each named by its file's
//! extension (`splat_runtime::io::formats`), saying what the target leaves out.

use anyhow::Result;
use splat_runtime::io::formats::{self, Format};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ConvertArgs {
    /// The scene to read: .ply (INRIA 3DGS, or a compressed PLY), .compressed.ply, .splat,
    /// .spz or .sog.
    pub input: PathBuf,
    /// The scene to write, in the format its extension names: .ply, .compressed.ply, .splat,
    /// .spz or .sog.
    pub output: PathBuf,
}

pub(crate) fn convert_cmd(args: &ConvertArgs) -> Result<()> {
    let format = Format::of(&args.output)?;
    crate::check_out_file("OUTPUT", &args.output)?;
    let cloud = crate::scene::read(&args.input)?;
    let most = format.most_sh_degree();
    if cloud.sh_degree > most {
        println!(
            "note: {} keeps SH to degree {most}; the scene's degree-{} terms are left out",
            format.extension(),
            cloud.sh_degree
        );
    }
    if cloud.antialiased && !format.keeps_antialiasing() {
        println!(
            "note: the scene was trained antialiased (--method 3dgs-aa); {} has no place to say so",
            format.extension()
        );
    }
    formats::write(&args.output, &cloud)?;
    let bytes = std::fs::metadata(&args.output)
        .map(|m| m.len())
        .unwrap_or(0);
    println!(
        "{} Gaussians (SH degree {}) from {} as {} ({:.2} MB, {:.1} bytes a Gaussian)",
        cloud.gaussians.len(),
        cloud.sh_degree.min(most),
        args.input.display(),
        format.extension(),
        bytes as f64 / 1e6,
        bytes as f64 / cloud.gaussians.len().max(1) as f64
    );
    crate::wrote(&args.output);
    Ok(())
}
