//! The keyframes' features beside a map file (`map.features` beside `map.json`): what a later run
//! tracks against, kept out of the JSON so that the JSON stays readable (a keyframe's 2 000 ORB
//! descriptors are 64 KB of bytes, twice that as hex).
//!
//! Layout, little-endian: the magic `QSMFEAT1`, the keyframe count (u32), then per keyframe its id
//! (u64), image width and height (f32), keypoint count `n` (u32), `n` keypoints (u, v, u_right as
//! f32, NaN without a stereo match; pyramid level u8; angle f32 degrees; descriptor 32 bytes), the
//! count `m` of its observations (u32) and `m` pairs (keypoint index u32, point id u64). 49 bytes a
//! keypoint and 12 an observation: about 100 KB for a keyframe of 2 000 keypoints observing 350
//! points. The JSON names the file and holds its length and FNV-1a 64 checksum, so a file that is
//! not the one the JSON was written with, or that was damaged, is refused on load.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use slam_core::{
    map::{Descriptor, Keypoint},
    KeyframeId, PointId,
};

/// First bytes of a features file (format version 1).
pub const FEATURES_MAGIC: &[u8; 8] = b"QSMFEAT1";

/// One keyframe's features as saved: its image size, keypoints with their descriptors, and which
/// point each observing keypoint observes.
#[derive(Debug, Clone, PartialEq)]
pub struct SavedFeatures {
    /// Image width and height, pixels.
    pub size: (f64, f64),
    /// Keypoints.
    pub keypoints: Vec<Keypoint>,
    /// One descriptor a keypoint.
    pub descriptors: Vec<Descriptor>,
    /// `(keypoint, point)`: the keypoints that observe a map point.
    pub observations: Vec<(u32, PointId)>,
}

/// What the JSON says of its features file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeaturesRef {
    /// The file's name, in the map file's folder.
    pub file: String,
    /// Its length, bytes.
    pub bytes: u64,
    /// Its FNV-1a 64 checksum, 16 hex digits.
    pub fnv1a64: String,
}

/// FNV-1a 64 of `bytes` (a checksum against damage, not against tampering).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// The features file's bytes; refused (naming the keyframe) when a keyframe's keypoints and descriptors
/// differ in number.
pub fn encode(features: &BTreeMap<KeyframeId, SavedFeatures>) -> Result<Vec<u8>, String> {
    if let Some((id, f)) = features.iter().find(|(_, f)| f.keypoints.len() != f.descriptors.len()) {
        return Err(format!("keyframe {id}: {} keypoints, {} descriptors", f.keypoints.len(), f.descriptors.len()));
    }
    let per: usize = features.values().map(|f| 24 + 49 * f.keypoints.len() + 12 * f.observations.len()).sum();
    let mut out = Vec::with_capacity(12 + per);
    out.extend_from_slice(FEATURES_MAGIC);
    out.extend_from_slice(&(features.len() as u32).to_le_bytes());
    for (id, f) in features {
        out.extend_from_slice(&id.to_le_bytes());
        out.extend_from_slice(&(f.size.0 as f32).to_le_bytes());
        out.extend_from_slice(&(f.size.1 as f32).to_le_bytes());
        out.extend_from_slice(&(f.keypoints.len() as u32).to_le_bytes());
        for (k, d) in f.keypoints.iter().zip(&f.descriptors) {
            for x in [k.u as f32, k.v as f32, k.u_right as f32] {
                out.extend_from_slice(&x.to_le_bytes());
            }
            out.push(k.level);
            out.extend_from_slice(&k.angle.to_le_bytes());
            out.extend_from_slice(d);
        }
        out.extend_from_slice(&(f.observations.len() as u32).to_le_bytes());
        for (k, p) in &f.observations {
            out.extend_from_slice(&k.to_le_bytes());
            out.extend_from_slice(&p.to_le_bytes());
        }
    }
    Ok(out)
}

/// A cursor over the file's bytes that says where it ran out.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], String> {
        let end = self.at + N;
        let b = self
            .bytes
            .get(self.at..end)
            .ok_or_else(|| format!("ends at byte {} inside {what}", self.bytes.len()))?
            .try_into()
            .map_err(|_| format!("byte {}: {what}", self.at))?;
        self.at = end;
        Ok(b)
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        self.take::<4>(what).map(u32::from_le_bytes)
    }
    fn f32(&mut self, what: &str) -> Result<f32, String> {
        self.take::<4>(what).map(f32::from_le_bytes)
    }
    fn u64(&mut self, what: &str) -> Result<u64, String> {
        self.take::<8>(what).map(u64::from_le_bytes)
    }
}

/// Read a features file's bytes; the message says what is wrong and at which byte.
pub fn decode(bytes: &[u8]) -> Result<BTreeMap<KeyframeId, SavedFeatures>, String> {
    let mut r = Reader { bytes, at: 0 };
    if &r.take::<8>("the magic")? != FEATURES_MAGIC {
        return Err(format!("not a features file (it does not start with {:?})", "QSMFEAT1"));
    }
    let n = r.u32("the keyframe count")?;
    let mut out = BTreeMap::new();
    for _ in 0..n {
        let id = r.u64("a keyframe id")?;
        let at = r.at;
        let size = (f64::from(r.f32("the image width")?), f64::from(r.f32("the image height")?));
        // a camera image is at most tens of thousands of pixels across
        if !(size.0 >= 1.0 && size.1 >= 1.0 && size.0 <= 65_536.0 && size.1 <= 65_536.0) {
            return Err(format!("byte {at}: keyframe {id}: image size {size:?}"));
        }
        let count = r.u32("a keypoint count")? as usize;
        // each keypoint takes 49 bytes: a count the rest of the file cannot hold is damage
        if count.saturating_mul(49) > bytes.len() - r.at {
            return Err(format!("byte {}: keyframe {id}: {count} keypoints do not fit in the file", r.at));
        }
        let (mut keypoints, mut descriptors) = (Vec::with_capacity(count), Vec::with_capacity(count));
        for i in 0..count {
            let at = r.at;
            let (u, v, u_right) = (r.f32("a keypoint")?, r.f32("a keypoint")?, r.f32("a keypoint")?);
            let level = r.take::<1>("a keypoint")?[0];
            let angle = r.f32("a keypoint")?;
            if !(u.is_finite() && v.is_finite() && !u_right.is_infinite() && angle.is_finite()) {
                return Err(format!("byte {at}: keyframe {id} keypoint {i}: not finite"));
            }
            // inside its image (a pixel of slack for sub-pixel positions), its angle in degrees
            let inside = |x: f32, n: f64| (-1.0..=n + 1.0).contains(&f64::from(x));
            if !(inside(u, size.0) && inside(v, size.1) && (u_right.is_nan() || inside(u_right, size.0)))
                || !(-360.0..=720.0).contains(&angle)
            {
                return Err(format!(
                    "byte {at}: keyframe {id} keypoint {i}: ({u}, {v}, right {u_right}, angle {angle}) is not a keypoint of a {}×{} image",
                    size.0, size.1
                ));
            }
            keypoints.push(Keypoint { u: u.into(), v: v.into(), u_right: u_right.into(), level, angle });
            descriptors.push(r.take::<32>("a descriptor")?);
        }
        let m = r.u32("an observation count")? as usize;
        if m.saturating_mul(12) > bytes.len() - r.at {
            return Err(format!("byte {}: keyframe {id}: {m} observations do not fit in the file", r.at));
        }
        let mut observations = Vec::with_capacity(m);
        for _ in 0..m {
            let at = r.at;
            let k = r.u32("an observation")?;
            if k as usize >= count {
                return Err(format!("byte {at}: keyframe {id}: keypoint {k} of {count}"));
            }
            observations.push((k, r.u64("an observation")?));
        }
        if out.insert(id, SavedFeatures { size, keypoints, descriptors, observations }).is_some() {
            return Err(format!("keyframe {id} appears twice"));
        }
    }
    if r.at != bytes.len() {
        return Err(format!("{} bytes after the last keyframe", bytes.len() - r.at));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> BTreeMap<KeyframeId, SavedFeatures> {
        let kp = |i: usize| Keypoint {
            u: 10.5 + i as f64,
            v: 20.25,
            u_right: if i % 2 == 0 { 3.5 } else { f64::NAN },
            level: (i % 8) as u8,
            angle: 12.5,
        };
        let f = |n: usize, id: u64| SavedFeatures {
            size: (1226.0, 370.0),
            keypoints: (0..n).map(kp).collect(),
            descriptors: (0..n).map(|i| [i as u8; 32]).collect(),
            observations: (0..n as u32).step_by(2).map(|k| (k, id * 100 + u64::from(k))).collect(),
        };
        [(0, f(5, 0)), (7, f(3, 7)), (9, f(0, 9))].into_iter().collect()
    }

    #[test]
    fn features_read_back_as_written_and_damage_is_named() {
        let s = sample();
        let bytes = encode(&s).expect("encodes");
        let mut odd = s.clone();
        odd.get_mut(&7).expect("keyframe 7").descriptors.pop();
        assert_eq!(encode(&odd).expect_err("mismatch"), "keyframe 7: 3 keypoints, 2 descriptors");
        let back = decode(&bytes).expect("decodes");
        assert_eq!(back.len(), 3);
        for (id, f) in &s {
            let b = &back[id];
            assert_eq!((b.size, &b.descriptors, &b.observations), (f.size, &f.descriptors, &f.observations));
            for (x, y) in b.keypoints.iter().zip(&f.keypoints) {
                assert_eq!((x.u, x.v, x.level, x.angle), (y.u, y.v, y.level, y.angle));
                assert!(x.u_right == y.u_right || (x.u_right.is_nan() && y.u_right.is_nan()));
            }
        }
        // cut short, a byte too many, another magic, a keypoint index beyond the keyframe's
        let e = decode(&bytes[..bytes.len() - 3]).expect_err("short");
        assert!(e.contains("ends at byte"), "{e}");
        let mut long = bytes.clone();
        long.push(0);
        assert!(decode(&long).expect_err("long").contains("1 bytes after"));
        let mut magic = bytes.clone();
        magic[0] = b'X';
        assert!(decode(&magic).expect_err("magic").contains("not a features file"));
        let mut index = bytes.clone();
        // the first keyframe's first observation: after the header (12), id, size, count (20) and 5
        // keypoints, and the observation count
        let at = 12 + 20 + 5 * 49 + 4;
        index[at..at + 4].copy_from_slice(&99u32.to_le_bytes());
        assert!(decode(&index).expect_err("index").contains("keypoint 99 of 5"));
        assert_ne!(fnv1a64(&bytes), fnv1a64(&index));
    }
}
