//! Image reading and writing through OpenCV's codecs, converted to `slam_core::Image`.

use std::path::{Path, PathBuf};

use opencv::{core, imgcodecs, prelude::*};
use slam_core::Image;

/// Errors of the front end (image I/O, OpenCV, the tracker's worker threads).
#[derive(Debug, thiserror::Error)]
pub enum FrontendError {
    /// An image file could not be read or decoded.
    #[error("cannot read image {path}: {message}")]
    ImageRead {
        /// File.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// An image file could not be written.
    #[error("cannot write image {path}: {message}")]
    ImageWrite {
        /// File.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// OpenCV failed while running.
    #[error("OpenCV: {0}")]
    OpenCv(String),
    /// A worker thread of the front end stopped without an answer (it panicked).
    #[error("the {0} thread stopped without an answer")]
    Thread(&'static str),
}

impl From<opencv::Error> for FrontendError {
    fn from(e: opencv::Error) -> Self {
        FrontendError::OpenCv(e.to_string())
    }
}

/// Read an image as BGR (colour files) or grey, into an owned [`Image`]: a PNG or JPEG file whose header
/// declares at most [`crate::image_size::MAX_PIXELS`] pixels.
pub fn read_image(path: impl AsRef<Path>, colour: bool) -> Result<Image, FrontendError> {
    let path = path.as_ref();
    let err = |m: String| FrontendError::ImageRead { path: path.to_path_buf(), message: m };
    // a regular file of at most the image limit, read here and decoded from memory: a folder, a pipe, a
    // link that loops or a device is named as what it is, and nothing is read without end
    let bytes = slam_core::files::read_bytes(path, &slam_core::files::IMAGE).map_err(|e| err(image_reason(&e)))?;
    // the size its header declares is checked before anything is decoded: a small file may declare a
    // huge image (a decompression bomb)
    crate::image_size::ImageHeader::parse(&mut std::io::Cursor::new(&bytes)).map_err(err)?;
    let flag = if colour { imgcodecs::IMREAD_COLOR } else { imgcodecs::IMREAD_GRAYSCALE };
    let m = imgcodecs::imdecode(&core::Vector::<u8>::from_slice(&bytes), flag).map_err(|e| err(e.to_string()))?;
    if m.empty() {
        return Err(err("could not decode (corrupt or unsupported file)".into()));
    }
    mat_to_image(&m).map_err(|e| err(e.to_string()))
}

/// Why an image file could not be read, in the words of [`FrontendError::ImageRead`]: `no such file` for
/// a missing one.
fn image_reason(e: &slam_core::files::ReadError) -> String {
    match e {
        slam_core::files::ReadError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            "no such file".into()
        }
        other => other.reason(),
    }
}

/// Write an image (format from the extension).
pub fn write_image(path: impl AsRef<Path>, image: &Image) -> Result<(), FrontendError> {
    let path = path.as_ref();
    let err = |m: String| FrontendError::ImageWrite { path: path.to_path_buf(), message: m };
    let s = path.to_str().ok_or_else(|| err("path is not UTF-8".into()))?;
    let m = image_to_mat(image).map_err(|e| err(e.to_string()))?;
    let ok = imgcodecs::imwrite(s, &m, &core::Vector::new()).map_err(|e| err(e.to_string()))?;
    if ok {
        Ok(())
    } else {
        Err(err("encoder refused".into()))
    }
}

/// Encode an image as JPEG in memory (quality 0-100; OpenCV's default is 95). Grey images stay grey.
pub fn encode_jpeg(image: &Image, quality: u8) -> Result<Vec<u8>, FrontendError> {
    let m = image_to_mat(image)?;
    let params = core::Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, i32::from(quality.min(100))]);
    let mut bytes = core::Vector::<u8>::new();
    if imgcodecs::imencode(".jpg", &m, &mut bytes, &params)? {
        Ok(bytes.to_vec())
    } else {
        Err(FrontendError::OpenCv("the JPEG encoder refused the image".into()))
    }
}

/// An OpenCV matrix of 8-bit pixels (one or three channels) as an owned [`Image`]. Public for
/// `slam-detect`, which calls OpenCV on its frames itself.
pub fn mat_to_image(m: &Mat) -> Result<Image, FrontendError> {
    let channels = m.channels();
    let cont = if m.is_continuous() { m.clone() } else { m.try_clone()? };
    let data = cont.data_bytes()?.to_vec();
    Image::new(m.cols() as u32, m.rows() as u32, channels as u8, data)
        .ok_or_else(|| FrontendError::OpenCv(format!("unexpected image layout: {channels} channels")))
}

/// An [`Image`] as an OpenCV matrix (`CV_8UC1` or `CV_8UC3`), copying its pixels. Public for
/// `slam-detect`, which calls OpenCV on its frames itself.
pub fn image_to_mat(image: &Image) -> Result<Mat, FrontendError> {
    let typ = if image.channels == 3 { core::CV_8UC3 } else { core::CV_8UC1 };
    let mut m = Mat::new_rows_cols_with_default(image.height as i32, image.width as i32, typ, core::Scalar::all(0.0))?;
    m.data_bytes_mut()?.copy_from_slice(&image.data);
    Ok(m)
}

/// A polyline of an [`Overlay`]: points, `closed` when the last point joins the first, BGR colour, line
/// width.
pub type Polyline = (Vec<[f64; 2]>, bool, [u8; 3], i32);

/// What [`draw_overlay`] draws: boxes, closed or open polylines, points and labels, in BGR colours.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overlay {
    /// Boxes with colour and label.
    pub boxes: Vec<(slam_core::geometry::BBox, [u8; 3], String)>,
    /// Polylines.
    pub lines: Vec<Polyline>,
    /// Labels at pixel positions.
    pub labels: Vec<([f64; 2], [u8; 3], String)>,
    /// Filled dots (position, colour, radius).
    pub dots: Vec<([f64; 2], [u8; 3], i32)>,
    /// Legend entries (colour, meaning), drawn in a panel at the top left.
    pub legend: Vec<([u8; 3], String)>,
}

/// Points along an image ellipse (`(x − c)ᵀ E⁻¹ (x − c) = 1`), for drawing; empty when the shape is not
/// positive definite.
pub fn ellipse_outline(e: &slam_core::geometry::Ellipse2, samples: usize) -> Vec<[f64; 2]> {
    let eig = e.shape.symmetric_eigen();
    if eig.eigenvalues.iter().any(|l| l.is_nan() || *l <= 0.0 || !l.is_finite()) {
        return Vec::new();
    }
    let (a, b) = (eig.eigenvalues[0].sqrt(), eig.eigenvalues[1].sqrt());
    let (v0, v1) = (eig.eigenvectors.column(0), eig.eigenvectors.column(1));
    (0..samples)
        .map(|i| {
            let t = std::f64::consts::TAU * i as f64 / samples as f64;
            let p = e.centre + v0 * (a * t.cos()) + v1 * (b * t.sin());
            [p.x, p.y]
        })
        .collect()
}

/// Draw an [`Overlay`] on a copy of an image (grey images become colour).
pub fn draw_overlay(image: &Image, overlay: &Overlay) -> Result<Image, FrontendError> {
    use opencv::imgproc;
    let mut m = image_to_mat(image)?;
    if m.channels() == 1 {
        let mut c = Mat::default();
        imgproc::cvt_color_def(&m, &mut c, imgproc::COLOR_GRAY2BGR)?;
        m = c;
    }
    let colour = |c: [u8; 3]| core::Scalar::new(c[0] as f64, c[1] as f64, c[2] as f64, 0.0);
    let clamp = |v: f64| v.clamp(-1.0e5, 1.0e5) as i32;
    for (pts, closed, c, width) in &overlay.lines {
        let v: core::Vector<core::Point> = pts.iter().map(|p| core::Point::new(clamp(p[0]), clamp(p[1]))).collect();
        if v.len() >= 2 {
            let mut all = core::Vector::<core::Vector<core::Point>>::new();
            all.push(v);
            imgproc::polylines(&mut m, &all, *closed, colour(*c), *width, imgproc::LINE_AA, 0)?;
        }
    }
    for (p, c, r) in &overlay.dots {
        imgproc::circle(&mut m, core::Point::new(clamp(p[0]), clamp(p[1])), *r, colour(*c), -1, imgproc::LINE_AA, 0)?;
    }
    for (b, c, label) in &overlay.boxes {
        let rect = core::Rect::new(clamp(b.xmin), clamp(b.ymin), b.width().max(1.0) as i32, b.height().max(1.0) as i32);
        imgproc::rectangle(&mut m, rect, colour(*c), 1, imgproc::LINE_8, 0)?;
        if !label.is_empty() {
            tag(&mut m, label, core::Point::new(clamp(b.xmin), (clamp(b.ymin) - 3).max(12)), *c, 0.4)?;
        }
    }
    for (p, c, label) in &overlay.labels {
        tag(&mut m, label, core::Point::new(clamp(p[0]), clamp(p[1])), *c, 0.5)?;
    }
    if !overlay.legend.is_empty() {
        // a dark panel, a colour swatch and the meaning per line
        let line = 18;
        let width = overlay
            .legend
            .iter()
            .map(|(_, t)| {
                let mut base = 0;
                imgproc::get_text_size(t, imgproc::FONT_HERSHEY_SIMPLEX, 0.45, 1, &mut base).map_or(100, |s| s.width)
            })
            .max()
            .unwrap_or(100)
            + 34;
        let panel = core::Rect::new(
            4,
            4,
            width.min(m.cols() - 8).max(1),
            (line * overlay.legend.len() as i32 + 8).min(m.rows() - 8).max(1),
        );
        {
            let mut roi = Mat::roi_mut(&mut m, panel)?;
            let mut dark = Mat::default();
            roi.convert_to(&mut dark, -1, 0.35, 0.0)?;
            dark.copy_to(&mut roi)?;
        }
        for (k, (c, text)) in overlay.legend.iter().enumerate() {
            let y = 8 + line * k as i32;
            imgproc::rectangle(&mut m, core::Rect::new(10, y + 3, 16, 10), colour(*c), -1, imgproc::LINE_8, 0)?;
            imgproc::put_text(
                &mut m,
                text,
                core::Point::new(32, y + 13),
                imgproc::FONT_HERSHEY_SIMPLEX,
                0.45,
                core::Scalar::all(255.0),
                1,
                imgproc::LINE_AA,
                false,
            )?;
        }
    }
    mat_to_image(&m)
}

/// Text on a filled box of its colour (black or white text, whichever reads better), its lower left
/// corner at `org`.
fn tag(m: &mut Mat, text: &str, org: core::Point, c: [u8; 3], scale: f64) -> Result<(), FrontendError> {
    use opencv::imgproc;
    let mut base = 0;
    let size = imgproc::get_text_size(text, imgproc::FONT_HERSHEY_SIMPLEX, scale, 1, &mut base)?;
    let bg = core::Scalar::new(c[0] as f64, c[1] as f64, c[2] as f64, 0.0);
    imgproc::rectangle(
        m,
        core::Rect::new(org.x - 1, org.y - size.height - 2, size.width + 2, size.height + base + 2),
        bg,
        -1,
        imgproc::LINE_8,
        0,
    )?;
    // BGR: perceived brightness of the background
    let light = 0.114 * c[0] as f64 + 0.587 * c[1] as f64 + 0.299 * c[2] as f64 > 140.0;
    let fg = if light { core::Scalar::all(0.0) } else { core::Scalar::all(255.0) };
    imgproc::put_text(m, text, org, imgproc::FONT_HERSHEY_SIMPLEX, scale, fg, 1, imgproc::LINE_AA, false)?;
    Ok(())
}

/// Why an image message could not be decoded.
fn message_error(what: &str, message: String) -> FrontendError {
    FrontendError::ImageRead { path: PathBuf::from(what), message }
}

/// A raw image message's pixels (ROS `sensor_msgs/msg/Image`: `mono8`, `rgb8`, `bgr8`, `mono16`, rows of
/// `step` bytes) as an [`Image`]: BGR when `colour` (a grey image repeated in the three channels, as
/// OpenCV reads a grey PNG in colour), else grey (colour converted as OpenCV converts); 16-bit pixels
/// keep their high byte, as OpenCV reads a 16-bit PNG into 8 bits. `what` names the message in errors.
#[allow(clippy::too_many_arguments)]
pub fn decode_raw_image(
    what: &str,
    (width, height): (u32, u32),
    encoding: &str,
    big_endian: bool,
    step: u32,
    data: &[u8],
    colour: bool,
) -> Result<Image, FrontendError> {
    let err = |m: String| message_error(what, m);
    if width == 0 || height == 0 || u64::from(width) * u64::from(height) > crate::image_size::MAX_PIXELS {
        return Err(err(format!("{width}×{height} pixels: an image has 1 to 8192 × 8192")));
    }
    let (channels, bytes) = match encoding {
        "mono8" => (1usize, 1usize),
        "mono16" => (1, 2),
        "rgb8" | "bgr8" => (3, 1),
        other => return Err(err(format!("encoding '{other}' is not decoded (mono8, rgb8, bgr8, mono16 are)"))),
    };
    let (w, h, step) = (width as usize, height as usize, step as usize);
    let row = w * channels * bytes;
    if step < row || data.len() < step * h {
        return Err(err(format!(
            "{w}×{h} {encoding} needs rows of {row} bytes; the message has step {step} and {} bytes",
            data.len()
        )));
    }
    let mut pixels = Vec::with_capacity(w * h * channels);
    for y in 0..h {
        let line = &data[y * step..y * step + row];
        if bytes == 2 {
            let high = usize::from(!big_endian);
            pixels.extend(line.chunks_exact(2).map(|p| p[high]));
        } else {
            pixels.extend_from_slice(line);
        }
    }
    let typ = if channels == 3 { core::CV_8UC3 } else { core::CV_8UC1 };
    let mut m = Mat::new_rows_cols_with_default(h as i32, w as i32, typ, core::Scalar::all(0.0))?;
    m.data_bytes_mut()?.copy_from_slice(&pixels);
    let code = match (channels, encoding, colour) {
        (1, _, true) => Some(opencv::imgproc::COLOR_GRAY2BGR),
        (3, "rgb8", true) => Some(opencv::imgproc::COLOR_RGB2BGR),
        (3, "rgb8", false) => Some(opencv::imgproc::COLOR_RGB2GRAY),
        (3, _, false) => Some(opencv::imgproc::COLOR_BGR2GRAY),
        _ => None,
    };
    if let Some(code) = code {
        let mut c = Mat::default();
        opencv::imgproc::cvt_color_def(&m, &mut c, code)?;
        m = c;
    }
    mat_to_image(&m)
}

/// A compressed image message's file (PNG or JPEG; its header checked as [`read_image`] checks a file's)
/// as an [`Image`], BGR when `colour`, else grey. `what` names the message in errors.
pub fn decode_compressed_image(what: &str, data: &[u8], colour: bool) -> Result<Image, FrontendError> {
    let err = |m: String| message_error(what, m);
    crate::image_size::ImageHeader::parse(&mut std::io::Cursor::new(data)).map_err(err)?;
    let flag = if colour { imgcodecs::IMREAD_COLOR } else { imgcodecs::IMREAD_GRAYSCALE };
    let m = imgcodecs::imdecode(&core::Vector::<u8>::from_slice(data), flag).map_err(|e| err(e.to_string()))?;
    if m.empty() {
        return Err(err("could not decode (corrupt or unsupported data)".into()));
    }
    mat_to_image(&m).map_err(|e| err(e.to_string()))
}

/// Encode an image as PNG in memory (lossless; for bags with compressed images).
pub fn encode_png(image: &Image) -> Result<Vec<u8>, FrontendError> {
    let m = image_to_mat(image)?;
    let mut bytes = core::Vector::<u8>::new();
    if imgcodecs::imencode(".png", &m, &mut bytes, &core::Vector::new())? {
        Ok(bytes.to_vec())
    } else {
        Err(FrontendError::OpenCv("the PNG encoder refused the image".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlay_draws_a_legend_panel_and_labels_on_their_colour() {
        let white = Image::new(320, 120, 1, vec![255; 320 * 120]).expect("image");
        let bbox = slam_core::geometry::BBox::new(150.0, 60.0, 300.0, 110.0);
        let overlay = Overlay {
            boxes: vec![(bbox, [40, 170, 60], "#3 car 0.91".into())],
            legend: vec![([40, 170, 60], "static object".into()), ([40, 30, 220], "moving object".into())],
            ..Overlay::default()
        };
        let out = draw_overlay(&white, &overlay).expect("draws");
        assert_eq!(out.channels, 3);
        let px = |x: usize, y: usize| {
            let k = 3 * (y * out.width as usize + x);
            [out.data[k], out.data[k + 1], out.data[k + 2]]
        };
        // the panel darkens the image behind the legend; its first swatch has the first entry's colour
        assert_eq!(px(100, 10), [89, 89, 89], "dark panel (0.35 × 255)");
        assert_eq!(px(15, 14), [40, 170, 60]);
        assert_eq!(px(15, 32), [40, 30, 220]);
        // outside the panel and the box the image is untouched
        assert_eq!(px(100, 100), [255, 255, 255]);
        // the box label sits on a filled tag of the box's colour, just above the box
        let tag = (150..230).filter(|&x| px(x, 50) == [40, 170, 60]).count();
        assert!(tag > 20, "{tag} tag pixels");
    }

    /// A JPEG of a grey gradient decodes (through OpenCV's reader) to the same size and grey layout,
    /// within a few grey levels of the original: JPEG is lossy, and at quality 90 a smooth gradient
    /// keeps its values to within about 2 levels.
    #[test]
    fn jpeg_encoding_keeps_size_and_grey_levels() {
        let (w, h) = (96u32, 40u32);
        let data: Vec<u8> = (0..h).flat_map(|_| (0..w).map(|x| (x * 2) as u8)).collect();
        let grey = Image::new(w, h, 1, data.clone()).expect("image");
        let bytes = encode_jpeg(&grey, 90).expect("encodes");
        assert_eq!(&bytes[..3], &[0xFF, 0xD8, 0xFF], "a JPEG starts with SOI and a marker");
        let dir = std::env::temp_dir().join(format!("slam-frontend-jpeg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("g.jpg");
        std::fs::write(&path, &bytes).expect("writes");
        let back = read_image(&path, false).expect("decodes");
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!((back.width, back.height, back.channels), (w, h, 1));
        let worst = back.data.iter().zip(&data).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(255);
        assert!(worst <= 4, "largest difference {worst} grey levels");
        assert!(bytes.len() < data.len(), "compressed: {} bytes for {} pixels", bytes.len(), data.len());
    }
}
