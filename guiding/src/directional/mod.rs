//! Distributions over directions: von Mises-Fisher lobes and their mixtures, the weighted EM
//! that fits a mixture to samples, Henyey-Greenstein phase functions fitted by vMF lobes, the
//! closed-form product of the two, and the lane-wide kernels they evaluate with. Nothing here
//! knows about space: a region of the field owns one mixture.

pub(crate) mod em;
pub mod hg;
pub(crate) mod lanes;
pub(crate) mod mixture;
pub mod product;
pub mod vmf;
