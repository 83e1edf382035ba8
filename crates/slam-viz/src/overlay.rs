//! The per-frame overlay of a run: what the system saw and built, drawn on the frame's left image.

use std::path::Path;

use nalgebra::{Isometry3, Point3};
use slam_core::{Detection, Image, TrackId};
use slam_frontend::{draw_overlay, ellipse_outline, write_image, Overlay};
use slam_pipeline::{
    objects::MappedObject,
    system::{FrameRecord, RunOutput},
};
use slam_quadric::{project, Camera, ImageSize, Intrinsics};

use crate::{plot::ObjectState, VizError};

/// What the overlay of a frame is drawn from: its record, the camera pose it is seen from, and the
/// objects as they stand (at the end of the run for the overlays of a finished run; as of the frame in
/// a recording made while the run goes).
pub struct FrameState<'a> {
    /// The frame's record (detections and their objects).
    pub record: &'a FrameRecord,
    /// Pose of the left camera, world from camera.
    pub world_from_camera: Isometry3<f64>,
    /// The objects.
    pub objects: &'a [&'a MappedObject],
}

/// How a detection box is shown: its object's state when that object has an ellipsoid or moves (its
/// colour), else `None` (grey in the overlays); and its label, `#id class score` (` moving` appended for
/// a moving object), or `class score` for a box given to no object.
pub fn box_style(d: &Detection, track: Option<TrackId>, objects: &[&MappedObject]) -> (Option<ObjectState>, String) {
    let Some(id) = track else { return (None, format!("{} {:.2}", d.class.name(), d.score)) };
    let object = objects.iter().find(|o| o.id == id);
    let st = object.map_or(ObjectState::Static, |o| ObjectState::of(o.dynamic, o.moving));
    let shown = object.is_some_and(|x| x.ellipsoid.is_some() || x.moving);
    let tail = if st == ObjectState::Moving { " moving" } else { "" };
    (shown.then_some(st), format!("#{} {} {:.2}{tail}", id.0, d.class.name(), d.score))
}

/// A mapped object's ellipsoid as the camera sees it: outline (64 points along the projected ellipse),
/// state, `#id class` label (` dynamic` appended) and where the label goes.
pub struct ProjectedObject {
    /// Points along the outline, pixels (a closed curve).
    pub outline: Vec<[f64; 2]>,
    /// The object's state (static or dynamic: moving objects are not mapped, so not drawn).
    pub state: ObjectState,
    /// `#id class`, with ` dynamic` for a dynamic object.
    pub label: String,
    /// Where the label is written: 20 px left of and 5 px below the ellipse's centre.
    pub label_at: [f64; 2],
}

/// The projected ellipsoid of a static or dynamic object (`None` for others, for an ellipsoid whose
/// projection is no ellipse, or off the image), drawn when the object is seen in the frame or its
/// centre lies less than 40 m ahead of the camera.
pub fn projected_object(
    obj: &MappedObject,
    camera: &Camera,
    frame: usize,
    image: ImageSize,
) -> Option<ProjectedObject> {
    let state = ObjectState::of(obj.dynamic, obj.moving);
    let (Some(e), ObjectState::Static | ObjectState::Dynamic) = (&obj.ellipsoid, state) else { return None };
    let ell = project(e, camera).ok().and_then(|conic| conic.ellipse())?;
    let outline = ellipse_outline(&ell, 64);
    let on_screen = outline.iter().any(|p| p[0] >= 0.0 && p[0] < image.width && p[1] >= 0.0 && p[1] < image.height);
    let seen_now = obj.observations.iter().any(|x| x.frame == frame);
    let ahead = (camera.world_from_camera.inverse() * Point3::from(e.centre())).z;
    (on_screen && (seen_now || ahead < 40.0)).then(|| {
        let tail = if state == ObjectState::Dynamic { " dynamic" } else { "" };
        ProjectedObject {
            outline,
            state,
            label: format!("#{} {}{tail}", obj.id.0, obj.class.name()),
            label_at: [ell.centre.x - 20.0, ell.centre.y + 5.0],
        }
    })
}

/// The overlay of frame `i` of a finished run ([`overlay_of`] with the run's final objects and poses).
pub fn frame_overlay(out: &RunOutput, i: usize, k: Intrinsics, image: ImageSize) -> Overlay {
    let objects: Vec<&MappedObject> = out.objects.iter().collect();
    overlay_of(&FrameState { record: &out.frames[i], world_from_camera: out.poses[i], objects: &objects }, k, image)
}

/// The overlay of a frame: each detection box with its object's id, class and score, coloured by the
/// object's state (grey: no object, or none fitted yet; [`box_style`]); each mapped object's projected
/// ellipsoid with `#id class` ([`projected_object`]); moving objects (not mapped) get no ellipsoid; each
/// object's past map-point centroids as a trail; a legend.
pub fn overlay_of(frame: &FrameState<'_>, k: Intrinsics, image: ImageSize) -> Overlay {
    let rec = frame.record;
    let camera = Camera::new(k, frame.world_from_camera);
    let grey = [170, 170, 170];
    let mut o = Overlay::default();
    for (d, t) in rec.detections.iter().zip(&rec.tracks) {
        let (state, label) = box_style(d, *t, frame.objects);
        o.boxes.push((d.bbox, state.map_or(grey, ObjectState::bgr), label));
    }
    let from_world = camera.world_from_camera.inverse();
    for obj in frame.objects {
        let seen_now = obj.observations.iter().any(|x| x.frame == rec.index);
        let c = ObjectState::of(obj.dynamic, obj.moving).bgr();
        if let Some(p) = projected_object(obj, &camera, rec.index, image) {
            o.lines.push((p.outline, true, c, 2));
            o.labels.push((p.label_at, c, p.label));
        }
        // trail: the object's centroids (from map points) up to this frame, projected
        let trail: Vec<[f64; 2]> = obj
            .observations
            .iter()
            .filter(|x| x.frame <= rec.index)
            .filter_map(|x| x.centroid)
            .filter_map(|p| {
                let q = from_world * Point3::from(p);
                (q.z > 0.5).then(|| [k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy])
            })
            .collect();
        if seen_now && trail.len() >= 2 {
            o.lines.push((trail.clone(), false, c, 1));
        }
        if seen_now {
            for p in trail {
                o.dots.push((p, c, 2));
            }
        }
    }
    o.legend = ObjectState::ALL.iter().map(|s| (s.bgr(), s.meaning().to_string())).collect();
    o.legend.push((grey, "detection without a fitted object".into()));
    o.legend.push(([255, 255, 255], "ellipse: projected ellipsoid; dots: its past centroids".into()));
    o
}

/// What [`write_overlays`] draws and where.
pub struct OverlayOptions<'a> {
    /// The left image of the played frame at a position in the run's records, as it was tracked (read,
    /// decoded, rectified); an error says why it cannot be had.
    pub left: &'a dyn Fn(usize) -> Result<Image, String>,
    /// The run's camera.
    pub k: Intrinsics,
    /// The run's image size.
    pub image: ImageSize,
    /// Draw every n-th record (1: all).
    pub every: u64,
    /// Image format, the file extension (`png`, `jpg`).
    pub format: &'a str,
}

/// Write the overlay of every `every`-th processed frame into `dir` (created), as
/// `<frame id, six digits>.<format>`; returns how many were written. A frame whose image cannot be
/// read again is skipped with a warning.
pub fn write_overlays(out: &RunOutput, opts: &OverlayOptions<'_>, dir: &Path) -> Result<usize, VizError> {
    std::fs::create_dir_all(dir).map_err(|source| VizError::CreateDir { path: dir.to_path_buf(), source })?;
    let mut count = 0;
    for (i, rec) in out.frames.iter().enumerate() {
        if i as u64 % opts.every.max(1) != 0 || rec.state.is_none() {
            continue;
        }
        // records are in input order: entry i of the played sequence is frame id rec.index
        let img: Image = match (opts.left)(i) {
            Ok(img) => img,
            Err(e) => {
                tracing::warn!("overlay of frame {}: {e}", rec.index);
                continue;
            }
        };
        let overlay = frame_overlay(out, i, opts.k, opts.image);
        write_image(dir.join(format!("{:06}.{}", rec.index, opts.format)), &draw_overlay(&img, &overlay)?)?;
        count += 1;
    }
    Ok(count)
}
