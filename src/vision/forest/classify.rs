//! Classification: leaves hold class histograms, splits maximise the entropy gain, and a
//! prediction's error is 0 or 1.

use super::Objective;

/// Classification of samples whose labels are `labels[sample]`, in `classes` classes.
#[derive(Clone, Debug)]
pub struct ClassObjective<'a> {
    pub labels: &'a [u8],
    pub classes: usize,
}

/// A leaf: the normalised histogram of its samples' classes.
pub type ClassLeaf = Vec<f32>;

/// The most probable class of a histogram (the lowest class on ties).
pub fn argmax(histogram: &[f32]) -> usize {
    let mut best = 0;
    for (c, &p) in histogram.iter().enumerate() {
        if p > histogram[best] {
            best = c;
        }
    }
    best
}

impl Objective for ClassObjective<'_> {
    type Stats = Vec<f64>;
    type Leaf = ClassLeaf;

    fn empty_stats(&self) -> Vec<f64> {
        vec![0.0; self.classes]
    }

    fn add(&self, stats: &mut Vec<f64>, sample: u32) {
        if let Some(c) = self
            .labels
            .get(sample as usize)
            .and_then(|&l| stats.get_mut(usize::from(l)))
        {
            *c += 1.0;
        }
    }

    fn merge(&self, a: &mut Vec<f64>, b: &Vec<f64>) {
        for (x, y) in a.iter_mut().zip(b) {
            *x += y;
        }
    }

    fn minus(&self, a: &Vec<f64>, b: &Vec<f64>) -> Vec<f64> {
        a.iter().zip(b).map(|(x, y)| x - y).collect()
    }

    fn count(&self, stats: &Vec<f64>) -> f64 {
        stats.iter().sum()
    }

    fn impurity(&self, stats: &Vec<f64>) -> f64 {
        let n: f64 = stats.iter().sum();
        if n <= 0.0 {
            return 0.0;
        }
        -stats
            .iter()
            .filter(|&&c| c > 0.0)
            .map(|&c| {
                let p = c / n;
                p * p.ln()
            })
            .sum::<f64>()
    }

    fn leaf(&self, samples: &[u32]) -> ClassLeaf {
        let mut h = self.empty_stats();
        for &s in samples {
            self.add(&mut h, s);
        }
        let n: f64 = h.iter().sum::<f64>().max(1.0);
        h.iter().map(|&c| (c / n) as f32).collect()
    }

    fn refit(&self, _old: &ClassLeaf, samples: &[u32]) -> ClassLeaf {
        self.leaf(samples)
    }

    fn error(&self, leaf: &ClassLeaf, sample: u32) -> f64 {
        let truth = self.labels.get(sample as usize).map_or(usize::MAX, |&l| usize::from(l));
        if argmax(leaf) == truth { 0.0 } else { 1.0 }
    }
}
