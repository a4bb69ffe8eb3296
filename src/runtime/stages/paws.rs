//! The paw stage: the paw model on the bottom colour frame, only around where the mouse
//! stands (its body joints' footprint on the glass, projected into the bottom camera).

use super::Posed;
use crate::core::frame::FramePair;
use crate::core::geometry::Camera;
use crate::runtime::pipeline::{Map, StageError};
use crate::runtime::pose_record::PoseRecord;
use crate::runtime::pose_record::PoseStatus;
use crate::vision::paws::{FOOTPRINT_MARGIN_MM, PawModel, footprint};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Runs a [`PawModel`] on each colour frame that comes with a mouse.
#[derive(Debug, Clone)]
pub struct PawStage {
    detector: Option<PawModel>,
    color: Camera,
    /// Whether the colour frames' size was found not to match: said once, by whichever of
    /// the stage's workers (its clones) finds it first.
    warned: Arc<AtomicBool>,
}

impl PawStage {
    /// A stage for the bottom camera `color`; without a detector it finds no paws (the
    /// fusion then puts every limb in its default configuration).
    pub fn new(detector: Option<PawModel>, color: Camera) -> Self {
        Self {
            detector,
            color,
            warned: Arc::default(),
        }
    }
}

impl Map for PawStage {
    type In = Posed;
    type Out = Posed;
    const NAME: &'static str = "paws";

    fn process(&mut self, mut input: Posed) -> Result<Posed, StageError> {
        let Posed { pair, record, others } = &mut input;
        for record in std::iter::once(record).chain(others) {
            self.detect(pair, record);
        }
        Ok(input)
    }
}

impl PawStage {
    /// The paws of the mouse of `record` in `pair`'s colour frame: those around where it
    /// stands (with several mice, each its own footprint).
    fn detect(&mut self, pair: &FramePair, record: &mut PoseRecord) {
        let (Some(detector), Some(color), PoseStatus::Ok) = (&mut self.detector, &pair.color, record.status) else {
            return;
        };
        let i = &self.color.intrinsics;
        if (color.width, color.height) != (i.width, i.height) {
            // The rig's colour camera is another size (a live rig without a calibration
            // for this camera mode): no paws rather than paws in the wrong place. The
            // joints then come from the fusion's defaults, as without a paw model.
            if !self.warned.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    "colour frames are {}x{} but the rig's colour camera is {}x{}: no paw detection (calibrate this camera)",
                    color.width,
                    color.height,
                    i.width,
                    i.height
                );
            }
            return;
        }
        if let Some((roi, px_per_mm)) = footprint(&record.pose, &self.color, FOOTPRINT_MARGIN_MM) {
            detector.detect(color, roi, px_per_mm, &mut record.paws);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::{ColorFrame, DepthFrame, FramePair, PixelFormat, Stamp};
    use crate::core::geometry::Rig;
    use crate::core::pose::Pose;

    /// Warnings caught while `f` runs.
    fn warnings(f: impl FnOnce()) -> Vec<String> {
        use tracing_subscriber::layer::SubscriberExt as _;
        let log = Arc::new(crate::runtime::status::events::EventLog::default());
        let subscriber =
            tracing_subscriber::registry().with(crate::runtime::status::events::EventLayer(Arc::clone(&log)));
        tracing::subscriber::with_default(subscriber, f);
        log.recent().into_iter().map(|e| e.text).collect()
    }

    #[test]
    fn a_wrong_colour_size_is_said_once_whatever_the_number_of_workers() {
        let rig = Rig::default_rig();
        let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models/paws.xml");
        let stage = PawStage::new(Some(PawModel::load(&models).unwrap()), rig.color);
        let mut workers = vec![stage.clone(), stage];
        let said = warnings(|| {
            for w in &mut workers {
                let stamp = Stamp::default();
                let color = ColorFrame {
                    stamp,
                    width: 2,
                    height: 2,
                    format: PixelFormat::Mono8,
                    data: vec![0; 4],
                };
                let pair = FramePair {
                    depth: Arc::new(DepthFrame::empty(stamp, 4, 4)),
                    color: Some(Arc::new(color)),
                    skew_ns: 0,
                    color_again: false,
                };
                let record = PoseRecord {
                    depth: stamp,
                    color: Some(stamp),
                    skew_ns: 0,
                    status: PoseStatus::Ok,
                    pose: Pose::default(),
                    paws: Vec::new(),
                    headings: None,
                    orientation: None,
                    raw_body: None,
                    velocities: None,
                    identity: None,
                };
                w.process(Posed {
                    pair,
                    record,
                    others: Vec::new(),
                })
                .unwrap();
            }
        });
        assert_eq!(
            said.iter().filter(|m| m.contains("no paw detection")).count(),
            1,
            "{said:?}"
        );
    }
}
