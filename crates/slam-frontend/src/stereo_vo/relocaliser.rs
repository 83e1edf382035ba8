//! Relocalisation when the motion model gives no accepted pose: along the motion (dropped frames), by
//! descriptors against the local map (no prediction: where the motion model broke), and by retrieval
//! from a descriptor index of every keyframe of the run ([`super::keyframe_index`]) that is still in
//! the map.

use std::time::Instant;

use nalgebra::Isometry3;
use slam_core::KeyframeId;
use slam_map::Map;

use super::checks::{judge, motion_limits, Support};
use super::frame::Frame;
use super::keyframe_index::KeyframeIndex;
use super::local_map::LocalMap;
use super::motion::{scaled, MotionModel};
use super::pose_search::{PoseSearch, Route};
use super::refine::Refined;
use crate::image_io::FrontendError;

/// What relocalisation found: the accepted candidate (refined pose, RANSAC inliers, route), the
/// first candidate pose whether accepted or not, and for a retrieved keyframe, the map its inliers
/// index (that keyframe's local map, the keyframe in slot 0).
pub(crate) type Relocalisation = (Option<(Refined, usize, Route)>, Option<Isometry3<f64>>, Option<LocalMap>);

/// Keyframes tried by retrieval ([`Relocaliser::retrieve`]): the best few by votes, since the keyframes
/// just before and after a place share most of its descriptors and the votes rank the right one near
/// the top, not always first; each costs one brute-force matching and PnP RANSAC, on a lost frame or a
/// frame not yet placed in a loaded map only.
const RETRIEVAL_CANDIDATES: usize = 3;

/// Most PnP RANSAC rounds on a retrieved keyframe's matches: enough to draw one 4-point sample of
/// right matches with 99.9 % probability when 30 % of them are right, `ln 0.001 / ln(1 − 0.3⁴)` = 850.
/// At a place the map holds, descriptor matches against a keyframe's own points are mostly right
/// (what survives the ratio test and the one-to-one assignment: 98 % on odometry 06 driven again,
/// both ways), and RANSAC stops as soon as its consensus makes further rounds pointless; a
/// keyframe whose matches agree less is no place to localise in, and on a road the map does not
/// hold the 5 000 rounds of relocalisation would take 60 ms per keyframe tried, every frame.
const RETRIEVAL_ITERATIONS: i32 = 850;

/// The descriptors of every keyframe of the run, for retrieval.
#[derive(Default)]
pub(crate) struct Relocaliser {
    pub(crate) index: KeyframeIndex,
}

/// What relocalisation reads of the tracker: the pose search, the motion model, the map, and the
/// keyframes retrieval may place a frame against (by id: those of one map segment, or of the map but a
/// segment).
pub(crate) struct Context<'a> {
    pub(crate) pose_search: &'a PoseSearch,
    pub(crate) motion: &'a MotionModel,
    pub(crate) map: &'a Map,
    pub(crate) among: std::ops::Range<KeyframeId>,
}

impl Relocaliser {
    /// Keep a keyframe's descriptors for retrieval.
    pub(crate) fn index(&mut self, id: KeyframeId, descriptors: &[[u8; 32]]) {
        let t0 = Instant::now();
        self.index.insert(id, descriptors);
        tracing::debug!(keyframe = id, ms = t0.elapsed().as_secs_f64() * 1e3, "keyframe indexed");
    }

    /// Relocalisation: by descriptors alone against the local map (4-point solver, 5000 RANSAC rounds,
    /// 2 × the RANSAC threshold, ≥ 12 inliers), verified by a search at the pose found and the
    /// refinement: it assumes nothing of the motion, so it finds the frame wherever the motion model
    /// went wrong (a reversal, a start after a standstill, dropped frames); then along the motion (the
    /// motion model applied 2 to 16 times: frames dropped by the recorder, where the descriptors alone
    /// were ambiguous); then by retrieval.
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
        {
            let all = cx.pose_search.match_all(map, frame);
            let found =
                cx.pose_search.pnp_ransac(map, frame, &all, (2.0 * cx.pose_search.config.ransac_px, 5000, 12))?;
            if let Some((pose, _)) = found {
                first.get_or_insert(pose);
                if let Some(found) = Self::verify(cx, map, frame, &pose, Route::Descriptors, accept)? {
                    return Ok((Some(found), first, None));
                }
            }
        }
        // each hypothesis of k − 1 dropped frames covers half a step either side of its prediction
        let (t1, r1) = motion_limits(&cx.motion.step_config(&cx.pose_search.config), 1.0);
        let bounds =
            (t1 + 0.5 * cx.motion.velocity.translation.vector.norm(), r1 + 0.5 * cx.motion.velocity.rotation.angle());
        for k in 2usize..=16 {
            let guess = (cx.motion.kf_from_last
                * scaled(&cx.motion.velocity, cx.motion.steps(cx.motion.gap) - 1.0 + k as f64))
            .inverse();
            if let Some((r, n)) = cx.pose_search.track_from(map, frame, &guess, bounds, &cx.motion.kf_from_measured)? {
                tracing::debug!(steps = k, inliers = r.inliers.len(), "relocalisation along the motion");
                first.get_or_insert(r.pose);
                if accept(&r, Route::Along(k)) {
                    return Ok((Some((r, n, Route::Along(k))), first, None));
                }
            }
        }
        let (found, retrieved) = self
            .retrieve(cx, frame)?
            .map_or((None, None), |(r, n, id, m)| (Some((r, n, Route::Retrieved(id))), Some(m)));
        Ok((found, first, retrieved))
    }

    /// Relocalisation by retrieval: the [`RETRIEVAL_CANDIDATES`] keyframes of the map that the
    /// descriptor index ([`super::keyframe_index`]) ranks best for the frame's descriptors, each tried
    /// alone: the points the keyframe observes matched by descriptors (a keyframe's own points, as
    /// ORB-SLAM2 relocalises, rather than its neighbourhood's: a fifth of the matching), PnP RANSAC
    /// with [`RETRIEVAL_ITERATIONS`] at most, then the keyframe's local map (it and its best
    /// covisible neighbours) searched at the pose found and the refinement ([`Relocaliser::verify`]);
    /// accepted only with full support ([`Support::Full`]: inliers, their spread, their error). The
    /// motion model is not consulted: a revisit or a long gap breaks it legitimately. Returns the
    /// refined pose as `curr_from_ref`, the RANSAC inliers, the keyframe's id and the map the inliers
    /// index.
    pub(crate) fn retrieve(
        &self,
        cx: &Context<'_>,
        frame: &Frame,
    ) -> Result<Option<(Refined, usize, KeyframeId, LocalMap)>, FrontendError> {
        if frame.points.len() < cx.pose_search.config.min_inliers {
            return Ok(None);
        }
        let t0 = Instant::now();
        let candidates =
            self.index.query_among(&frame.keypoint_desc, RETRIEVAL_CANDIDATES, &|id| cx.among.contains(&id));
        tracing::debug!(ms = t0.elapsed().as_secs_f64() * 1e3, "retrieval query");
        for (id, score) in candidates {
            if cx.map.keyframe(id).is_none() {
                continue;
            }
            let t0 = Instant::now();
            let own = LocalMap::of(cx.map, id, &[id]);
            let all = cx.pose_search.match_all(&own, frame);
            let matched = t0.elapsed().as_secs_f64() * 1e3;
            let ransac = (2.0 * cx.pose_search.config.ransac_px, RETRIEVAL_ITERATIONS, 12);
            let found = cx.pose_search.pnp_ransac(&own, frame, &all, ransac)?;
            let pnp = t0.elapsed().as_secs_f64() * 1e3 - matched;
            tracing::debug!(
                keyframe = id,
                score,
                points = own.len(),
                matches = all.len(),
                matched,
                pnp,
                "retrieved keyframe"
            );
            let Some((pose, _)) = found else { continue };
            let around: Vec<KeyframeId> = std::iter::once(id)
                .chain(cx.map.covisibility().best(id, cx.pose_search.config.local_neighbours))
                .collect();
            let map = LocalMap::of(cx.map, id, &around);
            let accept = |r: &Refined, route: Route| {
                judge(&cx.pose_search.config, cx.pose_search.image_size, cx.motion, r, route, frame) == Support::Full
            };
            if let Some((r, n, _)) = Self::verify(cx, &map, frame, &pose, Route::Retrieved(id), &accept)? {
                tracing::debug!(
                    keyframe = id,
                    inliers = r.inliers.len(),
                    ms = t0.elapsed().as_secs_f64() * 1e3,
                    "retrieved keyframe verified"
                );
                return Ok(Some((r, n, id, map)));
            }
        }
        Ok(None)
    }

    /// A candidate pose verified: the map searched at it (windows of twice the second search's),
    /// PnP RANSAC on those matches, the second search and the refinement; the result when `accept`
    /// takes it.
    fn verify(
        cx: &Context<'_>,
        map: &LocalMap,
        frame: &Frame,
        pose: &Isometry3<f64>,
        route: Route,
        accept: &dyn Fn(&Refined, Route) -> bool,
    ) -> Result<Option<(Refined, usize, Route)>, FrontendError> {
        let skip = vec![false; map.len()];
        let taken = vec![false; frame.keypoints.len()];
        let radius = 2.0 * cx.pose_search.config.local_radius;
        let scale = slam_map::ScalePyramid::default();
        let matches = cx.pose_search.search(map, pose, frame, &|_, l| radius * scale.scale(l), (&skip, &taken));
        let Some((pose, inliers)) = cx.pose_search.pnp_ransac(
            map,
            frame,
            &matches,
            (cx.pose_search.config.ransac_px, 200, cx.pose_search.config.weak_inliers),
        )?
        else {
            return Ok(None);
        };
        let Some((r, n)) = cx.pose_search.extend_and_refine(map, frame, &pose, inliers, &cx.motion.kf_from_measured)
        else {
            return Ok(None);
        };
        tracing::debug!(inliers = r.inliers.len(), ?route, "relocalisation candidate");
        Ok(accept(&r, route).then_some((r, n, route)))
    }
}
