//! A borrowed 8-bit grey image: what feature extraction (orientation) and stereo matching (sub-pixel
//! block matching) read pixels from, in a file of its own so that neither depends on the other.

use opencv::{core::Mat, prelude::*};

use crate::image_io::FrontendError;

/// A borrowed 8-bit grey image.
pub(crate) struct GreyView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
}

impl<'a> GreyView<'a> {
    pub(crate) fn of(m: &'a Mat) -> Result<Self, FrontendError> {
        Ok(Self { data: m.data_bytes()?, width: m.cols() as usize, height: m.rows() as usize })
    }

    /// Width and height, pixels.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The pixels, row by row.
    pub(crate) fn data(&self) -> &[u8] {
        self.data
    }

    pub(crate) fn at(&self, x: i64, y: i64) -> Option<i32> {
        (x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height)
            .then(|| self.data[y as usize * self.width + x as usize] as i32)
    }
}
