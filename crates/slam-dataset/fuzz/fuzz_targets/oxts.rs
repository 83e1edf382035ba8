//! Fuzz target: arbitrary text must give a value or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(s) = std::str::from_utf8(data) {
        let path = std::path::Path::new("fuzz-input");
        let _ = slam_dataset::kitti::raw::parse_oxts_packet(path, s).map(|p| slam_dataset::kitti::raw::oxts_poses(&[p, p]));
    }
});
