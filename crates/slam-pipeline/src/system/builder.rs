//! Wiring a [`System`] from its parts ([`SystemBuilder`]), and driving it frame by frame
//! ([`System::step`]) or over a whole source ([`System::run`]).
//!
//! The live map ([`slam_core::Map`]) is made here, empty or rebuilt from a saved map
//! ([`SystemBuilder::map`]), and moved into the tracking thread, which owns it for the whole run;
//! [`System::finish`] turns it into the run's [`SavedMap`], which the caller writes
//! ([`SavedMap::save`]).

use std::thread::JoinHandle;

use crossbeam_channel::{bounded, unbounded, Receiver, Sender};
use nalgebra::Isometry3;
use slam_core::{geometry::Intrinsics, Associator, DetectionSource, StereoTracker};
use slam_optim::SharedOptimizer;

use super::{
    threads::{detection_thread, mapping_thread, Detected},
    tracking_thread::TrackingThread,
    FrameInput, FrameRecord, FrameView, RunOutput, SystemConfig, SystemError,
};
use crate::{
    mapping::LocalMapper,
    objects::{FitMethod, MappedObject, ObjectMapper},
    saved_map::{LoadedMap, SavedMap},
};

/// A source of input frames, in increasing id order.
pub type FrameSource = Box<dyn Iterator<Item = FrameInput> + Send>;

/// Frames queued between the reader, detection and tracking (decoding and detection run ahead of
/// tracking by at most this many frames).
const QUEUE: usize = 4;

/// The parts of a [`System`], each behind its seam: the tracker ([`StereoTracker`], required), the
/// optimiser ([`SharedOptimizer`], required), the detector ([`DetectionSource`]; none: no objects),
/// the associator ([`Associator`]; default ODA gated at [`SystemConfig::projected_gate`]), the
/// ellipsoid method ([`FitMethod`], an initialiser with or without refinement; default
/// Tri+Yaw+refine), the frame source (only for [`System::run`]) and the settings.
///
/// Wiring a system and driving it frame by frame (the example of `docs/architecture.md`):
///
/// ```
/// use std::sync::Arc;
///
/// use slam_core::{DetectionSource, StereoTracker};
/// use slam_pipeline::{
///     objects::FitMethod,
///     system::{FrameInput, RunOutput, SystemBuilder, SystemConfig, SystemError},
/// };
/// use slam_quadric::Intrinsics;
///
/// fn wire_and_play(
///     tracker: Box<dyn StereoTracker>,
///     detector: Box<dyn DetectionSource>,
///     frames: impl IntoIterator<Item = FrameInput>,
/// ) -> Result<RunOutput, SystemError> {
///     let k = Intrinsics::new(718.856, 718.856, 607.193, 185.216);
///     let mut system = SystemBuilder::new(k, 0.537)
///         .config(SystemConfig::default())
///         .tracker(tracker)
///         .detector(Some(detector))
///         .associator(Box::new(slam_assoc::IouAssociator::default()))
///         .optimizer(Arc::new(slam_lm::LevenbergMarquardt::default()))
///         .method(FitMethod::refined(Arc::new(slam_quadric::init::Conic::default()), "Conic+refine"))
///         .build()?;
///     for frame in frames {
///         let record = system.step(frame)?;
///         println!("frame {}: {} boxes, keyframe {}", record.index, record.detections.len(), record.keyframe);
///     }
///     system.finish()
/// }
/// ```
pub struct SystemBuilder {
    intrinsics: Intrinsics,
    baseline: f64,
    config: SystemConfig,
    source: Option<FrameSource>,
    tracker: Option<Box<dyn StereoTracker>>,
    detector: Option<Box<dyn DetectionSource>>,
    associator: Option<Box<dyn Associator>>,
    optimizer: Option<SharedOptimizer>,
    method: FitMethod,
    loaded: Option<LoadedMap>,
}

impl SystemBuilder {
    /// A builder for a stereo rig (left camera intrinsics, baseline in metres) with default settings.
    pub fn new(intrinsics: Intrinsics, baseline: f64) -> Self {
        Self {
            intrinsics,
            baseline,
            config: SystemConfig::default(),
            source: None,
            tracker: None,
            detector: None,
            associator: None,
            optimizer: None,
            method: FitMethod::default(),
            loaded: None,
        }
    }

    /// Start from a map loaded from an earlier run ([`SavedMap::to_live`]): its keyframes, points and
    /// objects; the tracker localises in it before it tracks, and what the run adds extends it
    /// (nothing with [`SystemConfig::localise_only`]).
    pub fn map(mut self, loaded: Option<LoadedMap>) -> Self {
        self.loaded = loaded;
        self
    }

    /// Settings.
    pub fn config(mut self, config: SystemConfig) -> Self {
        self.config = config;
        self
    }

    /// The frames [`System::run`] plays.
    pub fn source(mut self, frames: FrameSource) -> Self {
        self.source = Some(frames);
        self
    }

    /// The visual front end.
    pub fn tracker(mut self, tracker: Box<dyn StereoTracker>) -> Self {
        self.tracker = Some(tracker);
        self
    }

    /// The detector (without one the system maps no objects).
    pub fn detector(mut self, detector: Option<Box<dyn DetectionSource>>) -> Self {
        self.detector = detector;
        self
    }

    /// The object associator (replaces the default ODA; [`SystemConfig::projected_gate`] is ODA's
    /// setting and then unused).
    pub fn associator(mut self, associator: Box<dyn Associator>) -> Self {
        self.associator = Some(associator);
        self
    }

    /// The optimiser of the local bundle adjustments and the object fits.
    pub fn optimizer(mut self, optimizer: SharedOptimizer) -> Self {
        self.optimizer = Some(optimizer);
        self
    }

    /// How objects' ellipsoids are computed (an initialiser, with or without the object optimisation).
    pub fn method(mut self, method: FitMethod) -> Self {
        self.method = method;
        self
    }

    /// Start the detection and local-mapping threads; the tracking runs on the thread that calls
    /// [`System::step`] or [`System::run`].
    pub fn build(self) -> Result<System, SystemError> {
        let tracker = self.tracker.ok_or(SystemError::Missing("tracker"))?;
        let optimizer = self.optimizer.ok_or(SystemError::Missing("optimizer"))?;
        let config = self.config;
        let (frame_tx, frame_rx) = bounded::<FrameInput>(QUEUE);
        let (det_tx, det_rx) = bounded::<Detected>(QUEUE);
        let (detector, every) = (self.detector, config.detect_every);
        let detection = std::thread::Builder::new()
            .name("detection".into())
            .spawn(move || detection_thread(detector, every, frame_rx, det_tx))
            .map_err(|_| SystemError::Thread("detection"))?;
        let (req_tx, req_rx) = unbounded();
        let (reply_tx, reply_rx) = unbounded();
        let mapper = LocalMapper::new(config.mapping, optimizer.clone());
        let texture = config.texture;
        let mapping = std::thread::Builder::new()
            .name("local mapping".into())
            .spawn(move || mapping_thread(mapper, texture, req_rx, reply_tx))
            .map_err(|_| SystemError::Thread("local mapping"))?;
        let associator = self.associator.unwrap_or_else(|| {
            Box::new(slam_assoc::Oda::new(slam_assoc::OdaConfig {
                min_projected_iou: config.projected_gate,
                ..slam_assoc::OdaConfig::default()
            }))
        });
        let mut objects = ObjectMapper::new(associator, config.objects, optimizer).with_method(self.method);
        let map = match self.loaded {
            Some(loaded) => {
                objects.restore(&loaded.objects, self.intrinsics);
                loaded.map
            }
            None => {
                let camera = slam_core::map::StereoCamera { k: self.intrinsics, baseline: self.baseline };
                slam_core::Map::new(camera, slam_core::map::ScalePyramid::default())
            }
        };
        let mut tracker = tracker;
        if map.keyframe_count() > 0 {
            tracker.load_map(&map);
        }
        let tracking = TrackingThread::new(tracker, map, objects, config, req_tx, reply_rx);
        Ok(System { source: self.source, frames: Some(frame_tx), detected: Some(det_rx), detection, mapping, tracking })
    }
}

/// A running system: detection and local mapping on their own threads, tracking on the caller's.
/// Drive it with [`System::step`] (one frame at a time, e.g. from a research script) or
/// [`System::run`] (the builder's source, decoded and detected ahead of tracking), then
/// [`System::finish`]. Both give the same output for the same frames.
pub struct System {
    source: Option<FrameSource>,
    frames: Option<Sender<FrameInput>>,
    detected: Option<Receiver<Detected>>,
    detection: JoinHandle<()>,
    mapping: JoinHandle<()>,
    tracking: TrackingThread,
}

impl System {
    /// Track one frame (its detection runs first, on the detection thread); returns its record. The
    /// record's local-mapping times are filled in later (see [`TrackingThread::records`]).
    pub fn step(&mut self, frame: FrameInput) -> Result<&FrameRecord, SystemError> {
        let (Some(frames), Some(detected)) = (&self.frames, &self.detected) else {
            return Err(SystemError::Thread("detection"));
        };
        frames.send(frame).map_err(|_| SystemError::Thread("detection"))?;
        let (input, dets, det) = detected.recv().map_err(|_| SystemError::Thread("detection"))?;
        self.tracking.step(&input, dets, det)
    }

    /// The tracking state so far (records, counts, objects).
    pub fn tracking_thread(&self) -> &TrackingThread {
        &self.tracking
    }

    /// Play the builder's source to its end and finish; `on_frame` sees each frame as soon as it is
    /// tracked ([`FrameView`]: progress output, a recording).
    pub fn run(mut self, on_frame: &mut dyn FnMut(&FrameView<'_>)) -> Result<RunOutput, SystemError> {
        let source = self.source.take().ok_or(SystemError::Missing("frame source"))?;
        let frames = self.frames.take().ok_or(SystemError::Thread("detection"))?;
        let detected = self.detected.take().ok_or(SystemError::Thread("detection"))?;
        let tracking = &mut self.tracking;
        std::thread::scope(|scope| {
            // the reader decodes ahead of detection; it stops when the input ends or tracking stopped
            scope.spawn(move || {
                for f in source {
                    if frames.send(f).is_err() {
                        break;
                    }
                }
            });
            // on an error the receiver is dropped on return, which stops detection and the reader
            for (input, dets, det) in detected {
                tracking.step(&input, dets, det)?;
                if let Some(view) = tracking.view(&input) {
                    on_frame(&view);
                }
            }
            Ok::<(), SystemError>(())
        })?;
        self.finish()
    }

    /// Wait for local mapping to answer every keyframe, stop the threads and hand over the map, the
    /// poses of all frames, the objects, the records and the counts.
    pub fn finish(mut self) -> Result<RunOutput, SystemError> {
        self.frames = None;
        self.tracking.drain_replies()?;
        self.tracking.stop_mapping();
        let Self { detection, mapping, tracking, .. } = self;
        detection.join().map_err(|_| SystemError::Thread("detection"))?;
        mapping.join().map_err(|_| SystemError::Thread("local mapping"))?;
        let mut map = SavedMap::from_live(&tracking.map);
        map.trajectory = tracking.trajectory;
        map.objects = tracking.objects.objects().filter_map(MappedObject::to_saved_object).collect();
        // local mapping culls points no keyframe observes any more; an object keeps the ids it was
        // given, so only those still in the map go into the file (which refers to nothing else)
        for o in &mut map.objects {
            o.points.retain(|p| map.points.contains_key(p));
        }
        let placed = map.trajectory.iter().map(|f| f.keyframe.is_some()).collect();
        let poses = map.frame_poses().into_iter().map(|p| p.unwrap_or_else(Isometry3::identity)).collect();
        Ok(RunOutput {
            map,
            poses,
            placed,
            objects: tracking.objects.objects().cloned().collect(),
            frames: tracking.records,
            counts: tracking.counts,
        })
    }
}
