//! The models a pipeline runs: the body forest and the paw cascade of a models directory, and
//! where the bundled ones are.

use crate::vision::forest::infer::{BodyEstimator, VoteSettings};
use crate::vision::forest::model::ModelError;
use crate::vision::paws::{PawError, PawModel};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The body forest's file name in a models directory.
pub const BODY_MODEL: &str = "body.forest";
/// The paw cascade's file name in a models directory.
pub const PAWS_MODEL: &str = "paws.xml";

/// The paw network's file in a models directory (`mousepose train paws --net`); run instead
/// of the cascade when a directory holds both.
pub const PAWS_NET_MODEL: &str = "paws.safetensors";

/// The paw model of a models directory: its network when it has one, else its cascade;
/// `None` when it has neither.
pub fn paws_file(dir: &Path) -> Option<PathBuf> {
    [PAWS_NET_MODEL, PAWS_MODEL]
        .iter()
        .map(|name| dir.join(name))
        .find(|p| p.is_file())
}

/// The orientation model's file name in a models directory.
pub const ORIENTATION_MODEL: &str = crate::vision::body_shape::MODEL_FILE;

/// Why the models cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelsError {
    #[error("no models directory given and no bundled models found (looked in {0})")]
    NotFound(String),
    #[error("cannot load the model {path:?}")]
    Body {
        path: PathBuf,
        #[source]
        source: ModelError,
    },
    #[error("cannot load the paw cascade")]
    Paws(#[source] PawError),
    #[error("cannot load the orientation model")]
    Orientation(#[source] Box<crate::vision::body_shape::ShapeModelError>),
}

/// Where the bundled models are: `$MOUSEPOSE_MODELS`, then beside an installed binary
/// (`<prefix>/share/mousepose/models`), then the source checkout the binary was built from.
///
/// # Errors
/// None of them holds a body forest.
pub fn default_models_dir() -> Result<PathBuf, ModelsError> {
    let mut candidates = Vec::new();
    if let Some(dir) = std::env::var_os("MOUSEPOSE_MODELS") {
        candidates.push(PathBuf::from(dir));
    }
    if let Ok(exe) = std::env::current_exe() {
        if let Some(prefix) = exe.parent().and_then(Path::parent) {
            candidates.push(prefix.join("share/mousepose/models"));
        }
    }
    candidates.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models"));
    candidates
        .iter()
        .find(|d| d.join(BODY_MODEL).is_file())
        .cloned()
        .ok_or_else(|| {
            ModelsError::NotFound(
                candidates
                    .iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            )
        })
}

/// The models of a directory, loaded.
#[derive(Debug)]
pub struct Models {
    pub dir: PathBuf,
    pub body: BodyEstimator,
    /// `None` when the directory has no paw model, so that older model directories still
    /// work (the limbs then take their default configuration).
    pub paws: Option<PawModel>,
    /// `None` when the directory has no orientation model (older model directories): head
    /// and tail are then told apart by the forest's votes and the motion alone.
    pub orientation: Option<crate::vision::body_shape::ShapeModel>,
}

impl Models {
    /// Loads the models of `dir`, or of the bundled directory when `None`.
    ///
    /// # Errors
    /// No bundled models, or a model file missing, damaged or of the wrong kind.
    pub fn load(dir: Option<&Path>) -> Result<Self, ModelsError> {
        Self::load_for(dir, true)
    }

    /// [`Self::load`] for a recording with colour frames or without (`color` false): then the
    /// paw cascade is not read, since nothing would run it, and `paws` is `None`.
    ///
    /// # Errors
    /// As [`Self::load`].
    pub fn load_for(dir: Option<&Path>, color: bool) -> Result<Self, ModelsError> {
        let dir = match dir {
            Some(dir) => dir.to_path_buf(),
            None => default_models_dir()?,
        };
        Ok(Self {
            body: load_body(&dir)?,
            paws: if color { load_paws(&dir)? } else { None },
            orientation: load_orientation(&dir)?,
            dir,
        })
    }

    /// The body forest's file.
    pub fn body_path(&self) -> PathBuf {
        self.dir.join(BODY_MODEL)
    }

    /// The orientation model's file, when there is one.
    pub fn orientation_path(&self) -> Option<PathBuf> {
        self.orientation.is_some().then(|| self.dir.join(ORIENTATION_MODEL))
    }

    /// The paw model's file, when there is one.
    pub fn paws_path(&self) -> Option<PathBuf> {
        self.paws.as_ref().and(paws_file(&self.dir))
    }

    /// Which models these are, for the outputs they make: the directory, whether it is the
    /// bundled one, and each file loaded with its size and SHA-256.
    pub fn used(&self) -> ModelsUsed {
        let files = [Some(self.body_path()), self.paws_path(), self.orientation_path()]
            .into_iter()
            .flatten()
            .filter_map(|path| {
                let name = path.file_name()?.to_string_lossy().into_owned();
                Some((name, ModelFile::of(&path)?))
            })
            .collect();
        let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
        let dir = canonical(&self.dir);
        ModelsUsed {
            bundled: default_models_dir().is_ok_and(|d| canonical(&d) == dir),
            dir,
            files,
        }
    }
}

/// Which models made an output: written into every `summary.json` (replay, each chunk of
/// `run`, and `report`, which copies its run's).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelsUsed {
    /// The models directory (absolute).
    pub dir: PathBuf,
    /// Whether it is the bundled models' directory.
    pub bundled: bool,
    /// Each model file loaded, by name (`body.forest`, `paws.xml`, `orientation.json`).
    pub files: BTreeMap<String, ModelFile>,
}

/// A model file's size and content hash (SHA-256 of its bytes, hex): the same file anywhere
/// has the same hash, and an adapted model differs from a bundled one. (Not a CRC-32: a forest
/// file ends with the CRC-32 of what comes before, so the CRC-32 of every whole forest file is
/// the same constant.)
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelFile {
    pub bytes: u64,
    pub sha256: String,
}

impl ModelFile {
    /// The file's size and hash; `None` when it cannot be read.
    pub fn of(path: &Path) -> Option<Self> {
        use sha2::Digest as _;
        use std::io::Read as _;
        let mut file = std::fs::File::open(path).ok()?;
        let mut hasher = sha2::Sha256::new();
        let mut buffer = vec![0u8; 1 << 16];
        let mut bytes = 0u64;
        loop {
            let n = file.read(&mut buffer).ok()?;
            if n == 0 {
                break;
            }
            hasher.update(buffer.get(..n)?);
            bytes += n as u64;
        }
        let sha256 = hasher.finalize().iter().fold(String::with_capacity(64), |mut s, b| {
            use std::fmt::Write as _;
            let _ = write!(s, "{b:02x}");
            s
        });
        Some(Self { bytes, sha256 })
    }
}

/// Loads the body forest of a models directory.
///
/// # Errors
/// The file is missing, damaged, or not a body forest.
pub fn load_body(models: &Path) -> Result<BodyEstimator, ModelsError> {
    let path = models.join(BODY_MODEL);
    // Straight into the run-time form: the bundled forest's 44 MB of decompressed trees and
    // 100 MB of training form are never held (see `BodyEstimator::load`).
    BodyEstimator::load(&path, VoteSettings::default()).map_err(|source| ModelsError::Body { path, source })
}

/// Loads the paw model of a models directory ([`paws_file`]); `None` when the directory has
/// none.
///
/// # Errors
/// The file is there but is not a paw model we can run.
pub fn load_paws(models: &Path) -> Result<Option<PawModel>, ModelsError> {
    let Some(path) = paws_file(models) else {
        return Ok(None);
    };
    PawModel::load(&path).map(Some).map_err(ModelsError::Paws)
}

/// Loads the orientation model of a models directory; `None` when the directory has none.
///
/// # Errors
/// The file is there but is not an orientation model this version reads.
pub fn load_orientation(models: &Path) -> Result<Option<crate::vision::body_shape::ShapeModel>, ModelsError> {
    let path = models.join(ORIENTATION_MODEL);
    if !path.exists() {
        return Ok(None);
    }
    crate::vision::body_shape::ShapeModel::load(&path)
        .map(Some)
        .map_err(|e| ModelsError::Orientation(Box::new(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_files_hash_is_its_contents_sha256() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("m");
        std::fs::write(&path, b"abc").unwrap_or_else(|e| panic!("{e}"));
        let file = ModelFile::of(&path).unwrap_or_else(|| panic!("readable"));
        assert_eq!(file.bytes, 3);
        assert_eq!(
            file.sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(ModelFile::of(&dir.path().join("none")).is_none());
    }
}
