//! The chessboard: its size and squares, the physical position of each inner corner, corner
//! detection with sub-pixel refinement, and the ordering of detected corners into physical
//! corners, so that a camera above and a camera below the board agree on which corner is which.
//!
//! Board frame: origin at the board's centre, x along the rows of inner corners (`cols` of them),
//! y along the columns (`rows` of them), z out of the printed side. Square `(a, b)` (`a` in
//! `0..=cols`, `b` in `0..=rows`) is dark when `a + b` is even, so the square beyond inner
//! corner `(0, 0)` is dark. With one of `cols`, `rows` odd and the other even, the four outer
//! squares beyond the corner corners are dark, light, light, dark in a way a half turn swaps,
//! which is what fixes the board's orientation in an image.

use crate::core::image::RgbImage;
use nalgebra::{Point2, Point3};
use std::fmt;
use std::path::{Path, PathBuf};

/// Errors about boards and the images they are looked for in.
#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    #[error("board size {0:?} is not COLSxROWS inner corners (e.g. 9x6), each from 2 to 64")]
    BadSize(String),
    #[error("square size {0} mm is not a positive length")]
    BadSquare(f64),
    #[error("board {0} has as many rows as columns; its orientation cannot be told")]
    Square(Board),
    #[error("board {0} needs one odd and one even side to tell its orientation (e.g. 9x6)")]
    Symmetric(Board),
    #[error("cannot read image {0:?}")]
    Unreadable(PathBuf),
    #[error("no {board} board found in {image:?}")]
    NotFound { image: PathBuf, board: Board },
    #[error("cannot tell which way the board lies in {0:?} (its outer squares are not visible)")]
    Orientation(PathBuf),
    #[error("OpenCV failed on {image:?}")]
    OpenCv {
        image: PathBuf,
        #[source]
        source: super::CvError,
    },
}

/// A chessboard: inner corners per row (`cols`) and per column (`rows`), and the square size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Board {
    pub cols: u32,
    pub rows: u32,
    pub square_mm: f64,
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.cols, self.rows)
    }
}

/// Which side of the board a camera sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The printed side (the board's +z side): the camera above a board lying on the glass.
    Front,
    /// Through the transparent film from behind, the pattern mirrored: the camera below the glass.
    Back,
}

impl Board {
    /// A board from `COLSxROWS` (inner corners) and the square size.
    ///
    /// # Errors
    /// A malformed size, a side outside 2-64, or a square size that is not positive.
    pub fn parse(size: &str, square_mm: f64) -> Result<Self, BoardError> {
        let bad = || BoardError::BadSize(size.to_owned());
        let (c, r) = size.trim().split_once(['x', 'X']).ok_or_else(bad)?;
        let cols: u32 = c.trim().parse().map_err(|_| bad())?;
        let rows: u32 = r.trim().parse().map_err(|_| bad())?;
        if !(2..=64).contains(&cols) || !(2..=64).contains(&rows) {
            return Err(bad());
        }
        if !(square_mm.is_finite() && square_mm > 0.0) {
            return Err(BoardError::BadSquare(square_mm));
        }
        Ok(Self { cols, rows, square_mm })
    }

    /// `COLSxROWS`.
    pub fn size_name(&self) -> String {
        self.to_string()
    }

    /// Inner corners in all.
    pub fn corner_count(&self) -> usize {
        (self.cols * self.rows) as usize
    }

    /// Checks that the board's orientation can be told from an image (extrinsics need it).
    ///
    /// # Errors
    /// [`BoardError::Square`] or [`BoardError::Symmetric`].
    pub fn check_orientable(&self) -> Result<(), BoardError> {
        if self.cols == self.rows {
            return Err(BoardError::Square(*self));
        }
        if (self.cols + self.rows) % 2 == 0 {
            return Err(BoardError::Symmetric(*self));
        }
        Ok(())
    }

    /// Inner corner `(i, j)` in the board frame, millimetres.
    pub fn corner_mm(&self, i: u32, j: u32) -> Point3<f64> {
        let s = self.square_mm;
        Point3::new(
            (f64::from(i) - f64::from(self.cols - 1) / 2.0) * s,
            (f64::from(j) - f64::from(self.rows - 1) / 2.0) * s,
            0.0,
        )
    }

    /// All inner corners in the board frame, row by row (`j` outer, `i` inner): the order of
    /// [`Board::physical_order`].
    pub fn object_points(&self) -> Vec<Point3<f64>> {
        (0..self.rows)
            .flat_map(|j| (0..self.cols).map(move |i| (i, j)))
            .map(|(i, j)| self.corner_mm(i, j))
            .collect()
    }

    /// The checkered area's size, millimetres: `(cols + 1, rows + 1)` squares.
    pub fn extent_mm(&self) -> (f64, f64) {
        (
            f64::from(self.cols + 1) * self.square_mm,
            f64::from(self.rows + 1) * self.square_mm,
        )
    }

    /// Whether the board point `(x, y)` (mm, board frame) is on the checkered area, and if so
    /// whether on a dark square.
    pub fn shade_at(&self, x: f64, y: f64) -> Option<bool> {
        let a = (x / self.square_mm + f64::from(self.cols + 1) / 2.0).floor();
        let b = (y / self.square_mm + f64::from(self.rows + 1) / 2.0).floor();
        if a < 0.0 || b < 0.0 || a > f64::from(self.cols) || b > f64::from(self.rows) {
            return None;
        }
        Some((a as i64 + b as i64) % 2 == 0)
    }

    /// Finds the inner corners in a grey image, refined to sub-pixel precision, in OpenCV's
    /// detection order (rows of `cols` corners); `None` when no board of this size is found.
    ///
    /// # Errors
    /// OpenCV fails (not: no board found).
    pub fn find_corners(&self, grey: &GreyPicture, image: &Path) -> Result<Option<Vec<Point2<f64>>>, BoardError> {
        let cv = |source: opencv_calib::Error| BoardError::OpenCv {
            image: image.to_owned(),
            source: source.into(),
        };
        let flags = opencv_calib::CALIB_CB_ADAPTIVE_THRESH
            | opencv_calib::CALIB_CB_NORMALIZE_IMAGE
            | opencv_calib::CALIB_CB_FAST_CHECK;
        let found = opencv_calib::find_chessboard_corners(grey.view(), self.cols, self.rows, flags).map_err(cv)?;
        let Some(mut corners) = found.filter(|c| c.len() == self.corner_count()) else {
            return Ok(None);
        };
        // The refinement window: under half the smallest spacing between neighbours.
        let mut spacing = f32::INFINITY;
        for (k, p) in corners.iter().enumerate() {
            if (k + 1) % self.cols as usize != 0 {
                spacing = spacing.min(dist(*p, corners[k + 1]));
            }
            if k + (self.cols as usize) < corners.len() {
                spacing = spacing.min(dist(*p, corners[k + self.cols as usize]));
            }
        }
        let half = ((spacing * 0.4).floor() as i32).clamp(2, 11);
        let criteria = opencv_calib::TermCriteria {
            kind: opencv_calib::TERM_EPS | opencv_calib::TERM_COUNT,
            max_count: 60,
            epsilon: 1e-4,
        };
        opencv_calib::corner_sub_pix(grey.view(), &mut corners, (half, half), (-1, -1), criteria).map_err(cv)?;
        Ok(Some(
            corners
                .iter()
                .map(|p| Point2::new(f64::from(p[0]), f64::from(p[1])))
                .collect(),
        ))
    }

    /// Reorders detected corners (rows of `cols`, as [`Board::find_corners`] returns them)
    /// into physical order (as [`Board::object_points`]), given the side of the board the
    /// camera sees: the handedness of the detected grid in the image picks the mirror, and
    /// the shade of the outer squares picks between a board and its half turn.
    ///
    /// # Errors
    /// [`BoardError::Orientation`] when no outer square can be sampled, or the board cannot be
    /// oriented (see [`Board::check_orientable`]).
    pub fn physical_order(
        &self,
        detected: &[Point2<f64>],
        grey: &GreyPicture,
        side: Side,
        image: &Path,
    ) -> Result<Vec<Point2<f64>>, BoardError> {
        self.check_orientable()?;
        let (cols, rows) = (self.cols as usize, self.rows as usize);
        if detected.len() != cols * rows {
            return Err(BoardError::NotFound {
                image: image.to_owned(),
                board: *self,
            });
        }
        let at = |c: usize, r: usize| detected[r * cols + c];
        let v_c = at(cols - 1, 0) - at(0, 0);
        let v_r = at(0, rows - 1) - at(0, 0);
        // Shade of the outer square beyond each detected corner corner (lower is darker).
        let mut shades = Vec::new();
        for (c, r, ci, ri) in [
            (0, 0, 1, 1),
            (cols - 1, 0, cols - 2, 1),
            (0, rows - 1, 1, rows - 2),
            (cols - 1, rows - 1, cols - 2, rows - 2),
        ] {
            let p = at(c, r);
            let q = at(ci, ri);
            let centre = p + (p - q) * 0.5;
            let radius = ((p - q).norm() * 0.18).max(1.0);
            shades.push(mean_around(grey, centre, radius));
        }
        let mut best: Option<(f64, bool, bool)> = None;
        for flip_x in [false, true] {
            for flip_y in [false, true] {
                let dir_i = if flip_x { -v_c } else { v_c };
                let dir_j = if flip_y { -v_r } else { v_r };
                let cross = dir_i.x * dir_j.y - dir_i.y * dir_j.x;
                let wanted = match side {
                    Side::Front => cross < 0.0,
                    Side::Back => cross > 0.0,
                };
                if !wanted {
                    continue;
                }
                // Predicted darkness of the outer square beyond each detected corner corner.
                let mut score = 0.0;
                let mut samples = 0;
                for (k, (c, r)) in [(0, 0), (cols - 1, 0), (0, rows - 1), (cols - 1, rows - 1)]
                    .into_iter()
                    .enumerate()
                {
                    let Some(shade) = shades[k] else { continue };
                    let i = if flip_x { cols - 1 - c } else { c };
                    let j = if flip_y { rows - 1 - r } else { r };
                    let a = if i == 0 { 0 } else { cols };
                    let b = if j == 0 { 0 } else { rows };
                    let dark = (a + b) % 2 == 0;
                    score += if dark { shade } else { -shade };
                    samples += 1;
                }
                if samples == 0 {
                    return Err(BoardError::Orientation(image.to_owned()));
                }
                if best.is_none_or(|(s, _, _)| score < s) {
                    best = Some((score, flip_x, flip_y));
                }
            }
        }
        let (_, flip_x, flip_y) = best.ok_or_else(|| BoardError::Orientation(image.to_owned()))?;
        let mut out = Vec::with_capacity(detected.len());
        for j in 0..rows {
            for i in 0..cols {
                let c = if flip_x { cols - 1 - i } else { i };
                let r = if flip_y { rows - 1 - j } else { j };
                out.push(at(c, r));
            }
        }
        Ok(out)
    }
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Mean grey level in a disc; `None` when the disc is not wholly inside the image.
fn mean_around(grey: &GreyPicture, centre: Point2<f64>, radius: f64) -> Option<f64> {
    let (w, h) = (f64::from(grey.width), f64::from(grey.height));
    if centre.x - radius < 0.0 || centre.y - radius < 0.0 || centre.x + radius >= w || centre.y + radius >= h {
        return None;
    }
    let (mut sum, mut n) = (0.0, 0u32);
    let r = radius.ceil() as i32;
    let (cx, cy) = (centre.x.round() as i32, centre.y.round() as i32);
    for dy in -r..=r {
        for dx in -r..=r {
            if f64::from(dx * dx + dy * dy) > radius * radius {
                continue;
            }
            if let Some(v) = grey.pixel(cx + dx, cy + dy) {
                sum += f64::from(v);
                n += 1;
            }
        }
    }
    (n > 0).then(|| sum / f64::from(n))
}

/// An 8-bit grey picture, row-major: what boards are found in.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GreyPicture {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
}

impl GreyPicture {
    /// A picture of `width * height` row-major pixels; `None` when the buffer holds another
    /// number, or the picture is empty or wider or taller than OpenCV's `int`.
    pub fn new(width: u32, height: u32, pixels: Vec<u8>) -> Option<Self> {
        let fits = |n: u32| n > 0 && i32::try_from(n).is_ok();
        let count = (width as usize).checked_mul(height as usize);
        (fits(width) && fits(height) && count == Some(pixels.len())).then_some(Self { width, height, pixels })
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pixels, row-major.
    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }

    /// The pixel at column `x`, row `y`; `None` outside the picture.
    pub fn pixel(&self, x: i32, y: i32) -> Option<u8> {
        let x = u32::try_from(x).ok().filter(|&x| x < self.width)?;
        let y = u32::try_from(y).ok().filter(|&y| y < self.height)?;
        Some(self.pixels[y as usize * self.width as usize + x as usize])
    }

    /// The picture as OpenCV's calls take it.
    pub(crate) fn view(&self) -> opencv_calib::Grey<'_> {
        opencv_calib::Grey {
            pixels: &self.pixels,
            width: self.width,
            height: self.height,
        }
    }
}

/// Reads an image file as 8-bit grey ([`RgbImage::read`]'s formats).
///
/// # Errors
/// [`BoardError::Unreadable`] when the file cannot be read or decoded.
pub fn read_grey(path: &Path) -> Result<GreyPicture, BoardError> {
    let unreadable = || BoardError::Unreadable(path.to_owned());
    let picture = RgbImage::read(path).map_err(|_| unreadable())?;
    GreyPicture::new(picture.width, picture.height, picture.grey()).ok_or_else(unreadable)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes_and_refuses_nonsense() {
        let b = Board::parse("9x6", 20.0).expect("9x6");
        assert_eq!((b.cols, b.rows, b.corner_count()), (9, 6, 54));
        assert!(Board::parse("9by6", 20.0).is_err());
        assert!(Board::parse("1x6", 20.0).is_err());
        assert!(Board::parse("9x6", 0.0).is_err());
        assert!(Board::parse("8x6", 20.0).expect("parses").check_orientable().is_err());
        assert!(b.check_orientable().is_ok());
    }

    #[test]
    fn squares_and_corners_agree() {
        let b = Board::parse("9x6", 20.0).expect("9x6");
        // The square beyond corner (0, 0) is dark, beyond (8, 0) light, beyond (8, 5) light.
        let c = b.corner_mm(0, 0);
        assert_eq!(b.shade_at(c.x - 5.0, c.y - 5.0), Some(true));
        let c = b.corner_mm(8, 0);
        assert_eq!(b.shade_at(c.x + 5.0, c.y - 5.0), Some(false));
        let c = b.corner_mm(8, 5);
        assert_eq!(b.shade_at(c.x + 5.0, c.y + 5.0), Some(false));
        assert_eq!(b.shade_at(0.0, 200.0), None);
        let pts = b.object_points();
        assert_eq!(pts.len(), 54);
        assert!((pts[0].x + 80.0).abs() < 1e-9 && (pts[0].y + 50.0).abs() < 1e-9);
    }
}
