//! Integrators: estimators of the radiance arriving at the camera along a ray.
//!
//! `walk` is the volumetric random walk; `VolPath` runs it unguided, the baseline every
//! guided estimator is compared against, and it must be unbiased on its own, which the
//! white-furnace and analytic tests check. The render session runs the same walk with guided
//! components and a trained field.

pub mod trace;
mod volpath;
pub mod walk;

pub use volpath::VolPath;
pub use walk::shadow_transmittance;
