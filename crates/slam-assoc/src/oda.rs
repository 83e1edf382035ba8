//! ODA: the object data association of Tian et al. (RA-L 2022, §VI).

use slam_core::{Assignment, AssociationInput, Associator, Region};

use crate::hungarian::{assign, Cost};

/// Weights of the three cues (the paper's α, β, γ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdaWeights {
    /// Semantic-inlier distance `a^p` (α, paper: 0.8).
    pub inliers: f64,
    /// Projected-ellipsoid IoU distance `a^g` (β, paper: 1.0).
    pub projection: f64,
    /// Kalman-predicted IoU distance `a^k` (γ, paper: 0.8).
    pub prediction: f64,
}

impl Default for OdaWeights {
    fn default() -> Self {
        Self { inliers: 0.8, projection: 1.0, prediction: 0.8 }
    }
}

/// Settings of [`Oda`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdaConfig {
    /// Cue weights.
    pub weights: OdaWeights,
    /// Largest normalised cost (in `[0, 1]`, see [`Oda`]) accepted for a match. Default 0.75: with only
    /// the prediction cue, IoU ≥ 0.25.
    pub max_cost: f64,
    /// Fewest tracked keypoints inside a detection for `a^p` to count. Default 5.
    pub min_flow_points: usize,
    /// A gate on top of the paper's cost: a track whose projected ellipsoid overlaps a detection by less
    /// than this IoU never takes it, however well the other cues agree (a fitted, static object does not
    /// jump to the next car in a row). Default `None` (the paper's cost alone).
    pub min_projected_iou: Option<f64>,
}

impl Default for OdaConfig {
    fn default() -> Self {
        Self { weights: OdaWeights::default(), max_cost: 0.75, min_flow_points: 5, min_projected_iou: None }
    }
}

/// The ODA associator.
///
/// Cost of detection `j` for track `i`:
///
/// ```text
/// a_ij = (α a^p + β a^g + γ a^k) / (α [a^p known] + β [a^g known] + γ [a^k known])
/// ```
///
/// * `a^p = 1 − |{x ∈ X_j : x_ref ∈ region_i}| / |X_j|`, with `X_j` the tracked keypoints whose current
///   position is inside detection `j`'s mask (or box) and `x_ref` their position in the reference
///   keyframe; known when `|X_j| ≥ min_flow_points` and track `i` has a reference region;
/// * `a^g = 1 − IoU(projected box of track i's ellipsoid, box j)`; known when the track has an ellipsoid;
/// * `a^k = 1 − IoU(predicted box of track i, box j)`; known when the track has a prediction.
///
/// With all three cues known this is the paper's cost divided by 2.6, so the paper's ranking is kept;
/// when a cue is missing (no ellipsoid yet, no flow) the others are renormalised rather than the missing
/// one counted as 0 or 1. Pairs with no known cue, different classes, or cost above `max_cost` are not
/// matched.
#[derive(Debug, Clone, Default)]
pub struct Oda {
    /// Settings.
    pub config: OdaConfig,
}

impl Oda {
    /// ODA with the given settings.
    pub fn new(config: OdaConfig) -> Self {
        Self { config }
    }

    /// The normalised cost matrix (rows: detections, columns: tracks), gated entries `None`. Exposed for
    /// inspection and tests.
    pub fn costs(&self, input: &AssociationInput<'_>) -> Vec<Vec<Cost>> {
        let w = &self.config.weights;
        // Points inside each detection (current position).
        let inside: Vec<Vec<usize>> = input
            .detections
            .iter()
            .map(|d| {
                let region = d.region();
                input
                    .flow
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| region.contains(p.current[0], p.current[1]))
                    .map(|(k, _)| k)
                    .collect()
            })
            .collect();
        input
            .detections
            .iter()
            .enumerate()
            .map(|(j, d)| {
                input
                    .tracks
                    .iter()
                    .map(|t| {
                        // one vehicle is called car, bus and truck in turn by a detector
                        if t.class.group() != d.class.group() {
                            return None;
                        }
                        let (mut num, mut den) = (0.0, 0.0);
                        if let Some(region) =
                            t.reference_region.filter(|_| inside[j].len() >= self.config.min_flow_points)
                        {
                            let hits = inside[j]
                                .iter()
                                .filter(|&&k| {
                                    let r = input.flow[k].reference;
                                    match region {
                                        Region::Box(b) => {
                                            r[0] >= b.xmin && r[0] <= b.xmax && r[1] >= b.ymin && r[1] <= b.ymax
                                        }
                                        Region::Mask(m) => m.contains(r[0], r[1]),
                                    }
                                })
                                .count();
                            num += w.inliers * (1.0 - hits as f64 / inside[j].len() as f64);
                            den += w.inliers;
                        }
                        if let Some(p) = t.projected {
                            if self.config.min_projected_iou.is_some_and(|g| p.iou(&d.bbox) < g) {
                                return None;
                            }
                            num += w.projection * (1.0 - p.iou(&d.bbox));
                            den += w.projection;
                        }
                        if let Some(p) = t.predicted {
                            num += w.prediction * (1.0 - p.iou(&d.bbox));
                            den += w.prediction;
                        }
                        if den <= 0.0 {
                            return None;
                        }
                        let c = num / den;
                        (c.is_finite() && c <= self.config.max_cost).then_some(c)
                    })
                    .collect()
            })
            .collect()
    }
}

impl Associator for Oda {
    fn name(&self) -> &'static str {
        "ODA"
    }

    fn associate(&mut self, input: &AssociationInput<'_>) -> Assignment {
        let costs = self.costs(input);
        let ids: Vec<_> = input.tracks.iter().map(|t| t.id).collect();
        assign(input.detections, &ids, |d, t| costs[d][t])
    }
}
