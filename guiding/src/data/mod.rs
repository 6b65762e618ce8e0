//! What the renderer hands the field: the training samples (a position, a direction towards
//! where light came from, its radiance and pdf) and the per-path recorder that turns a path's
//! vertices and contributions into them.

pub(crate) mod recorder;
pub(crate) mod sample;
