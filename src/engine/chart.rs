//! Small charts for reports (bar, line, confusion matrix) drawn into [`RgbImage`]s, their text
//! in the pictures' built-in 5x7 pixel font ([`crate::core::draw::draw_text`]).

pub use crate::core::draw::{draw_text, text_width};
use crate::core::image::RgbImage;

/// A data series: name, colour, values.
pub type Series<'a> = (&'a str, [u8; 3], &'a [f64]);

const W: u32 = 900;
const H: u32 = 520;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 50.0;
const BOTTOM: f64 = 110.0;
const INK: [u8; 3] = [30, 30, 30];
const GRID: [u8; 3] = [225, 225, 225];

fn nice_max(v: f64) -> f64 {
    if v.is_nan() || v <= 0.0 || !v.is_finite() {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    for m in [1.0, 2.0, 2.5, 5.0, 10.0] {
        if v <= m * p {
            return m * p;
        }
    }
    10.0 * p
}

fn frame(title: &str, y_label: &str, y_lo: f64, y_hi: f64) -> RgbImage {
    let mut img = RgbImage::new(W, H, [255, 255, 255]);
    draw_text(&mut img, LEFT as i64, 15, title, INK, 2);
    let plot_h = f64::from(H) - TOP - BOTTOM;
    for k in 0..=5 {
        let v = y_lo + (y_hi - y_lo) * f64::from(k) / 5.0;
        let y = TOP + plot_h * (1.0 - f64::from(k) / 5.0);
        img.line((LEFT, y), (f64::from(W) - RIGHT, y), GRID, 1.0);
        let label = format_number(v);
        draw_text(
            &mut img,
            LEFT as i64 - 8 - i64::from(text_width(&label, 1)),
            y as i64 - 3,
            &label,
            INK,
            1,
        );
    }
    img.line((LEFT, TOP), (LEFT, TOP + plot_h), INK, 1.0);
    img.line((LEFT, TOP + plot_h), (f64::from(W) - RIGHT, TOP + plot_h), INK, 1.0);
    draw_text(&mut img, 8, TOP as i64 - 20, y_label, INK, 1);
    img
}

fn format_number(v: f64) -> String {
    if v.abs() >= 100.0 || v == v.round() {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

/// Six labels along the x axis from `x_lo` over `span`, placed by `px`, and the axis's name
/// under them; `(left, plot_w, plot_h)` is the plot area.
fn x_axis(
    img: &mut RgbImage,
    (x_lo, span): (f64, f64),
    px: impl Fn(f64) -> f64,
    (left, plot_w, plot_h): (f64, f64, f64),
    x_label: &str,
) {
    for k in 0..=5 {
        let v = x_lo + span * f64::from(k) / 5.0;
        let label = format_number(v);
        let x = px(v) as i64 - i64::from(text_width(&label, 1)) / 2;
        draw_text(img, x, (TOP + plot_h) as i64 + 8, &label, INK, 1);
    }
    draw_text(
        img,
        (left + plot_w / 2.0) as i64,
        (TOP + plot_h) as i64 + 28,
        x_label,
        INK,
        1,
    );
}

fn legend(img: &mut RgbImage, series: &[Series<'_>]) {
    let mut x = LEFT as i64 + 10;
    let y = i64::from(H) - 22;
    for (name, colour, _) in series {
        for dy in 0..8 {
            for dx in 0..14 {
                img.put(x + dx, y + dy, *colour);
            }
        }
        draw_text(img, x + 20, y, name, INK, 1);
        x += 40 + i64::from(text_width(name, 1));
    }
}

/// Grouped bars: one group per category, one bar per series.
pub fn bar_chart(title: &str, y_label: &str, categories: &[String], series: &[Series<'_>]) -> RgbImage {
    let hi = nice_max(series.iter().flat_map(|s| s.2.iter().copied()).fold(0.0, f64::max));
    let mut img = frame(title, y_label, 0.0, hi);
    let plot_w = f64::from(W) - LEFT - RIGHT;
    let plot_h = f64::from(H) - TOP - BOTTOM;
    let group = plot_w / categories.len().max(1) as f64;
    let bar = group * 0.8 / series.len().max(1) as f64;
    for (c, name) in categories.iter().enumerate() {
        let x0 = LEFT + group * c as f64 + group * 0.1;
        for (k, (_, colour, values)) in series.iter().enumerate() {
            let v = values.get(c).copied().unwrap_or(0.0).max(0.0);
            let h = plot_h * (v / hi).min(1.0);
            let bx = x0 + bar * k as f64;
            for y in (TOP + plot_h - h) as i64..(TOP + plot_h) as i64 {
                for x in bx as i64..(bx + bar - 1.0) as i64 {
                    img.put(x, y, *colour);
                }
            }
        }
        // Category names, written downwards one above the other when long.
        let label: String = name.chars().take(14).collect();
        let lx = (x0 + group * 0.4) as i64 - i64::from(text_width(&label, 1)) / 2;
        draw_text(
            &mut img,
            lx,
            (TOP + plot_h) as i64 + 8 + (c as i64 % 2) * 12,
            &label,
            INK,
            1,
        );
    }
    legend(&mut img, series);
    img
}

/// Lines over a shared x axis.
pub fn line_chart(title: &str, x_label: &str, y_label: &str, x: &[f64], series: &[Series<'_>]) -> RgbImage {
    let all = || {
        series
            .iter()
            .flat_map(|s| s.2.iter().copied())
            .filter(|v| v.is_finite())
    };
    let (mut lo, mut hi) = (
        all().fold(f64::INFINITY, f64::min),
        all().fold(f64::NEG_INFINITY, f64::max),
    );
    if lo.is_nan() || hi.is_nan() || lo >= hi {
        lo -= 0.5;
        hi += 0.5;
    }
    let pad = (hi - lo) * 0.1;
    let (lo, hi) = (lo - pad, hi + pad);
    let mut img = frame(title, y_label, lo, hi);
    let plot_w = f64::from(W) - LEFT - RIGHT;
    let plot_h = f64::from(H) - TOP - BOTTOM;
    let (x_lo, x_hi) = (
        x.iter().copied().fold(f64::INFINITY, f64::min),
        x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    let span = if x_hi > x_lo { x_hi - x_lo } else { 1.0 };
    let px = |v: f64| LEFT + plot_w * (v - x_lo) / span;
    let py = |v: f64| TOP + plot_h * (1.0 - (v - lo) / (hi - lo));
    for &v in x {
        let label = format_number(v);
        draw_text(
            &mut img,
            px(v) as i64 - i64::from(text_width(&label, 1)) / 2,
            (TOP + plot_h) as i64 + 8,
            &label,
            INK,
            1,
        );
    }
    draw_text(
        &mut img,
        (LEFT + plot_w / 2.0) as i64,
        (TOP + plot_h) as i64 + 28,
        x_label,
        INK,
        1,
    );
    for (_, colour, values) in series {
        let pts: Vec<(f64, f64)> = x
            .iter()
            .zip(values.iter())
            .filter(|(_, v)| v.is_finite())
            .map(|(&a, &b)| (px(a), py(b)))
            .collect();
        for w in pts.windows(2) {
            img.line(w[0], w[1], *colour, 2.0);
        }
        for p in &pts {
            img.disc(*p, 3.5, *colour);
        }
    }
    legend(&mut img, series);
    img
}

/// A confusion matrix as a heat map, rows normalised to 1, with each cell's percentage.
pub fn confusion_chart(title: &str, labels: &[String], counts: &[Vec<u64>]) -> RgbImage {
    let n = labels.len().max(1);
    let cell = 70u32;
    let left = 130u32;
    let top = 60u32;
    let mut img = RgbImage::new(left + cell * n as u32 + 20, top + cell * n as u32 + 40, [255, 255, 255]);
    draw_text(&mut img, 10, 15, title, INK, 2);
    for (r, row) in counts.iter().enumerate() {
        let total = row.iter().sum::<u64>().max(1) as f64;
        for (c, &v) in row.iter().enumerate() {
            let f = v as f64 / total;
            let shade = (255.0 * (1.0 - f)) as u8;
            let colour = [shade, shade, 255];
            let (x0, y0) = (left + c as u32 * cell, top + r as u32 * cell);
            for y in y0..y0 + cell - 2 {
                for x in x0..x0 + cell - 2 {
                    img.put(i64::from(x), i64::from(y), colour);
                }
            }
            let text = format!("{:.1}", 100.0 * f);
            let ink = if f > 0.5 { [255, 255, 255] } else { INK };
            draw_text(&mut img, i64::from(x0) + 12, i64::from(y0) + 30, &text, ink, 1);
        }
        draw_text(&mut img, 8, i64::from(top + r as u32 * cell) + 30, &labels[r], INK, 1);
    }
    for (c, l) in labels.iter().enumerate() {
        let short: String = l.chars().take(11).collect();
        draw_text(
            &mut img,
            i64::from(left + c as u32 * cell) + 2,
            i64::from(top + cell * n as u32) + 10,
            &short,
            INK,
            1,
        );
    }
    img
}

/// Lines over a long shared x axis (a time series): six evenly spaced x ticks instead of one
/// per value, and a dashed horizontal line at each of `marks` (a threshold).
pub fn series_chart(
    title: &str,
    x_label: &str,
    y_label: &str,
    x: &[f64],
    series: &[Series<'_>],
    marks: &[f64],
) -> RgbImage {
    let all = || {
        series
            .iter()
            .flat_map(|s| s.2.iter().copied())
            .chain(marks.iter().copied())
            .filter(|v| v.is_finite())
    };
    let lo = all().fold(f64::INFINITY, f64::min).min(0.0);
    let hi = nice_max(all().fold(f64::NEG_INFINITY, f64::max));
    let (lo, hi) = if lo.is_finite() && hi > lo {
        (lo, hi)
    } else {
        (0.0, 1.0)
    };
    let mut img = frame(title, y_label, lo, hi);
    let plot_w = f64::from(W) - LEFT - RIGHT;
    let plot_h = f64::from(H) - TOP - BOTTOM;
    let finite = || x.iter().copied().filter(|v| v.is_finite());
    let (x_lo, x_hi) = (
        finite().fold(f64::INFINITY, f64::min),
        finite().fold(f64::NEG_INFINITY, f64::max),
    );
    let (x_lo, span) = if x_hi > x_lo { (x_lo, x_hi - x_lo) } else { (0.0, 1.0) };
    let px = |v: f64| LEFT + plot_w * (v - x_lo) / span;
    let py = |v: f64| TOP + plot_h * (1.0 - (v - lo) / (hi - lo));
    x_axis(&mut img, (x_lo, span), px, (LEFT, plot_w, plot_h), x_label);
    for &m in marks {
        let y = py(m);
        let mut x0 = LEFT;
        while x0 < LEFT + plot_w {
            img.line((x0, y), ((x0 + 6.0).min(LEFT + plot_w), y), [200, 60, 60], 1.0);
            x0 += 12.0;
        }
    }
    for (_, colour, values) in series {
        // Gaps (non-finite values) break the line.
        let mut last: Option<(f64, f64)> = None;
        for (&a, &b) in x.iter().zip(values.iter()) {
            if !(a.is_finite() && b.is_finite()) {
                last = None;
                continue;
            }
            let p = (px(a), py(b));
            if let Some(q) = last {
                img.line(q, p, *colour, 1.5);
            }
            last = Some(p);
        }
    }
    legend(&mut img, series);
    img
}

/// A path in a rectangle (the cage seen from above, `extent` its half sizes in mm, centred on
/// the origin), coloured from blue (start) to red (end), with the centre zone outlined.
/// An arena's own outline on a path chart: its corners and its centre, about the chart's
/// middle (mm).
#[derive(Clone, Copy, Debug)]
pub struct ChartOutline<'a> {
    pub corners: &'a [(f64, f64)],
    pub centre: (f64, f64),
}

/// `outline`, when given, is drawn with its centre zone (the outline at half its size about
/// its centre) instead of the rectangle's.
pub fn path_chart(
    title: &str,
    points: &[Option<(f64, f64)>],
    extent: (f64, f64),
    outline: Option<ChartOutline<'_>>,
) -> RgbImage {
    let (hx, hy) = extent;
    let scale = ((f64::from(W) - LEFT - RIGHT) / (2.0 * hx)).min((f64::from(H) - TOP - 30.0) / (2.0 * hy));
    let (w, h) = (2.0 * hx * scale, 2.0 * hy * scale);
    let mut img = RgbImage::new(W, H, [255, 255, 255]);
    draw_text(&mut img, LEFT as i64, 15, title, INK, 2);
    let (x0, y0) = ((f64::from(W) - w) / 2.0, TOP);
    // y up in the cage, down in the picture.
    let to_px = |(x, y): (f64, f64)| (x0 + (x + hx) * scale, y0 + (hy - y) * scale);
    match outline {
        Some(ChartOutline {
            corners,
            centre: (cx, cy),
        }) if corners.len() > 2 => {
            for (k, &a) in corners.iter().enumerate() {
                let b = corners[(k + 1) % corners.len()];
                img.line(to_px(a), to_px(b), INK, 2.0);
                let half = |p: (f64, f64)| (cx + (p.0 - cx) / 2.0, cy + (p.1 - cy) / 2.0);
                img.line(to_px(half(a)), to_px(half(b)), GRID, 1.0);
            }
        }
        _ => {
            img.rect((x0, y0), (x0 + w, y0 + h), INK, 2.0);
            img.rect(to_px((-hx / 2.0, hy / 2.0)), to_px((hx / 2.0, -hy / 2.0)), GRID, 1.0);
        }
    }
    let n = points.len().max(2) as f64;
    let mut last: Option<(f64, f64)> = None;
    for (i, p) in points.iter().enumerate() {
        let Some(p) = p else {
            last = None;
            continue;
        };
        let f = i as f64 / (n - 1.0);
        let colour = [(255.0 * f) as u8, 60, (255.0 * (1.0 - f)) as u8];
        let q = to_px(*p);
        if let Some(l) = last {
            img.line(l, q, colour, 1.5);
        }
        last = Some(q);
    }
    let label = format!("{:.0} x {:.0} mm", 2.0 * hx, 2.0 * hy);
    draw_text(&mut img, x0 as i64, (y0 + h) as i64 + 10, &label, INK, 1);
    img
}

/// Horizontal bars over time, one row per name: where each row's flags are set (a gait
/// diagram: stance of each paw over time).
pub fn raster_chart(title: &str, x_label: &str, x: &[f64], rows: &[(&str, Vec<bool>)]) -> RgbImage {
    let mut img = RgbImage::new(W, H, [255, 255, 255]);
    draw_text(&mut img, LEFT as i64, 15, title, INK, 2);
    let left = 130.0;
    let plot_w = f64::from(W) - left - RIGHT;
    let plot_h = f64::from(H) - TOP - BOTTOM;
    let row_h = plot_h / rows.len().max(1) as f64;
    let (x_lo, x_hi) = (
        x.iter().copied().fold(f64::INFINITY, f64::min),
        x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    let (x_lo, span) = if x_hi > x_lo { (x_lo, x_hi - x_lo) } else { (0.0, 1.0) };
    let step = if x.len() > 1 { span / (x.len() - 1) as f64 } else { 1.0 };
    let px = |v: f64| left + plot_w * (v - x_lo) / (span + step);
    for (r, (name, flags)) in rows.iter().enumerate() {
        let y = TOP + row_h * r as f64;
        draw_text(&mut img, 8, (y + row_h / 2.0) as i64 - 3, name, INK, 1);
        for (&v, &on) in x.iter().zip(flags) {
            if on {
                for yy in (y + 2.0) as i64..(y + row_h - 2.0) as i64 {
                    for xx in px(v) as i64..px(v + step).ceil() as i64 {
                        img.put(xx, yy, [40, 90, 200]);
                    }
                }
            }
        }
    }
    x_axis(&mut img, (x_lo, span), px, (left, plot_w, plot_h), x_label);
    img
}
