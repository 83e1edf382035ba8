//! A hand-made street for the tests: points in front of a camera driving along z, keyframes that see
//! them with exact projections, stereo where the point is near enough, and each point's descriptor
//! seen with a few bits flipped per view.

use std::{collections::BTreeMap, sync::Arc};

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{rngs::ChaCha8Rng, RngExt, SeedableRng};
use slam_quadric::Intrinsics;

use crate::{
    camera::{ScalePyramid, StereoCamera},
    descriptor::Descriptor,
    insert::{CreationPolicy, Inserted},
    keyframe::{Features, Keypoint},
    NewKeyframe, PointId,
};

pub(crate) const SIZE: (f64, f64) = (1241.0, 376.0);

pub(crate) fn camera() -> StereoCamera {
    StereoCamera { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), baseline: 0.54 }
}

pub(crate) fn map() -> crate::Map {
    crate::Map::new(camera(), ScalePyramid::default())
}

/// A street of `n` points: x ±12 m, y −2..1.5 m, z 4..60 m, each with a random descriptor.
pub(crate) struct Street {
    pub(crate) points: Vec<Vector3<f64>>,
    pub(crate) descriptors: Vec<Descriptor>,
    rng: ChaCha8Rng,
}

impl Street {
    pub(crate) fn new(seed: u64, n: usize) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let points = (0..n)
            .map(|_| {
                Vector3::new(rng.random_range(-12.0..12.0), rng.random_range(-2.0..1.5), rng.random_range(4.0..60.0))
            })
            .collect();
        let descriptors = (0..n).map(|_| std::array::from_fn(|_| rng.random::<u8>())).collect();
        Self { points, descriptors, rng }
    }

    /// The keyframe at `z` metres along the road seeing every point in view: its features (keypoints
    /// in the order of the points seen), the world index of each keypoint, and its pose.
    pub(crate) fn view(&mut self, z: f64, near_stereo: f64) -> (Features, Vec<usize>, Isometry3<f64>) {
        let cam = camera();
        let pose = Isometry3::translation(0.0, 0.0, z);
        let mut keypoints = Vec::new();
        let mut descriptors = Vec::new();
        let mut index = Vec::new();
        for (i, x) in self.points.iter().enumerate() {
            let c = (pose.inverse() * Point3::from(*x)).coords;
            if c.z < 1.0 {
                continue;
            }
            let o = cam.observe(&c);
            if !(0.0..SIZE.0).contains(&o[0]) || !(0.0..SIZE.1).contains(&o[1]) {
                continue;
            }
            let level = ((60.0 / c.z).ln() / 1.2f64.ln()).floor().clamp(0.0, 7.0) as u8;
            let u_right = if c.z < near_stereo { o[2] } else { f64::NAN };
            keypoints.push(Keypoint { u: o[0], v: o[1], u_right, level, angle: 0.0 });
            let mut d = self.descriptors[i];
            for _ in 0..3 {
                let bit = self.rng.random_range(0..256usize);
                d[bit / 8] ^= 1 << (bit % 8);
            }
            descriptors.push(d);
            index.push(i);
        }
        (Features::new(keypoints, descriptors, SIZE).expect("same lengths"), index, pose)
    }

    /// A new keyframe of the view at `z`, its keypoints matched to the map points `matched` gives for
    /// their world indices.
    pub(crate) fn keyframe(
        &mut self,
        map: &crate::Map,
        frame: usize,
        z: f64,
        matched: &dyn Fn(usize) -> Option<PointId>,
    ) -> (NewKeyframe, Vec<usize>) {
        let (features, index, pose) = self.view(z, 40.0 * 0.54);
        let parent = map.keyframes().last().map(|k| k.id);
        let kf = NewKeyframe {
            id: map.next_keyframe_id(),
            frame,
            pose,
            parent,
            matched: index.iter().map(|&i| matched(i)).collect(),
            features: Arc::new(features),
        };
        (kf, index)
    }

    /// Insert the view at `z` as a keyframe, its keypoints matched to the points `seen` holds for their
    /// world indices; `seen` then holds the points it made too. What the insertion made, and the world
    /// index of each keypoint.
    pub(crate) fn insert(
        &mut self,
        map: &mut crate::Map,
        (frame, z): (usize, f64),
        policy: &CreationPolicy,
        seen: &mut BTreeMap<usize, PointId>,
    ) -> (Inserted, Vec<usize>) {
        let (kf, index) = self.keyframe(map, frame, z, &|i| seen.get(&i).copied());
        let id = kf.id;
        let inserted = map.insert_keyframe(kf, policy).expect("insert");
        for (kp, p) in map.keyframe(id).expect("kf").observations() {
            seen.entry(index[kp]).or_insert(p);
        }
        (inserted, index)
    }
}
