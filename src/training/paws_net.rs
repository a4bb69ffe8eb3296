//! Training the paw network ([`crate::vision::paws::net`]) on labelled real bottom views, and
//! rendered ones beside them when given.
//!
//! Each labelled frame's bottom view is taken in grey at the network's scale and at four other
//! sizes (x0.8 to x1.25: a view told or found a little off its true scale still finds its
//! paws), standardised as the detector does; rendered views at their own scale, half of each
//! batch when there are any. Training draws crops of [`CROP_PX`] pixels, half of them near a
//! labelled paw and half anywhere, each turned or mirrored (one of the eight ways), its
//! contrast and brightness varied and noise added. The target of each heatmap cell is a
//! Gaussian of its distance from the nearest paw (sigma [`TARGET_SIGMA_MM`]); the loss is
//! CenterNet's penalty-reduced focal loss (Zhou, Wang and Krahenbuhl 2019), which weighs the few
//! cells on a paw against the many beside and between them. AdamW with a cosine-decayed
//! learning rate.

use crate::core::frame::ColorFrame;
use crate::synth::dataset::Dataset;
use crate::training::paws_data::{DATASET_PX_PER_MM, PawDataError, bottom_frame};
use crate::training::paws_real::RealViews;
use crate::vision::paws::PawError;
use crate::vision::paws::grey::{GreyImage, Greyer};
use crate::vision::paws::net::{NET_PX_PER_MM, NET_STRIDE, PawNet, standardise};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Optimizer, VarBuilder, VarMap};
use rand::{Rng, SeedableRng};
use std::path::Path;

/// The side of a training crop (pixels at [`NET_PX_PER_MM`]).
pub const CROP_PX: usize = 48;

/// The spread of a paw's target about its centre (mm).
pub const TARGET_SIGMA_MM: f64 = 1.2;

/// The sizes each view is also learnt at, relative to its true scale.
const SIZES: [f64; 5] = [0.8, 0.9, 1.0, 1.12, 1.25];

/// Cells whose target is at least this are a paw's own (the focal loss's positives).
const POSITIVE_TARGET: f32 = 0.8;

/// How the network is trained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NetParams {
    pub iterations: usize,
    pub batch: usize,
    /// Channels of the inner layers.
    pub width: usize,
    pub learning_rate: f64,
    /// Heatmap probability a paw needs to be reported.
    pub threshold: f32,
    pub seed: u64,
}

impl Default for NetParams {
    fn default() -> Self {
        Self {
            iterations: 2000,
            batch: 16,
            width: 12,
            learning_rate: 2e-3,
            threshold: 0.4,
            seed: 1,
        }
    }
}

/// One bottom view at one size, standardised, with its paws (pixels of the view).
#[derive(Clone, Debug)]
pub struct NetView {
    pub pixels: Vec<f32>,
    pub width: usize,
    pub height: usize,
    pub paws: Vec<(f64, f64)>,
}

/// `frame`'s region `roi`, seen at `px_per_mm`, in grey at the network's scale and
/// standardised, with `paws` (pixels of the frame) moved into it.
fn net_view(
    greyer: &mut Greyer,
    grey: &mut GreyImage,
    frame: &ColorFrame,
    roi: (u32, u32, u32, u32),
    px_per_mm: f64,
    paws: impl Iterator<Item = (f64, f64)>,
) -> Option<NetView> {
    let place = greyer.convert(frame, roi, px_per_mm, NET_PX_PER_MM, grey)?;
    let mut pixels = Vec::new();
    standardise(grey, &mut pixels);
    Some(NetView {
        pixels,
        width: grey.width,
        height: grey.height,
        paws: paws
            .map(|(x, y)| {
                (
                    (x - place.x0) / place.frame_px_per_px,
                    (y - place.y0) / place.frame_px_per_px,
                )
            })
            .collect(),
    })
}

/// The bottom views of the labelled frames `which`, each at every size of training.
pub fn real_views(views: &RealViews, which: &[usize]) -> Vec<NetView> {
    let mut greyer = Greyer::default();
    let mut grey = GreyImage::default();
    let mut out = Vec::new();
    for &k in which.iter().filter(|&&k| k < views.frames.len()) {
        let paws = views.paws_in(k);
        for size in SIZES {
            out.extend(net_view(
                &mut greyer,
                &mut grey,
                &views.frames[k],
                views.roi(k),
                views.px_per_mm / size,
                paws.iter().map(|&(_, x, y)| (x, y)),
            ));
        }
    }
    out
}

/// The bottom views of a rendered dataset (at its own scale, the full sensor's), their paws
/// those on the glass and visible, the cascade's positives ([`super::paws_data`]): a lifted
/// paw is learnt as no paw.
///
/// # Errors
/// The dataset cannot be read, or holds no visible paw on the glass.
pub fn render_views(dir: &Path) -> Result<Vec<NetView>, PawDataError> {
    let ds = Dataset::open(dir)?;
    let mut greyer = Greyer::default();
    let mut grey = GreyImage::default();
    let mut out = Vec::new();
    ds.for_each(|sample| {
        let Some(view) = &sample.bottom else {
            return Ok(());
        };
        let frame = bottom_frame(view);
        let (rx, ry) = (f64::from(view.region.x0), f64::from(view.region.y0));
        let paws = view
            .paws
            .iter()
            .filter(|p| p.x1 > p.x0 && p.contact && p.visible)
            .map(|p| (f64::from(p.x0 + p.x1) / 2.0 - rx, f64::from(p.y0 + p.y1) / 2.0 - ry));
        out.extend(net_view(
            &mut greyer,
            &mut grey,
            &frame,
            (0, 0, frame.width, frame.height),
            DATASET_PX_PER_MM,
            paws,
        ));
        Ok(())
    })?;
    if out.iter().all(|v| v.paws.is_empty()) {
        return Err(PawDataError::NoPaws { path: dir.to_owned() });
    }
    Ok(out)
}

/// A batch of crops and their targets, each from `real` or (half of them, when there are
/// any) from `renders`.
fn batch(real: &[NetView], renders: &[NetView], n: usize, rng: &mut impl Rng) -> candle_core::Result<(Tensor, Tensor)> {
    let cells = CROP_PX / NET_STRIDE;
    let mut xs = vec![0f32; n * CROP_PX * CROP_PX];
    let mut ts = vec![0f32; n * cells * cells];
    let sigma_px = TARGET_SIGMA_MM * NET_PX_PER_MM;
    for b in 0..n {
        let views = if !renders.is_empty() && rng.gen_bool(0.5) {
            renders
        } else {
            real
        };
        let v = &views[rng.gen_range(0..views.len())];
        let (cx, cy) = if !v.paws.is_empty() && rng.gen_bool(0.5) {
            let p = v.paws[rng.gen_range(0..v.paws.len())];
            let reach = CROP_PX as f64 * 0.4;
            (p.0 + rng.gen_range(-reach..reach), p.1 + rng.gen_range(-reach..reach))
        } else {
            (rng.gen_range(0.0..v.width as f64), rng.gen_range(0.0..v.height as f64))
        };
        let (ox, oy) = (
            (cx - CROP_PX as f64 / 2.0).round() as i64,
            (cy - CROP_PX as f64 / 2.0).round() as i64,
        );
        let (flip_x, flip_y, transpose) = (rng.gen_bool(0.5), rng.gen_bool(0.5), rng.gen_bool(0.5));
        // The view's pixel offset from the crop's corner of crop pixel (i, j).
        let from_crop = |i: usize, j: usize| {
            let (u, w) = if transpose { (j, i) } else { (i, j) };
            (
                if flip_x { CROP_PX - 1 - u } else { u },
                if flip_y { CROP_PX - 1 - w } else { w },
            )
        };
        let gain = rng.gen_range(0.75f32..1.33);
        let offset = rng.gen_range(-0.3f32..0.3);
        let crop = &mut xs[b * CROP_PX * CROP_PX..(b + 1) * CROP_PX * CROP_PX];
        for j in 0..CROP_PX {
            for i in 0..CROP_PX {
                let (u, w) = from_crop(i, j);
                let (x, y) = (ox + u as i64, oy + w as i64);
                let inside = x >= 0 && y >= 0 && (x as usize) < v.width && (y as usize) < v.height;
                let value = if inside {
                    v.pixels[y as usize * v.width + x as usize]
                } else {
                    0.0
                };
                crop[j * CROP_PX + i] = value * gain + offset + rng.gen_range(-0.1f32..0.1);
            }
        }
        for j in 0..cells {
            for i in 0..cells {
                // The cell's centre: between its first and last pixel, in the view.
                let (u0, w0) = from_crop(NET_STRIDE * i, NET_STRIDE * j);
                let (u1, w1) = from_crop(NET_STRIDE * i + NET_STRIDE - 1, NET_STRIDE * j + NET_STRIDE - 1);
                let x = ox as f64 + (u0 + u1) as f64 / 2.0 + 0.5;
                let y = oy as f64 + (w0 + w1) as f64 / 2.0 + 0.5;
                let d2 = v
                    .paws
                    .iter()
                    .map(|p| (x - p.0).powi(2) + (y - p.1).powi(2))
                    .fold(f64::INFINITY, f64::min);
                ts[b * cells * cells + j * cells + i] = (-d2 / (2.0 * sigma_px * sigma_px)).exp() as f32;
            }
        }
    }
    Ok((
        Tensor::from_vec(xs, (n, 1, CROP_PX, CROP_PX), &Device::Cpu)?,
        Tensor::from_vec(ts, (n, 1, cells, cells), &Device::Cpu)?,
    ))
}

/// Draws the new network's weights from `rng`, as `candle_nn::conv2d` draws them (Kaiming's
/// normal for the weights, uniform within one over the root of the inputs for the biases),
/// layer by layer in the order of their names: `candle`'s own draws come from an unseeded
/// generator, so two trainings of one seed would start, and end, apart.
fn seed_weights(vars: &VarMap, rng: &mut impl Rng) -> candle_core::Result<()> {
    let vars = vars
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("the weights' lock was poisoned".into()))?;
    let mut names: Vec<&String> = vars.keys().collect();
    names.sort();
    for name in names {
        let var = &vars[name];
        let layer = name.rsplit_once('.').map_or(name.as_str(), |(layer, _)| layer);
        let weight = vars
            .get(&format!("{layer}.weight"))
            .ok_or_else(|| candle_core::Error::Msg(format!("no weight for {name}")))?;
        let (_, inputs, kh, kw) = weight.dims4()?;
        let values: Vec<f32> = if var.rank() == 4 {
            let normal = rand_distr::Normal::new(0.0, (2.0 / (inputs * kh * kw) as f64).sqrt())
                .map_err(|e| candle_core::Error::Msg(e.to_string()))?;
            (0..var.elem_count()).map(|_| rng.sample(normal) as f32).collect()
        } else {
            let bound = 1.0 / (inputs as f64).sqrt();
            (0..var.elem_count())
                .map(|_| rng.gen_range(-bound..bound) as f32)
                .collect()
        };
        var.set(&Tensor::from_vec(values, var.shape(), &Device::Cpu)?)?;
    }
    Ok(())
}

/// `log(1 + e^x)`, without overflow.
fn softplus(x: &Tensor) -> candle_core::Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// The penalty-reduced focal loss of `logits` against the Gaussian `targets`, per positive.
fn focal_loss(logits: &Tensor, targets: &Tensor) -> candle_core::Result<Tensor> {
    let p = candle_nn::ops::sigmoid(logits)?;
    let positive = targets.ge(POSITIVE_TARGET)?.to_dtype(DType::F32)?;
    let negative = (positive.neg()? + 1.0)?;
    // -log p = softplus(-x); -log(1 - p) = softplus(x).
    let on_paws = ((&positive * (p.neg()? + 1.0)?.sqr()?)? * softplus(&logits.neg()?)?)?;
    let beside = (((negative * (targets.neg()? + 1.0)?.powf(4.0)?)? * p.sqr()?)? * softplus(logits)?)?;
    let count = f64::from(positive.sum_all()?.to_scalar::<f32>()?.max(1.0));
    (on_paws.sum_all()? + beside.sum_all()?)? / count
}

/// Trains a network on the labelled real views `real` and, half of each batch when there are
/// any, the rendered views `renders`; `progress` is told each iteration done and the loss's
/// running mean.
///
/// # Errors
/// No real view holds a paw, or the training's arithmetic fails.
pub fn train(
    real: &[NetView],
    renders: &[NetView],
    params: &NetParams,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<PawNet, PawError> {
    if real.iter().all(|v| v.paws.is_empty()) {
        return Err(PawError::Training {
            reason: "no labelled paw to learn from".into(),
        });
    }
    let failed = |e: candle_core::Error| PawError::Training { reason: e.to_string() };
    let vars = VarMap::new();
    let vb = VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu);
    let net = PawNet::new(&vb, params.width, params.threshold).map_err(failed)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(params.seed);
    seed_weights(&vars, &mut rng).map_err(failed)?;
    let adam = candle_nn::ParamsAdamW {
        lr: params.learning_rate,
        weight_decay: 1e-4,
        ..candle_nn::ParamsAdamW::default()
    };
    let mut optimiser = candle_nn::AdamW::new(vars.all_vars(), adam).map_err(failed)?;
    let mut mean = None;
    for it in 0..params.iterations {
        let done = it as f64 / params.iterations as f64;
        optimiser.set_learning_rate(params.learning_rate * 0.5 * (1.0 + (std::f64::consts::PI * done).cos()));
        let (x, t) = batch(real, renders, params.batch, &mut rng).map_err(failed)?;
        let loss = focal_loss(&net.forward(&x).map_err(failed)?, &t).map_err(failed)?;
        optimiser.backward_step(&loss).map_err(failed)?;
        let l = f64::from(loss.to_scalar::<f32>().map_err(failed)?);
        let m = mean.map_or(l, |m: f64| 0.98 * m + 0.02 * l);
        mean = Some(m);
        progress(it + 1, m);
    }
    Ok(net)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The heatmap of one network on one fixed image.
    fn output(net: &PawNet) -> Vec<f32> {
        let x: Vec<f32> = (0..32 * 32).map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0).collect();
        let x = Tensor::from_vec(x, (1, 1, 32, 32), &Device::Cpu).unwrap();
        net.forward(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap()
    }

    #[test]
    fn one_seed_trains_one_network_and_another_seed_another() {
        let view = NetView {
            pixels: (0..64 * 64).map(|i| ((i * 13 % 29) as f32 / 14.0) - 1.0).collect(),
            width: 64,
            height: 64,
            paws: vec![(20.0, 20.0), (40.0, 44.0)],
        };
        let params = NetParams {
            iterations: 4,
            batch: 2,
            width: 4,
            ..NetParams::default()
        };
        let run = |seed| {
            output(
                &train(
                    std::slice::from_ref(&view),
                    &[],
                    &NetParams { seed, ..params },
                    &mut |_, _| {},
                )
                .unwrap(),
            )
        };
        let first = run(3);
        assert_eq!(first, run(3));
        assert_ne!(first, run(4));
    }
}
