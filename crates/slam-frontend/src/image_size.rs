//! The size of an image file without decoding it where the header tells ([`image_size`]: PNG's
//! `IHDR`), and a stereo pair's sizes checked against each other ([`stereo_pair`]), before a run starts.

use std::path::{Path, PathBuf};

use crate::{read_image, FrontendError};

/// Errors of the size checks; each names the file(s).
#[derive(Debug, thiserror::Error)]
pub enum ImageSizeError {
    /// The file could not be opened or read.
    #[error("cannot read image {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file that is not PNG could not be decoded.
    #[error(transparent)]
    Decode(#[from] FrontendError),
    /// The two images of a pair differ in size.
    #[error("image sizes differ: left {} is {}×{}, right {} is {}×{} (a stereo pair must have one size)", .left.display(), .left_size.0, .left_size.1, .right.display(), .right_size.0, .right_size.1)]
    Mismatch {
        /// Left image.
        left: PathBuf,
        /// Its size.
        left_size: (u32, u32),
        /// Right image.
        right: PathBuf,
        /// Its size.
        right_size: (u32, u32),
    },
    /// An image without pixels.
    #[error("{}: empty image ({}×{})", .path.display(), .size.0, .size.1)]
    Empty {
        /// The file.
        path: PathBuf,
        /// Its size.
        size: (u32, u32),
    },
}

/// The width and height of an image file, read from its header (PNG) or by decoding it.
pub fn image_size(path: &Path) -> Result<(u32, u32), ImageSizeError> {
    let mut head = [0u8; 24];
    use std::io::Read;
    // a pipe would block the open, a device never end: regular files only
    slam_core::files::check_readable(path, &slam_core::files::IMAGE)
        .map_err(|e| ImageSizeError::Io { path: path.to_path_buf(), source: std::io::Error::other(e.reason()) })?;
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .map_err(|source| ImageSizeError::Io { path: path.to_path_buf(), source })?;
    if n == 24 && head[..8] == *b"\x89PNG\r\n\x1a\n" && head[12..16] == *b"IHDR" {
        let w = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
        let h = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
        return Ok((w, h));
    }
    let img = read_image(path, false)?;
    Ok((img.width, img.height))
}

/// A stereo pair: both images readable, of the same size, and not empty.
pub fn stereo_pair(left: &Path, right: &Path) -> Result<(u32, u32), ImageSizeError> {
    let l = image_size(left)?;
    let r = image_size(right)?;
    if l != r {
        return Err(ImageSizeError::Mismatch {
            left: left.to_path_buf(),
            left_size: l,
            right: right.to_path_buf(),
            right_size: r,
        });
    }
    if l.0 == 0 || l.1 == 0 {
        return Err(ImageSizeError::Empty { path: left.to_path_buf(), size: l });
    }
    Ok(l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write_image;
    use slam_core::Image;

    #[test]
    fn sizes_come_from_the_header_and_a_mismatch_names_both_files() {
        let dir = std::env::temp_dir().join(format!("image-size-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let (a, b) = (dir.join("a.png"), dir.join("b.png"));
        write_image(&a, &Image::new(6, 4, 1, vec![0; 24]).expect("image")).expect("write");
        write_image(&b, &Image::new(5, 4, 1, vec![0; 20]).expect("image")).expect("write");
        assert_eq!(image_size(&a).expect("size"), (6, 4));
        assert_eq!(stereo_pair(&a, &a).expect("pair"), (6, 4));
        let e = stereo_pair(&a, &b).expect_err("mismatch").to_string();
        assert!(e.contains("a.png is 6×4") && e.contains("b.png is 5×4"), "{e}");
        let e = image_size(&dir.join("none.png")).expect_err("missing").to_string();
        assert!(e.starts_with("cannot read image ") && e.contains("none.png"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
