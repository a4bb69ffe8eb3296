//! Masks drawn by hand as PNG images (a region of interest: the arena): any PNG (grey, grey
//! with alpha, RGB, RGBA, palette; 1 to 16 bits), one pixel per depth pixel; a pixel is inside
//! when any of its colour channels is not black (alpha is ignored).

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Why a mask cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum MaskError {
    #[error("cannot open the mask {path:?}")]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("the mask {path:?} is not a readable PNG image")]
    Decode {
        path: PathBuf,
        #[source]
        source: png::DecodingError,
    },
    #[error("the mask {path:?} is {width}x{height} pixels but the depth frames are {expected_width}x{expected_height}")]
    Size {
        path: PathBuf,
        width: u32,
        height: u32,
        expected_width: u32,
        expected_height: u32,
    },
    #[error("the mask {path:?} is black everywhere: nothing is inside it")]
    Empty { path: PathBuf },
}

/// Reads the mask at `path` for `width` x `height` frames: 1 inside, 0 outside, row-major.
///
/// # Errors
/// The file cannot be read or decoded, is of another size, or has nothing inside.
pub fn read_mask_png(path: &Path, width: u32, height: u32) -> Result<Vec<u8>, MaskError> {
    let file = File::open(path).map_err(|source| MaskError::Open {
        path: path.to_owned(),
        source,
    })?;
    let decode = |source| MaskError::Decode {
        path: path.to_owned(),
        source,
    };
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(decode)?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).map_err(decode)?;
    if (info.width, info.height) != (width, height) {
        return Err(MaskError::Size {
            path: path.to_owned(),
            width: info.width,
            height: info.height,
            expected_width: width,
            expected_height: height,
        });
    }
    let (channels, colours) = match info.color_type {
        png::ColorType::Grayscale => (1, 1),
        png::ColorType::GrayscaleAlpha => (2, 1),
        png::ColorType::Rgb => (3, 3),
        png::ColorType::Rgba => (4, 3),
        // EXPAND turns palettes into RGB(A).
        png::ColorType::Indexed => (3, 3),
    };
    let mask: Vec<u8> = buf
        .get(..info.buffer_size())
        .unwrap_or_default()
        .chunks_exact(channels)
        .map(|px| u8::from(px.iter().take(colours).any(|&v| v != 0)))
        .collect();
    if !mask.contains(&1) {
        return Err(MaskError::Empty { path: path.to_owned() });
    }
    Ok(mask)
}
