//! Stand-in for the cascade detector until it lands (finds nothing).

use super::PawDetection;
use crate::frame::ColorFrame;
use std::path::Path;

#[derive(Clone, Debug)]
pub struct PawDetector;

#[derive(Debug, thiserror::Error)]
#[error("no paw detector yet")]
pub struct PawError;

impl PawDetector {
    pub fn load(_path: &Path) -> Result<Self, PawError> {
        Err(PawError)
    }

    pub fn detect(
        &mut self,
        _frame: &ColorFrame,
        _roi: (u32, u32, u32, u32),
        _px_per_mm: f64,
        out: &mut Vec<PawDetection>,
    ) {
        out.clear();
    }
}
