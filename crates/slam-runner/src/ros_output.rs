//! A run for ROS tools: the results as an MCAP file (`run --mcap FILE`) that Foxglove opens, on the
//! input's own time line (a bag's header stamps; a folder's frame times from 0), and `inspect`, what a
//! bag holds and which pair a run would read ([`inspect_bag`]).
//!
//! | topic | type | messages |
//! |---|---|---|
//! | `/tf` | `tf2_msgs/msg/TFMessage` | one per frame with a pose: `slam_camera` (the left camera) in `slam_map` |
//! | `/slam/trajectory` | `nav_msgs/msg/Path` | one, at the last frame's time: every pose |
//! | `/slam/objects` | `visualization_msgs/msg/MarkerArray` | one, at the last frame's time: per mapped object an ellipsoid (a scaled sphere; green static, orange dynamic) in namespace `objects` and a `#id class` text above it in `labels`, both with the object's id |
//! | `/slam/map_points` | `sensor_msgs/msg/PointCloud2` | one, at the last frame's time: the map's points (x, y, z as 32-bit floats) |
//!
//! `slam_map` is the left camera of the first frame (the raw one when the run rectified its images), as
//! in the trajectory files. The file is written atomically (`slam_core::files::AtomicWrite`), without
//! compression threads. Its summary repeats the schemas and channels, which readers that go by the index
//! need (the Python `mcap` package's, Foxglove's older versions); the `mcap` crate writes those in hash
//! order, so two writes of the same run hold the same messages but not always the same bytes.

use std::{collections::BTreeMap, path::Path};

use nalgebra::{Point3, Vector3};
use slam_dataset::{
    recording::{camera_info_topic, choose_topics, pair_by_stamp, SourceOptions},
    rig::read_calibration,
    ros::{
        bag::Bag,
        msgs::{
            markers_message, output_schemas, path_message, point_cloud_message, tf_message, Marker, MARKERS, PATH,
            POINT_CLOUD, TF,
        },
    },
};

use crate::{
    error::{Result, RunnerError},
    run::Outcome,
};

/// The world frame's name in the written file.
pub const WORLD_FRAME: &str = "slam_map";
/// The camera's frame name in the written file.
pub const CAMERA_FRAME: &str = "slam_camera";

/// The topics written, with their types.
pub const TOPICS: [(&str, &str); 4] =
    [("/tf", TF), ("/slam/trajectory", PATH), ("/slam/objects", MARKERS), ("/slam/map_points", POINT_CLOUD)];

/// Each played frame's time on the input's time line, nanoseconds: a bag frame's left header stamp,
/// else the frame time from 0.
pub fn frame_stamps(o: &Outcome) -> Vec<i64> {
    match o.seq.recording.as_ref().and_then(|r| r.bag.as_ref()) {
        Some(b) => b.frames.iter().map(|f| f.left.stamp_ns).collect(),
        None => o.seq.times.iter().map(|t| (t * 1e9).round() as i64).collect(),
    }
}

/// The messages of a run: `(topic, log time, CDR bytes)` in time order.
pub fn messages(o: &Outcome) -> Vec<(&'static str, i64, Vec<u8>)> {
    let stamps = frame_stamps(o);
    let out = &o.out;
    let placed: Vec<(i64, nalgebra::Isometry3<f64>)> = (0..out.poses.len())
        .filter(|&k| out.placed.get(k).copied().unwrap_or(true))
        .filter_map(|k| Some((*stamps.get(k)?, o.raw_left(&out.poses[k]))))
        .collect();
    let mut msgs: Vec<(&'static str, i64, Vec<u8>)> =
        placed.iter().map(|(t, p)| ("/tf", *t, tf_message(*t, WORLD_FRAME, CAMERA_FRAME, p))).collect();
    let last = placed.last().map(|p| p.0).or_else(|| stamps.last().copied()).unwrap_or(0);
    msgs.push(("/slam/trajectory", last, path_message(last, WORLD_FRAME, &placed)));
    let mut markers = Vec::new();
    for obj in o.objects_in_raw_left().iter().filter(|ob| !ob.moving) {
        let Some(e) = &obj.ellipsoid else { continue };
        let id = obj.id.0 as i32;
        let color = if obj.dynamic { [1.0, 0.55, 0.0, 0.6] } else { [0.1, 0.8, 0.2, 0.6] };
        markers.push(Marker {
            ns: "objects".into(),
            id,
            pose: e.world_from_quadric,
            scale: e.semi_axes * 2.0,
            color,
            text: None,
        });
        // the label floats above the ellipsoid (y points down in the camera's world)
        let mut above = nalgebra::Isometry3::translation(0.0, 0.0, 0.0);
        above.translation.vector =
            e.world_from_quadric.translation.vector - Vector3::new(0.0, e.semi_axes.max() + 0.3, 0.0);
        markers.push(Marker {
            ns: "labels".into(),
            id,
            pose: above,
            scale: Vector3::new(0.0, 0.0, 0.5),
            color: [1.0, 1.0, 1.0, 1.0],
            text: Some(format!("#{} {}", obj.id.0, obj.class.name())),
        });
    }
    msgs.push(("/slam/objects", last, markers_message(last, WORLD_FRAME, &markers)));
    let points: Vec<Point3<f64>> =
        out.map.points.values().map(|p| o.point_in_raw_left(&Point3::from(p.position))).collect();
    msgs.push(("/slam/map_points", last, point_cloud_message(last, WORLD_FRAME, &points)));
    msgs
}

/// Write the run's MCAP file (module doc); returns a line saying what was written.
pub fn write_results_mcap(o: &Outcome, path: &Path) -> Result<String> {
    let msgs = messages(o);
    let err = |e: String| RunnerError::Invalid(format!("writing {}: {e}", path.display()));
    let file = slam_core::files::AtomicWrite::create(path)?;
    let f = std::fs::OpenOptions::new().write(true).open(file.temporary()).map_err(|e| err(e.to_string()))?;
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .library("quadric-slam")
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .create(std::io::BufWriter::new(f))
        .map_err(|e| err(e.to_string()))?;
    let mut channels = BTreeMap::new();
    for (name, text) in output_schemas() {
        let schema = w.add_schema(name, "ros2msg", text.as_bytes()).map_err(|e| err(e.to_string()))?;
        for (topic, ty) in TOPICS.iter().filter(|(_, ty)| *ty == name) {
            let _ = ty;
            let id = w.add_channel(schema, topic, "cdr", &BTreeMap::new()).map_err(|e| err(e.to_string()))?;
            channels.insert(*topic, id);
        }
    }
    let mut sequence: BTreeMap<&str, u32> = BTreeMap::new();
    let mut order: Vec<&(&str, i64, Vec<u8>)> = msgs.iter().collect();
    order.sort_by_key(|m| m.1);
    for (topic, t, data) in order {
        let seq = sequence.entry(topic).or_default();
        let header = mcap::records::MessageHeader {
            channel_id: channels[topic],
            sequence: *seq,
            log_time: (*t).max(0) as u64,
            publish_time: (*t).max(0) as u64,
        };
        *seq += 1;
        w.write_to_known_channel(&header, data).map_err(|e| err(e.to_string()))?;
    }
    w.finish().map_err(|e| err(e.to_string()))?;
    drop(w);
    file.commit()?;
    let count = |t: &str| msgs.iter().filter(|m| m.0 == t).count();
    Ok(format!(
        "wrote {}: /tf ({} poses), /slam/trajectory, /slam/objects, /slam/map_points ({} points)",
        path.display(),
        count("/tf"),
        o.out.map.points.len()
    ))
}

/// What `slam-app inspect BAG` prints: every topic with its type, message count, rate and span, the
/// camera infos, the pair a run would read and why (or why none), and the bag's warnings.
pub fn inspect_bag(path: &Path, opts: &SourceOptions) -> Result<String> {
    if opts.rate_hz.is_some() {
        return Err(RunnerError::Invalid("--rate is for a folder of images without times.txt, not a bag".into()));
    }
    let bag = Bag::open(path)?;
    let mut lines = vec![format!("{}: {} file(s), {} topics", path.display(), bag.files.len(), bag.topics.len())];
    lines.push(
        "\n| topic | type | encoding | messages | rate Hz | span s | image layouts |\n|---|---|---|---:|---:|---:|---|"
            .into(),
    );
    for t in &bag.topics {
        let rate = t.rate_hz().map_or("-".to_string(), |r| format!("{r:.2}"));
        let span = t.span_ns.map_or("-".to_string(), |(a, b)| format!("{:.3}", (b - a) as f64 * 1e-9));
        let layouts = t.layouts.iter().cloned().collect::<Vec<_>>().join(", ");
        let bad = if t.unreadable > 0 { format!(" ({} unreadable)", t.unreadable) } else { String::new() };
        lines.push(format!(
            "| {} | {} | {} | {}{bad} | {rate} | {span} | {layouts} |",
            t.name, t.schema, t.encoding, t.count
        ));
    }
    for (topic, info) in &bag.camera_infos {
        lines.push(format!(
            "{topic}: {}×{}, fx {:.2} px, P[0][3] {:.3}, distortion {} ({} coefficients, {})",
            info.width,
            info.height,
            info.p[0],
            info.p[3],
            if info.d.iter().any(|v| *v != 0.0) { "yes" } else { "none" },
            info.d.len(),
            if info.distortion_model.is_empty() { "no model" } else { &info.distortion_model }
        ));
    }
    let calib = opts.calib.as_deref().map(read_calibration).transpose()?;
    match choose_topics(&bag, opts, calib.as_ref()) {
        Ok(c) => {
            let stamps = |t: &str| {
                bag.images.get(t).map(|v| v.iter().map(|m| m.stamp_ns).collect::<Vec<_>>()).unwrap_or_default()
            };
            let p = pair_by_stamp(&stamps(&c.left), &stamps(&c.right));
            lines.push(format!(
                "\na run would read left {} and right {}: {}; {} pairs (frame period {:.1} ms, stamps paired within {:.1} ms; {} left and {} right images without a partner); calibration from {}",
                c.left,
                c.right,
                c.why,
                p.pairs.len(),
                p.period_ns as f64 * 1e-6,
                p.tolerance_ns as f64 * 1e-6,
                p.unpaired_left.len(),
                p.unpaired_right,
                match &calib {
                    Some(f) => f.path.display().to_string(),
                    None => format!("{} and {}", camera_info_topic(&c.left), camera_info_topic(&c.right)),
                }
            ));
        }
        Err(why) => lines.push(format!("\na run could not choose a pair: {why}")),
    }
    for w in &bag.warnings {
        lines.push(format!("warning: {w}"));
    }
    Ok(lines.join("\n"))
}
