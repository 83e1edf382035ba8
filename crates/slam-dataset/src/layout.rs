//! Derived layouts of an odometry sequence: its frames played in another order as a sequence of their
//! own (the images linked, not copied; the calibration linked; the frame times at the sequence's frame
//! period; the ground-truth poses in the same order). Two orders test what a drive over mapped road
//! does: **there and back** (the frames forwards, then backwards, then forwards again ..., each reversal
//! sharing its end frame: a car driving the same street to and fro, reversing without turning), a
//! **standstill** (one frame repeated: a car waiting at a light) and **reversed** (the frames from the
//! last to the first: the same street driven the other way, for a run in the map of the forward
//! drive).

use std::path::{Path, PathBuf};

use crate::DatasetError;

/// An order of a sequence's frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// `legs` legs over the frames: forwards, backwards, forwards, ...; a reversal does not repeat its
    /// end frame (legs of `n` frames give `n + (legs − 1)(n − 1)` frames).
    ThereAndBack {
        /// Legs (at least 1).
        legs: usize,
    },
    /// Frame `at` shown `extra` more times right after itself.
    Standstill {
        /// The frame repeated (an index into the sequence's frames).
        at: usize,
        /// Extra copies.
        extra: usize,
    },
    /// The frames from the last to the first.
    Reversed,
}

/// Most frames a derived layout may have: a day of driving at 10 Hz. Beyond it a typo (a number of
/// legs or copies one meant smaller) would write millions of links.
pub const MAX_FRAMES: usize = 864_000;

impl Order {
    /// The source frame of each frame of the layout, for a sequence of `n` frames.
    pub fn frames(&self, n: usize) -> Result<Vec<usize>, String> {
        if n == 0 {
            return Err("the sequence has no frames".into());
        }
        let total = match *self {
            Order::ThereAndBack { legs: 0 } => return Err("a drive there and back needs at least 1 leg".into()),
            Order::ThereAndBack { legs } => (legs - 1).saturating_mul(n - 1).saturating_add(n),
            Order::Standstill { at, .. } if at >= n => {
                return Err(format!("frame {at} is not one of the sequence's {n} frames (0 to {})", n - 1))
            }
            Order::Standstill { extra, .. } => n.saturating_add(extra),
            Order::Reversed => n,
        };
        if total > MAX_FRAMES {
            return Err(format!("{total} frames: a derived layout has at most {MAX_FRAMES} (a day at 10 Hz)"));
        }
        Ok(match *self {
            Order::ThereAndBack { legs } => {
                let mut out: Vec<usize> = (0..n).collect();
                for leg in 1..legs {
                    if leg % 2 == 1 {
                        out.extend((0..n - 1).rev());
                    } else {
                        out.extend(1..n);
                    }
                }
                out
            }
            Order::Standstill { at, extra } => {
                (0..=at).chain(std::iter::repeat_n(at, extra)).chain(at + 1..n).collect()
            }
            Order::Reversed => (0..n).rev().collect(),
        })
    }
}

/// Write the layout of odometry sequence `sequence` (a `sequences/NN` folder with `image_0`, `image_1`,
/// `calib.txt`, and maybe `times.txt` and `../../poses/NN.txt`) played in `order` into `out` (which must
/// not exist, or be an empty folder): `out/sequences/NN/{image_0, image_1}` links to the source images,
/// `calib.txt` linked, `times.txt` at the source's median frame period (0.1 s without times), and
/// `out/poses/NN.txt` in the same order when the source has poses. Returns the new sequence folder.
pub fn write_layout(sequence: &Path, order: Order, out: &Path) -> Result<PathBuf, DatasetError> {
    let invalid = |path: &Path, message: String| DatasetError::Invalid { path: path.to_path_buf(), message };
    let seq = crate::kitti::stereo::open_stereo(sequence)?;
    if seq.layout != crate::kitti::stereo::Layout::Odometry {
        return Err(invalid(sequence, "a derived layout is made from an odometry sequence (sequences/NN)".into()));
    }
    let name = sequence
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| invalid(sequence, "the sequence folder has no name".into()))?;
    let frames = order.frames(seq.ids.len()).map_err(|m| invalid(sequence, m))?;
    if out.exists()
        && std::fs::read_dir(out)
            .map_err(|source| DatasetError::Io { path: out.to_path_buf(), source })?
            .next()
            .is_some()
    {
        return Err(invalid(out, "exists and is not empty: a layout is written into a new or empty folder".into()));
    }
    let dir = out.join("sequences").join(name);
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| DatasetError::Io { path, source }
    };
    let absolute = |p: &Path| std::fs::canonicalize(p).map_err(io(p));
    for (cam, images) in [("image_0", &seq.left), ("image_1", &seq.right)] {
        let folder = dir.join(cam);
        std::fs::create_dir_all(&folder).map_err(io(&folder))?;
        for (i, &f) in frames.iter().enumerate() {
            let target = absolute(&images[f])?;
            let link = folder.join(format!("{i:06}.png"));
            std::os::unix::fs::symlink(&target, &link).map_err(io(&link))?;
        }
    }
    let calib = dir.join("calib.txt");
    std::os::unix::fs::symlink(absolute(&sequence.join("calib.txt"))?, &calib).map_err(io(&calib))?;
    let mut steps: Vec<f64> = seq.times.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    steps.sort_by(f64::total_cmp);
    let period = steps.get(steps.len() / 2).copied().unwrap_or(0.1);
    let times: String = (0..frames.len()).map(|i| format!("{:.6e}\n", period * i as f64)).collect();
    slam_core::files::write_atomic(&dir.join("times.txt"), times.as_bytes())?;
    let poses = sequence.join("../../poses").join(format!("{name}.txt"));
    if poses.is_file() {
        let text = crate::read_text(&poses, &slam_core::files::DOCUMENT)?;
        let lines: Vec<&str> = text.lines().collect();
        let mut reordered = String::new();
        for &f in &frames {
            let id = seq.ids[f];
            let line = lines.get(id).ok_or_else(|| invalid(&poses, format!("no line for frame {id}")))?;
            reordered.push_str(line);
            reordered.push('\n');
        }
        let folder = out.join("poses");
        std::fs::create_dir_all(&folder).map_err(io(&folder))?;
        slam_core::files::write_atomic(&folder.join(format!("{name}.txt")), reordered.as_bytes())?;
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orders_give_the_frames_of_a_drive_there_and_back_of_a_standstill_and_reversed() {
        assert_eq!(Order::ThereAndBack { legs: 1 }.frames(3), Ok(vec![0, 1, 2]));
        assert_eq!(Order::Reversed.frames(4), Ok(vec![3, 2, 1, 0]));
        assert!(Order::Reversed.frames(0).is_err());
        assert_eq!(Order::ThereAndBack { legs: 3 }.frames(3), Ok(vec![0, 1, 2, 1, 0, 1, 2]));
        assert_eq!(Order::ThereAndBack { legs: 5 }.frames(51).map(|f| f.len()), Ok(251));
        assert_eq!(Order::Standstill { at: 1, extra: 2 }.frames(4), Ok(vec![0, 1, 1, 1, 2, 3]));
        assert!(Order::Standstill { at: 4, extra: 2 }.frames(4).is_err());
        assert!(Order::ThereAndBack { legs: 0 }.frames(4).is_err());
        assert!(Order::ThereAndBack { legs: 1 << 40 }.frames(51).expect_err("too many").contains("at most"));
        assert!(Order::Standstill { at: 0, extra: usize::MAX }.frames(51).is_err());
    }

    /// The shipped odometry excerpt there and back: every link points at the source frame the order
    /// gives, the poses follow it line for line, the times at 0.1 s; an existing non-empty folder is
    /// refused.
    #[test]
    fn a_layout_links_the_frames_in_order_with_their_poses() {
        let src = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_odom_06/sequences/06"));
        let out = std::env::temp_dir().join(format!("layout-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let dir = write_layout(&src, Order::ThereAndBack { legs: 3 }, &out).expect("layout");
        let order = Order::ThereAndBack { legs: 3 }.frames(51).expect("order");
        let poses = std::fs::read_to_string(out.join("poses/06.txt")).expect("poses");
        let source_poses = std::fs::read_to_string(src.join("../../poses/06.txt")).expect("source poses");
        let source: Vec<&str> = source_poses.lines().collect();
        for (i, (line, &f)) in poses.lines().zip(&order).enumerate() {
            assert_eq!(line, source[f], "pose of frame {i}");
            let link = std::fs::read_link(dir.join(format!("image_0/{i:06}.png"))).expect("link");
            assert!(link.ends_with(format!("image_0/{f:06}.png")), "{link:?}");
        }
        assert_eq!(poses.lines().count(), order.len());
        let seq = crate::kitti::stereo::open_stereo(&dir).expect("opens as a sequence");
        assert_eq!(seq.ids.len(), 151);
        assert!((seq.times[150] - 15.0).abs() < 1e-9, "{}", seq.times[150]);
        assert!(seq.ground_truth.is_some());
        let again = write_layout(&src, Order::Standstill { at: 20, extra: 2 }, &out).expect_err("not empty");
        assert!(again.to_string().contains("not empty"), "{again}");
        let _ = std::fs::remove_dir_all(&out);
    }
}
