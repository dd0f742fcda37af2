//! Image operations as free functions over a plain image type ([`Image`]): conversion from 8-bit
//! input, Gaussian smoothing of a region, pyramids, and bilinear sampling of values and gradients
//! at sub-pixel points with a [`Border`] policy.
//!
//! Pixel `(i, j)` has its centre at the real coordinates `(i, j)`.

pub mod fft;
mod fields;
mod filter;
pub mod flow;
pub mod hog;
mod integral;
pub mod keypoints;
mod resample;
mod sample;

pub use fields::{FIELDS, descriptor_fields_into};
pub use filter::{
    COARSE_EPS, GaussianKernel, Preprocessor, downsample_half, downsample_half_into,
    downsample_half_rows_into, gaussian_blur, gaussian_blur_into, gaussian_blur_rows_into,
    gaussian_kernel, pad_replicate_into, pyramid,
};
pub use integral::Integral;
pub use resample::{resample_window, resample_window_on};
pub use sample::{
    Border, ImageView, MAX_PLANES, STAMP_LEVELS, new_stamp, sample_grid_shifted, sample_value,
    sample_values, sample_values_gradients,
};

use crate::error::{Error, Result};
use std::path::Path;

/// A single-channel image stored row by row without padding.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

/// An image whose pixels belong to someone else (a frame from numpy, a decoder's buffer): the
/// width, the height and `width * height` pixels row by row.
#[derive(Clone, Copy, Debug)]
pub struct ImageRef<'a, T> {
    pub width: usize,
    pub height: usize,
    pub data: &'a [T],
}

impl<'a, T> ImageRef<'a, T> {
    /// A view of `data` as `width x height` pixels (`None` when the lengths disagree).
    pub fn new(width: usize, height: usize, data: &'a [T]) -> Option<Self> {
        (width.checked_mul(height) == Some(data.len())).then_some(ImageRef {
            width,
            height,
            data,
        })
    }

    /// One row.
    #[inline]
    pub fn row(&self, y: usize) -> &'a [T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }
}

impl<'a, T> From<&'a Image<T>> for ImageRef<'a, T> {
    fn from(i: &'a Image<T>) -> Self {
        ImageRef {
            width: i.width,
            height: i.height,
            data: &i.data,
        }
    }
}

/// 8-bit grayscale image (the live input of a tracker).
pub type GrayU8 = Image<u8>;
/// 32-bit float grayscale image, intensities in 0..255.
pub type GrayF32 = Image<f32>;

impl<T: Copy + Default> Image<T> {
    /// An image filled with the default value.
    pub fn new(width: usize, height: usize) -> Self {
        Image {
            width,
            height,
            data: vec![T::default(); width * height],
        }
    }

    /// Wraps a buffer; `None` if its length is not `width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Image {
            width,
            height,
            data,
        })
    }

    /// The pixel at column `x`, row `y`.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// Sets the pixel at column `x`, row `y`.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, v: T) {
        self.data[y * self.width + x] = v;
    }

    /// One row.
    #[inline]
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Resizes the buffer (keeping its allocation when it is large enough).
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, T::default());
    }
}

/// A pixel type the filters can read.
pub trait Pixel: Copy + Default + Send + Sync + 'static {
    fn to_f32(self) -> f32;
}
impl Pixel for u8 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
}
impl Pixel for f32 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
}

impl GrayU8 {
    /// A `width x height` image of uniform noise over the gray levels, drawn from `rng`.
    pub fn noise(width: usize, height: usize, rng: &mut crate::rng::Rng) -> GrayU8 {
        Image {
            width,
            height,
            data: (0..width * height)
                .map(|_| (rng.uniform() * 255.99) as u8)
                .collect(),
        }
    }

    /// The image as floats (gray levels 0..255).
    pub fn to_f32(&self) -> GrayF32 {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| v as f32).collect(),
        }
    }
}

impl GrayF32 {
    /// A view of the whole image for sampling.
    pub fn view(&self) -> ImageView<'_> {
        ImageView::new(&self.data, self.width, self.height, 0, 0)
    }
}

/// Luma of an sRGB pixel, as 8-bit (ITU-R BT.601 weights, as most trackers use).
#[inline]
pub fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((299 * r as u32 + 587 * g as u32 + 114 * b as u32 + 500) / 1000) as u8
}

/// Grayscale version of a decoded image.
pub fn gray_from_dynamic(img: &image::DynamicImage) -> GrayU8 {
    match img {
        image::DynamicImage::ImageLuma8(g) => Image {
            width: g.width() as usize,
            height: g.height() as usize,
            data: g.as_raw().clone(),
        },
        other => {
            let rgb = other.to_rgb8();
            let data = rgb.pixels().map(|p| luma(p[0], p[1], p[2])).collect();
            Image {
                width: rgb.width() as usize,
                height: rgb.height() as usize,
                data,
            }
        }
    }
}

/// A colour frame: its three channels (red, green, blue) as planes, and its grey image (luma,
/// [`luma`]) for everything that reads grey. A tracker with `channels = rgb` reads the
/// channels; every other reader reads `gray`, the same image [`load_gray`] gives.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColourU8 {
    pub gray: GrayU8,
    pub channels: [GrayU8; 3],
}

impl ColourU8 {
    /// The frame of `width x height` pixels given as interleaved `r, g, b` bytes (`None` when
    /// the length is not `3 width height`).
    pub fn from_rgb(width: usize, height: usize, rgb: &[u8]) -> Option<Self> {
        let gray = Image {
            width,
            height,
            data: rgb
                .chunks_exact(3)
                .map(|p| luma(p[0], p[1], p[2]))
                .collect(),
        };
        Self::from_rgb_and_gray(rgb, gray)
    }

    /// The frame given as interleaved `r, g, b` bytes and its grey image made elsewhere (a
    /// decoder's, whose grey the command line's trackers read); `None` when the lengths
    /// disagree.
    pub fn from_rgb_and_gray(rgb: &[u8], gray: GrayU8) -> Option<Self> {
        let (width, height) = (gray.width, gray.height);
        let n = gray.data.len();
        if n != width.checked_mul(height)? || n.checked_mul(3)? != rgb.len() {
            return None;
        }
        let plane = |c: usize| Image {
            width,
            height,
            data: rgb.iter().skip(c).step_by(3).copied().collect(),
        };
        Some(ColourU8 {
            channels: [plane(0), plane(1), plane(2)],
            gray,
        })
    }

    /// The pixels as `[r, g, b]`, row by row.
    pub fn rgb_pixels(&self) -> impl Iterator<Item = [u8; 3]> + '_ {
        let [r, g, b] = &self.channels;
        (0..r.data.len()).map(|i| [r.data[i], g.data[i], b.data[i]])
    }

    /// The frame's size.
    pub fn size(&self) -> (usize, usize) {
        (self.gray.width, self.gray.height)
    }
}

/// A frame as a sequence hands it out: grey, or in colour when a tracker asked for it.
#[derive(Clone, Debug, PartialEq)]
pub enum Frame8 {
    Gray(GrayU8),
    Colour(ColourU8),
}

impl Frame8 {
    /// The grey image (a colour frame's luma).
    pub fn gray(&self) -> &GrayU8 {
        match self {
            Frame8::Gray(g) => g,
            Frame8::Colour(c) => &c.gray,
        }
    }
}

/// Reads an image file in colour (a grey file's three channels are its grey); the error names
/// the path.
pub fn load_colour(path: &Path) -> Result<ColourU8> {
    let img = load_dynamic(path)?;
    // The grey every other reader sees: the same as `load_gray`'s.
    ColourU8::from_rgb_and_gray(img.to_rgb8().as_raw(), gray_from_dynamic(&img)).ok_or_else(|| {
        Error::Image {
            path: path.to_path_buf(),
            message: "its pixels do not fill its size".into(),
        }
    })
}

/// The size of an image file, read from its header.
pub fn image_size(path: &Path) -> Result<(usize, usize)> {
    crate::files::check_regular(path)?;
    let (w, h) = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?
        .into_dimensions()
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: read_message(&e),
        })?;
    Ok((w as usize, h as usize))
}

/// Checks that a JPEG or PNG file is whole: it ends with its end marker (a file cut short by a
/// copy or a crash decodes in part, without an error, otherwise).
fn check_complete(
    path: &Path,
    format: Option<image::ImageFormat>,
) -> std::result::Result<(), String> {
    use std::io::{Read, Seek, SeekFrom};
    let (end, what): (&[u8], &str) = match format {
        Some(image::ImageFormat::Jpeg) => (&[0xFF, 0xD9], "JPEG end-of-image marker"),
        Some(image::ImageFormat::Png) => (b"IEND\xAE\x42\x60\x82", "PNG IEND chunk"),
        _ => return Ok(()),
    };
    let mut f = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let len = f.metadata().map_err(|e| e.to_string())?.len();
    let n = len.min(256);
    f.seek(SeekFrom::Start(len - n))
        .map_err(|e| e.to_string())?;
    let mut tail = vec![0u8; n as usize];
    f.read_exact(&mut tail).map_err(|e| e.to_string())?;
    // Some writers pad after the marker.
    while tail
        .last()
        .is_some_and(|&b| b == 0 || b.is_ascii_whitespace())
    {
        tail.pop();
    }
    if tail.ends_with(end) {
        Ok(())
    } else {
        Err(format!(
            "the file is cut short (no {what} at its end; {len} bytes)"
        ))
    }
}

/// Reads an image file (png, jpeg, pgm/ppm) as 8-bit grayscale; the error names the path.
pub fn load_gray(path: &Path) -> Result<GrayU8> {
    let img = load_dynamic(path)?;
    Ok(gray_from_dynamic(&img))
}

/// The most pixels a frame may have (64 megapixels, e.g. 8192 x 8192), whatever its pixel
/// type: larger images are refused before they are decoded.
pub const MAX_PIXELS: u64 = 64 << 20;

/// Why an image could not be read, in the user's terms (the image crate's "Format error
/// decoding Png: ..." or "The image format could not be determined" alone read like a
/// programmer's note).
pub fn read_message(e: &image::ImageError) -> String {
    use image::ImageError as E;
    match e {
        E::Unsupported(u) => match u.format_hint() {
            image::error::ImageFormatHint::Unknown => {
                "not an image regtrack reads (PNG, JPEG, BMP, TIFF, PNM, WebP...): its \
                 contents are of no image format"
                    .to_string()
            }
            hint => format!("a {hint} image regtrack cannot read ({u})"),
        },
        E::Decoding(d) => format!("the file is damaged or not the image its name says ({d})"),
        E::Limits(l) => format!("too large to read ({l})"),
        E::IoError(io) => format!("the file could not be read ({io})"),
        other => other.to_string(),
    }
}

/// Reads an image file as decoded by the `image` crate; the error names the path. Images of
/// more than [`MAX_PIXELS`] are refused before decoding, and a JPEG or PNG file cut short (no
/// end marker) is refused rather than decoded in part.
pub fn load_dynamic(path: &Path) -> Result<image::DynamicImage> {
    // Missing, a folder, a device, a FIFO or a loop of links: each named as what it is.
    crate::files::check_regular(path)?;
    let bad = |message: String| Error::Image {
        path: path.to_path_buf(),
        message,
    };
    let open = || -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
        image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))
    };
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| bad(read_message(&e)))?;
    if w as u64 * h as u64 > MAX_PIXELS {
        return Err(bad(format!(
            "{w}x{h} is more than the {} megapixels a frame may have",
            MAX_PIXELS >> 20
        )));
    }
    let mut reader = open()?;
    check_complete(path, reader.format()).map_err(bad)?;
    let mut limits = image::Limits::default();
    // Room for the largest pixel type (16-bit RGBA) of the largest frame.
    limits.max_alloc = Some(MAX_PIXELS * 8 + (1 << 20));
    reader.limits(limits);
    // A decoder that panics on a malformed file (zune-jpeg 0.5 overflows on some, found by
    // fuzzing) is a bad frame, not a crash.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.decode()))
        .unwrap_or_else(|_| {
            Err(image::ImageError::Decoding(
                image::error::DecodingError::new(
                    image::error::ImageFormatHint::Unknown,
                    "the decoder failed on this file (it is malformed)",
                ),
            ))
        })
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: read_message(&e),
        })
}
