//! Constant-velocity Kalman filter on a box, with the state of SORT (Bewley et al., ICIP 2016):
//! `x = [u, v, s, r, u̇, v̇, ṡ]` where `(u, v)` is the box centre, `s` its area and `r` its aspect
//! ratio (width / height, assumed constant). The measurement is `[u, v, s, r]`. One step per frame.

use nalgebra::{SMatrix, SVector};
use slam_core::geometry::BBox;

type State = SVector<f64, 7>;
type Cov = SMatrix<f64, 7, 7>;

/// Measurement noise variances for `(u, v, s, r)` (px², px², px⁴, 1).
const MEAS_VAR: [f64; 4] = [1.0, 1.0, 10.0, 10.0];
/// Initial variances: positions as measured, velocities very uncertain.
const INIT_VAR: [f64; 7] = [10.0, 10.0, 10.0, 10.0, 1e4, 1e4, 1e4];
/// Process noise variances per step.
const PROC_VAR: [f64; 7] = [1.0, 1.0, 1.0, 1e-2, 1e-2, 1e-2, 1e-4];

/// A SORT-style box filter.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanBoxFilter {
    x: State,
    p: Cov,
}

fn measure(b: &BBox) -> [f64; 4] {
    let [u, v] = b.centre();
    let (w, h) = (b.width().max(1e-6), b.height().max(1e-6));
    [u, v, w * h, w / h]
}

impl KalmanBoxFilter {
    /// A filter initialised at a box with zero velocity.
    pub fn new(b: &BBox) -> Self {
        let z = measure(b);
        let x = State::from_column_slice(&[z[0], z[1], z[2], z[3], 0.0, 0.0, 0.0]);
        Self { x, p: Cov::from_diagonal(&SVector::from(INIT_VAR)) }
    }

    /// The box of the current state.
    pub fn bbox(&self) -> BBox {
        let s = self.x[2].max(1e-6);
        let r = self.x[3].max(1e-6);
        let w = (s * r).sqrt();
        let h = s / w;
        BBox::new(self.x[0] - w / 2.0, self.x[1] - h / 2.0, self.x[0] + w / 2.0, self.x[1] + h / 2.0)
    }

    /// Velocity of the box centre, pixels per step.
    pub fn velocity(&self) -> [f64; 2] {
        [self.x[4], self.x[5]]
    }

    /// Advance one step and return the predicted box.
    pub fn predict(&mut self) -> BBox {
        if self.x[2] + self.x[6] <= 0.0 {
            self.x[6] = 0.0;
        }
        let mut f = Cov::identity();
        f[(0, 4)] = 1.0;
        f[(1, 5)] = 1.0;
        f[(2, 6)] = 1.0;
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + Cov::from_diagonal(&SVector::from(PROC_VAR));
        self.bbox()
    }

    /// Correct with a measured box. Non-finite boxes are ignored (the state is kept).
    pub fn update(&mut self, b: &BBox) {
        let z = measure(b);
        if !z.iter().all(|v| v.is_finite()) {
            return;
        }
        let mut h = SMatrix::<f64, 4, 7>::zeros();
        for i in 0..4 {
            h[(i, i)] = 1.0;
        }
        let y = SVector::<f64, 4>::from(z) - h * self.x;
        let s = h * self.p * h.transpose() + SMatrix::<f64, 4, 4>::from_diagonal(&SVector::from(MEAS_VAR));
        let Some(s_inv) = s.try_inverse() else { return };
        let k = self.p * h.transpose() * s_inv;
        self.x += k * y;
        self.p = (Cov::identity() - k * h) * self.p;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learns_constant_velocity() {
        let mut f = KalmanBoxFilter::new(&BBox::new(100.0, 50.0, 140.0, 80.0));
        for k in 1..20 {
            f.predict();
            let dx = 5.0 * k as f64;
            f.update(&BBox::new(100.0 + dx, 50.0, 140.0 + dx, 80.0));
        }
        let p = f.predict();
        assert!((p.centre()[0] - (120.0 + 5.0 * 20.0)).abs() < 0.5, "{p:?}");
        assert!((p.width() - 40.0).abs() < 0.5 && (p.height() - 30.0).abs() < 0.5);
        assert!((f.velocity()[0] - 5.0).abs() < 0.2);
        f.update(&BBox::new(f64::NAN, 0.0, 1.0, 1.0));
        assert!(f.bbox().xmin.is_finite());
    }
}
