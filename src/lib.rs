//! zerovar: a volumetric path tracer built around zero-variance path guiding.
//!
//! The library holds everything the `zerovar` binary does: scene loading and validation
//! (`scene`), geometry (`shapes`, `accel`), surfaces and phase functions (`bsdf`, `phase`),
//! participating media (`media`) and the estimators that move through them (`tracking`),
//! `lights`, the `camera`, the `integrators`, and the `render` session that drives them over
//! tiles, accumulates a `film` and writes images (`output`).
//!
//! ```no_run
//! use zerovar::guided::Components;
//! use zerovar::render::{Budget, RenderOptions, render};
//! let scene = zerovar::scene::load("scenes/fog-sphere.toml".as_ref(), &[]).unwrap();
//! let mut options = RenderOptions::unguided(Budget::Samples(16), 0);
//! options.guiding.components = Components::FULL; // train a field, then render with it
//! let result = render(&scene, &options, &|_, _| true).unwrap();
//! println!("mean pixel {:?}", result.film.average());
//! ```

pub mod accel;
pub mod bsdf;
pub mod camera;
pub mod compare;
pub mod distribution;
pub mod film;
pub mod guided;
pub mod integrators;
pub mod lights;
pub mod math;
pub mod media;
pub mod metrics;
pub mod output;
pub mod phase;
pub mod plot;
pub mod render;
pub mod rng;
pub mod scene;
pub mod shapes;
pub mod stats;
pub mod tracking;
pub mod transform;
