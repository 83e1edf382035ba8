//! IoU-only association (the QuadricSLAM-style baseline).

use slam_core::{Assignment, AssociationInput, Associator};

use crate::hungarian::assign;

/// Settings of [`IouAssociator`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IouConfig {
    /// Smallest IoU accepted for a match. Default 0.25 (same gate as ODA's default with one cue).
    pub min_iou: f64,
}

impl Default for IouConfig {
    fn default() -> Self {
        Self { min_iou: 0.25 }
    }
}

/// Hungarian assignment on `1 − IoU(track's last box, detection box)`, same class only.
#[derive(Debug, Clone, Default)]
pub struct IouAssociator {
    /// Settings.
    pub config: IouConfig,
}

impl Associator for IouAssociator {
    fn name(&self) -> &'static str {
        "IoU"
    }

    fn associate(&mut self, input: &AssociationInput<'_>) -> Assignment {
        let ids: Vec<_> = input.tracks.iter().map(|t| t.id).collect();
        assign(input.detections, &ids, |d, t| {
            let (det, trk) = (&input.detections[d], &input.tracks[t]);
            if det.class.group() != trk.class.group() {
                return None;
            }
            let iou = trk.last.iou(&det.bbox);
            (iou >= self.config.min_iou).then_some(1.0 - iou)
        })
    }
}
