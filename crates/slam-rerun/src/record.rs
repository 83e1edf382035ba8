//! Writing a recording with rerun's logging SDK: a [`Recorder`] fed frame by frame while a run goes
//! (its own thread encodes the images and logs; rerun's file sink streams to disk), and
//! [`record_map`] for a saved map. Both write to a temporary sibling of the file
//! ([`slam_core::files::AtomicWrite`]) and put it in place only when the recording is whole: a failed or
//! interrupted run leaves the previous recording as it was.

use std::{
    path::{Path, PathBuf},
    thread::JoinHandle,
};

use crossbeam_channel::{bounded, Receiver, Sender};
use nalgebra::Isometry3;
use re_sdk::{RecordingStream, RecordingStreamBuilder};
use re_sdk_types::{
    archetypes::{
        Boxes2D, Clear, Ellipsoids3D, EncodedImage, LineStrips2D, LineStrips3D, Pinhole, Points3D, Scalars,
        TextDocument, TextLog, Transform3D, ViewCoordinates,
    },
    components::{Color, MediaType, Radius, TextLogLevel},
    datatypes::Quaternion,
};
use slam_core::files::AtomicWrite;
use slam_pipeline::{objects::MappedObject, saved_map::SavedMap, system::FrameView};

use crate::scene::{
    estimate_block, keyframe_points, path, position, rotation_columns, state_level, state_log_level, FrameScene,
    NewPoints, ObjectShape, PathBlocks, SceneSetup, FRAME_TIMELINE, JPEG_QUALITY, TIME_TIMELINE,
};

/// The application id recordings are written under (the viewer groups recordings by it).
pub const APPLICATION_ID: &str = "quadric-slam";

/// Frames queued between the run and the recorder's thread: the run waits when the recorder falls
/// this far behind, so memory stays bounded (each frame holds its image).
const QUEUE: usize = 4;

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The recording file could not be created.
    #[error("cannot create the recording {}: {message}", path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// Logging or writing failed while the recording was being made.
    #[error("writing the recording {}: {message}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// An image could not be encoded.
    #[error("recording frame {frame}: {source}")]
    Image {
        /// Frame id.
        frame: usize,
        /// The encoder's error.
        source: slam_frontend::FrontendError,
    },
    /// The recorder's thread stopped unexpectedly.
    #[error("the recorder's thread stopped unexpectedly while writing {}", path.display())]
    Thread {
        /// The file.
        path: PathBuf,
    },
}

/// What a finished recording holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordingStats {
    /// Frames on the `frame` timeline.
    pub frames: usize,
    /// Images (JPEG).
    pub images: usize,
    /// Map points.
    pub points: usize,
    /// Objects with an ellipsoid at the end.
    pub objects: usize,
    /// Size of the file, bytes.
    pub bytes: u64,
}

impl RecordingStats {
    /// The line a command prints for a recording written to `path`.
    pub fn summary(&self, path: &std::path::Path) -> String {
        format!(
            "wrote {}: rerun recording, {} frames, {} images, {} map points, {} objects, {:.1} MB (open it with `rerun {}`, from `pip install rerun-sdk==0.36.3`)",
            path.display(),
            self.frames,
            self.images,
            self.points,
            self.objects,
            self.bytes as f64 / 1e6,
            path.display()
        )
    }
}

/// What the recorder's thread is sent.
enum Message {
    Frame(Box<FrameScene>),
    /// The run's final state, logged at its last frame: the trajectory after local mapping's
    /// corrections and the objects.
    End {
        frame: usize,
        time_s: Option<f64>,
        trajectory: Vec<[f32; 3]>,
        objects: Vec<ObjectShape>,
    },
}

/// A recording made while a run goes: [`Recorder::create`] before the first frame, [`Recorder::frame`]
/// from the run's `on_frame` observer, [`Recorder::finish`] with the run's output.
///
/// The observer's thread (the tracking thread) only copies the frame's content ([`FrameScene`], the
/// left image included); a thread of the recorder's own encodes the image as JPEG and logs, and rerun's
/// file sink writes as the run goes (no whole-run buffer), into the temporary sibling of the file, which
/// [`Recorder::finish`] puts in place; a recorder dropped unfinished (a run stopped early) removes it.
pub struct Recorder {
    path: PathBuf,
    file: Option<AtomicWrite>,
    setup: SceneSetup,
    recorded: NewPoints,
    last: Option<(usize, Option<f64>)>,
    tx: Option<Sender<Message>>,
    worker: Option<JoinHandle<Result<RecordingStats, RecordError>>>,
}

impl Recorder {
    /// Create the recording at `path` (replacing a file there) and log what does not change: the world
    /// frame's axes, the camera's pinhole, the ground truth and the legend.
    pub fn create(path: &Path, setup: SceneSetup) -> Result<Self, RecordError> {
        let file = start(path)?;
        let rec = open(&file)?;
        let mut writer = Writer::new(rec, path);
        writer.setup(&setup)?;
        let (tx, rx) = bounded(QUEUE);
        let worker = std::thread::Builder::new()
            .name("rerun recorder".into())
            .spawn(move || writer.run(rx))
            .map_err(|e| RecordError::Create { path: path.to_path_buf(), message: e.to_string() })?;
        Ok(Self {
            path: path.to_path_buf(),
            file: Some(file),
            setup,
            recorded: NewPoints::default(),
            last: None,
            tx: Some(tx),
            worker: Some(worker),
        })
    }

    /// Record one frame of the run. When the recorder's thread has stopped (an error), the frame is
    /// dropped; [`Recorder::finish`] reports the error.
    pub fn frame(&mut self, view: &FrameView<'_>) {
        let scene = FrameScene::of_view(view, &self.setup, &mut self.recorded);
        self.last = Some((scene.frame, scene.time_s));
        if let Some(tx) = &self.tx {
            if tx.send(Message::Frame(Box::new(scene))).is_err() {
                // the thread ended with an error: stop sending, finish() reports it
                self.tx = None;
            }
        }
    }

    /// Log the run's final trajectory (`poses`, one per played frame, after local mapping's
    /// corrections) and objects at its last frame, write everything out and close the file.
    pub fn finish(mut self, poses: &[Isometry3<f64>], objects: &[MappedObject]) -> Result<RecordingStats, RecordError> {
        if let (Some(tx), Some((frame, time_s))) = (&self.tx, self.last) {
            let end = Message::End {
                frame,
                time_s,
                trajectory: poses.iter().map(position).collect(),
                objects: objects.iter().filter_map(ObjectShape::of_mapped).collect(),
            };
            // a closed channel means the thread ended with an error, reported below
            let _ = tx.send(end);
        }
        self.tx = None;
        let worker = self.worker.take().ok_or_else(|| RecordError::Thread { path: self.path.clone() })?;
        let mut stats = worker.join().map_err(|_| RecordError::Thread { path: self.path.clone() })??;
        stats.points = self.recorded.count();
        let file = self.file.take().ok_or_else(|| RecordError::Thread { path: self.path.clone() })?;
        stats.bytes = file_size(file.temporary())?;
        file.commit().map_err(|e| RecordError::Write { path: self.path.clone(), message: e.to_string() })?;
        Ok(stats)
    }
}

impl Drop for Recorder {
    /// A recorder dropped unfinished (a run stopped early, an error) stops its thread and removes its
    /// temporary file: a file of the same name from before stays as it was.
    fn drop(&mut self) {
        self.tx = None;
        if let Some(worker) = self.worker.take() {
            // the error, if any, has no one to go to here; finish() is the way to see it
            let _ = worker.join();
        }
    }
}

/// Write a saved map as a recording at `path` (replacing a file there): each frame of its trajectory
/// on the `frame` timeline with its final pose and state, each keyframe's map points (bounded) at its
/// frame, each object's final ellipsoid from the frame it was first seen in. No images or frustum
/// (a map file keeps no camera intrinsics).
pub fn record_map(map: &SavedMap, path: &Path) -> Result<RecordingStats, RecordError> {
    let file = start(path)?;
    let mut writer = Writer::new(open(&file)?, path);
    writer.log_static(path::WORLD, &ViewCoordinates::RDF())?;
    writer.legend()?;
    let mut points = 0;
    for scene in FrameScene::of_map(map) {
        points += scene.points.iter().map(|(_, xs)| xs.len()).sum::<usize>();
        writer.frame(scene)?;
    }
    let mut stats = writer.close()?;
    stats.points = points;
    stats.bytes = file_size(file.temporary())?;
    file.commit().map_err(|e| RecordError::Write { path: path.to_path_buf(), message: e.to_string() })?;
    Ok(stats)
}

/// The temporary sibling the recording at `path` is written to (which proves the folder writable).
fn start(path: &Path) -> Result<AtomicWrite, RecordError> {
    AtomicWrite::create(path).map_err(|e| RecordError::Create { path: path.to_path_buf(), message: e.to_string() })
}

/// A recording stream whose file sink writes into `file`'s temporary file.
fn open(file: &AtomicWrite) -> Result<RecordingStream, RecordError> {
    RecordingStreamBuilder::new(APPLICATION_ID)
        .save(file.temporary())
        .map_err(|e| RecordError::Create { path: file.destination().to_path_buf(), message: e.to_string() })
}

fn file_size(path: &Path) -> Result<u64, RecordError> {
    std::fs::metadata(path)
        .map(|m| m.len())
        .map_err(|e| RecordError::Write { path: path.to_path_buf(), message: e.to_string() })
}

/// Colours of map points and trajectories, RGB.
const POINT_COLOUR: [u8; 3] = [120, 150, 200];
const ESTIMATE_COLOUR: [u8; 3] = [30, 120, 255];
const FINAL_COLOUR: [u8; 3] = [255, 255, 255];
const TRUTH_COLOUR: [u8; 3] = [240, 200, 40];

/// The logging side: one recording stream and what it has logged so far.
struct Writer {
    rec: RecordingStream,
    path: PathBuf,
    blocks: PathBlocks,
    objects: Option<Vec<ObjectShape>>,
    stats: RecordingStats,
}

fn rgb(c: [u8; 3]) -> Color {
    Color::from_rgb(c[0], c[1], c[2])
}

impl Writer {
    fn new(rec: RecordingStream, path: &Path) -> Self {
        Self {
            rec,
            path: path.to_path_buf(),
            blocks: PathBlocks::default(),
            objects: None,
            stats: RecordingStats::default(),
        }
    }

    fn failed(&self, e: impl std::fmt::Display) -> RecordError {
        RecordError::Write { path: self.path.clone(), message: e.to_string() }
    }

    fn log(&self, entity: &str, what: &impl re_sdk::AsComponents) -> Result<(), RecordError> {
        self.rec.log(entity, what).map_err(|e| self.failed(e))
    }

    fn log_static(&self, entity: &str, what: &impl re_sdk::AsComponents) -> Result<(), RecordError> {
        self.rec.log_static(entity, what).map_err(|e| self.failed(e))
    }

    /// What does not change over a run.
    fn setup(&mut self, s: &SceneSetup) -> Result<(), RecordError> {
        self.log_static(path::WORLD, &ViewCoordinates::RDF())?;
        let pinhole = Pinhole::from_focal_length_and_resolution(
            [s.k.fx as f32, s.k.fy as f32],
            [s.image.width as f32, s.image.height as f32],
        )
        .with_principal_point([s.k.cx as f32, s.k.cy as f32])
        .with_image_plane_distance(2.0);
        self.log_static(path::IMAGE, &pinhole)?;
        if let Some(truth) = &s.truth {
            let strip: Vec<[f32; 3]> = truth.iter().map(position).collect();
            self.log_static(path::TRUTH, &LineStrips3D::new([strip]).with_colors([rgb(TRUTH_COLOUR)]))?;
        }
        self.legend()
    }

    fn legend(&self) -> Result<(), RecordError> {
        let text = "\
Boxes and ellipsoids are coloured by their object's state: green static (mapped), orange dynamic (flagged), \
red moving (not mapped); a box whose object has no ellipsoid yet has a light colour of its own per track, \
a box given to no object is grey. Trajectories: blue the estimate at tracking time, white the final one \
(after local mapping's corrections), yellow the ground truth. Map points: blue-grey.";
        self.log_static(path::LEGEND, &TextDocument::new(text))
    }

    /// Log frames until the run ends, then the end state; close the stream.
    fn run(mut self, rx: Receiver<Message>) -> Result<RecordingStats, RecordError> {
        for message in rx {
            match message {
                Message::Frame(scene) => self.frame(*scene)?,
                Message::End { frame, time_s, trajectory, objects } => {
                    self.time(frame, time_s);
                    self.log(path::FINAL, &LineStrips3D::new([trajectory]).with_colors([rgb(FINAL_COLOUR)]))?;
                    self.objects(objects)?;
                }
            }
        }
        self.close()
    }

    fn time(&self, frame: usize, time_s: Option<f64>) {
        self.rec.set_time_sequence(FRAME_TIMELINE, frame as i64);
        if let Some(t) = time_s {
            self.rec.set_duration_secs(TIME_TIMELINE, t);
        }
    }

    /// One frame.
    fn frame(&mut self, s: FrameScene) -> Result<(), RecordError> {
        self.time(s.frame, s.time_s);
        self.stats.frames += 1;
        if let Some(pose) = &s.pose {
            let camera = Transform3D::from_translation_mat3x3(position(pose), rotation_columns(pose));
            self.log(path::CAMERA, &camera)?;
            let (block, strip) = self.blocks.push(position(pose));
            let strip = strip.to_vec();
            self.log(&estimate_block(block), &LineStrips3D::new([strip]).with_colors([rgb(ESTIMATE_COLOUR)]))?;
        }
        if s.camera_view {
            match &s.image {
                Some(image) => {
                    let jpeg = slam_frontend::encode_jpeg(image, JPEG_QUALITY)
                        .map_err(|source| RecordError::Image { frame: s.frame, source })?;
                    self.log(path::IMAGE, &EncodedImage::new(jpeg).with_media_type(MediaType::jpeg()))?;
                    self.stats.images += 1;
                }
                // an unreadable frame: no image rather than the last one
                None => self.log(path::IMAGE, &Clear::flat())?,
            }
            self.boxes_and_outlines(&s)?;
        }
        for (kf, points) in &s.points {
            let cloud = Points3D::new(points.iter().copied())
                .with_colors([rgb(POINT_COLOUR)])
                .with_radii([Radius::new_ui_points(1.5)]);
            self.log(&keyframe_points(*kf), &cloud)?;
        }
        self.objects(s.objects)?;
        self.state(&s.state)
    }

    fn boxes_and_outlines(&self, s: &FrameScene) -> Result<(), RecordError> {
        let boxes = Boxes2D::from_mins_and_sizes(s.boxes.iter().map(|b| b.min), s.boxes.iter().map(|b| b.size))
            .with_colors(s.boxes.iter().map(|b| rgb(b.colour)))
            .with_labels(s.boxes.iter().map(|b| b.label.clone()));
        self.log(path::DETECTIONS, &boxes)?;
        let outlines = LineStrips2D::new(s.outlines.iter().map(|o| o.points.clone()))
            .with_colors(s.outlines.iter().map(|o| rgb(o.colour)))
            .with_labels(s.outlines.iter().map(|o| o.label.clone()));
        self.log(path::ELLIPSES, &outlines)
    }

    /// The objects, when they changed since they were last logged.
    fn objects(&mut self, objects: Vec<ObjectShape>) -> Result<(), RecordError> {
        if self.objects.as_ref() == Some(&objects) {
            return Ok(());
        }
        let f = |v: [f64; 3]| [v[0] as f32, v[1] as f32, v[2] as f32];
        let shapes = Ellipsoids3D::from_centers_and_half_sizes(
            objects.iter().map(|o| f(o.centre)),
            objects.iter().map(|o| f(o.half_sizes)),
        )
        .with_quaternions(objects.iter().map(|o| Quaternion::from_xyzw(o.quaternion.map(|q| q as f32))))
        .with_colors(objects.iter().map(|o| rgb(o.colour())))
        .with_labels(objects.iter().map(|o| o.label.clone()))
        .with_class_ids(objects.iter().map(|o| o.class));
        self.log(path::OBJECTS, &shapes)?;
        self.stats.objects = objects.len();
        self.objects = Some(objects);
        Ok(())
    }

    fn state(&self, s: &crate::scene::FrameState) -> Result<(), RecordError> {
        let text = match s.inliers {
            Some(n) if n > 0 => format!("{} ({n} inliers)", s.name),
            _ => s.name.clone(),
        };
        self.log(path::STATE, &TextLog::new(text).with_level(TextLogLevel::from(state_log_level(&s.name))))?;
        if let Some(level) = state_level(&s.name) {
            self.log(path::LEVEL, &Scalars::single(level))?;
        }
        let figures = [
            (path::INLIERS, s.inliers.map(|n| n as f64)),
            (path::TRACKED_POINTS, s.tracked_map_points.map(|n| n as f64)),
            (path::REPROJECTION, s.reprojection_rms_px),
            (path::FRAME_MS, s.frame_ms),
        ];
        for (entity, value) in figures {
            if let Some(v) = value {
                self.log(entity, &Scalars::single(v))?;
            }
        }
        Ok(())
    }

    /// Write out what is queued and close the file.
    fn close(self) -> Result<RecordingStats, RecordError> {
        self.rec.flush_blocking().map_err(|e| self.failed(e))?;
        let stats = self.stats;
        // dropping the stream ends the file sink's thread, which finishes the file
        drop(self.rec);
        Ok(stats)
    }
}
