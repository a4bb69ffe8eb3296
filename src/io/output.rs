//! Output directories that never look complete before they are: work goes into a hidden
//! staging directory beside the destination, which is renamed into place only at the end.

use std::fs;
use std::path::{Path, PathBuf};

/// Errors preparing or committing an output directory.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("output directory {0:?} is not empty (use --force to replace it)")]
    NotEmpty(PathBuf),
    #[error("output path {0:?} exists and is not a directory")]
    NotADirectory(PathBuf),
    #[error("cannot {action} {path:?}")]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
}

fn io<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> OutputError + 'a {
    move |source| OutputError::Io {
        path: path.to_owned(),
        action,
        source,
    }
}

/// An output directory being written: write into [`Staging::path`], then [`Staging::commit`].
/// Dropped without committing, the staging directory is removed.
#[derive(Debug)]
pub struct Staging {
    staging: PathBuf,
    dest: PathBuf,
    committed: bool,
}

impl Staging {
    /// Checks that `dest` may be written (absent, an empty directory, or anything with
    /// `force`) and creates an empty staging directory beside it.
    ///
    /// # Errors
    /// When `dest` is a non-empty directory without `force`, a file, or the parent cannot be
    /// created or written.
    pub fn new(dest: &Path, force: bool) -> Result<Self, OutputError> {
        if dest.exists() {
            if !dest.is_dir() {
                return Err(OutputError::NotADirectory(dest.to_owned()));
            }
            let mut entries = fs::read_dir(dest).map_err(io(dest, "read"))?;
            if entries.next().is_some() && !force {
                return Err(OutputError::NotEmpty(dest.to_owned()));
            }
        }
        let name = dest
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".to_owned());
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent).map_err(io(&parent, "create directory"))?;
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(io(&staging, "remove"))?;
        }
        fs::create_dir(&staging).map_err(io(&staging, "create directory"))?;
        Ok(Self {
            staging,
            dest: dest.to_owned(),
            committed: false,
        })
    }

    /// Where to write.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Moves the finished output into place, replacing what was there.
    ///
    /// # Errors
    /// When the old destination cannot be removed or the rename fails.
    pub fn commit(mut self) -> Result<PathBuf, OutputError> {
        if self.dest.exists() {
            fs::remove_dir_all(&self.dest).map_err(io(&self.dest, "replace"))?;
        }
        fs::rename(&self.staging, &self.dest).map_err(io(&self.dest, "create"))?;
        self.committed = true;
        Ok(self.dest.clone())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: a leftover staging directory is hidden and named as partial.
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}
