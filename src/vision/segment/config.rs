//! The segmenter's settings ([`SegmenterConfig`]): their defaults, their checks, and a
//! [`Segmenter`] built from them and a [`Background`].

use super::{Background, Scratch, SegmentError, Segmenter};
use serde::{Deserialize, Serialize};

/// The segmenter's settings: plain data, read from a config file (missing fields take their
/// defaults), checked and turned into a [`Segmenter`] by [`SegmenterConfig::build`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmenterConfig {
    /// A pixel this high above the floor (mm) is the mouse.
    pub min_height_mm: f32,
    /// Nothing higher than this above the floor (mm) is the mouse (a hand, the lid).
    pub max_height_mm: f32,
    /// The mouse is nearer to the camera than the background model by at least this much (mm):
    /// walls and objects fixed in the cage are never foreground.
    pub background_margin_mm: f32,
    /// The mouse's component grows into connected pixels at least this high above the floor
    /// (and nearer than the background by as much, or by `background_margin_mm` if less): the
    /// tail lying on the floor. On a noisy floor the segmenter raises it for the frame.
    pub grow_height_mm: f32,
    /// A mouse smaller than this (mm^2 seen from above) is no mouse.
    pub min_area_mm2: f32,
    /// Along thin parts the mouse also grows into pixels where the median of five readings in
    /// a line is at least this high (mm; more on a noisier floor): the tail's tip.
    pub ridge_height_mm: f32,
    /// Holes inside the mouse up to this size (mm^2) are filled.
    pub max_hole_mm2: f32,
    /// Parts of the mask narrower than twice this (mm), the tail and thin limbs, are left out
    /// of the body's centroid, heading, length and width.
    pub body_core_mm: f32,
    /// Empty frames a background model is made of; the floor plane is fitted again after this
    /// many updates.
    pub background_frames: usize,
    /// How far (mm) one empty frame moves the background's running median at a pixel.
    pub background_step_mm: f32,
    /// Background readings within this distance (mm) of a floor plane hypothesis support it.
    pub floor_tolerance_mm: f32,
}

impl Default for SegmenterConfig {
    fn default() -> Self {
        Self {
            min_height_mm: 5.0,
            max_height_mm: 120.0,
            background_margin_mm: 5.0,
            grow_height_mm: 2.5,
            ridge_height_mm: 1.5,
            min_area_mm2: 400.0,
            max_hole_mm2: 150.0,
            body_core_mm: 4.0,
            background_frames: 30,
            background_step_mm: 0.5,
            floor_tolerance_mm: 4.0,
        }
    }
}

impl SegmenterConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`SegmentError::Config`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), SegmentError> {
        let check = |name: &'static str, value: f32, ok: bool, expected: &'static str| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(SegmentError::Config {
                    name,
                    value: f64::from(value),
                    expected,
                })
            }
        };
        check(
            "min_height_mm",
            self.min_height_mm,
            self.min_height_mm > 0.0,
            "a height above 0 mm",
        )?;
        check(
            "max_height_mm",
            self.max_height_mm,
            self.max_height_mm > self.min_height_mm,
            "more than min_height_mm",
        )?;
        check(
            "background_margin_mm",
            self.background_margin_mm,
            self.background_margin_mm >= 0.0,
            "0 mm or more",
        )?;
        check(
            "grow_height_mm",
            self.grow_height_mm,
            self.grow_height_mm > 0.0 && self.grow_height_mm <= self.min_height_mm,
            "above 0 mm and at most min_height_mm",
        )?;
        check(
            "ridge_height_mm",
            self.ridge_height_mm,
            self.ridge_height_mm > 0.0,
            "above 0 mm",
        )?;
        check(
            "min_area_mm2",
            self.min_area_mm2,
            self.min_area_mm2 >= 0.0,
            "0 mm^2 or more",
        )?;
        check(
            "max_hole_mm2",
            self.max_hole_mm2,
            self.max_hole_mm2 >= 0.0,
            "0 mm^2 or more",
        )?;
        check(
            "body_core_mm",
            self.body_core_mm,
            (0.0..=50.0).contains(&self.body_core_mm),
            "between 0 and 50 mm",
        )?;
        check(
            "background_step_mm",
            self.background_step_mm,
            self.background_step_mm > 0.0,
            "above 0 mm",
        )?;
        check(
            "floor_tolerance_mm",
            self.floor_tolerance_mm,
            self.floor_tolerance_mm > 0.0,
            "above 0 mm",
        )?;
        if self.background_frames == 0 {
            return Err(SegmentError::Config {
                name: "background_frames",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }

    /// Checks the settings and makes a segmenter for `background`.
    ///
    /// # Errors
    /// [`SegmentError::Config`] when a setting is out of range.
    pub fn build(&self, background: Background) -> Result<Segmenter, SegmentError> {
        self.validate()?;
        let n = background.region.len();
        let padded = (background.region.width as usize + 2) * (background.region.height as usize + 2);
        let mut segmenter = Segmenter {
            config: self.clone(),
            background,
            world_from_camera: None,
            lo: vec![0; n],
            hi_strong: vec![0; n],
            near_wall: Vec::new(),
            scratch: Scratch {
                strong: vec![0; n],
                jump: vec![0; n],
                jump_span: 0..0,
                mask: vec![0; n],
                tiles: Vec::new(),
                column_counts: Vec::new(),
                tile_cluster: Vec::new(),
                labels: vec![0; padded],
                local: vec![0; padded],
                before: vec![0; padded],
                core: vec![0; padded],
                stack: Vec::new(),
                grown: Vec::new(),
                refused: Vec::new(),
                column_first: Vec::new(),
                column_last: Vec::new(),
                branch: Vec::new(),
                components: Default::default(),
                open_tmp: Vec::new(),
            },
        };
        segmenter.background.refit_every = self.background_frames;
        segmenter.background.step_mm = self.background_step_mm;
        segmenter.background.floor_tolerance_mm = self.floor_tolerance_mm;
        segmenter.update_thresholds();
        Ok(segmenter)
    }
}
