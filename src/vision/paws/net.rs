//! The paws found by a small convolutional network instead of the cascade: a heatmap of paw
//! centres, one cell a millimetre on the glass, from the bottom view in grey at
//! [`NET_PX_PER_MM`]. Each local maximum of the heatmap above the model's threshold is a paw.
//!
//! The network: a 3x3 convolution at the input's resolution, a 2x2 max-pool, four 3x3
//! convolutions (the last two dilated 2 and 4, so that a cell sees 17 mm of the glass around
//! it: a paw and the toes, heel and floor beside it), each followed by a ReLU, and a 1x1
//! convolution to one logit per cell. A peak whose centre lies in the box of a surer one is
//! the same paw (its toes and its heel), dropped as the cascade drops a paw found twice. It is
//! trained through `candle` on the CPU, each convolution one matrix product over its kernel's
//! shifted views of the input (`unfolded`); the weights
//! are a `safetensors` file ([`PawNet::load`]) that `mousepose train paws --net` writes. At run
//! time the same layers run as plain loops ([`Layers`], [`crate::vision::forest::simd::conv`]: twelve
//! output channels by eight columns held in registers, in AVX2 where the processor has it):
//! `candle`'s general convolution (unfolding each layer's input into a matrix first) took
//! several times as long on these few channels, and a test holds the two to the same heatmap.

use super::detect::suppress_repeats;
use super::grey::{GreyImage, Greyer};
use super::{PawDetection, PawError, WINDOW_PX};
use crate::core::frame::ColorFrame;
use crate::vision::forest::simd::{self, CONV_BLOCK, Kernel};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, VarBuilder, conv2d};
use std::collections::HashMap;
use std::path::Path;

/// The scale the network sees the glass at (pixels per millimetre).
pub const NET_PX_PER_MM: f64 = 2.0;

/// Input pixels per heatmap cell along each axis.
pub const NET_STRIDE: usize = 2;

/// The layers' names in the weights file, input first.
const LAYER_NAMES: [&str; 6] = ["c1", "c2", "c3", "c4", "c5", "head"];

/// The version of the weights file's layout, kept in its `meta` tensor.
const FORMAT_VERSION: f32 = 1.0;

/// The network's layers.
#[derive(Clone, Debug)]
pub struct PawNet {
    convs: Vec<Conv2d>,
    head: Conv2d,
    /// Channels of the inner layers.
    pub width: usize,
    /// Heatmap probability a paw needs to be reported.
    pub threshold: f32,
}

fn config(dilation: usize) -> Conv2dConfig {
    Conv2dConfig {
        padding: dilation,
        dilation,
        ..Conv2dConfig::default()
    }
}

impl PawNet {
    /// The network with `width` inner channels, its weights from `vb` (new ones when `vb` is
    /// a training variable map's).
    ///
    /// # Errors
    /// `vb` lacks a weight or holds one of another shape.
    pub fn new(vb: &VarBuilder<'_>, width: usize, threshold: f32) -> candle_core::Result<Self> {
        let half = (width / 2).max(1);
        let convs = vec![
            conv2d(1, half, 3, config(1), vb.pp(LAYER_NAMES[0]))?,
            conv2d(half, width, 3, config(1), vb.pp(LAYER_NAMES[1]))?,
            conv2d(width, width, 3, config(1), vb.pp(LAYER_NAMES[2]))?,
            conv2d(width, width, 3, config(2), vb.pp(LAYER_NAMES[3]))?,
            conv2d(width, width, 3, config(4), vb.pp(LAYER_NAMES[4]))?,
        ];
        let head = conv2d(
            width,
            1,
            1,
            Conv2dConfig {
                padding: 0,
                ..Conv2dConfig::default()
            },
            vb.pp(LAYER_NAMES[5]),
        )?;
        Ok(Self {
            convs,
            head,
            width,
            threshold,
        })
    }

    /// The logits of a batch `(n, 1, h, w)` of standardised grey images: `(n, 1, h / 2, w / 2)`.
    ///
    /// # Errors
    /// The input is not of that shape.
    pub fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut x = unfolded(&self.convs[0], x)?.relu()?.max_pool2d(NET_STRIDE)?;
        for conv in &self.convs[1..] {
            x = unfolded(conv, &x)?.relu()?;
        }
        unfolded(&self.head, &x)
    }

    /// Reads a weights file.
    ///
    /// # Errors
    /// The file cannot be read, is not `safetensors`, or is not a paw network of this
    /// version.
    pub fn load(path: &Path) -> Result<Self, PawError> {
        let bytes = std::fs::read(path).map_err(|source| PawError::Io {
            path: path.to_owned(),
            action: "read",
            source,
        })?;
        let damaged = |reason: String| PawError::Format {
            path: path.to_owned(),
            reason,
        };
        let tensors = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu)
            .map_err(|e| damaged(format!("it is not a safetensors file ({e})")))?;
        let meta: Vec<f32> = tensors
            .get("meta")
            .and_then(|t| t.to_vec1().ok())
            .ok_or_else(|| damaged("it has no paw network's `meta` tensor".into()))?;
        let [version, threshold, width] = meta[..] else {
            return Err(damaged(format!("its `meta` tensor has {} values, not 3", meta.len())));
        };
        if version != FORMAT_VERSION {
            return Err(damaged(format!(
                "it is a paw network of layout {version}, and this mousepose reads {FORMAT_VERSION}"
            )));
        }
        let vb = VarBuilder::from_tensors(tensors, DType::F32, &Device::Cpu);
        Self::new(&vb, width as usize, threshold).map_err(|e| damaged(format!("its weights do not fit ({e})")))
    }

    /// Writes the weights and settings to `path` (`safetensors`).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), PawError> {
        let mut tensors: HashMap<String, Tensor> = HashMap::new();
        for (name, conv) in LAYER_NAMES.iter().zip(self.convs.iter().chain([&self.head])) {
            tensors.insert(format!("{name}.weight"), conv.weight().clone());
            if let Some(b) = conv.bias() {
                tensors.insert(format!("{name}.bias"), b.clone());
            }
        }
        let meta = [FORMAT_VERSION, self.threshold, self.width as f32];
        let meta = Tensor::new(&meta[..], &Device::Cpu).map_err(|e| PawError::Training { reason: e.to_string() })?;
        tensors.insert("meta".into(), meta);
        candle_core::safetensors::save(&tensors, path).map_err(|e| PawError::Io {
            path: path.to_owned(),
            action: "write",
            source: std::io::Error::other(e.to_string()),
        })
    }
}

/// `conv` on `x` `(n, c, h, w)`, padded to keep its size (as every layer here is), as one
/// matrix product: the kernel's taps are shifted views of `x` side by side, `(n, taps * c, h *
/// w)`, and the weights `(outputs, taps * c)`. This is what training runs, forward and
/// backward: `candle`'s own convolution on these few channels went through a dot product per
/// output pixel, unvectorised, and took several times as long; its matrix product is `gemm`'s,
/// vectorised for the processor it runs on.
fn unfolded(conv: &Conv2d, x: &Tensor) -> candle_core::Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    let (outputs, _, k, _) = conv.weight().dims4()?;
    let Conv2dConfig { padding, dilation, .. } = *conv.config();
    let columns = if k == 1 {
        x.reshape((n, c, h * w))?
    } else {
        let padded = x
            .pad_with_zeros(2, padding, padding)?
            .pad_with_zeros(3, padding, padding)?;
        let mut taps = Vec::with_capacity(k * k);
        for ky in 0..k {
            for kx in 0..k {
                taps.push(padded.narrow(2, ky * dilation, h)?.narrow(3, kx * dilation, w)?);
            }
        }
        Tensor::cat(&taps, 1)?.reshape((n, k * k * c, h * w))?
    };
    // `[output][input][ky][kx]` to `[output][(ky * k + kx) * c + input]`, the columns' order.
    let weights = conv.weight().permute((0, 2, 3, 1))?.reshape((outputs, k * k * c))?;
    let mut y = weights.broadcast_matmul(&columns)?;
    if let Some(bias) = conv.bias() {
        y = y.broadcast_add(&bias.reshape((1, outputs, 1))?)?;
    }
    y.reshape((n, outputs, h, w))
}

/// One convolution's weights, as the run-time loops read them ([`simd::ConvLayer`]).
#[derive(Clone, Debug)]
struct Layer {
    inputs: usize,
    outputs: usize,
    /// 1 or 3.
    kernel: usize,
    dilation: usize,
    /// `[block of outputs][input][ky][kx][output in the block]` ([`simd::ConvLayer::weights`]).
    weights: Vec<f32>,
    bias: Vec<f32>,
    /// Followed by a ReLU (every layer but the head).
    relu: bool,
}

impl Layer {
    fn of(conv: &Conv2d, relu: bool) -> candle_core::Result<Self> {
        let (outputs, inputs, kernel, _) = conv.weight().dims4()?;
        let bias = match conv.bias() {
            Some(b) => b.to_vec1()?,
            None => vec![0.0; outputs],
        };
        // candle's `[output][input][ky][kx]`, regrouped.
        let flat: Vec<f32> = conv.weight().flatten_all()?.to_vec1()?;
        let taps = kernel * kernel;
        let mut weights = vec![0.0; outputs.div_ceil(CONV_BLOCK) * inputs * taps * CONV_BLOCK];
        for (n, &v) in flat.iter().enumerate() {
            let (o, i, t) = (n / (inputs * taps), n / taps % inputs, n % taps);
            weights[((o / CONV_BLOCK * inputs + i) * taps + t) * CONV_BLOCK + o % CONV_BLOCK] = v;
        }
        Ok(Self {
            inputs,
            outputs,
            kernel,
            dilation: conv.config().dilation,
            weights,
            bias,
            relu,
        })
    }

    /// `out` = this layer on `input` (`inputs` planes of `w` x `h`, zero beyond the edges),
    /// by `kernel`; `padded` is scratch for the input's copy with a
    /// border of zeros.
    fn run(&self, kernel: Kernel, input: &[f32], w: usize, h: usize, padded: &mut Vec<f32>, out: &mut Vec<f32>) {
        let layer = simd::ConvLayer {
            inputs: self.inputs,
            outputs: self.outputs,
            kernel: self.kernel,
            dilation: self.dilation,
            weights: &self.weights,
            bias: &self.bias,
            relu: self.relu,
        };
        let (reach, pw) = (layer.reach(), layer.padded_width(w));
        let pplane = pw * (h + 2 * reach);
        padded.clear();
        padded.resize(self.inputs * pplane, 0.0);
        for (dst, src) in padded.chunks_exact_mut(pplane).zip(input.chunks_exact(w * h)) {
            for (y, row) in src.chunks_exact(w).enumerate() {
                dst[(y + reach) * pw + reach..][..w].copy_from_slice(row);
            }
        }
        out.clear();
        out.resize(self.outputs * w * h, 0.0);
        simd::conv(kernel, &layer, padded, w, h, out);
    }
}

/// The network's layers as the run-time loops read them, with their scratch planes.
#[derive(Clone, Debug)]
pub struct Layers {
    layers: Vec<Layer>,
    kernel: Kernel,
    a: Vec<f32>,
    b: Vec<f32>,
    padded: Vec<f32>,
}

impl Layers {
    fn of(net: &PawNet) -> candle_core::Result<Self> {
        // Every layer but the head is followed by a ReLU.
        let layers = net
            .convs
            .iter()
            .map(|conv| Layer::of(conv, true))
            .chain([Layer::of(&net.head, false)])
            .collect::<candle_core::Result<_>>()?;
        Ok(Self {
            layers,
            kernel: Kernel::detect(),
            a: Vec::new(),
            b: Vec::new(),
            padded: Vec::new(),
        })
    }

    /// The heatmap's probabilities of a standardised grey image of `w` x `h` pixels, row by
    /// row, `w / 2` cells a row: [`PawNet::forward`]'s result, through the sigmoid.
    pub fn heatmap(&mut self, input: &[f32], w: usize, h: usize, out: &mut Vec<f32>) {
        let Self {
            layers,
            kernel,
            a,
            b,
            padded,
        } = self;
        let Some((first, rest)) = layers.split_first() else {
            return;
        };
        first.run(*kernel, input, w, h, padded, a);
        // 2x2 max-pool: odd last rows and columns dropped, as candle does.
        let (cw, ch) = (w / NET_STRIDE, h / NET_STRIDE);
        b.clear();
        for plane in a.chunks_exact(w * h) {
            for y in 0..ch {
                for x in 0..cw {
                    let at = |dy: usize, dx: usize| plane[(2 * y + dy) * w + 2 * x + dx];
                    b.push(at(0, 0).max(at(0, 1)).max(at(1, 0)).max(at(1, 1)));
                }
            }
        }
        for layer in rest {
            layer.run(*kernel, b, cw, ch, padded, a);
            std::mem::swap(a, b);
        }
        out.clear();
        out.extend(b.iter().map(|&v| 1.0 / (1.0 + (-v).exp())));
    }
}

/// A grey image standardised as the network sees it: zero mean and unit spread over the
/// image.
pub fn standardise(grey: &GreyImage, out: &mut Vec<f32>) {
    out.clear();
    let n = grey.data.len().max(1) as f64;
    let mean = grey.data.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = grey.data.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n;
    let spread = var.sqrt().max(1.0);
    out.extend(grey.data.iter().map(|&v| ((f64::from(v) - mean) / spread) as f32));
}

/// The peaks of a heatmap of `width` cells a row: `(cell x, cell y, probability)`, the
/// centre refined to the probability-weighted mean of the 3x3 cells around the peak.
pub fn peaks(heat: &[f32], width: usize, threshold: f32, out: &mut Vec<(f64, f64, f32)>) {
    let height = heat.len() / width.max(1);
    let at = |x: i64, y: i64| -> Option<f32> {
        (x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height)
            .then(|| heat[y as usize * width + x as usize])
    };
    out.clear();
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            let p = heat[y as usize * width + x as usize];
            if p < threshold {
                continue;
            }
            let (mut sx, mut sy, mut sw, mut top) = (0.0, 0.0, 0.0, true);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(q) = at(x + dx, y + dy) else { continue };
                    // Of two equal neighbours the first in reading order is the peak.
                    if q > p || (q == p && (dy, dx) < (0, 0)) {
                        top = false;
                    }
                    sx += f64::from(q) * (x + dx) as f64;
                    sy += f64::from(q) * (y + dy) as f64;
                    sw += f64::from(q);
                }
            }
            if top {
                out.push((sx / sw, sy / sw, p));
            }
        }
    }
}

/// Finds paws with a [`PawNet`]. Cheap to clone: one per worker thread.
#[derive(Clone, Debug)]
pub struct NetDetector {
    layers: Layers,
    /// Heatmap probability a paw needs to be reported.
    threshold: f32,
    greyer: Greyer,
    grey: GreyImage,
    input: Vec<f32>,
    heat: Vec<f32>,
    peaks: Vec<(f64, f64, f32)>,
}

impl NetDetector {
    /// A detector running `net`.
    ///
    /// # Errors
    /// The network's weights cannot be read out (they are not `f32`).
    pub fn new(net: &PawNet) -> Result<Self, PawError> {
        let layers = Layers::of(net).map_err(|e| PawError::Training { reason: e.to_string() })?;
        Ok(Self {
            threshold: net.threshold,
            layers,
            greyer: Greyer::default(),
            grey: GreyImage::default(),
            input: Vec::new(),
            heat: Vec::new(),
            peaks: Vec::new(),
        })
    }

    /// Reports peaks of this probability and more instead of the network's own threshold.
    pub fn set_threshold(&mut self, threshold: f32) {
        self.threshold = threshold;
    }

    /// Detects paws in `frame` within `roi`, the glass seen at `px_per_mm`: clears `out`, then
    /// pushes a box of the cascade's window (12 mm) around each paw, `score` the heatmap's
    /// probability, surest first, a peak in a surer one's box dropped.
    pub fn detect(
        &mut self,
        frame: &ColorFrame,
        roi: (u32, u32, u32, u32),
        px_per_mm: f64,
        out: &mut Vec<PawDetection>,
    ) {
        out.clear();
        let Some(place) = self
            .greyer
            .convert(frame, roi, px_per_mm, NET_PX_PER_MM, &mut self.grey)
        else {
            return;
        };
        let (w, h) = (self.grey.width, self.grey.height);
        if w < NET_STRIDE || h < NET_STRIDE {
            return;
        }
        standardise(&self.grey, &mut self.input);
        self.layers.heatmap(&self.input, w, h, &mut self.heat);
        let cells = w / NET_STRIDE;
        peaks(&self.heat, cells, self.threshold, &mut self.peaks);
        let half = f64::from(WINDOW_PX) / 2.0 * place.frame_px_per_px * NET_PX_PER_MM;
        for &(cx, cy, p) in &self.peaks {
            // A cell covers input pixels [2c, 2c + 2): its centre is at 2c + 1.
            let (x, y) = place.to_frame(cx * NET_STRIDE as f64 + 1.0, cy * NET_STRIDE as f64 + 1.0);
            out.push(PawDetection {
                x0: (x - half) as f32,
                y0: (y - half) as f32,
                x1: (x + half) as f32,
                y1: (y + half) as f32,
                score: p,
            });
        }
        suppress_repeats(out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Module;

    #[test]
    fn peaks_are_local_maxima_refined_to_their_neighbours() {
        let w = 8;
        let mut heat = vec![0.0f32; w * 6];
        heat[2 * w + 2] = 0.9;
        heat[2 * w + 3] = 0.9; // a tie: one peak between the two
        heat[2 * w + 4] = 0.1;
        heat[4 * w + 6] = 0.6;
        heat[4 * w + 7] = 0.3; // no peak: a neighbour is surer
        let mut found = Vec::new();
        peaks(&heat, w, 0.5, &mut found);
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(
            (found[0].0 - 2.5).abs() < 0.06 && (found[0].1 - 2.0).abs() < 1e-9,
            "{found:?}"
        );
        assert!(found[1].0 > 6.0 && found[1].0 < 6.5, "{found:?}");
    }

    #[test]
    fn the_unfolded_convolution_is_candles_forward_and_backward() {
        let vm = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        let net = PawNet::new(&vb, 6, 0.4).unwrap();
        let worst = |a: &Tensor, b: &Tensor| -> f32 {
            let d = (a - b).unwrap().abs().unwrap().flatten_all().unwrap();
            d.max(0).unwrap().to_scalar().unwrap()
        };
        for conv in net.convs.iter().chain([&net.head]) {
            let c = conv.weight().dims4().unwrap().1;
            let x = Tensor::randn(0f32, 1f32, (2, c, 13, 11), &Device::Cpu).unwrap();
            let (ours, candles) = (unfolded(conv, &x).unwrap(), conv.forward(&x).unwrap());
            assert_eq!(ours.dims(), candles.dims());
            assert!(
                worst(&ours, &candles) < 1e-5,
                "{:?}: {}",
                conv.config(),
                worst(&ours, &candles)
            );
            // The same gradient for the weights and the bias, through a loss that weighs the
            // outputs unequally.
            let weigh = Tensor::randn(0f32, 1f32, ours.dims(), &Device::Cpu).unwrap();
            let loss = |y: &Tensor| (y * &weigh).unwrap().sum_all().unwrap();
            let (g, h) = (loss(&ours).backward().unwrap(), loss(&candles).backward().unwrap());
            for v in [conv.weight(), conv.bias().unwrap()] {
                let (a, b) = (g.get(v).unwrap(), h.get(v).unwrap());
                assert!(worst(a, b) < 1e-3, "{:?}: {}", conv.config(), worst(a, b));
            }
        }
    }

    #[test]
    fn a_network_written_is_read_back_the_same() {
        let vm = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        let net = PawNet::new(&vb, 6, 0.4).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("paws.safetensors");
        net.save(&path).unwrap();
        let back = PawNet::load(&path).unwrap();
        assert_eq!((back.width, back.threshold), (6, 0.4));
        let x = Tensor::randn(0f32, 1f32, (1, 1, 20, 24), &Device::Cpu).unwrap();
        let (a, b): (Vec<f32>, Vec<f32>) = (
            net.forward(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap(),
            back.forward(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap(),
        );
        assert_eq!(a, b);
        // The run-time loops give candle's heatmap (odd sizes too: the pool drops the last
        // row and column).
        for (h, w) in [(20, 24), (17, 31)] {
            let x = Tensor::randn(0f32, 1f32, (1, 1, h, w), &Device::Cpu).unwrap();
            let reference: Vec<f32> = candle_nn::ops::sigmoid(&net.forward(&x).unwrap())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            let mut layers = Layers::of(&back).unwrap();
            let mut heat = Vec::new();
            layers.heatmap(&x.flatten_all().unwrap().to_vec1().unwrap(), w, h, &mut heat);
            assert_eq!(heat.len(), reference.len());
            let worst = heat
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(worst < 1e-5, "{worst}");
        }
        std::fs::write(&path, b"not a network").unwrap();
        let e = PawNet::load(&path).unwrap_err().to_string();
        assert!(e.contains("damaged"), "{e}");
    }
}
