//! The bad-input suite, readers: every parser fed truncated, malformed, non-finite, out-of-range, empty
//! and wrongly typed text returns an error naming the file (and the line where there is one); nothing
//! panics and nothing is silently dropped. (`crates/slam-app/tests/bad_input.rs` has the commands.)

use std::path::Path;

use slam_dataset::{
    detections::DetectionFile,
    kitti::{
        calib::Calib,
        poses::parse_kitti_poses,
        raw::{parse_oxts_packet, parse_timestamps},
        tracking::parse_tracking_labels,
        tracklets::parse_tracklets,
    },
    trajectory::parse_tum,
    DatasetError,
};

/// What an error must say: the file, the line (when `Some`) and a piece of its message.
fn expect(name: &str, r: Result<(), DatasetError>, line: Option<usize>, text: &str) -> Result<(), String> {
    let Err(e) = r else { return Err(format!("{name}: accepted")) };
    let s = e.to_string();
    let line_ok = match (line, &e) {
        (Some(l), DatasetError::Parse { line, .. }) => *line == l,
        (Some(_), _) => false,
        (None, _) => true,
    };
    if !s.contains(name) || !s.contains(text) || !line_ok {
        return Err(format!("{name}: want line {line:?} and '{text}', got: {s}"));
    }
    Ok(())
}

const OXTS: &str = "49.0 8.4 112.9 0.02 0.01 1.5 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24";
const POSE: &str = "1 0 0 0 0 1 0 0 0 0 1 0";
const LABEL: &str = "0 0 Car 0 0 -1.5 10 20 50 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1";

fn tracklets(count: usize, poses: &str, declared_poses: usize) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<boost_serialization>\n<tracklets>\n<count>{count}</count>\n<item>\n\
         <objectType>Car</objectType>\n<h>1.5</h>\n<w>1.6</w>\n<l>3.9</l>\n<first_frame>0</first_frame>\n\
         <poses>\n<count>{declared_poses}</count>\n{poses}</poses>\n</item>\n</tracklets>\n</boost_serialization>\n"
    )
}

fn pose_item(tx: &str) -> String {
    format!(
        "<item><tx>{tx}</tx><ty>0</ty><tz>0</tz><rx>0</rx><ry>0</ry><rz>0</rz><state>1</state>\
         <occlusion>0</occlusion><truncation>0</truncation></item>\n"
    )
}

fn unit<T>(r: Result<T, DatasetError>) -> Result<(), DatasetError> {
    r.map(|_| ())
}

#[test]
fn every_reader_names_file_and_line() {
    let p = |n: &str| Path::new(n).to_path_buf();
    let det = |body: &str| format!(r#"{{"version":1,"frames":[{{"frame":3,"detections":[{body}]}}]}}"#);
    let rle = |size: &str, counts: &str| {
        det(&format!(
            r#"{{"class":2,"score":0.5,"box":[1,1,5,5],"mask":{{"rle":{{"size":{size},"counts":{counts}}}}}}}"#
        ))
    };
    let poly = |pts: &str| det(&format!(r#"{{"class":2,"score":0.5,"box":[1,1,5,5],"mask":{{"polygon":{pts}}}}}"#));
    type Case<'a> = (&'a str, Result<(), DatasetError>, Option<usize>, &'a str);
    let cases: Vec<Case> = vec![
        // OXTS packets
        ("oxts-empty.txt", unit(parse_oxts_packet(&p("oxts-empty.txt"), "\n\n")), None, "empty OXTS packet"),
        (
            "oxts-short.txt",
            unit(parse_oxts_packet(&p("oxts-short.txt"), "49.0 8.4 112.9")),
            Some(1),
            "expected 30 numbers, found 3",
        ),
        (
            "oxts-nan.txt",
            unit(parse_oxts_packet(&p("oxts-nan.txt"), &OXTS.replacen("112.9", "nan", 1))),
            Some(1),
            "non-finite",
        ),
        (
            "oxts-word.txt",
            unit(parse_oxts_packet(&p("oxts-word.txt"), &format!("\n{}", OXTS.replacen("8.4", "east", 1)))),
            Some(2),
            "not a number: 'east'",
        ),
        ("oxts-long.txt", unit(parse_oxts_packet(&p("oxts-long.txt"), &format!("{OXTS} 25"))), Some(1), "found 31"),
        // timestamps
        ("ts-date.txt", unit(parse_timestamps(&p("ts-date.txt"), "2011-09-26\n")), Some(1), "expected 'date time'"),
        (
            "ts-colon.txt",
            unit(parse_timestamps(&p("ts-colon.txt"), "2011-09-26 13:02:25.9\n2011-09-26 13:02\n")),
            Some(2),
            "HH:MM:SS",
        ),
        ("ts-word.txt", unit(parse_timestamps(&p("ts-word.txt"), "2011-09-26 13:xx:25.9\n")), Some(1), "bad minute"),
        ("ts-inf.txt", unit(parse_timestamps(&p("ts-inf.txt"), "2011-09-26 13:02:inf\n")), Some(1), "non-finite"),
        (
            "ts-gap.txt",
            unit(parse_timestamps(&p("ts-gap.txt"), "2011-09-26 13:02:25.9\n\n2011-09-26 13:02:26.0\n")),
            Some(2),
            "blank line between frame lines",
        ),
        // KITTI poses
        (
            "poses-inf.txt",
            unit(parse_kitti_poses(&p("poses-inf.txt"), &format!("{POSE}\n1 0 0 inf 0 1 0 0 0 0 1 0\n"))),
            Some(2),
            "non-finite",
        ),
        ("poses-13.txt", unit(parse_kitti_poses(&p("poses-13.txt"), &format!("{POSE} 1\n"))), Some(1), "found 13"),
        ("poses-zero.txt", unit(parse_kitti_poses(&p("poses-zero.txt"), "0 0 0 0 0 0 0 0 0 0 0 0\n")), Some(1), ""),
        (
            "poses-word.txt",
            unit(parse_kitti_poses(&p("poses-word.txt"), &POSE.replacen('0', "o", 1))),
            Some(1),
            "not a number: 'o'",
        ),
        // TUM
        (
            "poses-far.txt",
            unit(parse_kitti_poses(&p("poses-far.txt"), &format!("{POSE}\n1 0 0 1e300 0 1 0 0 0 0 1 0\n"))),
            Some(2),
            "a drive's poses stay within",
        ),
        (
            "oxts-lat.txt",
            unit(parse_oxts_packet(&p("oxts-lat.txt"), &OXTS.replacen("49.0", "95.0", 1))),
            Some(1),
            "not geographic coordinates",
        ),
        (
            "ts-clock.txt",
            unit(parse_timestamps(&p("ts-clock.txt"), "2011-09-26 25:99:32.4\n")),
            Some(1),
            "not a time of day",
        ),
        (
            "ts-back.txt",
            unit(parse_timestamps(&p("ts-back.txt"), "2011-09-26 13:02:25.9\n2011-09-26 13:02:25.8\n")),
            Some(2),
            "is not after the line before",
        ),
        (
            "labels-type.txt",
            unit(parse_tracking_labels(&p("labels-type.txt"), &LABEL.replacen("Car", "Spaceship", 1))),
            Some(1),
            "unknown type 'Spaceship'",
        ),
        (
            "labels-size.txt",
            unit(parse_tracking_labels(&p("labels-size.txt"), &LABEL.replacen("1.5 1.6 3.9", "1.5 0 3.9", 1))),
            Some(1),
            "each must be positive",
        ),
        ("labels-empty.txt", unit(parse_tracking_labels(&p("labels-empty.txt"), "\n")), None, "no labels"),
        (
            "det-mask-size.json",
            unit(DetectionFile::parse(
                &p("det-mask-size.json"),
                r#"{"version":1,"image_size":[1242,375],"frames":[{"frame":0,"detections":[{"class":2,"score":0.5,"box":[1,1,5,5],"mask":{"rle":{"size":[10,10],"counts":[100]}}}]}]}"#,
            )),
            None,
            "mask size 10×10 (height × width) is not the image's 375×1242",
        ),
        (
            "labels-trunc.txt",
            unit(parse_tracking_labels(&p("labels-trunc.txt"), &LABEL.replacen("Car 0 0", "Car 7 0", 1))),
            Some(1),
            "truncated 7 outside 0-2",
        ),
        (
            "calib-twice.txt",
            unit(Calib::parse(&p("calib-twice.txt"), "P1: 1 2 3\nP1: 4 5 6\n")),
            Some(2),
            "key 'P1' again (first on line 1)",
        ),
        (
            "calib-rot.txt",
            unit(Calib::parse(&p("calib-rot.txt"), "R: 1 0 0 0 2 0 0 0 1\n").and_then(|c| c.rotation("R"))),
            Some(1),
            "'R' is not a rotation",
        ),
        ("tum-7.tum", unit(parse_tum(&p("tum-7.tum"), "0 0 0 0 0 0 1\n")), Some(1), "expected 8 numbers, found 7"),
        (
            "tum-zero-q.tum",
            unit(parse_tum(&p("tum-zero-q.tum"), "# t x y z qx qy qz qw\n0 0 0 0 0 0 0 0\n")),
            Some(2),
            "quaternion is not unit",
        ),
        ("tum-nan.tum", unit(parse_tum(&p("tum-nan.tum"), "nan 0 0 0 0 0 0 1\n")), Some(1), "non-finite"),
        // tracking labels
        (
            "labels-short.txt",
            unit(parse_tracking_labels(&p("labels-short.txt"), &format!("{LABEL}\n0 1 Car 0\n"))),
            Some(2),
            "",
        ),
        (
            "labels-inf.txt",
            unit(parse_tracking_labels(&p("labels-inf.txt"), &LABEL.replace("20.0", "-inf"))),
            Some(1),
            "non-finite",
        ),
        (
            "labels-frame.txt",
            unit(parse_tracking_labels(&p("labels-frame.txt"), &LABEL.replacen("0 0 Car", "-3 0 Car", 1))),
            Some(1),
            "",
        ),
        // calibration
        (
            "calib-nan.txt",
            unit(
                Calib::parse(&p("calib-nan.txt"), "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nP1: nan 0 0 0 0 1 0 0 0 0 1 0\n")
                    .and_then(|c| c.matrix3x4("P1")),
            ),
            Some(2),
            "non-finite",
        ),
        (
            "calib-missing.txt",
            unit(
                Calib::parse(&p("calib-missing.txt"), "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n").and_then(|c| c.matrix3x4("P1")),
            ),
            None,
            "P1",
        ),
        (
            "calib-short.txt",
            unit(Calib::parse(&p("calib-short.txt"), "R0_rect: 1 0 0 0 1 0 0 0\n").and_then(|c| c.matrix3("R0_rect"))),
            Some(1),
            "",
        ),
        // tracklets
        (
            "tl-unbalanced.xml",
            unit(parse_tracklets(&p("tl-unbalanced.xml"), "<boost_serialization><tracklets>")),
            None,
            "",
        ),
        (
            "tl-count.xml",
            unit(parse_tracklets(&p("tl-count.xml"), &tracklets(2, &pose_item("1"), 1))),
            None,
            "declares 2 tracklets, has 1",
        ),
        (
            "tl-poses.xml",
            unit(parse_tracklets(&p("tl-poses.xml"), &tracklets(1, &pose_item("1"), 3))),
            None,
            "declares 3 poses, has 1",
        ),
        (
            "tl-nan.xml",
            unit(parse_tracklets(&p("tl-nan.xml"), &tracklets(1, &pose_item("nan"), 1))),
            None,
            "<tx> is not a finite number",
        ),
        ("tl-empty.xml", unit(parse_tracklets(&p("tl-empty.xml"), "")), None, ""),
        (
            "tl-mismatch.xml",
            unit(parse_tracklets(&p("tl-mismatch.xml"), "<?xml version=\"1.0\"?>\n<tracklets>\n<count>1</item>\n")),
            Some(3),
            "",
        ),
        (
            "tl-deep.xml",
            unit(parse_tracklets(&p("tl-deep.xml"), &format!("\n{}{}", "<a>".repeat(5000), "</a>".repeat(5000)))),
            Some(2),
            "nest deeper than 64",
        ),
        (
            "tl-no-tracklets.xml",
            unit(parse_tracklets(
                &p("tl-no-tracklets.xml"),
                "<!DOCTYPE boost_serialization>\n<boost_serialization>\n</boost_serialization>",
            )),
            Some(2),
            "no <tracklets> element",
        ),
        // detection files
        (
            "det-neg-score.json",
            unit(DetectionFile::parse(&p("det-neg-score.json"), &det(r#"{"class":2,"score":-0.1,"box":[1,1,5,5]}"#))),
            None,
            "frame 3 detection 0: score -0.1",
        ),
        (
            "det-empty-box.json",
            unit(DetectionFile::parse(&p("det-empty-box.json"), &det(r#"{"class":2,"score":0.5,"box":[5,1,5,5]}"#))),
            None,
            "frame 3 detection 0",
        ),
        (
            "det-rle-sum.json",
            unit(DetectionFile::parse(&p("det-rle-sum.json"), &rle("[4, 4]", "[3, 2]"))),
            None,
            "RLE counts sum to 5, image has 16 pixels",
        ),
        (
            "det-rle-huge.json",
            unit(DetectionFile::parse(&p("det-rle-huge.json"), &rle("[100000, 100000]", "[1]"))),
            None,
            "larger than 100 megapixels",
        ),
        (
            "det-poly-2.json",
            unit(DetectionFile::parse(&p("det-poly-2.json"), &poly("[[1, 1], [2, 2]]"))),
            None,
            "at least 3 finite points",
        ),
        (
            "det-poly-huge.json",
            unit(DetectionFile::parse(&p("det-poly-huge.json"), &poly("[[0, 0], [1e6, 0], [1e6, 1e6]]"))),
            None,
            "polygon too large",
        ),
        (
            "det-unknown-key.json",
            unit(DetectionFile::parse(
                &p("det-unknown-key.json"),
                &det(r#"{"class":2,"score":0.5,"box":[1,1,5,5],"colour":"red"}"#),
            )),
            Some(1),
            "colour",
        ),
        (
            "det-negative-frame.json",
            unit(DetectionFile::parse(
                &p("det-negative-frame.json"),
                r#"{"version":1,"frames":[{"frame":-1,"detections":[]}]}"#,
            )),
            Some(1),
            "",
        ),
        ("det-empty.json", unit(DetectionFile::parse(&p("det-empty.json"), "")), Some(1), "EOF"),
        (
            "det-class-big.json",
            unit(DetectionFile::parse(
                &p("det-class-big.json"),
                &det(r#"{"class":70000,"score":0.5,"box":[1,1,5,5]}"#),
            )),
            Some(1),
            "",
        ),
    ];
    let n = cases.len();
    let failures: Vec<String> =
        cases.into_iter().filter_map(|(name, r, line, text)| expect(name, r, line, text).err()).collect();
    assert!(failures.is_empty(), "{} of {n} cases failed:\n{}", failures.len(), failures.join("\n"));
    assert!(n >= 35, "{n}");
}
