//! The shipped YOLOX-nano on ONNX Runtime (the library `tools/setup.sh` installs): the file is the
//! original export with a symbolic input height and width and nothing else changed, it runs at 416 × 416
//! and 736 × 224, and at 416 × 416 it gives the original's output.

use std::{ops::Range, path::PathBuf};

use sha2::{Digest, Sha256};
use slam_detect::onnx::{OnnxNet, RuntimeOptions};
use slam_frontend::read_image;

fn repo(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

fn runtime() -> RuntimeOptions {
    RuntimeOptions::cpu(repo(".ort"))
}

/// sha256 of the upstream export (fixtures/yolox_nano/SOURCE.md), whose input is fixed at 1 × 3 × 416 × 416.
const ORIGINAL_SHA256: &str = "695e750a5d5754bb5a8d5325643b59282191a7e7a564e435a415fd3c578eab14";

// A protocol-buffer reader just large enough to walk down to the input's shape and write it back: an ONNX
// file is a serialised `ModelProto`.

fn varint(b: &[u8], i: &mut usize) -> u64 {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = b[*i];
        *i += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte & 0x80 == 0 {
            break;
        }
    }
    v
}

fn put_varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The fields of one message: number, the whole field's bytes and its payload's.
fn fields(msg: &[u8]) -> Vec<(u64, Range<usize>, Range<usize>)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < msg.len() {
        let start = i;
        let key = varint(msg, &mut i);
        let payload = match key & 7 {
            0 => {
                let from = i;
                varint(msg, &mut i);
                from..i
            }
            1 => i..i + 8,
            2 => {
                let len = varint(msg, &mut i) as usize;
                i..i + len
            }
            5 => i..i + 4,
            other => panic!("wire type {other} is not in an ONNX file"),
        };
        i = payload.end;
        out.push((key >> 3, start..i, payload));
    }
    out
}

/// `msg` with the `nth` field numbered `number` (a message) replaced by `edit` of its payload.
fn replace(msg: &[u8], number: u64, nth: usize, edit: &dyn Fn(&[u8]) -> Vec<u8>) -> Vec<u8> {
    let mut out = Vec::with_capacity(msg.len() + 16);
    let mut seen = 0;
    for (n, whole, payload) in fields(msg) {
        if n == number {
            if seen == nth {
                let new = edit(&msg[payload]);
                put_varint((number << 3) | 2, &mut out);
                put_varint(new.len() as u64, &mut out);
                out.extend(new);
                seen += 1;
                continue;
            }
            seen += 1;
        }
        out.extend_from_slice(&msg[whole]);
    }
    assert!(seen > nth, "field {number} #{nth} not found");
    out
}

/// The shipped model with its input's height and width set back to 416: ModelProto.graph (7) →
/// GraphProto.input (11) → ValueInfoProto.type (2) → TypeProto.tensor_type (1) → shape (2) → dims 3 and 4
/// (field 1), each a `Dimension` holding only `dim_value` (field 1) = 416.
fn with_fixed_input(model: &[u8]) -> Vec<u8> {
    let dim = |_: &[u8]| {
        let mut d = vec![0x08];
        put_varint(416, &mut d);
        d
    };
    let shape = |s: &[u8]| replace(&replace(s, 1, 2, &dim), 1, 3, &dim);
    let tensor = |t: &[u8]| replace(t, 2, 0, &shape);
    let ty = |t: &[u8]| replace(t, 1, 0, &tensor);
    let value_info = |v: &[u8]| replace(v, 2, 0, &ty);
    let graph = |g: &[u8]| replace(g, 11, 0, &value_info);
    replace(model, 7, 0, &graph)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The shipped frame 50 of drive 0005 (grey camera 0) sampled into a `1 × 3 × h × w` blob, BGR 0-255 (the
/// grey value in all three channels), nearest pixel: the same input for both models.
fn blob(w: usize, h: usize) -> Vec<f32> {
    let frame = repo("fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync/image_00/data/0000000050.png");
    let img = read_image(frame, false).expect("reads");
    let (iw, ih) = (img.width as usize, img.height as usize);
    let mut out = vec![0f32; 3 * w * h];
    for y in 0..h {
        for x in 0..w {
            let v = f32::from(img.data[(y * ih / h) * iw + x * iw / w]);
            for c in 0..3 {
                out[(c * h + y) * w + x] = v;
            }
        }
    }
    out
}

#[test]
fn the_shipped_model_is_the_original_with_a_symbolic_input_size() {
    let shipped = std::fs::read(repo("fixtures/yolox_nano/yolox_nano.onnx")).expect("the shipped model");
    let original = with_fixed_input(&shipped);
    assert_ne!(original, shipped, "the shipped input is not fixed");
    assert_eq!(hex(&Sha256::digest(&original)), ORIGINAL_SHA256, "only the input's height and width differ");
}

#[test]
fn it_runs_at_any_multiple_of_32_and_equals_the_original_at_416() {
    let shipped = repo("fixtures/yolox_nano/yolox_nano.onnx");
    let original = std::env::temp_dir().join(format!("yolox-nano-416-{}.onnx", std::process::id()));
    std::fs::write(&original, with_fixed_input(&std::fs::read(&shipped).expect("read"))).expect("write");
    let mut symbolic = OnnxNet::load(&shipped, &runtime()).expect("the shipped model loads");
    let mut fixed = OnnxNet::load(&original, &runtime()).expect("the original loads");

    let input = blob(416, 416);
    let (shape, a) = symbolic.forward(&input, [416, 416], |s, v| (s.to_vec(), v.to_vec())).expect("runs");
    let (shape_fixed, b) = fixed.forward(&input, [416, 416], |s, v| (s.to_vec(), v.to_vec())).expect("runs");
    // 52 × 52 + 26 × 26 + 13 × 13 = 3549 cells of 85 values
    assert_eq!((shape.as_slice(), shape_fixed.as_slice()), (&[1i64, 3549, 85][..], &[1i64, 3549, 85][..]));
    let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(worst <= 1e-4, "largest difference {worst}");
    assert!(a.chunks_exact(85).any(|row| row[4] > 0.5), "something is found in the frame");
    assert!(symbolic.take_forward_ms() > 0.0, "forward passes are timed");

    // the KITTI input: 92 × 28 + 46 × 14 + 23 × 7 = 3381 cells; the original refuses it
    let wide = blob(736, 224);
    let shape = symbolic.forward(&wide, [736, 224], |s, _| s.to_vec()).expect("runs at 736 x 224");
    assert_eq!(shape, [1, 3381, 85]);
    let e = fixed.forward(&wide, [736, 224], |_, _| ()).expect_err("fixed at 416").to_string();
    assert!(e.contains("dimensions"), "{e}");
    std::fs::remove_file(&original).ok();
}
