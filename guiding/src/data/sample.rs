//! The training sample a renderer hands to the field, and its validation.

use crate::GuidingError;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// One observation of incident radiance at a point.
///
/// `direction` is the unit direction light arrives *from*, pointing away from `position`
/// towards the source (the direction the path was continued in). `radiance` is the scalar
/// (luminance-like) incident radiance observed along it and `pdf` the density (per steradian)
/// with which the renderer sampled `direction`. The EM weight of the sample is
/// `radiance / pdf`, and the mean of these weights over a region estimates its fluence
/// `Phi(x)`; so each sample must be an unbiased one-sample estimate of the fluence at its
/// position (see [`PathRecorder`](crate::PathRecorder) for how it keeps this with
/// next-event estimation). Zero-radiance samples are valid and matter: they are the
/// directions where no light was found.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Where the radiance was observed.
    pub position: Vec3,
    /// Unit incident direction, pointing away from `position` towards the light.
    pub direction: Vec3,
    /// Incident radiance along `direction` (finite, >= 0).
    pub radiance: f32,
    /// Density with which `direction` was sampled (finite, > 0).
    pub pdf: f32,
    /// Distance to where the radiance came from (the next vertex), or infinity for light
    /// from infinitely far. Parallax-aware fitting (`FieldConfig::parallax`) re-aims the
    /// direction from the region's centre towards that point.
    pub distance: f32,
    /// True when `position` is in a medium, false on a surface.
    pub volume: bool,
}

impl Sample {
    /// The EM weight `radiance / pdf`, in double precision (it may exceed the f32 range).
    #[inline]
    pub fn weight(&self) -> f64 {
        f64::from(self.radiance) / f64::from(self.pdf)
    }

    /// Checks the sample, explaining what is wrong with it.
    pub fn validate(&self) -> Result<(), String> {
        if !self.position.is_finite() {
            return Err(format!("position {} is not finite", self.position));
        }
        let len = self.direction.length();
        if !(len.is_finite() && (len - 1.0).abs() < 1e-3) {
            return Err(format!("direction {} is not a unit vector", self.direction));
        }
        if !(self.radiance.is_finite() && self.radiance >= 0.0) {
            return Err(format!("radiance {} is negative or not finite", self.radiance));
        }
        if !(self.pdf.is_finite() && self.pdf > 0.0) {
            return Err(format!("pdf {} is not finite and positive", self.pdf));
        }
        if self.distance.is_nan() || self.distance < 0.0 {
            return Err(format!("distance {} is negative or NaN", self.distance));
        }
        Ok(())
    }
}

/// Validates a batch, naming the first bad sample.
pub(crate) fn validate_all(samples: &[Sample]) -> Result<(), GuidingError> {
    use rayon::prelude::*;
    // In parallel, and still the first invalid sample whatever the thread count.
    match samples.par_iter().position_first(|s| s.validate().is_err()) {
        Some(index) => Err(GuidingError::InvalidSample {
            index,
            reason: samples[index].validate().expect_err("found invalid"),
        }),
        None => Ok(()),
    }
}
