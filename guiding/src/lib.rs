//! Zero-variance path guiding, as a library that stands alone: vMF mixtures, online weighted
//! EM and an adaptive spatial tree, embedded by a renderer the way Cycles embeds Open PGL.
//!
//! The field learns the incident radiance `L(x, w) = Phi(x) V_L(w)` from the paths of each
//! render pass: a kd-tree of regions, each holding a fluence estimate `Phi` and a mixture of
//! von Mises-Fisher lobes `V_L`. While rendering, a per-thread [`VolumeDistribution`] loads the
//! region at a vertex, multiplies the mixture by the phase function (Henyey-Greenstein, fitted
//! by vMF lobes) in closed form, and samples the product; it also estimates incident and
//! in-scattered radiance for zero-variance distance sampling and Russian roulette.
//!
//! ```
//! use glam::{Vec2, Vec3};
//! use zerovar_guiding::{Field, FieldConfig, PathRecorder, Sample, VolumeDistribution};
//!
//! let mut field = Field::new(FieldConfig::default())?;
//! let mut recorder = PathRecorder::new();
//! let mut samples: Vec<Sample> = Vec::new();
//! // A pass: per path, record vertices and contributions, then emit samples.
//! recorder.add_vertex(Vec3::ZERO, Vec3::Z, 0.25, 1.0, true);
//! recorder.add_contribution(2.0);
//! recorder.finish(&mut samples);
//! field.update(&samples)?; // between passes
//! let mut dist = VolumeDistribution::default(); // per thread, reused
//! if dist.init(&field, Vec3::ZERO, 0.5) {
//!     dist.apply_hg_product(Vec3::X, 0.6);
//!     let (dir, pdf) = dist.sample_with_pdf(Vec2::new(0.2, 0.7));
//!     assert!((dist.pdf(dir) - pdf).abs() <= 1e-6 * pdf);
//! }
//! # Ok::<(), zerovar_guiding::GuidingError>(())
//! ```
//!
//! Directions are always unit vectors pointing away from the vertex towards where light comes
//! from (which is the new path direction). The phase-function convention is
//! `cos theta = dot(ray_dir, new_dir)`, `ray_dir` being the direction the path travelled.

mod config;
mod data;
mod directional;
mod distribution;
mod error;
mod field;
mod spatial;
#[cfg(test)]
mod testutil;

pub use config::{FieldConfig, SampleKind};
pub use data::recorder::{Branch, PathRecorder};
pub use data::sample::Sample;
pub use directional::mixture::{MAX_LOBES, Mixture};
pub use directional::vmf::VmfLobe;
pub use directional::{hg, product, vmf};
pub use distribution::{MAX_PRODUCT_LOBES, ProductKind, VolumeDistribution};
pub use error::GuidingError;
pub use field::io::{FORMAT_VERSION, MAGIC};
pub use field::stats::FieldStats;
pub use field::{Field, Region};
