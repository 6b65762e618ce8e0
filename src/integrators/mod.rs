//! Integrators: estimators of the radiance arriving at the camera along a ray.
//!
//! `VolPath` is the unguided volumetric path tracer every guided estimator is compared
//! against; it must be unbiased on its own, which the white-furnace and analytic tests check.

mod volpath;

pub use volpath::{VolPath, shadow_transmittance};
