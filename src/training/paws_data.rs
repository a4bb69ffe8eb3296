//! Training and test material cut from synthetic datasets' bottom views.
//!
//! Each bottom view (RGB at the full sensor's 2 px/mm) is first turned into what the camera
//! really delivers, a Bayer RG mosaic, and then into a grey image at the canonical scale by
//! the detector's own conversion ([`super::grey`]), so training sees exactly the pixels the
//! detector will. Each view is also seen as binned colour cameras deliver it
//! ([`CutParams::binnings`], [`BottomView::binned`]: blocks averaged; binned 4x4, 0.5 px/mm,
//! enlarged to the canonical scale by the detector), and material is cut from every one.
//!
//! * Positives: windows centred on paws that touch the glass and are visible, augmented by
//!   a random rotation, a size change of up to 10 %, a shift of up to one pixel, a
//!   brightness/contrast change and sensor-like noise. Lifted paws are not used: the figure
//!   that matters is recall on paws on the glass, and a lifted paw seen through fur is a
//!   different, dimmer pattern.
//! * Backgrounds: the whole grey view with every paw's box (grown by a pixel) marked as
//!   excluded; negatives are windows of these that touch no paw (fur, tail, the cage floor),
//!   drawn by the trainer at every scale the detector runs.
//! * Hard negatives: windows centred on what real bottom views show that looks like a paw
//!   and is not one: the snout, the chin, the throat, the belly, the genitals, the tail's base,
//!   and the glare, glass marks and pale belly fur of views rendered with clutter
//!   ([`crate::synth::views::BottomClutter`]), each at a random size the detector runs at
//!   (0.8-1.25 windows), turned and shifted a little; none touching a paw's box.

use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::core::geometry::{Camera, Rig};
use crate::core::skeleton::Joint;
use crate::synth::dataset::{Dataset, Sample};
use crate::synth::views::{BottomView, Mark};
use crate::vision::paws::CANONICAL_PX_PER_MM;
use crate::vision::paws::grey::{GreyImage, Greyer};
use crate::vision::paws::train::{Background, TrainingSet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::Path;

/// Pixels per millimetre of datasets' bottom views (the full 1280x1024 sensor).
pub const DATASET_PX_PER_MM: f64 = 2.0;

/// A bottom view as the camera delivers it: a Bayer mosaic of the view's region whose
/// pattern follows the full frame's (red at even x, even y).
pub fn bottom_frame(view: &BottomView) -> ColorFrame {
    let r = view.region;
    let format = match (r.x0 % 2, r.y0 % 2) {
        (0, 0) => PixelFormat::BayerRg8,
        (1, 0) => PixelFormat::BayerGr8,
        (0, _) => PixelFormat::BayerGb8,
        _ => PixelFormat::BayerBg8,
    };
    let (w, h) = (r.width as usize, r.height as usize);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let c = format.bayer_channel(x, y).unwrap_or(1);
            data.push(view.rgb.get((y * w + x) * 3 + c).copied().unwrap_or(0));
        }
    }
    ColorFrame {
        stamp: Stamp::default(),
        width: r.width,
        height: r.height,
        format,
        data,
    }
}

/// A bottom view seen at `px_per_mm` in grey at the canonical scale, and the scale from
/// view pixels to it.
pub fn canonical_view(view: &BottomView, px_per_mm: f64, greyer: &mut Greyer) -> Option<(GreyImage, f64)> {
    let frame = bottom_frame(view);
    let mut grey = GreyImage::default();
    let place = greyer.convert(
        &frame,
        (0, 0, frame.width, frame.height),
        px_per_mm,
        CANONICAL_PX_PER_MM,
        &mut grey,
    )?;
    Some((grey, place.frame_px_per_px))
}

/// How positives are cut.
#[derive(Clone, Copy, Debug)]
pub struct CutParams {
    pub width: usize,
    pub height: usize,
    /// Augmented copies per paw (besides the plain one).
    pub augment: usize,
    /// Windows cut around each hard negative's place.
    pub hard_per_place: usize,
    /// The colour binnings each view is also seen at ([`BottomView::binned`]), 1 being the
    /// full sensor: material is cut from every one, so the cascade knows paws as a binned
    /// camera blurs them.
    pub binnings: &'static [u32],
    pub seed: u64,
}

/// Where in `camera`'s image the hard negatives of a sample lie: its body's landmarks that
/// look like paws from below, then the centres of `marks` (the view's, in the same image).
pub fn hard_places(sample: &Sample, camera: &Camera, marks: &[Mark]) -> Vec<(f64, f64)> {
    let j = |joint: Joint| sample.joints[joint.index()];
    let lerp = |a: Joint, b: Joint, t: f64| {
        let (a, b) = (j(a), j(b));
        a + (b - a) * t
    };
    let body = [
        j(Joint::Snout),
        lerp(Joint::Snout, Joint::Head, 0.5),    // the chin
        lerp(Joint::Head, Joint::Neck, 0.6),     // the throat
        j(Joint::MidBack),                       // the belly
        lerp(Joint::Rump, Joint::TailBase, 0.7), // the genitals
        j(Joint::TailBase),
        lerp(Joint::TailBase, Joint::TailTip, 0.15),
    ];
    let mut places: Vec<(f64, f64)> = body
        .iter()
        .filter_map(|p| camera.project_world(p))
        .map(|p| (p.x, p.y))
        .collect();
    places.extend(marks.iter().map(Mark::centre));
    places
}

/// Where a window is cut: centred on `(cx, cy)` of the image, turned by `angle` radians,
/// `scale` image pixels per window pixel.
#[derive(Clone, Copy, Debug)]
pub struct Warp {
    pub cx: f64,
    pub cy: f64,
    pub angle: f64,
    pub scale: f64,
}

/// Samples the `width x height` window `warp` of `img` bilinearly into `out`.
pub fn warp_window(img: &GreyImage, warp: Warp, width: usize, height: usize, out: &mut Vec<f32>) {
    let Warp { cx, cy, angle, scale } = warp;
    out.clear();
    let (s, c) = angle.sin_cos();
    for j in 0..height {
        for i in 0..width {
            let u = (i as f64 + 0.5 - width as f64 / 2.0) * scale;
            let v = (j as f64 + 0.5 - height as f64 / 2.0) * scale;
            let x = cx + c * u - s * v - 0.5;
            let y = cy + s * u + c * v - 0.5;
            out.push(bilinear(img, x, y));
        }
    }
}

fn bilinear(img: &GreyImage, x: f64, y: f64) -> f32 {
    let x = x.clamp(0.0, (img.width - 1) as f64);
    let y = y.clamp(0.0, (img.height - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let p = |x: usize, y: usize| f32::from(img.data[y * img.width + x]);
    let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
    let bottom = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Reads a dataset's bottom views into positives and backgrounds.
///
/// # Errors
/// When the dataset cannot be read, or holds no visible paw on the glass.
pub fn load(dir: &Path, params: CutParams) -> Result<TrainingSet, PawDataError> {
    let ds = Dataset::open(dir)?;
    let mut set = TrainingSet {
        width: params.width,
        height: params.height,
        ..TrainingSet::default()
    };
    let rig = ds.meta.rig.unwrap_or_else(Rig::default_rig);
    let mut cutter = Cutter::new(params);
    ds.for_each(|sample| {
        let Some(full) = &sample.bottom else {
            return Ok(());
        };
        for &binning in params.binnings {
            let camera = rig.with_color_binning(binning).color;
            let px_per_mm = DATASET_PX_PER_MM / f64::from(binning);
            if binning == 1 {
                cutter.cut(&mut set, &sample, full, px_per_mm, &camera);
            } else {
                cutter.cut(&mut set, &sample, &full.binned(binning), px_per_mm, &camera);
            }
        }
        Ok(())
    })?;
    if set.paws == 0 {
        return Err(PawDataError::NoPaws { path: dir.to_owned() });
    }
    Ok(set)
}

/// Cuts the training material of one view after another, its random draws in order.
pub(crate) struct Cutter {
    params: CutParams,
    greyer: Greyer,
    rng: ChaCha8Rng,
    hard_rng: ChaCha8Rng,
    buf: Vec<f32>,
}

impl Cutter {
    pub(crate) fn new(params: CutParams) -> Self {
        Self {
            params,
            greyer: Greyer::default(),
            rng: ChaCha8Rng::seed_from_u64(params.seed ^ 0x9A75_0001),
            hard_rng: ChaCha8Rng::seed_from_u64(params.seed ^ 0x4A2D_0001),
            buf: Vec::new(),
        }
    }

    /// Cuts the positives, hard negatives and background of `view` (of `sample`, seen at
    /// `px_per_mm` by `camera`) into `set`.
    fn cut(&mut self, set: &mut TrainingSet, sample: &Sample, view: &BottomView, px_per_mm: f64, camera: &Camera) {
        let Some((grey, k)) = canonical_view(view, px_per_mm, &mut self.greyer) else {
            return;
        };
        let (rx, ry) = (f64::from(view.region.x0), f64::from(view.region.y0));
        let paws: Vec<PawWindow> = view
            .paws
            .iter()
            .filter(|paw| paw.x1 > paw.x0)
            .map(|paw| PawWindow {
                bounds: [
                    ((f64::from(paw.x0) - rx) / k) as f32,
                    ((f64::from(paw.y0) - ry) / k) as f32,
                    ((f64::from(paw.x1) - rx) / k) as f32,
                    ((f64::from(paw.y1) - ry) / k) as f32,
                ],
                centre: (paw.contact && paw.visible).then(|| {
                    (
                        (f64::from(paw.x0 + paw.x1) / 2.0 - rx) / k,
                        (f64::from(paw.y0 + paw.y1) / 2.0 - ry) / k,
                    )
                }),
            })
            .collect();
        let hard: Vec<(f64, f64)> = hard_places(sample, camera, &view.marks)
            .into_iter()
            .map(|(x, y)| ((x - rx) / k, (y - ry) / k))
            .collect();
        self.cut_canonical(set, grey, &paws, &hard);
    }

    /// Cuts a view already at the canonical scale: a positive (and its augmented copies) at the
    /// centre of each positive paw, hard negatives around each of `hard` (none touching a
    /// paw's box), and the view as a background with every paw's box excluded.
    pub(crate) fn cut_canonical(
        &mut self,
        set: &mut TrainingSet,
        grey: GreyImage,
        paws: &[PawWindow],
        hard: &[(f64, f64)],
    ) {
        // Each box grown by a pixel.
        let excluded: Vec<[f32; 4]> = paws
            .iter()
            .map(|p| {
                [
                    p.bounds[0] - 1.0,
                    p.bounds[1] - 1.0,
                    p.bounds[2] + 1.0,
                    p.bounds[3] + 1.0,
                ]
            })
            .collect();
        for (cx, cy) in paws.iter().filter_map(|p| p.centre) {
            set.paws += 1;
            for a in 0..=self.params.augment {
                let (angle, scale, dx, dy, gain, offset, noise) = if a == 0 {
                    (0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0)
                } else {
                    (
                        self.rng.gen_range(0.0..std::f64::consts::TAU),
                        self.rng.gen_range(0.9..1.1),
                        self.rng.gen_range(-1.0..1.0),
                        self.rng.gen_range(-1.0..1.0),
                        self.rng.gen_range(0.8f32..1.2),
                        self.rng.gen_range(-8.0f32..8.0),
                        self.rng.gen_range(0.0f32..2.5),
                    )
                };
                let warp = Warp {
                    cx: cx + dx,
                    cy: cy + dy,
                    angle,
                    scale,
                };
                warp_window(&grey, warp, self.params.width, self.params.height, &mut self.buf);
                for v in &self.buf {
                    let n: f32 = StandardNormal.sample(&mut self.rng);
                    let p = v * gain + offset + n * noise;
                    set.positives.push((p + 0.5).clamp(0.0, 255.0) as u8);
                }
            }
        }
        for &(cx, cy) in hard {
            for _ in 0..self.params.hard_per_place {
                let scale = self.hard_rng.gen_range(0.8..1.25);
                let warp = Warp {
                    cx: cx + self.hard_rng.gen_range(-1.5..1.5),
                    cy: cy + self.hard_rng.gen_range(-1.5..1.5),
                    angle: self.hard_rng.gen_range(0.0..std::f64::consts::TAU),
                    scale,
                };
                let half = self.params.width as f64 * scale / 2.0;
                let (x0, y0, x1, y1) = (warp.cx - half, warp.cy - half, warp.cx + half, warp.cy + half);
                let inside = x0 >= 0.0 && y0 >= 0.0 && x1 <= grey.width as f64 && y1 <= grey.height as f64;
                // The turned window's corners reach out to half its diagonal.
                let r = half * std::f64::consts::SQRT_2;
                let touches = excluded.iter().any(|b| {
                    warp.cx - r < f64::from(b[2])
                        && warp.cx + r > f64::from(b[0])
                        && warp.cy - r < f64::from(b[3])
                        && warp.cy + r > f64::from(b[1])
                });
                if !inside || touches {
                    continue;
                }
                warp_window(&grey, warp, self.params.width, self.params.height, &mut self.buf);
                set.hard
                    .extend(self.buf.iter().map(|v| (v + 0.5).clamp(0.0, 255.0) as u8));
            }
        }
        set.backgrounds.push(Background { grey, excluded });
    }
}

/// A paw's box in a view at the canonical scale (x0, y0, x1, y1), kept out of the negatives,
/// and its centre when it is cut as a positive (on the glass and visible).
pub(crate) struct PawWindow {
    pub(crate) bounds: [f32; 4],
    pub(crate) centre: Option<(f64, f64)>,
}

/// Why a dataset gives no paw material.
#[derive(Debug, thiserror::Error)]
pub enum PawDataError {
    #[error(transparent)]
    Dataset(#[from] crate::synth::dataset::DatasetError),
    #[error("{path:?} has no bottom views with paws to train or test on")]
    NoPaws { path: std::path::PathBuf },
    #[error(transparent)]
    Labels(#[from] crate::io::paw_labels::LabelError),
    #[error("cannot take the bottom view of the labelled image {path:?}: {why}")]
    Image { path: std::path::PathBuf, why: String },
}
