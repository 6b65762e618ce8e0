//! zerovar's lab: what measures renders rather than makes them. [`compare`] renders a scene
//! with several methods at equal time or samples, over seeds, against a reference;
//! [`metrics`] holds the image errors it reports (relMSE with the reference's own noise taken
//! out, trimmed variants); [`plot`] draws convergence plots. The `zerovar` binary, built from
//! this crate, is the command line over the renderer (`zerovar`) and this lab. Kept apart so
//! that the renderer as a library carries no plotting.

pub mod compare;
pub mod metrics;
pub mod plot;
