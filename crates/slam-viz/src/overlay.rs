//! The per-frame overlay of a run: what the system saw and built, drawn on the frame's left image.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
};

use nalgebra::Point3;
use slam_core::Image;
use slam_frontend::{draw_overlay, ellipse_outline, read_image, write_image, Overlay};
use slam_pipeline::system::RunOutput;
use slam_quadric::{project, Camera, ImageSize, Intrinsics};

use crate::{plot::ObjectState, VizError};

/// The overlay of frame `i`: each detection box with its object's id, class and score, coloured by the
/// object's state (grey: no object); each mapped object's projected ellipsoid with `#id class`; moving
/// objects (not mapped) get no ellipsoid; each object's past map-point centroids as a trail; a legend.
pub fn frame_overlay(out: &RunOutput, i: usize, k: Intrinsics, image: ImageSize) -> Overlay {
    let rec = &out.frames[i];
    let camera = Camera::new(k, out.poses[i]);
    let grey = [170, 170, 170];
    let state_of: BTreeMap<u64, ObjectState> =
        out.objects.iter().map(|o| (o.id.0, ObjectState::of(o.dynamic, o.moving))).collect();
    let mut o = Overlay::default();
    for (d, t) in rec.detections.iter().zip(&rec.tracks) {
        let (c, label) = match t {
            Some(id) => {
                let st = state_of.get(&id.0).copied().unwrap_or(ObjectState::Static);
                let c = if out.objects.iter().any(|x| x.id == *id && (x.ellipsoid.is_some() || x.moving)) {
                    st.bgr()
                } else {
                    grey
                };
                let tail = if st == ObjectState::Moving { " moving" } else { "" };
                (c, format!("#{} {} {:.2}{tail}", id.0, d.class.name(), d.score))
            }
            None => (grey, format!("{} {:.2}", d.class.name(), d.score)),
        };
        o.boxes.push((d.bbox, c, label));
    }
    let from_world = camera.world_from_camera.inverse();
    for obj in &out.objects {
        let seen_now = obj.observations.iter().any(|x| x.frame == rec.index);
        let state = ObjectState::of(obj.dynamic, obj.moving);
        let c = state.bgr();
        if let (Some(e), ObjectState::Static | ObjectState::Dynamic) = (&obj.ellipsoid, state) {
            if let Some(ell) = project(e, &camera).ok().and_then(|conic| conic.ellipse()) {
                let outline = ellipse_outline(&ell, 64);
                let on_screen =
                    outline.iter().any(|p| p[0] >= 0.0 && p[0] < image.width && p[1] >= 0.0 && p[1] < image.height);
                if on_screen && (seen_now || (from_world * Point3::from(e.centre())).z < 40.0) {
                    o.lines.push((outline, true, c, 2));
                    let tail = if state == ObjectState::Dynamic { " dynamic" } else { "" };
                    o.labels.push((
                        [ell.centre.x - 20.0, ell.centre.y + 5.0],
                        c,
                        format!("#{} {}{tail}", obj.id.0, obj.class.name()),
                    ));
                }
            }
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
    /// The played frames' left images, in the order of the run's records.
    pub left: &'a [PathBuf],
    /// Read the images in colour (else grey).
    pub colour: bool,
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
        let img: Image = match read_image(&opts.left[i], opts.colour) {
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
