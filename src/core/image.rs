//! Small RGB images for previews, overlays and reports: PNG output, a depth colour map,
//! lines, boxes and discs, side-by-side panels; pictures read. Skeletons and text are drawn by
//! [`crate::core::draw`].

use super::geometry::Intrinsics;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// An 8-bit RGB image.
#[derive(Clone, PartialEq, Eq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl std::fmt::Debug for RgbImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RgbImage({}x{})", self.width, self.height)
    }
}

/// Errors reading or writing an image.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("cannot create {path:?}")]
    Create {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot encode PNG {path:?}")]
    Encode {
        path: std::path::PathBuf,
        #[source]
        source: png::EncodingError,
    },
    #[error("{path:?} is not a picture that can be read (PNG, JPEG, BMP or TIFF)")]
    Unreadable {
        path: std::path::PathBuf,
        #[source]
        source: image::ImageError,
    },
}

impl RgbImage {
    /// An image filled with one colour.
    pub fn new(width: u32, height: u32, fill: [u8; 3]) -> Self {
        let data = fill.repeat(width as usize * height as usize);
        Self { width, height, data }
    }

    pub fn get(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        Some([self.data[i], self.data[i + 1], self.data[i + 2]])
    }

    /// Sets a pixel; coordinates outside the image are ignored.
    pub fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        self.data[i..i + 3].copy_from_slice(&c);
    }

    /// A straight line of the given thickness.
    pub fn line(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: [u8; 3], thickness: f64) {
        let len = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
        let steps = (len * 2.0).ceil().max(1.0) as usize;
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            self.disc((x0 + (x1 - x0) * t, y0 + (y1 - y0) * t), thickness / 2.0, c);
        }
    }

    /// A filled disc.
    pub fn disc(&mut self, (cx, cy): (f64, f64), r: f64, c: [u8; 3]) {
        let r = r.max(0.5);
        let (x0, x1) = ((cx - r).floor() as i64, (cx + r).ceil() as i64);
        let (y0, y1) = ((cy - r).floor() as i64, (cy + r).ceil() as i64);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                if dx * dx + dy * dy <= r * r {
                    self.put(x, y, c);
                }
            }
        }
    }

    /// The outline of a rectangle.
    pub fn rect(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: [u8; 3], thickness: f64) {
        self.line((x0, y0), (x1, y0), c, thickness);
        self.line((x1, y0), (x1, y1), c, thickness);
        self.line((x1, y1), (x0, y1), c, thickness);
        self.line((x0, y1), (x0, y0), c, thickness);
    }

    /// The sub-image `[x0, x0 + w) x [y0, y0 + h)`, clipped to the image.
    pub fn crop(&self, x0: u32, y0: u32, w: u32, h: u32) -> RgbImage {
        let w = w.min(self.width.saturating_sub(x0));
        let h = h.min(self.height.saturating_sub(y0));
        let mut out = RgbImage::new(w, h, [0; 3]);
        for y in 0..h {
            let src = ((y0 + y) as usize * self.width as usize + x0 as usize) * 3;
            let dst = y as usize * w as usize * 3;
            out.data[dst..dst + w as usize * 3].copy_from_slice(&self.data[src..src + w as usize * 3]);
        }
        out
    }

    /// The image scaled by an integer factor (nearest neighbour).
    pub fn upscale(&self, k: u32) -> RgbImage {
        let k = k.max(1) as usize;
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 {
            return RgbImage::new(0, 0, [0; 3]);
        }
        let mut data = Vec::with_capacity(w * k * h * k * 3);
        for row in self.data.chunks_exact(w * 3).take(h) {
            let start = data.len();
            for px in row.chunks_exact(3) {
                for _ in 0..k {
                    data.extend_from_slice(px);
                }
            }
            for _ in 1..k {
                data.extend_from_within(start..start + w * k * 3);
            }
        }
        RgbImage {
            width: self.width * k as u32,
            height: self.height * k as u32,
            data,
        }
    }

    /// Images side by side, top-aligned, with `gap` pixels of `background` between them.
    pub fn hstack(images: &[RgbImage], gap: u32, background: [u8; 3]) -> RgbImage {
        let width = images.iter().map(|i| i.width).sum::<u32>() + gap * images.len().saturating_sub(1) as u32;
        let height = images.iter().map(|i| i.height).max().unwrap_or(0);
        let mut out = RgbImage::new(width, height, background);
        let mut x0 = 0;
        for img in images {
            for y in 0..img.height {
                let src = y as usize * img.width as usize * 3;
                let dst = (y as usize * width as usize + x0 as usize) * 3;
                out.data[dst..dst + img.width as usize * 3]
                    .copy_from_slice(&img.data[src..src + img.width as usize * 3]);
            }
            x0 += img.width + gap;
        }
        out
    }

    /// Reads a picture file (PNG, JPEG, BMP or TIFF, any channel count or depth) as 8-bit RGB.
    ///
    /// # Errors
    /// When the file cannot be read or is not a picture of those formats.
    pub fn read(path: &Path) -> Result<Self, ImageError> {
        let unreadable = |source| ImageError::Unreadable {
            path: path.to_owned(),
            source,
        };
        let picture = image::ImageReader::open(path)
            .map_err(|e| unreadable(image::ImageError::IoError(e)))?
            .with_guessed_format()
            .map_err(|e| unreadable(image::ImageError::IoError(e)))?
            .decode()
            .map_err(unreadable)?
            .into_rgb8();
        Ok(Self {
            width: picture.width(),
            height: picture.height(),
            data: picture.into_raw(),
        })
    }

    /// The image in 8-bit grey, with OpenCV's weights and rounding (`COLOR_RGB2GRAY`:
    /// 0.299 R + 0.587 G + 0.114 B), so a grey picture stays as it is.
    pub fn grey(&self) -> Vec<u8> {
        self.data
            .chunks_exact(3)
            .map(|p| ((u32::from(p[0]) * 4899 + u32::from(p[1]) * 9617 + u32::from(p[2]) * 1868 + 8192) >> 14) as u8)
            .collect()
    }

    /// Writes the image as a PNG file.
    ///
    /// # Errors
    /// When the file cannot be created or written.
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        let file = File::create(path).map_err(|source| ImageError::Create {
            path: path.to_owned(),
            source,
        })?;
        self.encode_png(BufWriter::new(file), png::Compression::Default)
            .map_err(|source| ImageError::Encode {
                path: path.to_owned(),
                source,
            })
    }

    /// The image as PNG bytes, compressed fast (for pictures served live).
    ///
    /// # Errors
    /// Never in practice: encoding into memory fails only on an image of zero size.
    pub fn to_png(&self) -> Result<Vec<u8>, png::EncodingError> {
        let mut bytes = Vec::new();
        self.encode_png(&mut bytes, png::Compression::Fast)?;
        Ok(bytes)
    }

    fn encode_png(&self, out: impl std::io::Write, compression: png::Compression) -> Result<(), png::EncodingError> {
        let mut encoder = png::Encoder::new(out, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(compression);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&self.data)?;
        writer.finish()
    }
}

/// A perceptual colour map (blue-cyan-yellow-red) for `t` in `[0, 1]`.
pub fn colour_map(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 6] = [
        [48.0, 18.0, 59.0],
        [50.0, 130.0, 230.0],
        [30.0, 210.0, 170.0],
        [170.0, 235.0, 50.0],
        [250.0, 150.0, 30.0],
        [180.0, 20.0, 10.0],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let k = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - k as f64;
    std::array::from_fn(|c| (STOPS[k][c] * (1.0 - f) + STOPS[k + 1][c] * f).round() as u8)
}

/// A depth image (mm, 0 = none) colour-mapped between `near` and `far`, no reading black.
pub fn depth_to_rgb(depth: &[u16], width: u32, height: u32, near: f64, far: f64) -> RgbImage {
    let mut out = RgbImage::new(width, height, [0; 3]);
    for (i, &z) in depth.iter().enumerate().take(width as usize * height as usize) {
        if z > 0 {
            let c = colour_map((far - f64::from(z)) / (far - near));
            out.data[i * 3..i * 3 + 3].copy_from_slice(&c);
        }
    }
    out
}

/// A rectangle of an image, in pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Region {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

impl Region {
    /// The whole image of a camera.
    pub fn full(intrinsics: &Intrinsics) -> Self {
        Self {
            x0: 0,
            y0: 0,
            width: intrinsics.width,
            height: intrinsics.height,
        }
    }

    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// The smallest region holding both.
    pub fn union(&self, other: &Region) -> Region {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        let x0 = self.x0.min(other.x0);
        let y0 = self.y0.min(other.y0);
        let x1 = (self.x0 + self.width).max(other.x0 + other.width);
        let y1 = (self.y0 + self.height).max(other.y0 + other.height);
        Region {
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
        }
    }

    /// The region grown by `margin` pixels on every side, clipped to `width` x `height`.
    pub fn grown(&self, margin: u32, width: u32, height: u32) -> Region {
        let x0 = self.x0.saturating_sub(margin);
        let y0 = self.y0.saturating_sub(margin);
        let x1 = (self.x0 + self.width + margin).min(width);
        let y1 = (self.y0 + self.height + margin).min(height);
        Region {
            x0,
            y0,
            width: x1.saturating_sub(x0),
            height: y1.saturating_sub(y0),
        }
    }

    /// The part of `self` inside `other`.
    pub fn intersect(&self, other: &Region) -> Region {
        let x0 = self.x0.max(other.x0);
        let y0 = self.y0.max(other.y0);
        let x1 = (self.x0 + self.width).min(other.x0 + other.width);
        let y1 = (self.y0 + self.height).min(other.y0 + other.height);
        Region {
            x0,
            y0,
            width: x1.saturating_sub(x0),
            height: y1.saturating_sub(y0),
        }
    }

    /// Whether the pixel `(x, y)` of the full image lies in the region.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && y >= self.y0 && x < self.x0 + self.width && y < self.y0 + self.height
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_picture_written_reads_back_and_a_grey_one_stays_grey() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("picture.png");
        let mut picture = RgbImage::new(5, 3, [0, 0, 0]);
        for (i, p) in picture.data.chunks_exact_mut(3).enumerate() {
            let v = (i * 17) as u8;
            p.copy_from_slice(&[v, v, v]);
        }
        picture.write_png(&path).unwrap_or_else(|e| panic!("{e}"));
        let read = RgbImage::read(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read, picture);
        let grey: Vec<u8> = picture.data.iter().step_by(3).copied().collect();
        assert_eq!(read.grey(), grey);
        // OpenCV's weights: pure red, green and blue.
        let rgb = RgbImage {
            width: 3,
            height: 1,
            data: vec![255, 0, 0, 0, 255, 0, 0, 0, 255],
        };
        assert_eq!(rgb.grey(), vec![76, 150, 29]);
    }

    #[test]
    fn a_file_that_is_no_picture_is_named_in_one_sentence() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("notes.png");
        std::fs::write(&path, "not a picture").unwrap_or_else(|e| panic!("{e}"));
        let message = RgbImage::read(&path).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            message.contains("notes.png") && message.contains("is not a picture"),
            "{message}"
        );
    }
}
