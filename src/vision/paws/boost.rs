//! Gentle AdaBoost of decision stumps for one cascade stage (OpenCV's `stageType BOOST`,
//! `boostType GAB`, `maxDepth 1`): each round fits, by weighted least squares on labels
//! +1/-1, the one-feature stump that best explains the samples, then re-weights the samples
//! by `exp(-y f(x))`. The stage's threshold is then set so the positives' hit rate is met.
//!
//! Feature values are quantised per feature into 256 bins whose edges are midpoints between
//! sample values (quantiles), so a round costs one pass over a byte per feature and sample,
//! and a stump's threshold is a bin edge: `value < edge` exactly when `bin < edge index`, so
//! the learnt stage behaves on the samples exactly as the detector will.

use rayon::prelude::*;

/// Bins per feature.
pub const BINS: usize = 256;

/// Feature values of all samples, quantised per feature.
#[derive(Clone, Debug)]
pub struct Binned {
    pub features: usize,
    pub samples: usize,
    /// `bins[f * samples + i]`: the bin of sample `i` under feature `f`.
    pub bins: Vec<u8>,
    /// `edges[f * (BINS - 1) + k]`: bin `k + 1` starts at this value.
    pub edges: Vec<f32>,
}

impl Binned {
    /// Quantises `features` features of `samples` samples; `values(f, out)` writes feature
    /// `f`'s value of every sample into `out`. Runs on rayon's threads, one feature at a time.
    pub fn build(features: usize, samples: usize, values: impl Fn(usize, &mut [f32]) + Sync) -> Self {
        let mut bins = vec![0u8; features * samples];
        let mut edges = vec![0f32; features * (BINS - 1)];
        if samples > 0 {
            bins.par_chunks_mut(samples)
                .zip(edges.par_chunks_mut(BINS - 1))
                .enumerate()
                .for_each_init(
                    || (vec![0f32; samples], vec![0f32; samples]),
                    |(vals, sorted), (f, (bin_row, edge_row))| {
                        values(f, vals);
                        sorted.copy_from_slice(vals);
                        sorted.sort_unstable_by(f32::total_cmp);
                        for (k, e) in edge_row.iter_mut().enumerate() {
                            let i = ((k + 1) * samples / BINS).clamp(1, samples.max(2) - 1);
                            *e = if samples > 1 {
                                midpoint(sorted[i - 1], sorted[i])
                            } else {
                                sorted[0]
                            };
                        }
                        for (b, &v) in bin_row.iter_mut().zip(vals.iter()) {
                            *b = edge_row.partition_point(|&e| e <= v) as u8;
                        }
                    },
                );
        }
        Self {
            features,
            samples,
            bins,
            edges,
        }
    }

    /// The threshold of splitting feature `f` before bin `b` (1..BINS).
    pub fn edge(&self, f: usize, b: usize) -> f32 {
        self.edges[f * (BINS - 1) + b - 1]
    }
}

/// The midpoint of two single-precision values that is strictly above `a` when `b > a`.
fn midpoint(a: f32, b: f32) -> f32 {
    let m = ((f64::from(a) + f64::from(b)) / 2.0) as f32;
    if m <= a && b > a { b } else { m }
}

/// A stump over binned features: samples in bins below `bin` get `left`, the others `right`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BinStump {
    pub feature: usize,
    pub bin: usize,
    pub threshold: f32,
    pub left: f32,
    pub right: f32,
}

/// The stump minimising the weighted squared error of `labels` (+1/-1) under `weights`.
pub fn best_stump(data: &Binned, labels: &[f32], weights: &[f64]) -> Option<BinStump> {
    let n = data.samples;
    let best = (0..data.features)
        .into_par_iter()
        .map_init(
            || (vec![0f64; BINS], vec![0f64; BINS]),
            |(w_hist, s_hist), f| {
                w_hist.iter_mut().for_each(|v| *v = 0.0);
                s_hist.iter_mut().for_each(|v| *v = 0.0);
                let row = &data.bins[f * n..(f + 1) * n];
                for ((&b, &w), &y) in row.iter().zip(weights).zip(labels) {
                    w_hist[b as usize] += w;
                    s_hist[b as usize] += w * f64::from(y);
                }
                let (w_all, s_all): (f64, f64) = (w_hist.iter().sum(), s_hist.iter().sum());
                let (mut wl, mut sl) = (0.0, 0.0);
                let mut best: Option<(f64, usize, f64, f64)> = None;
                for b in 1..BINS {
                    wl += w_hist[b - 1];
                    sl += s_hist[b - 1];
                    if w_hist[b - 1] == 0.0 && b > 1 {
                        continue;
                    }
                    let (wr, sr) = (w_all - wl, s_all - sl);
                    if wl <= 1e-300 || wr <= 1e-300 {
                        continue;
                    }
                    let gain = sl * sl / wl + sr * sr / wr;
                    if best.is_none_or(|(g, ..)| gain > g) {
                        best = Some((gain, b, sl / wl, sr / wr));
                    }
                }
                best.map(|(gain, b, l, r)| (gain, f, b, l, r))
            },
        )
        .flatten()
        .reduce_with(|a, b| if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) { b } else { a })?;
    let (_, feature, bin, left, right) = best;
    Some(BinStump {
        feature,
        bin,
        threshold: data.edge(feature, bin),
        left: left as f32,
        right: right as f32,
    })
}

/// What boosting one stage gives.
#[derive(Clone, Debug)]
pub struct BoostedStage {
    pub stumps: Vec<BinStump>,
    pub threshold: f32,
    /// Fraction of the positives the stage passes.
    pub hit_rate: f64,
    /// Fraction of the negatives the stage passes.
    pub false_alarm: f64,
}

/// Boosts one stage on `data` whose first `positives` samples are positives and the rest
/// negatives: adds stumps until the false-alarm rate at the threshold meeting `min_hit_rate`
/// is at most `max_false_alarm`, or `max_weak` stumps.
pub fn boost_stage(
    data: &Binned,
    positives: usize,
    min_hit_rate: f64,
    max_false_alarm: f64,
    max_weak: usize,
) -> BoostedStage {
    let n = data.samples;
    let negatives = n - positives;
    let labels: Vec<f32> = (0..n).map(|i| if i < positives { 1.0 } else { -1.0 }).collect();
    let mut weights: Vec<f64> = (0..n)
        .map(|i| {
            if i < positives {
                0.5 / positives as f64
            } else {
                0.5 / negatives.max(1) as f64
            }
        })
        .collect();
    let mut sums = vec![0f64; n];
    let mut out = BoostedStage {
        stumps: Vec::new(),
        threshold: f32::NEG_INFINITY,
        hit_rate: 1.0,
        false_alarm: 1.0,
    };
    let mut scratch = Vec::with_capacity(positives);
    while out.stumps.len() < max_weak.max(1) {
        let Some(stump) = best_stump(data, &labels, &weights) else {
            break;
        };
        let row = &data.bins[stump.feature * n..(stump.feature + 1) * n];
        let mut total = 0.0;
        for i in 0..n {
            let v = if (row[i] as usize) < stump.bin {
                stump.left
            } else {
                stump.right
            };
            sums[i] += f64::from(v);
            weights[i] *= (-f64::from(labels[i]) * f64::from(v)).exp();
            total += weights[i];
        }
        if total > 0.0 {
            weights.iter_mut().for_each(|w| *w /= total);
        }
        out.stumps.push(stump);
        scratch.clear();
        scratch.extend_from_slice(&sums[..positives]);
        scratch.sort_unstable_by(f64::total_cmp);
        let miss = ((1.0 - min_hit_rate) * positives as f64).floor() as usize;
        let at = scratch
            .get(miss.min(positives.saturating_sub(1)))
            .copied()
            .unwrap_or(0.0);
        out.threshold = f32_at_or_below(at);
        let t = super::cascade::applied_threshold(out.threshold);
        out.hit_rate = sums[..positives].iter().filter(|&&s| s >= t).count() as f64 / positives.max(1) as f64;
        out.false_alarm = sums[positives..].iter().filter(|&&s| s >= t).count() as f64 / negatives.max(1) as f64;
        if out.false_alarm <= max_false_alarm {
            break;
        }
    }
    out
}

/// The largest single-precision value not above `v`.
pub fn f32_at_or_below(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) <= v || f.is_nan() {
        f
    } else if f > 0.0 {
        f32::from_bits(f.to_bits() - 1)
    } else if f < 0.0 {
        f32::from_bits(f.to_bits() + 1)
    } else {
        -f32::from_bits(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_separable_toy_set_is_split_by_one_stump() {
        // Feature 1 separates: positives above 0.5; feature 0 is noise.
        let n = 200;
        let positives = 100;
        let value = |f: usize, i: usize| -> f32 {
            let pos = i < positives;
            match f {
                0 => ((i * 7919) % 101) as f32 / 101.0,
                _ => {
                    let u = ((i * 31) % 97) as f32 / 97.0 * 0.4;
                    if pos { 0.55 + u } else { 0.05 + u }
                }
            }
        };
        let data = Binned::build(2, n, |f, out| {
            for (i, v) in out.iter_mut().enumerate() {
                *v = value(f, i);
            }
        });
        let stage = boost_stage(&data, positives, 1.0, 0.0, 5);
        assert_eq!(stage.stumps.len(), 1);
        let s = stage.stumps[0];
        assert_eq!(s.feature, 1);
        assert!(s.threshold > 0.45 && s.threshold < 0.55, "{s:?}");
        assert!(s.left < 0.0 && s.right > 0.0);
        assert_eq!(stage.hit_rate, 1.0);
        assert_eq!(stage.false_alarm, 0.0);
        // The threshold classifies raw values as the bins did.
        for i in 0..n {
            let v = value(1, i);
            assert_eq!(v >= s.threshold, i < positives);
        }
    }

    #[test]
    fn bins_agree_with_edges() {
        let data = Binned::build(1, 1000, |_, out| {
            for (i, v) in out.iter_mut().enumerate() {
                *v = ((i * 37) % 1000) as f32 * 0.01 - 3.0;
            }
        });
        for i in 0..1000 {
            let v = ((i * 37) % 1000) as f32 * 0.01 - 3.0;
            let b = data.bins[i] as usize;
            if b > 0 {
                assert!(v >= data.edge(0, b));
            }
            if b < BINS - 1 {
                assert!(v < data.edge(0, b + 1));
            }
        }
    }

    #[test]
    fn threshold_rounds_down() {
        let v = 0.1f64;
        assert!(f64::from(f32_at_or_below(v)) <= v);
        assert_eq!(f32_at_or_below(0.5), 0.5);
        for v in [-0.1f64, 1e-50, -1e-50, 3.3] {
            let f = f32_at_or_below(v);
            assert!(f64::from(f) <= v, "{v}: {f}");
            // Tight: the next single-precision value up is above `v`.
            let up = if f > 0.0 {
                f32::from_bits(f.to_bits() + 1)
            } else if f < 0.0 {
                f32::from_bits(f.to_bits() - 1)
            } else {
                f32::from_bits(1)
            };
            assert!(f64::from(up) > v, "{v}: {f}");
        }
    }
}
