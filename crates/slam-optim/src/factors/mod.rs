//! Built-in factors. Every one has an analytic Jacobian checked against [`crate::factor::numeric_jacobians`].
//!
//! | factor | keys | residual |
//! |---|---|---|
//! | [`BalReprojection`] | BAL camera, point | BAL pixel error (2) |
//! | [`MonoReprojection`] | pose `T_wc`, point | pixel error (2) |
//! | [`StereoReprojection`] | pose `T_wc`, point | left pixel and right `u` (3) |
//! | [`Between`] | pose `X_i`, pose `X_j` | `Log(Z⁻¹ X_i⁻¹ X_j)` (6) |
//! | [`PosePrior`] | pose | `Log(Z⁻¹ X)` (6) |
//! | [`PointPrior`] | point | `X − Z` (3) |
//! | [`BoxFactor`] | pose `T_wc`, ellipsoid | predicted − detected box (4) |
//! | [`AxisPrior`] | ellipsoid | `a − a_prior` (3) |
//! | [`TexturePlane`] | ellipsoid | distance of the camera-side tangent plane to a fitted plane (1) |
//! | [`SurfaceDepth`] | ellipsoid | depth of its centre behind a stereo surface point, less its chord along the ray (1) |
//! | [`AxisDirection`] | ellipsoid | `d × (R e_k)`: an axis along a direction, e.g. gravity (3) |

mod bal;
mod object;
mod reproj;
mod se3;

pub use bal::BalReprojection;
pub use object::{
    cuboid_box_error, AxisDirection, AxisPrior, BoxFactor, CuboidBoxFactor, CuboidSurface, SurfaceDepth, TexturePlane,
};
pub use reproj::{MonoReprojection, StereoReprojection};
pub use se3::{Between, PointPrior, PosePrior};
