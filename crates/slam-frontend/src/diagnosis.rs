//! What a stereo pair's images show, for a run that could not track most of its frames: whether the
//! two cameras look swapped (most row matches at negative disparity), and whether the images are nearly
//! black or of a small value range (as 12-bit data stored in 16-bit files reads when taken as 8 bits).
//! The run says so instead of only counting lost frames.

use std::path::Path;

use opencv::{core, features2d, prelude::*};
use slam_core::Image;

use crate::{
    image_io::image_to_mat,
    image_size::{image_header, ImageHeader},
    read_image, FrontendError,
};

/// Fewest row matches before their disparities say anything about the rig: with fewer, chance alone
/// (a few false matches of either sign) decides the share.
pub const MIN_MATCHES: usize = 20;

/// Share of negative disparities from which the cameras are said to be swapped. In a rectified pair
/// with the left camera on the left, a point's disparity `u_left − u_right` is positive (zero at
/// infinity); false matches along a row fall on either side about equally, so a correct rig shows well
/// under half, a swapped one nearly all.
pub const SWAPPED_SHARE: f64 = 0.6;

/// A 99th percentile of grey values below this (of 255) is a nearly black image: a daylight road scene
/// spreads over most of the 8-bit range (KITTI's: 99th percentile above 200); a quarter of it is two
/// stops under.
pub const DARK_P99: u8 = 64;

/// A spread between the 1st and the 99th percentile below this (grey levels) is a small value range:
/// ORB's corner test asks for 20 grey levels of contrast (OpenCV's FAST threshold), which few pixels
/// of such an image have.
pub const SMALL_RANGE: u8 = 32;

/// Largest row difference of a match in a rectified pair, pixels (the matcher allows 2 px too).
const ROW_PX: f32 = 2.0;

/// Smallest |disparity| counted, pixels: points at infinity (zero disparity) have no sign.
const MIN_DISPARITY_PX: f32 = 1.0;

/// What one stereo pair shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairDiagnosis {
    /// ORB matches between the two images on the same row (within 2 px), whatever their disparity.
    pub matches: usize,
    /// Of those, with a disparity `u_left − u_right` below −1 px.
    pub negative: usize,
    /// Of those, with a disparity above +1 px.
    pub positive: usize,
    /// Grey values of the left image as read (8 bits) at the 1st and the 99th percentile.
    pub percentiles: (u8, u8),
    /// The left file's header (its bit depth).
    pub header: ImageHeader,
}

/// Look at one stereo pair (grey, as the tracker reads it): row matches of ORB features with no
/// disparity limit, and the left image's value range.
pub fn diagnose_pair(left: &Path, right: &Path) -> Result<PairDiagnosis, FrontendError> {
    let header = image_header(left)
        .map_err(|e| FrontendError::ImageRead { path: left.to_path_buf(), message: e.to_string() })?;
    let (l, r) = (read_image(left, false)?, read_image(right, false)?);
    diagnose_images(&l, &r, header)
}

/// [`diagnose_pair`] on images already read (colour ones are looked at in grey), whose source has
/// samples of `header`'s bit depth (a bag's messages: their encoding's).
pub fn diagnose_images(l: &Image, r: &Image, header: ImageHeader) -> Result<PairDiagnosis, FrontendError> {
    let grey = |i: &Image| -> Result<Image, FrontendError> {
        if i.channels == 1 {
            return Ok(i.clone());
        }
        let mut g = Mat::default();
        opencv::imgproc::cvt_color_def(&image_to_mat(i)?, &mut g, opencv::imgproc::COLOR_BGR2GRAY)?;
        crate::image_io::mat_to_image(&g)
    };
    let (l, r) = (grey(l)?, grey(r)?);
    let mut hist = [0usize; 256];
    for &v in &l.data {
        hist[v as usize] += 1;
    }
    let at = |q: f64| {
        let target = (q * l.data.len() as f64).ceil() as usize;
        let mut seen = 0;
        hist.iter().position(|&n| {
            seen += n;
            seen >= target.max(1)
        })
    };
    let percentiles = (at(0.01).unwrap_or(0) as u8, at(0.99).unwrap_or(0) as u8);
    let (lm, rm) = (image_to_mat(&l)?, image_to_mat(&r)?);
    let mut orb = features2d::ORB::create_def()?;
    let mut features = |m: &Mat| -> Result<(core::Vector<core::KeyPoint>, Mat), FrontendError> {
        let (mut kps, mut desc) = (core::Vector::new(), Mat::default());
        orb.detect_and_compute(m, &core::no_array(), &mut kps, &mut desc, false)?;
        Ok((kps, desc))
    };
    let ((lk, ld), (rk, rd)) = (features(&lm)?, features(&rm)?);
    let (mut matches, mut negative, mut positive) = (0, 0, 0);
    if !ld.empty() && !rd.empty() {
        let matcher = features2d::BFMatcher::new(core::NORM_HAMMING, true)?;
        let mut found = core::Vector::<core::DMatch>::new();
        matcher.train_match(&ld, &rd, &mut found, &core::no_array())?;
        for m in found.iter() {
            let (a, b) = (lk.get(m.query_idx as usize)?.pt(), rk.get(m.train_idx as usize)?.pt());
            if (a.y - b.y).abs() > ROW_PX {
                continue;
            }
            matches += 1;
            let d = a.x - b.x;
            negative += usize::from(d < -MIN_DISPARITY_PX);
            positive += usize::from(d > MIN_DISPARITY_PX);
        }
    }
    Ok(PairDiagnosis { matches, negative, positive, percentiles, header })
}

impl PairDiagnosis {
    /// Whether most matches with a sign have a negative disparity ([`SWAPPED_SHARE`] of at least
    /// [`MIN_MATCHES`]).
    pub fn swapped(&self) -> bool {
        let signed = self.negative + self.positive;
        signed >= MIN_MATCHES && self.negative as f64 >= SWAPPED_SHARE * signed as f64
    }

    /// What is wrong with these images, one sentence each (none when nothing is found).
    pub fn findings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.swapped() {
            out.push(format!(
                "{} of {} matches along the image rows have a negative disparity (a point further right in the right \
                 image than in the left): the cameras look swapped (left images in the right camera's folder?)",
                self.negative,
                self.negative + self.positive
            ));
        }
        let (p1, p99) = self.percentiles;
        let deep = if self.header.bit_depth > 8 {
            format!(
                "; the files hold {}-bit samples, read as their top 8 bits: data of fewer bits (e.g. 12-bit, 0-4095) \
                 stored in {}-bit files reads this way: convert them to 8 bits over their real range (bit depth?)",
                self.header.bit_depth, self.header.bit_depth
            )
        } else {
            String::new()
        };
        if p99 < DARK_P99 {
            out.push(format!(
                "the images are nearly black: 99 % of the left image's pixels are at most {p99} of 255{deep}"
            ));
        } else if p99.saturating_sub(p1) < SMALL_RANGE {
            out.push(format!(
                "the images have a small value range: 98 % of the left image's pixels lie within {p1}-{p99} of 255, \
                 too little contrast for the corner detector{deep}"
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(cam: &str, i: usize) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(format!("../../fixtures/kitti_odom_06/sequences/06/{cam}/{i:06}.png"))
    }

    /// The shipped pair: most row matches at positive disparity, a full value range; the same pair
    /// swapped: most negative; its left image scaled to 0-15 (12-bit data read as 8): nearly black,
    /// and said to be 16-bit when the file is.
    #[test]
    fn swapped_cameras_and_dark_images_are_told_apart_from_a_good_pair() {
        let (l, r) = (fixture("image_0", 0), fixture("image_1", 0));
        let good = diagnose_pair(&l, &r).expect("reads");
        assert!(good.matches >= MIN_MATCHES && !good.swapped(), "{good:?}");
        assert!(good.findings().is_empty(), "{:?}", good.findings());
        let swapped = diagnose_pair(&r, &l).expect("reads");
        assert!(swapped.swapped(), "{swapped:?}");
        assert!(swapped.findings()[0].contains("the cameras look swapped"), "{:?}", swapped.findings());
        let dir = std::env::temp_dir().join(format!("diagnosis-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let img = read_image(&l, false).expect("read");
        let dark =
            slam_core::Image::new(img.width, img.height, 1, img.data.iter().map(|v| v / 16).collect()).expect("image");
        let (dl, dr) = (dir.join("l.png"), dir.join("r.png"));
        crate::write_image(&dl, &dark).expect("write");
        crate::write_image(&dr, &dark).expect("write");
        let d = diagnose_pair(&dl, &dr).expect("reads");
        assert!(d.percentiles.1 < DARK_P99, "{d:?}");
        let f = d.findings();
        assert!(f.iter().any(|s| s.contains("nearly black")) && !f.iter().any(|s| s.contains("16-bit")), "{f:?}");
        let sixteen = PairDiagnosis { header: ImageHeader { bit_depth: 16, ..d.header }, ..d };
        assert!(sixteen.findings().iter().any(|s| s.contains("16-bit samples")), "{:?}", sixteen.findings());
        std::fs::remove_dir_all(&dir).ok();
    }
}
