//! Finding inputs in folders: the images of a sequence or of a plain folder ([`list_images`]), their
//! frame ids ([`frame_ids`]), and the sequence folders of an image-free KITTI tracking folder
//! ([`tracking_sequences`]).

use std::path::{Path, PathBuf};

use crate::{kitti::frames::frame_id, DatasetError};

/// The images to run a detector over: the left images of a KITTI stereo sequence in any layout
/// [`open_stereo`](crate::kitti::stereo::open_stereo) accepts, else the PNG / JPG files of `input` or of
/// its `image_2`, `image_02/data`, `image_0` or `image_00/data` (the first that has any); sorted by frame
/// id when the names are numbers (9.png before 10.png), else by name.
pub fn list_images(input: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let mut images = match crate::kitti::stereo::open_stereo(input) {
        Ok(seq) => seq.left,
        Err(_) => image_files(input).ok_or_else(|| DatasetError::Invalid {
            path: input.to_path_buf(),
            message: "is neither a KITTI stereo sequence (odometry, raw or tracking layout) nor a folder of PNG/JPG \
                      images (searched also its image_2, image_02/data, image_0, image_00/data)"
                .into(),
        })?,
    };
    images.sort_by_key(|p| (frame_id(p), p.clone()));
    Ok(images)
}

fn image_files(input: &Path) -> Option<Vec<PathBuf>> {
    let candidates = [
        input.to_path_buf(),
        input.join("image_2"),
        input.join("image_02/data"),
        input.join("image_0"),
        input.join("image_00/data"),
    ];
    for dir in candidates {
        let Ok(rd) = std::fs::read_dir(&dir) else { continue };
        let mut v: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png") || x.eq_ignore_ascii_case("jpg")))
            .collect();
        if !v.is_empty() {
            v.sort();
            return Some(v);
        }
    }
    None
}

/// The frame id of each image: the number in its file name (KITTI's `000042.png` is frame 42), so that
/// a detection file lines up with ground truth however frames are missing. `None` when the names are
/// not all distinct increasing numbers (the caller then numbers by position).
pub fn frame_ids(images: &[PathBuf]) -> Option<Vec<usize>> {
    let ids: Option<Vec<usize>> = images.iter().map(|p| frame_id(p)).collect();
    ids.filter(|ids| ids.windows(2).all(|w| w[0] < w[1]))
}

/// The sequence folders (those holding `label_02.txt`) of an image-free KITTI tracking folder, sorted;
/// a sequence folder itself is the one sequence.
pub fn tracking_sequences(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    if dir.join("label_02.txt").is_file() {
        return Ok(vec![dir.to_path_buf()]);
    }
    let mut seqs: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| DatasetError::Invalid { path: dir.to_path_buf(), message: format!("cannot list sequences: {e}") })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("label_02.txt").is_file())
        .collect();
    seqs.sort();
    if seqs.is_empty() {
        return Err(DatasetError::Invalid {
            path: dir.to_path_buf(),
            message: "is neither a sequence folder (label_02.txt, poses_orbslam3.txt, calib.txt) nor a folder of them"
                .into(),
        });
    }
    Ok(seqs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("slam-dataset-folders-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("scratch");
        d
    }

    #[test]
    fn images_are_found_in_kitti_subfolders_and_sorted_by_number() {
        let root = scratch("images");
        let dir = root.join("image_02/data");
        std::fs::create_dir_all(&dir).expect("dir");
        for n in ["10.png", "9.png", "notes.txt", "11.JPG"] {
            std::fs::write(dir.join(n), b"x").expect("write");
        }
        let found = list_images(&root).expect("found");
        let names: Vec<String> = found.iter().map(|p| p.file_name().expect("name").to_string_lossy().into()).collect();
        assert_eq!(names, ["9.png", "10.png", "11.JPG"]);
        assert_eq!(frame_ids(&found), Some(vec![9, 10, 11]));
        assert_eq!(frame_ids(&[dir.join("a.png"), dir.join("b.png")]), None, "names are not numbers");
        let e = list_images(&scratch("empty")).expect_err("nothing").to_string();
        assert!(e.contains("is neither a KITTI stereo sequence"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn tracking_sequences_are_the_labelled_subfolders_sorted() {
        let root = scratch("tracking");
        for s in ["0002", "0000", "junk"] {
            std::fs::create_dir_all(root.join(s)).expect("dir");
        }
        std::fs::write(root.join("0002/label_02.txt"), b"").expect("write");
        std::fs::write(root.join("0000/label_02.txt"), b"").expect("write");
        assert_eq!(tracking_sequences(&root).expect("two"), [root.join("0000"), root.join("0002")]);
        assert_eq!(tracking_sequences(&root.join("0002")).expect("itself"), [root.join("0002")]);
        let e = tracking_sequences(&root.join("junk")).expect_err("none").to_string();
        assert!(e.contains("is neither a sequence folder"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }
}
