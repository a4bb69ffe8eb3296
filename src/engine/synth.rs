//! The rendering engines behind `mousepose synth dataset|session|moseq`: a spec and an output
//! directory in, what was written out (`synth chessboard` is [`crate::engine::calibrate`]'s).

use crate::engine::progress::Progress;
use crate::engine::{Failure, output_failure};
use crate::io::output::Staging;
use crate::synth::dataset::{DatasetSpec, write_dataset};
use crate::synth::moseq::{MoseqSpec, moseq_camera, write_moseq};
use crate::synth::session::{SessionSpec, write_session};
use anyhow::Context as _;
use std::path::PathBuf;

/// What `synth dataset` renders, and where.
#[derive(Clone, Debug)]
pub struct DatasetOptions {
    /// The dataset directory to create.
    pub out: PathBuf,
    pub spec: DatasetSpec,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// What `synth session` renders, and where.
#[derive(Clone, Debug)]
pub struct SessionOptions {
    /// The session directory to create.
    pub out: PathBuf,
    pub spec: SessionSpec,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// What `synth moseq` renders, and where.
#[derive(Clone, Debug)]
pub struct MoseqOptions {
    /// The recording directory to create.
    pub out: PathBuf,
    pub spec: MoseqSpec,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// What `synth dataset` wrote.
#[derive(Clone, Debug)]
pub struct DatasetSummary {
    pub out: PathBuf,
    pub images: u64,
}

/// What `synth session` wrote.
#[derive(Clone, Debug)]
pub struct SessionSummary {
    pub out: PathBuf,
    pub depth_frames: u64,
    pub color_frames: u64,
    /// The preview picture in the session.
    pub preview: PathBuf,
}

/// `mousepose synth moseq`.
///
/// # Errors
/// A frame size the camera table lacks, an output directory in the way (the user's), or a
/// recording that cannot be written.
pub fn synth_moseq(options: &MoseqOptions, progress: &dyn Progress) -> Result<PathBuf, Failure> {
    let spec = options.spec;
    // A size the camera table lacks is the user's mistake: said before anything is written.
    moseq_camera(&spec).map_err(Failure::usage)?;
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    progress.start("rendering", spec.frames);
    write_moseq(staging.path(), &spec, |done, _| progress.set_done(done))
        .with_context(|| format!("writing the MoSeq recording {:?}", options.out))?;
    progress.finish();
    let out = staging.commit()?;
    tracing::info!(message = "MoSeq recording written.", path = %out.display(), frames = spec.frames);
    Ok(out)
}

/// `mousepose synth dataset`.
///
/// # Errors
/// An output directory in the way (the user's), or a dataset that cannot be written.
pub fn synth_dataset(options: &DatasetOptions, progress: &dyn Progress) -> Result<DatasetSummary, Failure> {
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let spec = options.spec;
    progress.start("rendering", spec.count);
    let rig = crate::core::geometry::Rig::default_rig();
    write_dataset(staging.path(), &rig, &spec, |done| progress.set_done(done))
        .with_context(|| format!("writing dataset {:?}", options.out))?;
    progress.finish();
    let out = staging.commit()?;
    tracing::info!(message = "Dataset written.", path = %out.display(), images = spec.count);
    Ok(DatasetSummary {
        out,
        images: spec.count,
    })
}

/// `mousepose synth session`.
///
/// # Errors
/// An output directory in the way (the user's), or a session that cannot be written.
pub fn synth_session(options: &SessionOptions, progress: &dyn Progress) -> Result<SessionSummary, Failure> {
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let spec = options.spec;
    progress.start("rendering", 0);
    let summary = write_session(staging.path(), &spec, |done, total| {
        progress.set_total(total);
        progress.set_done(done);
    })
    .with_context(|| format!("writing session {:?}", options.out))?;
    progress.finish();
    let out = staging.commit()?;
    tracing::info!(
        message = "Session written.",
        path = %out.display(),
        depth_frames = summary.depth_frames,
        color_frames = summary.color_frames,
        preview = %out.join(crate::synth::session::PREVIEW_FILE).display(),
    );
    Ok(SessionSummary {
        preview: out.join(crate::synth::session::PREVIEW_FILE),
        out,
        depth_frames: summary.depth_frames,
        color_frames: summary.color_frames,
    })
}
