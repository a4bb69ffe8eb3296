//! `mousepose export nwb|moseq|video`: the arguments of each, handed to the engines of
//! [`crate::engine::export`], and what they wrote printed.

pub mod moseq;
pub mod nwb;
pub mod video;

use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum ExportCommand {
    /// A run's poses as NWB 2.x with ndx-pose (24 PoseEstimationSeries, the skeleton, the
    /// cameras), written by pynwb.
    Nwb(Box<nwb::NwbArgs>),
    /// A session in MoSeq's layout: depth.avi (FFV1 16-bit), depth_ts.txt, metadata.json,
    /// and the colour camera as color.avi (FFV1) with color_ts.txt.
    Moseq(moseq::MoseqArgs),
    /// A run's frames side by side (depth view, bottom view, side view) with the skeleton,
    /// paws and frame counters drawn, as an H.264 MP4.
    Video(video::VideoArgs),
}

/// `mousepose export`.
pub fn command(command: &ExportCommand) -> crate::app::Outcome {
    match command {
        ExportCommand::Nwb(args) => nwb::command(args),
        ExportCommand::Moseq(args) => moseq::command(args),
        ExportCommand::Video(args) => video::command(args),
    }
}
