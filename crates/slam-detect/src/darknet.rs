//! A Darknet model's `.weights` checked against its `.cfg` before OpenCV reads them. OpenCV's reader
//! takes as many numbers as each layer of the cfg asks for and does not notice a file that is too
//! short (the missing weights are whatever the memory held: hundreds of junk boxes a frame) or too long
//! (the weights of another, larger model: no box at all). The cfg gives every layer's size, so the file
//! must hold exactly its header and those numbers.

use std::path::Path;

/// Classes of the rows the decode reads: COCO's 80, whose indices are the class ids of a detection.
pub const COCO_CLASSES: usize = 80;

/// What a cfg asks of its weights file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WeightsSize {
    /// 32-bit floats of every layer, in order.
    pub floats: u64,
    /// Layers that hold weights.
    pub layers: usize,
}

/// One `[section]` of a cfg: its type, its `key=value` lines, and its line number.
struct Section {
    kind: String,
    line: usize,
    keys: Vec<(String, String)>,
}

impl Section {
    fn get(&self, key: &str) -> Option<&str> {
        self.keys.iter().rev().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// An integer key, `default` when absent; an error names the line of the section.
    fn int(&self, key: &str, default: i64) -> Result<i64, String> {
        match self.get(key) {
            None => Ok(default),
            Some(v) => {
                v.trim().parse().map_err(|_| format!("line {}: [{}] {key}={v} is not an integer", self.line, self.kind))
            }
        }
    }
}

fn sections(text: &str) -> Vec<Section> {
    let mut out: Vec<Section> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split(['#', ';']).next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if let Some(kind) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            out.push(Section { kind: kind.trim().to_string(), line: i + 1, keys: Vec::new() });
        } else if let (Some(s), Some((k, v))) = (out.last_mut(), line.split_once('=')) {
            s.keys.push((k.trim().to_string(), v.trim().to_string()));
        }
    }
    out
}

/// The weights a cfg's layers need, and a check that its detection layers give the rows the decode
/// reads (at least one `[yolo]` or `[region]` layer, each of [`COCO_CLASSES`] classes). Layers are
/// sized as Darknet (and OpenCV's reader) size them: a convolution of `filters` outputs over the
/// previous layer's channels in `groups` groups holds `filters` biases, with batch normalisation
/// `3 × filters` more (scales, means, variances), and `filters × channels / groups × size²` weights;
/// routes join (and split, with `groups`) earlier layers' channels; `reorg` folds space into channels;
/// the other layers keep their input's channels and hold nothing.
pub fn weights_size(cfg: &str) -> Result<WeightsSize, String> {
    let all = sections(cfg);
    let Some(net) = all.first().filter(|s| s.kind == "net" || s.kind == "network") else {
        return Err("does not start with a [net] section".into());
    };
    let mut channels: Vec<i64> = Vec::new();
    let input = net.int("channels", 3)?;
    let (mut floats, mut layers, mut heads) = (0u64, 0usize, 0usize);
    for s in &all[1..] {
        let i = channels.len() as i64;
        let prev = channels.last().copied().unwrap_or(input);
        let bad = |m: String| format!("line {}: [{}] {m}", s.line, s.kind);
        let out = match s.kind.as_str() {
            "convolutional" => {
                let (filters, size, groups) = (s.int("filters", 1)?, s.int("size", 1)?, s.int("groups", 1)?);
                if filters <= 0 || size <= 0 || groups <= 0 || prev % groups != 0 {
                    return Err(bad(format!(
                        "filters={filters}, size={size}, groups={groups} over {prev} input channels: each must be \
                         positive and groups must divide the channels"
                    )));
                }
                let bn = s.int("batch_normalize", 0)? != 0;
                let (f, c, k) = (filters as u64, (prev / groups) as u64, size as u64);
                floats += f * if bn { 4 } else { 1 } + f * c * k * k;
                layers += 1;
                filters
            }
            "route" => {
                let spec = s.get("layers").ok_or_else(|| bad("has no layers=".into()))?;
                let mut sum = 0;
                for t in spec.split(',') {
                    let v: i64 = t.trim().parse().map_err(|_| bad(format!("layers={spec}: not integers")))?;
                    let at = if v < 0 { i + v } else { v };
                    let c = usize::try_from(at)
                        .ok()
                        .and_then(|a| channels.get(a))
                        .ok_or_else(|| bad(format!("layers={spec}: layer {at} does not come before it")))?;
                    sum += c;
                }
                let groups = s.int("groups", 1)?.max(1);
                sum / groups
            }
            "reorg" => prev * s.int("stride", 2)?.pow(2),
            "yolo" | "region" => {
                let classes = s.int("classes", 0)?;
                if classes != COCO_CLASSES as i64 {
                    return Err(bad(format!(
                        "classes={classes}: the detections are read as COCO's {COCO_CLASSES} classes (a class index \
                         is a COCO class id), so a model of other classes cannot be used"
                    )));
                }
                heads += 1;
                prev
            }
            "maxpool" | "avgpool" | "dropout" | "upsample" | "shortcut" | "softmax" | "scale_channels" | "sam" => prev,
            other => {
                return Err(bad(format!(
                    "a layer type the weights check does not size (neither does OpenCV's Darknet reader, apart from \
                     [connected], which no YOLO detector of rows has): {other}"
                )))
            }
        };
        channels.push(out);
    }
    if heads == 0 {
        return Err("has no [yolo] or [region] layer: its output is not the rows of boxes the decode reads".into());
    }
    Ok(WeightsSize { floats, layers })
}

/// Bytes of a weights file's header: major, minor and revision (32-bit each), then the count of images
/// seen in training, 64-bit from format 0.2 on, 32-bit before (as Darknet and OpenCV read it).
pub fn header_bytes(head: &[u8]) -> Option<u64> {
    let int = |k: usize| head.get(4 * k..4 * k + 4).map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let (major, minor) = (int(0)?, int(1)?);
    Some(if major * 10 + minor >= 2 { 20 } else { 16 })
}

/// Check that the `weights` file holds what `cfg` asks for, exactly: its header and
/// [`weights_size`]'s floats. An error is the file it is about (the cfg, or the weights) and what is
/// wrong, naming the other file and the figures.
pub fn check_weights(cfg: &Path, weights: &Path) -> Result<(), (std::path::PathBuf, String)> {
    let of_cfg = |m: String| (cfg.to_path_buf(), m);
    let of_weights = |m: String| (weights.to_path_buf(), m);
    let text = slam_core::files::read_text(cfg, &slam_core::files::SMALL).map_err(|e| of_cfg(e.reason()))?;
    let need = weights_size(&text).map_err(of_cfg)?;
    let have = slam_core::files::regular_file(weights).map_err(|e| of_weights(e.reason()))?;
    let mut head = [0u8; 8];
    {
        use std::io::Read;
        let mut f = std::fs::File::open(weights).map_err(|e| of_weights(e.to_string()))?;
        let n = f.read(&mut head).map_err(|e| of_weights(e.to_string()))?;
        if n < 8 {
            return Err(of_weights(format!(
                "holds {have} bytes, too few for a Darknet weights header; {} needs {} weights ({} bytes)",
                cfg.display(),
                need.floats,
                4 * need.floats
            )));
        }
    }
    let header = header_bytes(&head).unwrap_or(20);
    let expected = header + 4 * need.floats;
    if have == expected {
        return Ok(());
    }
    let what = if have < expected {
        format!("{} bytes too few: the file is cut short, or another model's", expected - have)
    } else {
        format!("{} bytes too many: the weights of another model", have - expected)
    };
    Err(of_weights(format!(
        "holds {have} bytes, but {} needs {expected} ({header} of header and {} weights of its {} layers with \
         weights): {what}; give the .weights that belong to this .cfg",
        cfg.display(),
        need.floats,
        need.layers
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/detector").join(name)
    }

    /// The shipped Yolo-Fastest's cfg asks for exactly the weights its file holds (1 384 268 bytes: a
    /// 20-byte header and 346 062 floats); a layer more, a filter more or another class count does not.
    #[test]
    fn the_shipped_pair_fits_and_a_changed_cfg_does_not() {
        let (cfg, weights) = (shipped("yolo-fastest-1.1.cfg"), shipped("yolo-fastest-1.1.weights"));
        check_weights(&cfg, &weights).expect("the shipped pair");
        let text = std::fs::read_to_string(&cfg).expect("cfg");
        let size = weights_size(&text).expect("sizes");
        assert_eq!((size.floats, size.layers), (346_062, 84));
        // one more output of the first convolution: 3 × 3 × 3 weights + 4 batch-norm values, and the
        // next layer's inputs grow by one channel
        let wider = text.replacen("filters=8", "filters=9", 1);
        assert!(weights_size(&wider).expect("sizes").floats > size.floats);
        let other = text.replace("classes=80", "classes=3");
        assert!(weights_size(&other).expect_err("3 classes").contains("classes=3"), "COCO's classes only");
        let no_head = text.replace("[yolo]", "[dropout]");
        assert!(weights_size(&no_head).expect_err("no head").contains("no [yolo] or [region]"));
        let unknown = text.replacen("[maxpool]", "[lstm]", 1);
        assert!(weights_size(&unknown).expect_err("lstm").contains("lstm"));
        assert!(weights_size("[convolutional]\nfilters=8\n").expect_err("no net").contains("[net]"));
        let route = "[net]\nchannels=3\n[convolutional]\nfilters=4\n[route]\nlayers=-5\n[yolo]\nclasses=80\n";
        assert!(weights_size(route).expect_err("route").contains("layer -4 does not come before it"));
    }

    #[test]
    fn a_cut_or_padded_weights_file_is_refused_with_its_figures() {
        let dir = std::env::temp_dir().join(format!("darknet-weights-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let cfg = shipped("yolo-fastest-1.1.cfg");
        let bytes = std::fs::read(shipped("yolo-fastest-1.1.weights")).expect("weights");
        let (half, long, empty) = (dir.join("half.weights"), dir.join("long.weights"), dir.join("empty.weights"));
        std::fs::write(&half, &bytes[..700_000]).expect("write");
        std::fs::write(&long, [&bytes[..], &[0u8; 400]].concat()).expect("write");
        std::fs::write(&empty, b"").expect("write");
        let (file, e) = check_weights(&cfg, &half).expect_err("cut");
        assert!(file == half && e.starts_with("holds 700000 bytes, but") && e.contains("needs 1384268"), "{e}");
        assert!(e.contains("684268 bytes too few: the file is cut short"), "{e}");
        let (_, e) = check_weights(&cfg, &long).expect_err("long");
        assert!(e.contains("400 bytes too many"), "{e}");
        let (_, e) = check_weights(&cfg, &empty).expect_err("empty");
        assert!(e.contains("holds 0 bytes, too few for a Darknet weights header"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
