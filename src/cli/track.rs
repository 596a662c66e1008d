//! `tumble track`: the visual frontend on an ASL folder's images.

use super::common::{print_frontend, track_bar, FrontendArgs};
use super::CliResult;
use clap::Args;
use std::path::PathBuf;

/// Flags of `tumble track`.
#[derive(Args)]
pub struct TrackArgs {
    /// ASL folder (mav0/ or its parent) with camN/data.csv and the images.
    input: PathBuf,
    /// Camera folder to track.
    #[arg(long, default_value = "cam0")]
    camera: String,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    frontend: FrontendArgs,
}

impl TrackArgs {
    pub fn run(self) -> CliResult {
        let ds = tumble::io::asl::read_asl(&self.input, &Default::default())?;
        let k = ds.camera_index(&self.camera)?;
        let bar = track_bar(ds.cameras[k].frames.len());
        let (_, report) =
            tumble::vio::frontend::track_asl_into(&ds, k, &self.frontend.options(), &self.out, &mut |d, _| {
                bar.set_position(d as u64)
            })?;
        bar.finish_and_clear();
        print_frontend(&report);
        Ok(())
    }
}
