//! The size of an image file from its header, without decoding it ([`image_header`]: PNG's `IHDR`,
//! JPEG's start-of-frame segment), refused beyond [`MAX_PIXELS`] before anything is decoded (every
//! image read goes through this: `read_image` parses the header of the bytes it read first), and a
//! stereo pair's sizes checked against each other ([`stereo_pair`]), before a run starts.

use std::path::{Path, PathBuf};

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
    /// The file's header is not a PNG's or a JPEG's, or declares a size that is refused.
    #[error("cannot read image {}: {message}", .path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
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

/// Most pixels of an image this program decodes: 8192 × 8192. Decoded as 8-bit colour that is 192 MiB,
/// the most an encoded image may take on disk (`slam_core::files::IMAGE`), so that a small file cannot
/// ask for more memory than a large one (a 2.6 MB PNG can declare 30000 × 30000 pixels: 2.7 GB
/// decoded). The largest automotive camera images are about 4000 × 3000.
pub const MAX_PIXELS: u64 = 8192 * 8192;

/// What an image file's header says, read before anything is decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageHeader {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Bits per sample (8 or 16 for PNG, 8 or 12 for JPEG).
    pub bit_depth: u8,
    /// `PNG` or `JPEG`.
    pub format: &'static str,
}

impl ImageHeader {
    /// The header at the start of an image file's bytes: PNG (`IHDR`) or JPEG (the first start-of-frame
    /// segment, after any others); anything else is refused, as is a size of zero or beyond
    /// [`MAX_PIXELS`].
    pub fn parse(read: &mut (impl std::io::Read + std::io::Seek)) -> Result<Self, String> {
        let mut head = [0u8; 8];
        read.read_exact(&mut head[..2]).map_err(|_| "empty or too short to be an image".to_string())?;
        let header = if head[..2] == [0x89, b'P'] {
            let mut rest = [0u8; 24];
            read.read_exact(&mut rest).map_err(|_| "a PNG file cut short before its size".to_string())?;
            if rest[..6] != *b"NG\r\n\x1a\n" || rest[10..14] != *b"IHDR" {
                return Err("not a PNG file: its signature or first chunk (IHDR) is wrong".into());
            }
            let be = |k: usize| u32::from_be_bytes([rest[k], rest[k + 1], rest[k + 2], rest[k + 3]]);
            Self { width: be(14), height: be(18), bit_depth: rest[22], format: "PNG" }
        } else if head[..2] == [0xFF, 0xD8] {
            jpeg_frame(read)?
        } else {
            return Err("neither a PNG nor a JPEG file (the formats read: their headers give the size before \
                        anything is decoded)"
                .into());
        };
        header.check()?;
        Ok(header)
    }

    /// Refuse an empty image and one of more than [`MAX_PIXELS`].
    fn check(&self) -> Result<(), String> {
        let pixels = u64::from(self.width) * u64::from(self.height);
        if pixels == 0 {
            return Err(format!("its {} header declares an empty image ({}×{})", self.format, self.width, self.height));
        }
        if pixels > MAX_PIXELS {
            return Err(format!(
                "its {} header declares {}×{} pixels ({:.0} megapixels), more than the {} megapixels (8192 × 8192) \
                 an image may have here: decoded it would take {}; not decoded",
                self.format,
                self.width,
                self.height,
                pixels as f64 / 1e6,
                MAX_PIXELS / 1_000_000,
                slam_core::memory::human_bytes(3.0 * pixels as f64 * f64::from(self.bit_depth.max(8)) / 8.0)
            ));
        }
        Ok(())
    }
}

/// The first start-of-frame segment of a JPEG stream after its SOI marker (`read` is just past it): the
/// frame's sample precision and size. Other segments are skipped by their lengths.
fn jpeg_frame(read: &mut (impl std::io::Read + std::io::Seek)) -> Result<ImageHeader, String> {
    let short = |_| "a JPEG file cut short before its size (no start-of-frame segment)".to_string();
    loop {
        let mut marker = [0u8; 2];
        read.read_exact(&mut marker).map_err(short)?;
        if marker[0] != 0xFF {
            return Err("a JPEG file whose segments do not follow each other (corrupt)".into());
        }
        // fill bytes before a marker
        let mut code = marker[1];
        while code == 0xFF {
            let mut b = [0u8; 1];
            read.read_exact(&mut b).map_err(short)?;
            code = b[0];
        }
        // markers without a length: TEM, RSTn
        if code == 0x01 || (0xD0..=0xD7).contains(&code) {
            continue;
        }
        let mut len = [0u8; 2];
        read.read_exact(&mut len).map_err(short)?;
        let len = u16::from_be_bytes(len);
        if len < 2 {
            return Err("a JPEG file with a segment shorter than its own length field (corrupt)".into());
        }
        // start of frame: C0-CF except DHT (C4), JPG (C8) and DAC (CC)
        if (0xC0..=0xCF).contains(&code) && ![0xC4, 0xC8, 0xCC].contains(&code) {
            let mut f = [0u8; 5];
            read.read_exact(&mut f).map_err(short)?;
            return Ok(ImageHeader {
                width: u32::from(u16::from_be_bytes([f[3], f[4]])),
                height: u32::from(u16::from_be_bytes([f[1], f[2]])),
                bit_depth: f[0],
                format: "JPEG",
            });
        }
        if code == 0xDA || code == 0xD9 {
            return Err("a JPEG file whose image data comes before its size (no start-of-frame segment)".into());
        }
        read.seek(std::io::SeekFrom::Current(i64::from(len) - 2)).map_err(|e| e.to_string())?;
    }
}

/// The header of an image file ([`ImageHeader::parse`]), read without decoding anything; the error
/// names the file.
pub fn image_header(path: &Path) -> Result<ImageHeader, ImageSizeError> {
    // a pipe would block the open, a device never end: regular files only
    slam_core::files::check_readable(path, &slam_core::files::IMAGE)
        .map_err(|e| ImageSizeError::Io { path: path.to_path_buf(), source: std::io::Error::other(e.reason()) })?;
    let file = std::fs::File::open(path).map_err(|source| ImageSizeError::Io { path: path.to_path_buf(), source })?;
    ImageHeader::parse(&mut std::io::BufReader::new(file))
        .map_err(|message| ImageSizeError::Header { path: path.to_path_buf(), message })
}

/// The width and height of an image file, from its header ([`image_header`]).
pub fn image_size(path: &Path) -> Result<(u32, u32), ImageSizeError> {
    image_header(path).map(|h| (h.width, h.height))
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

    /// The PNG signature and an `IHDR` chunk declaring `w × h` 8-bit RGB, and nothing else.
    fn png_header(w: u32, h: u32) -> Vec<u8> {
        let mut v = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
        v.extend(w.to_be_bytes());
        v.extend(h.to_be_bytes());
        v.extend([8, 2, 0, 0, 0, 0, 0, 0, 0]);
        v
    }

    #[test]
    fn headers_give_size_and_depth_and_a_bomb_is_refused_before_decoding() {
        let parse = |bytes: &[u8]| ImageHeader::parse(&mut std::io::Cursor::new(bytes));
        let h = parse(&png_header(1226, 370)).expect("png");
        assert_eq!((h.width, h.height, h.bit_depth, h.format), (1226, 370, 8, "PNG"));
        // 30000 × 30000 in 33 bytes: refused from the header alone
        let e = parse(&png_header(30_000, 30_000)).expect_err("bomb");
        assert!(e.contains("declares 30000×30000 pixels (900 megapixels)") && e.contains("not decoded"), "{e}");
        assert!(parse(&png_header(0, 370)).expect_err("empty").contains("empty image (0×370)"));
        // a JPEG from OpenCV's encoder: the size is in its start-of-frame segment, after JFIF's APP0
        let img = Image::new(64, 24, 1, vec![128; 64 * 24]).expect("image");
        let jpeg = crate::encode_jpeg(&img, 90).expect("jpeg");
        let h = parse(&jpeg).expect("jpeg header");
        assert_eq!((h.width, h.height, h.bit_depth, h.format), (64, 24, 8, "JPEG"));
        // a JPEG cut before its frame segment, a BMP, nothing
        assert!(parse(&jpeg[..4]).expect_err("cut").contains("cut short"));
        assert!(parse(b"BM\0\0\0\0").expect_err("bmp").contains("neither a PNG nor a JPEG"));
        assert!(parse(b"").expect_err("empty file").contains("too short"));
        // read_image refuses the bomb by its header: a 33-byte file
        let dir = std::env::temp_dir().join(format!("image-bomb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let bomb = dir.join("bomb.png");
        std::fs::write(&bomb, png_header(30_000, 30_000)).expect("write");
        let e = crate::read_image(&bomb, false).expect_err("refused").to_string();
        assert!(e.contains("bomb.png") && e.contains("30000×30000"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
