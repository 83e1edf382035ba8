//! Image reading and writing through OpenCV's codecs, converted to `slam_core::Image`.

use std::path::{Path, PathBuf};

use opencv::{core, imgcodecs, prelude::*};
use slam_core::Image;

/// Errors of the front end.
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
    /// The detector model could not be loaded.
    #[error("cannot load detector model {path}: {message}")]
    Model {
        /// Model file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// OpenCV failed while running.
    #[error("OpenCV: {0}")]
    OpenCv(String),
}

impl From<opencv::Error> for FrontendError {
    fn from(e: opencv::Error) -> Self {
        FrontendError::OpenCv(e.to_string())
    }
}

/// Read an image as BGR (colour files) or grey, into an owned [`Image`].
pub fn read_image(path: impl AsRef<Path>, colour: bool) -> Result<Image, FrontendError> {
    let path = path.as_ref();
    let err = |m: String| FrontendError::ImageRead { path: path.to_path_buf(), message: m };
    let s = path.to_str().ok_or_else(|| err("path is not UTF-8".into()))?;
    if !path.is_file() {
        return Err(err("no such file".into()));
    }
    let flag = if colour { imgcodecs::IMREAD_COLOR } else { imgcodecs::IMREAD_GRAYSCALE };
    let m = imgcodecs::imread(s, flag).map_err(|e| err(e.to_string()))?;
    if m.empty() {
        return Err(err("could not decode (corrupt or unsupported file)".into()));
    }
    mat_to_image(&m).map_err(|e| err(e.to_string()))
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

pub(crate) fn mat_to_image(m: &Mat) -> Result<Image, FrontendError> {
    let channels = m.channels();
    let cont = if m.is_continuous() { m.clone() } else { m.try_clone()? };
    let data = cont.data_bytes()?.to_vec();
    Image::new(m.cols() as u32, m.rows() as u32, channels as u8, data)
        .ok_or_else(|| FrontendError::OpenCv(format!("unexpected image layout: {channels} channels")))
}

pub(crate) fn image_to_mat(image: &Image) -> Result<Mat, FrontendError> {
    let typ = if image.channels == 3 { core::CV_8UC3 } else { core::CV_8UC1 };
    let mut m = Mat::new_rows_cols_with_default(image.height as i32, image.width as i32, typ, core::Scalar::all(0.0))?;
    m.data_bytes_mut()?.copy_from_slice(&image.data);
    Ok(m)
}

/// Draw detections (boxes and `name score` labels) on a copy of an image.
pub fn draw_detections(
    image: &Image,
    dets: &[slam_core::Detection],
    name: impl Fn(slam_core::ClassId) -> String,
) -> Result<Image, FrontendError> {
    let mut m = image_to_mat(image)?;
    if m.channels() == 1 {
        let mut c = Mat::default();
        opencv::imgproc::cvt_color_def(&m, &mut c, opencv::imgproc::COLOR_GRAY2BGR)?;
        m = c;
    }
    for d in dets {
        let b = d.bbox;
        let colour = core::Scalar::new(
            40.0 + (d.class.0 as f64 * 73.0) % 200.0,
            200.0,
            255.0 - (d.class.0 as f64 * 41.0) % 200.0,
            0.0,
        );
        let rect = core::Rect::new(b.xmin as i32, b.ymin as i32, b.width().max(1.0) as i32, b.height().max(1.0) as i32);
        opencv::imgproc::rectangle(&mut m, rect, colour, 2, opencv::imgproc::LINE_8, 0)?;
        let label = format!("{} {:.2}", name(d.class), d.score);
        let org = core::Point::new(b.xmin as i32, (b.ymin as i32 - 4).max(12));
        opencv::imgproc::put_text(
            &mut m,
            &label,
            org,
            opencv::imgproc::FONT_HERSHEY_SIMPLEX,
            0.45,
            colour,
            1,
            opencv::imgproc::LINE_AA,
            false,
        )?;
    }
    mat_to_image(&m)
}
