//! The views the orientation model ([`crate::vision::body_shape`]) learns from and is
//! evaluated on: each rendered mouse of a dataset segmented as the pipeline segments it, once
//! with its tail hidden (its pixels given back to the floor, as a depth camera that does not
//! see a 3-5 mm tail shows it), once as rendered, and once with its tail raised (blurred a
//! pixel wider and reading [`RAISED_TAIL_MM`] above the floor, as real Kinects show a tail
//! through mixed pixels), each at the dataset's resolution and at half of it with 2 mm of depth
//! noise added (about the 1.9 mm a pixel and the noise of real time-of-flight rigs). As in the
//! pipeline, a tail found as one ([`crate::vision::tail`]) is taken out of the body before its
//! shape is judged.

use super::{MaskSource, segmented_image};
use crate::core::geometry::Rig;
use crate::core::rng::item_rng;
use crate::core::skeleton::{BACKGROUND_LABEL, Joint, Part};
use crate::synth::dataset::Sample;
use crate::synth::render::Cage;
use crate::vision::body_shape::{Features, aligned};
use crate::vision::segment::SegmentError;
use crate::vision::tail::find_tail_in;
use nalgebra::{Point2, Point3, Vector2};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

/// Depth noise (mm, one standard deviation) added to the half-resolution views.
pub const COARSE_NOISE_MM: f64 = 2.0;
/// A raised tail's height above the floor (mm), at least: what a real Kinect reads of a tail.
pub const RAISED_TAIL_MM: f32 = 16.0;

/// How a view shows the tail.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TailCase {
    Hidden,
    AsRendered,
    Raised,
}

/// One view of a rendered mouse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub features: Features,
    /// Whether the head lies toward the features' `+axis` (from the true tail base and neck).
    pub head_plus: bool,
    /// Whether the tail was hidden, and whether the view is the half-resolution one.
    pub tail_hidden: bool,
    pub coarse: bool,
}

/// The six views of each sample (fewer where the mouse is not found or too small).
///
/// # Errors
/// When the rig's cage gives the segmenter no background.
pub fn views(samples: &[Sample], rig: &Rig, seed: u64) -> Result<Vec<View>, SegmentError> {
    let masks = MaskSource::for_rig(rig)?;
    let threads = rayon::current_num_threads().max(1);
    let share = samples.len().div_ceil(threads).max(1);
    let cage = Cage::new(&rig.depth);
    let chunks: Vec<Result<Vec<View>, SegmentError>> = samples
        .par_chunks(share)
        .map(|chunk| {
            let mut segmenter = masks.segmenter()?;
            let mut out = Vec::new();
            for s in chunk {
                let base = s.joints[Joint::TailBase.index()];
                let neck = s.joints[Joint::Neck.index()];
                let heading = Vector2::new(neck.x - base.x, neck.y - base.y);
                let floor = cage.depth(s.top.region);
                let mut rng = item_rng(seed, 0x0E1, s.index);
                let labels = &s.top.label;
                let width = s.top.region.width as usize;
                let tail_at = |x: usize, y: usize| x < width && labels.get(y * width + x) == Some(&Part::Tail.label());
                for case in [TailCase::Hidden, TailCase::AsRendered, TailCase::Raised] {
                    let depth: Vec<u16> = (0..s.top.depth.len())
                        .map(|k| {
                            let (d, f) = (s.top.depth[k], floor[k]);
                            let floor_depth = f.round().clamp(0.0, 65535.0) as u16;
                            match case {
                                TailCase::Hidden if labels[k] == Part::Tail.label() => floor_depth,
                                TailCase::Raised => {
                                    // The tail, and the floor a pixel around it, read raised.
                                    let (x, y) = (k % width, k / width);
                                    let near_tail = tail_at(x, y)
                                        || (labels[k] == BACKGROUND_LABEL
                                            && (tail_at(x + 1, y)
                                                || tail_at(x, y + 1)
                                                || x.checked_sub(1).is_some_and(|x| tail_at(x, y))
                                                || y.checked_sub(1).is_some_and(|y| tail_at(x, y))));
                                    if near_tail {
                                        d.min((f - RAISED_TAIL_MM).round().clamp(0.0, 65535.0) as u16)
                                    } else {
                                        d
                                    }
                                }
                                _ => d,
                            }
                        })
                        .collect();
                    let Some(image) = segmented_image(&mut segmenter, &depth, s.top.region)? else {
                        continue;
                    };
                    let mut tail = find_tail_in(&image, rig.depth.intrinsics.fx)
                        .map(|(t, _)| t.pixels)
                        .unwrap_or_default();
                    tail.sort_unstable();
                    let r = image.region;
                    for coarse in [false, true] {
                        let points: Vec<Point3<f64>> = image
                            .on_mouse()
                            .filter(|(k, _)| tail.binary_search(k).is_err())
                            .filter_map(|(k, d)| {
                                let (x, y) = (
                                    r.x0 as usize + k % r.width as usize,
                                    r.y0 as usize + k / r.width as usize,
                                );
                                if coarse && (x % 2 == 1 || y % 2 == 1) {
                                    return None;
                                }
                                let noise = if coarse {
                                    let n: f64 = StandardNormal.sample(&mut rng);
                                    COARSE_NOISE_MM * n
                                } else {
                                    0.0
                                };
                                let pixel = Point2::new(x as f64, y as f64);
                                Some(
                                    rig.depth.world_from_camera
                                        * rig.depth.intrinsics.unproject(&pixel, f64::from(d) + noise),
                                )
                            })
                            .collect();
                        if let Some(a) = aligned(&points) {
                            out.push(View {
                                features: a.features,
                                head_plus: a.axis.dot(&heading) > 0.0,
                                tail_hidden: case == TailCase::Hidden,
                                coarse,
                            });
                        }
                    }
                }
            }
            Ok(out)
        })
        .collect();
    let mut out = Vec::with_capacity(samples.len() * 6);
    for chunk in chunks {
        out.extend(chunk?);
    }
    Ok(out)
}
