//! CSV files the app writes are real CSV: a field holding the delimiter (a sequence folder named with a
//! comma) is quoted, so every row still has the header's columns.

use std::process::Command;

#[test]
fn a_sequence_named_with_a_comma_stays_one_field() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");
    let dir = std::env::temp_dir().join(format!("slam-app-csv-{}", std::process::id()));
    let seq = dir.join("drive,03");
    std::fs::create_dir_all(&seq).expect("dir");
    std::fs::copy(format!("{root}/fixtures/kitti_tracking/0003/label_02.txt"), seq.join("label_02.txt"))
        .expect("copy labels");
    let out = dir.join("assoc.csv");
    let o = Command::new(env!("CARGO_BIN_EXE_slam-app"))
        .current_dir(root)
        .args(["assoc", "kitti"])
        .arg(&dir)
        .arg("--csv")
        .arg(&out)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut reader = csv::Reader::from_path(&out).expect("CSV opens");
    let header = reader.headers().expect("header").clone();
    assert_eq!(header.len(), 6, "{header:?}");
    let rows: Vec<csv::StringRecord> = reader.records().collect::<Result<_, _>>().expect("rows parse");
    // three conditions × two associators
    assert_eq!(rows.len(), 6);
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
        assert_eq!(&r[0], "drive,03");
        assert!(r[5].parse::<usize>().is_ok(), "id switches: {r:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
