//! Relocalisation when the motion model gives no accepted pose: along the motion (dropped frames), by
//! descriptors against the local map and the older keyframes kept, and by retrieval from a descriptor
//! index of every keyframe of the run ([`crate::keyframe_index`]).

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use nalgebra::Isometry3;
use slam_core::{KeyframeCorrection, KeyframeId};

use super::checks::{judge, motion_limits, Support};
use super::frame::Frame;
use super::keyframes::{apply_correction, Keyframes, Reference};
use super::local_map::LocalMap;
use super::motion::{scaled, MotionModel};
use super::refine::Refined;
use super::tracker::{Route, Tracker};
use crate::image_io::FrontendError;
use crate::keyframe_index::KeyframeIndex;
use crate::matching::KeypointGrid;

/// What relocalisation found: the accepted candidate (refined pose, RANSAC inliers, route), the
/// first candidate pose whether accepted or not, and for a retrieved keyframe, the map its inliers
/// index (that keyframe's points in the reference keyframe's frame).
pub(crate) type Relocalisation = (Option<(Refined, usize, Route)>, Option<Isometry3<f64>>, Option<LocalMap>);

/// Keyframes tried by retrieval ([`Relocaliser::retrieve`]): the best few by votes, since the keyframes
/// just before and after a place share most of its descriptors and the votes rank the right one near
/// the top, not always first; each costs one brute-force matching and PnP RANSAC, on a lost frame only.
const RETRIEVAL_CANDIDATES: usize = 3;

/// The keyframes of the whole run kept for retrieval: the descriptors of all their keypoints in the
/// index, and their map points by id (keypoints dropped).
#[derive(Default)]
pub(crate) struct Relocaliser {
    pub(crate) index: KeyframeIndex,
    archive: BTreeMap<KeyframeId, Reference>,
}

/// What relocalisation reads of the tracker: the pose search, the motion model and the keyframes.
pub(crate) struct Context<'a> {
    pub(crate) tracker: &'a Tracker,
    pub(crate) motion: &'a MotionModel,
    pub(crate) keyframes: &'a Keyframes,
}

impl Relocaliser {
    /// Keep a keyframe for retrieval: all its keypoints' descriptors in the index and its map points
    /// in the archive.
    pub(crate) fn archive(&mut self, kf: &Reference) {
        let t0 = Instant::now();
        self.index.insert(kf.id, &kf.frame.keypoint_desc);
        let mut kept = kf.clone();
        kept.frame.keypoints = Vec::new();
        kept.frame.keypoint_desc = Vec::new();
        kept.frame.grid = KeypointGrid::default();
        self.archive.insert(kf.id, kept);
        tracing::debug!(keyframe = kf.id, ms = t0.elapsed().as_secs_f64() * 1e3, "keyframe indexed");
    }

    /// The pose of keyframe `id` in the world, if it is archived.
    pub(crate) fn world_from(&self, id: KeyframeId) -> Option<Isometry3<f64>> {
        self.archive.get(&id).map(|k| k.world_from_kf)
    }

    /// Apply a mapper's correction to the archived keyframe it concerns, and carry the reference's pose
    /// over when the correction moved the reference's parent (`reference`: after
    /// [`Keyframes::correct`]).
    pub(crate) fn correct(&mut self, c: &KeyframeCorrection, reference: Option<&Reference>) {
        if let Some(kf) = self.archive.get_mut(&c.id) {
            apply_correction(kf, c);
        }
        let Some(r) = reference else { return };
        if r.id != c.id && r.parent.is_some_and(|(parent, _)| parent == c.id) {
            if let Some(kf) = self.archive.get_mut(&r.id) {
                kf.world_from_kf = r.world_from_kf;
            }
        }
    }

    /// Relocalisation: along the motion (the motion model applied 2 to 16 times: frames dropped by the
    /// recorder look like that), then by descriptors alone against the local map and
    /// then against each older keyframe (4-point solver, 5000 RANSAC rounds, 2 × the RANSAC threshold,
    /// ≥ 12 inliers), each candidate verified by a second search and the refinement.
    /// Returns the first candidate `accept` takes, and the pose of the first one found (accepted or
    /// not: where a new map segment starts when nothing better is found).
    pub(crate) fn relocalise(
        &self,
        cx: &Context<'_>,
        map: &LocalMap,
        frame: &Frame,
        accept: &dyn Fn(&Refined, Route) -> bool,
    ) -> Result<Relocalisation, FrontendError> {
        let mut first = None;
        // each hypothesis of k − 1 dropped frames covers half a step either side of its prediction
        let (t1, r1) = motion_limits(&cx.motion.step_config(&cx.tracker.config), 1.0);
        let bounds =
            (t1 + 0.5 * cx.motion.velocity.translation.vector.norm(), r1 + 0.5 * cx.motion.velocity.rotation.angle());
        for k in 2usize..=16 {
            let guess = (cx.motion.kf_from_last
                * scaled(&cx.motion.velocity, cx.motion.steps(cx.motion.gap) - 1.0 + k as f64))
            .inverse();
            if let Some((r, n)) = cx.tracker.track_from(map, frame, &guess, bounds, &cx.motion.kf_from_measured)? {
                tracing::debug!(steps = k, inliers = r.inliers.len(), "relocalisation along the motion");
                first.get_or_insert(r.pose);
                if accept(&r, Route::Along(k)) {
                    return Ok((Some((r, n, Route::Along(k))), first, None));
                }
            }
        }
        let Some(reference) = &cx.keyframes.reference else { return Ok((None, first, None)) };
        let ref_from_world = reference.world_from_kf.inverse();
        let mut maps = vec![None];
        for kf in cx.keyframes.local.iter().skip(cx.tracker.config.local_keyframes) {
            let mut single = LocalMap::default();
            single.add_keyframe(kf, ref_from_world * kf.world_from_kf, &mut HashMap::new());
            maps.push(Some(single));
        }
        for candidate in &maps {
            let m = candidate.as_ref().unwrap_or(map);
            let all = cx.tracker.match_all(m, frame);
            let Some((pose, _)) =
                cx.tracker.pnp_ransac(m, frame, &all, (2.0 * cx.tracker.config.ransac_px, 5000, 12))?
            else {
                continue;
            };
            first.get_or_insert(pose);
            // verify against the local map at the candidate pose
            let skip = vec![false; map.points.len()];
            let taken = vec![false; frame.keypoints.len()];
            let radius = 2.0 * cx.tracker.config.local_radius;
            let matches = cx.tracker.search(map, &pose, frame, &|_, o| radius * 1.2f64.powi(o), &skip, &taken);
            let Some((pose, inliers)) = cx.tracker.pnp_ransac(
                map,
                frame,
                &matches,
                (cx.tracker.config.ransac_px, 200, cx.tracker.config.weak_inliers),
            )?
            else {
                continue;
            };
            if let Some((r, n)) = cx.tracker.extend_and_refine(map, frame, &pose, inliers, &cx.motion.kf_from_measured)
            {
                tracing::debug!(inliers = r.inliers.len(), "relocalisation by descriptors");
                first.get_or_insert(r.pose);
                if accept(&r, Route::Descriptors) {
                    return Ok((Some((r, n, Route::Descriptors)), first, None));
                }
            }
        }
        let (found, retrieved) = self
            .retrieve(cx, frame)?
            .map_or((None, None), |(r, n, id, m)| (Some((r, n, Route::Retrieved(id))), Some(m)));
        Ok((found, first, retrieved))
    }

    /// Relocalisation by retrieval: the [`RETRIEVAL_CANDIDATES`] keyframes of the whole run that the
    /// descriptor index ([`crate::keyframe_index`]) ranks best for the frame's descriptors, each tried alone (its map points matched by descriptors, PnP RANSAC
    /// as in [`Relocaliser::relocalise`], a second search at the pose found, the refinement) and accepted
    /// only with full support ([`Support::Full`]: inliers, their spread, their error). The motion
    /// model is not consulted: a revisit or a long gap breaks it legitimately. Returns the refined
    /// pose as `curr_from_ref`, the RANSAC inliers, the keyframe's id and the map the inliers index.
    pub(crate) fn retrieve(
        &self,
        cx: &Context<'_>,
        frame: &Frame,
    ) -> Result<Option<(Refined, usize, KeyframeId, LocalMap)>, FrontendError> {
        let Some(reference) = &cx.keyframes.reference else { return Ok(None) };
        if frame.points.len() < cx.tracker.config.min_inliers {
            return Ok(None);
        }
        let ref_from_world = reference.world_from_kf.inverse();
        for (id, score) in self.index.query(&frame.keypoint_desc, RETRIEVAL_CANDIDATES) {
            let Some(kf) = self.archive.get(&id) else { continue };
            let ref_from_kf = ref_from_world * kf.world_from_kf;
            let mut map = LocalMap::default();
            map.add_keyframe(kf, ref_from_kf, &mut HashMap::new());
            let all = cx.tracker.match_all(&map, frame);
            let Some((pose, _)) =
                cx.tracker.pnp_ransac(&map, frame, &all, (2.0 * cx.tracker.config.ransac_px, 5000, 12))?
            else {
                tracing::debug!(keyframe = id, score, matches = all.len(), "retrieved keyframe: no PnP pose");
                continue;
            };
            let skip = vec![false; map.points.len()];
            let taken = vec![false; frame.keypoints.len()];
            let radius = 2.0 * cx.tracker.config.local_radius;
            let matches = cx.tracker.search(&map, &pose, frame, &|_, o| radius * 1.2f64.powi(o), &skip, &taken);
            let Some((pose, inliers)) = cx.tracker.pnp_ransac(
                &map,
                frame,
                &matches,
                (cx.tracker.config.ransac_px, 200, cx.tracker.config.weak_inliers),
            )?
            else {
                continue;
            };
            let Some((r, n)) = cx.tracker.extend_and_refine(&map, frame, &pose, inliers, &cx.motion.kf_from_measured)
            else {
                continue;
            };
            let support = judge(&cx.tracker.config, cx.tracker.image_size, cx.motion, &r, Route::Retrieved(id), frame);
            tracing::debug!(keyframe = id, score, inliers = r.inliers.len(), ?support, "retrieved keyframe");
            if support == Support::Full {
                return Ok(Some((r, n, id, map)));
            }
        }
        Ok(None)
    }
}
