//! zerovar: a volumetric path tracer built around zero-variance path guiding.
//!
//! The library holds everything a render needs (the `zerovar` binary, in `lab/`, parses
//! arguments and runs comparisons):
//! load a scene from a file ([`scene::load`]) or build one in code ([`SceneBuilder`]), set
//! [`RenderOptions`] (checked by [`RenderOptions::validate`]), train a guiding field, render
//! to an in-memory image, read the counters, report progress and cancel through a callback.
//!
//! ```
//! use zerovar::guided::Components;
//! use zerovar::render::{Budget, TrainBudget, render};
//! use zerovar::RenderOptions;
//!
//! let scene = zerovar::scene::load("scenes/fog-sphere.toml".as_ref(), &[]).unwrap();
//! let mut options = RenderOptions::unguided(Budget::Samples(2), 7);
//! options.guiding.components = Components::FULL; // train a field, then render with it
//! options.guiding.train = TrainBudget::Passes(2);
//! // The callback sees (done, total) and may cancel by returning false.
//! let result = render(&scene, &options, &|_done, _total| true).unwrap();
//! assert_eq!(result.spp, 2);
//! assert!(result.image.iter().flatten().all(|v| v.is_finite()));
//! println!("trained {:?}, mean pixel {:?}", result.training.map(|t| t.spp), result.film.average());
//! ```
//!
//! The modules come in two tiers. The **application API**, what a host program needs, is
//! re-exported here: [`scene`] (load, [`SceneBuilder`], the element descriptions of
//! [`scene::desc`]), [`render`] (options, training, rendering, cancellation), [`guided`]'s
//! [`TrainedField`], [`film`] and [`output`] (EXR/PNG) and [`stats`]. Comparison runs, error
//! metrics and plots are the lab's (`zerovar-lab`, which also builds the `zerovar` binary), so
//! the library does not carry plotting.
//! The **building blocks** are public for research code that assembles its own integrator
//! or extends the renderer: [`media`] (with the [`media::DensityFunction`] trait for host
//! densities), [`tracking`] (free-flight and transmittance estimators), [`phase`], [`bsdf`],
//! [`lights`], [`camera`], [`filter`], [`shapes`], [`integrators`], [`math`], [`rng`], [`transform`] and
//! [`files`]; they follow the same rules but change more freely between versions. The
//! acceleration structure and sampling tables are private.

mod accel;
pub mod bsdf;
pub mod camera;
mod distribution;
pub mod files;
pub mod film;
pub mod filter;
pub mod guided;
pub mod integrators;
pub mod lights;
pub mod math;
pub mod media;
pub mod output;
pub mod phase;
pub mod render;
pub mod rng;
pub mod scene;
pub mod shapes;
pub mod stats;
pub mod tracking;
pub mod transform;

pub use film::Film;
pub use guided::TrainedField;
pub use render::{Budget, GuidingOptions, OptionsError, RenderError, RenderOptions, RenderResult};
pub use scene::{Scene, SceneBuilder, SceneError};
