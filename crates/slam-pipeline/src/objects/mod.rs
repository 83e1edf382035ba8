//! The object mapper: posed detections in, ellipsoids out.
//!
//! Per frame: the boxes of the objects' projected ellipsoids are given to the associator (ODA's
//! `a^g` cue), detections are assigned to tracks, and each track keeps its observations (frame,
//! camera, box). An object gets an ellipsoid once it has `min_views` boxes away from the image border
//! seen with at least `min_parallax_deg` between the first and the latest ray; it is re-optimised each
//! time `refit_every` new boxes have arrived. Fitting is [`slam_optim::object::refine`] (DQP starts,
//! box error with Huber on the exact clipped bounds, class prior on the axes, upright constraint, and a
//! joint stage under a pose-drift prior when boxes and poses disagree) on at most `max_views` evenly
//! spaced views. An object whose fitted boxes still miss by more than `dynamic_rms_px` (RMS) is flagged
//! dynamic: a moving object cannot be explained by one static ellipsoid.
//!
//! The parts, each in its module: settings ([`config`]), class knowledge ([`classes`]), the record
//! of an object and its observations ([`object`]), association glue ([`association`]), motion
//! evidence from the stereo points ([`motion`]), evidence for and against a static ellipsoid
//! ([`evidence`]), fitting ([`fitting`]), the mapper's bookkeeping ([`mapper`]), the object map
//! file ([`output`]) and the objects of a loaded map ([`restore`]).

pub mod association;
pub mod classes;
pub mod config;
pub mod evidence;
pub mod fitting;
pub mod flow;
pub mod mapper;
pub mod method;
pub mod motion;
pub mod object;
pub mod output;
pub mod restore;

pub use association::suppress_duplicate_boxes;
pub use classes::{class_prior, physical_limits, physically_plausible, PhysicalLimits};
pub use config::MapperConfig;
pub use evidence::{free_space_votes, surface_cue, StereoNoise, MIN_FREE_SPACE_RAYS};
pub use fitting::{FitJob, FitMethod, FitResult};
pub use mapper::ObjectMapper;
pub use motion::{scene_flow, FlowedPoint, RaySplit, SceneFlow, FLOW_POSE_SIGMA_M, MIN_FLOW_POINTS, MOTION_WINDOW};
pub use object::{MappedObject, Observation, PointsCentroid};
pub use output::{object_map_text, write_object_map, write_object_map_in, INPUT_POSES_WORLD, OBJECT_MAP_VERSION};
