//! Image I/O on the shipped fixtures; bad input gives errors naming the file.

use std::path::PathBuf;

use slam_frontend::{read_image, write_image, FrontendError};

fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures").join(rel)
}

fn frame7() -> PathBuf {
    fixture("kitti_raw_0052/2011_09_26/2011_09_26_drive_0052_sync/image_02/data/0000000007.png")
}

#[test]
fn image_round_trip_and_errors() {
    let img = read_image(frame7(), true).expect("reads");
    assert_eq!((img.width, img.height, img.channels), (1242, 375, 3));
    let grey = read_image(frame7(), false).expect("reads");
    assert_eq!(grey.channels, 1);
    let out = std::env::temp_dir().join(format!("frontend-{}.png", std::process::id()));
    write_image(&out, &img).expect("writes");
    assert_eq!(read_image(&out, true).expect("reads back"), img);
    let missing = read_image("/no/such/image.png", true).expect_err("missing");
    assert!(missing.to_string().contains("/no/such/image.png"));
    let corrupt = std::env::temp_dir().join(format!("frontend-corrupt-{}.png", std::process::id()));
    std::fs::write(&corrupt, b"\x89PNG\r\n\x1a\nnot really").expect("write");
    assert!(matches!(read_image(&corrupt, true), Err(FrontendError::ImageRead { .. })));
}
