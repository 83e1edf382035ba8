//! Checks of a stereo pair's images before any work starts: both readable and of one size.

use std::path::Path;

use crate::error::{Context, Result, RunnerError};

/// The width and height of an image file, read from its header (PNG) or by decoding it.
pub fn image_size(path: &Path) -> Result<(u32, u32)> {
    let mut head = [0u8; 24];
    use std::io::Read;
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .context_with(|| format!("cannot read image {}", path.display()))?;
    if n == 24 && head[..8] == *b"\x89PNG\r\n\x1a\n" && head[12..16] == *b"IHDR" {
        let w = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
        let h = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
        return Ok((w, h));
    }
    let img = slam_frontend::read_image(path, false)?;
    Ok((img.width, img.height))
}

/// A stereo pair: both images readable and of the same size (a mismatch names both files).
pub fn stereo_pair(left: &Path, right: &Path) -> Result<(u32, u32)> {
    let l = image_size(left)?;
    let r = image_size(right)?;
    if l != r {
        return Err(RunnerError::Invalid(format!(
            "image sizes differ: left {} is {}×{}, right {} is {}×{} (a stereo pair must have one size)",
            left.display(),
            l.0,
            l.1,
            right.display(),
            r.0,
            r.1
        )));
    }
    if l.0 == 0 || l.1 == 0 {
        return Err(RunnerError::Invalid(format!("{}: empty image ({}×{})", left.display(), l.0, l.1)));
    }
    Ok(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PNG header (signature + IHDR) of the given size; the rest of the file is not needed.
    fn png_header(w: u32, h: u32) -> Vec<u8> {
        let mut b = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
        b.extend(w.to_be_bytes());
        b.extend(h.to_be_bytes());
        b
    }

    #[test]
    fn pair_sizes_come_from_png_headers_and_mismatches_name_both_files() {
        let dir = std::env::temp_dir().join(format!("slam-runner-check-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let (l, r, z) = (dir.join("l.png"), dir.join("r.png"), dir.join("z.png"));
        std::fs::write(&l, png_header(1242, 375)).expect("write");
        std::fs::write(&r, png_header(1241, 375)).expect("write");
        std::fs::write(&z, png_header(0, 375)).expect("write");
        assert_eq!(image_size(&l).expect("size"), (1242, 375));
        assert_eq!(stereo_pair(&l, &l).expect("same"), (1242, 375));
        let e = stereo_pair(&l, &r).expect_err("differ").to_string();
        assert!(e.contains("l.png is 1242×375") && e.contains("r.png is 1241×375"), "{e}");
        assert!(stereo_pair(&z, &z).expect_err("empty").to_string().contains("empty image"));
        assert!(image_size(&dir.join("missing.png")).expect_err("missing").to_string().contains("cannot read image"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
