//! Reading a recording back with rerun's own decoder: the entities it holds, the frames of its
//! `frame` timeline, its images and map points, and the last ellipsoids logged (what the viewer shows
//! at the recording's end).

use std::{
    collections::BTreeSet,
    path::{Path, PathBuf},
};

use re_sdk::{
    log::{Chunk, LogMsg},
    ComponentIdentifier, TimelineName,
};
use re_sdk_types::{
    archetypes::{Ellipsoids3D, EncodedImage, Points3D},
    components::{Position3D, Text, Translation3D},
};

use slam_core::files::{check_readable, Limit};

use crate::scene::{path, FRAME_TIMELINE};

/// What a recording holds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordingSummary {
    /// Entity paths (without a leading `/`).
    pub entities: BTreeSet<String>,
    /// Values of the `frame` timeline.
    pub frames: BTreeSet<i64>,
    /// Images logged at [`path::IMAGE`].
    pub images: usize,
    /// Map points logged under [`path::POINTS`].
    pub points: usize,
    /// The last ellipsoids logged at [`path::OBJECTS`] (latest frame; the last logged among equals):
    /// centres and labels.
    pub objects: Vec<([f32; 3], String)>,
}

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
#[error("reading the recording {}: {message}", path.display())]
pub struct ReadError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub message: String,
}

/// What the reader takes: it streams the file (messages are decoded one by one), so the limit only keeps
/// out what no run writes.
const RECORDING: Limit = Limit {
    bytes: 64 << 30,
    what: "a rerun recording",
    why: "a recording takes about 0.1 MB per frame of odometry 06 (JPEG images), so this holds runs of over 500 000 frames",
};

/// Decode the recording at `path` and summarise it. Only a regular file is read
/// ([`slam_core::files::check_readable`]).
pub fn summarise(path: &Path) -> Result<RecordingSummary, ReadError> {
    let err = |m: String| ReadError { path: path.to_path_buf(), message: m };
    check_readable(path, &RECORDING).map_err(|e| err(e.reason()))?;
    let file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let messages =
        re_log_encoding::DecoderApp::decode_eager(std::io::BufReader::new(file)).map_err(|e| err(e.to_string()))?;
    let mut s = RecordingSummary::default();
    let frame = TimelineName::from_static_str(FRAME_TIMELINE);
    let mut latest: Option<i64> = None;
    for msg in messages {
        let LogMsg::ArrowMsg(_, arrow) = msg.map_err(|e| err(e.to_string()))? else { continue };
        let chunk = Chunk::from_arrow_msg(&arrow).map_err(|e| err(e.to_string()))?;
        let entity = chunk.entity_path().to_string().trim_start_matches('/').to_string();
        if let Some(times) = chunk.timelines().get(&frame) {
            s.frames.extend(times.times_raw().iter().copied());
        }
        if entity == path::IMAGE {
            s.images += rows(&chunk, EncodedImage::descriptor_blob().component);
        }
        if entity.starts_with(path::POINTS) {
            let positions = Points3D::descriptor_positions().component;
            s.points += chunk.iter_component::<Position3D>(positions).map(|row| row.as_slice().len()).sum::<usize>();
        }
        if entity == path::OBJECTS {
            let (centres, labels) =
                (Ellipsoids3D::descriptor_centers().component, Ellipsoids3D::descriptor_labels().component);
            let rows = chunk
                .iter_component_indices(frame, centres)
                .zip(chunk.iter_component::<Translation3D>(centres))
                .zip(chunk.iter_component::<Text>(labels));
            for (((t, _), c), l) in rows {
                let t = t.as_i64();
                if latest.is_none_or(|x| t >= x) {
                    latest = Some(t);
                    s.objects =
                        c.as_slice().iter().zip(l.as_slice()).map(|(c, l)| (c.0 .0, l.as_str().to_string())).collect();
                }
            }
        }
        s.entities.insert(entity);
    }
    Ok(s)
}

/// Rows of a chunk that hold a component.
fn rows(chunk: &Chunk, component: ComponentIdentifier) -> usize {
    chunk.iter_component_offsets(component).count()
}
