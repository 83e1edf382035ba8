//! A detector over a list of image files (`slam-app detect`): each readable image is detected and, on
//! request, drawn with its boxes into an overlay folder; an unreadable image is counted, logged and
//! skipped.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
};

use opencv::{core, prelude::*};
use slam_core::{DetectError, Detection, DetectionSource, Image};
use slam_frontend::{
    image_io::{image_to_mat, mat_to_image},
    read_image, write_image, FrontendError,
};

/// Errors of [`detect_images`].
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The detector failed on an image.
    #[error("detecting in {path}")]
    Detect {
        /// The image.
        path: PathBuf,
        /// Why.
        #[source]
        source: DetectError,
    },
    /// An overlay could not be drawn or written.
    #[error(transparent)]
    Frontend(#[from] FrontendError),
}

/// What [`detect_images`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatchDetections {
    /// Detections per frame id (every readable frame, also those without detections).
    pub frames: BTreeMap<usize, Vec<Detection>>,
    /// `[width, height]` of the first readable image.
    pub image_size: Option<[u32; 2]>,
    /// Unreadable images skipped.
    pub skipped: usize,
    /// Detections in all frames.
    pub total: usize,
}

/// Run `detector` over `images` (`(frame id, file)`), in order; with `overlays`, write each frame drawn
/// with its boxes there as `<file stem>.png`. `tick` is called once per image (progress).
pub fn detect_images(
    detector: &mut dyn DetectionSource,
    images: &[(usize, PathBuf)],
    overlays: Option<&Path>,
    tick: &mut dyn FnMut(),
) -> Result<BatchDetections, BatchError> {
    let mut out = BatchDetections::default();
    for (i, path) in images {
        let i = *i;
        let img = match read_image(path, true) {
            Ok(img) => img,
            Err(e) => {
                tracing::warn!("frame {i} skipped: {e}");
                out.skipped += 1;
                tick();
                continue;
            }
        };
        out.image_size.get_or_insert([img.width, img.height]);
        let d = detector.detect(i, Some(&img)).map_err(|source| BatchError::Detect { path: path.clone(), source })?;
        out.total += d.len();
        if let Some(o) = overlays {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| format!("{i:06}"));
            write_image(o.join(format!("{name}.png")), &draw_detections(&img, &d, |c| c.name().to_string())?)?;
        }
        out.frames.insert(i, d);
        tick();
    }
    Ok(out)
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

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::{geometry::BBox, ClassId};

    /// One box per frame, the frame id as its left edge.
    struct OneBox;

    impl DetectionSource for OneBox {
        fn name(&self) -> &str {
            "one box"
        }
        fn needs_image(&self) -> bool {
            true
        }
        fn detect(&mut self, frame: usize, image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
            assert!(image.is_some());
            let x = frame as f64;
            Ok(vec![Detection::new(ClassId(2), 0.9, BBox::new(x, 1.0, x + 4.0, 5.0))])
        }
    }

    #[test]
    fn readable_images_are_detected_and_drawn_and_unreadable_ones_skipped() {
        let dir = std::env::temp_dir().join(format!("batch-detect-{}", std::process::id()));
        let overlays = dir.join("overlays");
        std::fs::create_dir_all(&overlays).expect("dir");
        let img = Image::new(16, 8, 3, vec![90; 16 * 8 * 3]).expect("image");
        write_image(dir.join("a.png"), &img).expect("write");
        let images = vec![(3, dir.join("a.png")), (4, dir.join("missing.png"))];
        let mut ticks = 0;
        let out = detect_images(&mut OneBox, &images, Some(&overlays), &mut || ticks += 1).expect("runs");
        assert_eq!((out.skipped, out.total, ticks), (1, 1, 2));
        assert_eq!(out.image_size, Some([16, 8]));
        assert_eq!(out.frames.keys().copied().collect::<Vec<_>>(), [3]);
        assert_eq!(out.frames[&3][0].bbox.xmin, 3.0, "the frame id reaches the detector");
        assert!(overlays.join("a.png").is_file());
        std::fs::remove_dir_all(&dir).ok();
    }
}
