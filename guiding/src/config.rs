//! The settings of a guiding field, with defaults and validation.

use crate::GuidingError;
use crate::directional::mixture::MAX_LOBES;
use serde::{Deserialize, Serialize};

/// Which training samples a field learns from, by `Sample::volume`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum SampleKind {
    /// Every sample.
    #[default]
    All,
    /// Only samples recorded at vertices in a medium (`volume == true`).
    Volume,
    /// Only samples recorded at surface vertices (`volume == false`).
    Surface,
}

/// Settings of a [`Field`](crate::Field). `Default` gives the values listed per field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FieldConfig {
    /// Lobes each region's mixture starts with (default 8, at most [`MAX_LOBES`]).
    pub initial_lobes: usize,
    /// Concentration of the starting lobes (default 2).
    pub initial_kappa: f32,
    /// Lobes a mixture may grow to by splitting (default 32; used when `split_merge` is on).
    pub max_lobes: usize,
    /// A leaf splits once it has seen this many samples since it was created (default 4,000).
    pub max_samples_per_leaf: usize,
    /// Leaves at this depth never split (default 32).
    pub max_depth: u32,
    /// EM iterations per update of a region (default 4).
    pub em_iterations: u32,
    /// Dirichlet prior strength `v` on the lobe weights, in samples (default 0.01).
    pub weight_prior: f32,
    /// Mean cosine `r0` the per-lobe prior pulls towards (default 0: uniform).
    pub mean_cosine_prior: f32,
    /// Strength of the mean-cosine prior, in samples (default 0.2).
    pub mean_cosine_prior_strength: f32,
    /// Largest concentration the EM may fit (default 32,000, about 0.3 degrees).
    pub max_kappa: f32,
    /// Stepwise-EM exponent `alpha` in (0.5, 1]: the `t`-th batch of a region gets step size
    /// `t^-alpha`. 1 (default) weighs all samples equally; smaller values forget early,
    /// poorly guided passes faster.
    pub step_exponent: f32,
    /// Split and merge lobes by their chi-square divergence (Ruppert et al. 2020); default off.
    pub split_merge: bool,
    /// A lobe whose share of the chi-square divergence exceeds this is split (default 0.5).
    pub split_threshold: f32,
    /// Two lobes closer than this (chi-square of one against the other) merge (default 0.025).
    pub merge_threshold: f32,
    /// Stochastic spatial filtering: `lookup` picks among the region at the position and its
    /// nearby regions, driven by the caller's random number (default off).
    pub spatial_filter: bool,
    /// Nearby regions considered by the spatial filter (default 4, at most 16).
    pub filter_neighbours: usize,
    /// A nearby region is used when its centre lies within this many times the spread of the
    /// query region's samples (default 1.5).
    pub filter_radius: f32,
    /// Which samples the field learns from (default all).
    pub samples: SampleKind,
    /// Parallax-aware lobes (Ruppert et al. 2020; default on): each lobe learns how far its
    /// light comes from, and lookups re-aim it from the region's centre to the query point,
    /// so a region resolves a nearby source seen at different angles across it.
    pub parallax: bool,
}

impl Default for FieldConfig {
    fn default() -> Self {
        Self {
            initial_lobes: 8,
            initial_kappa: 2.0,
            max_lobes: MAX_LOBES,
            max_samples_per_leaf: 4_000,
            max_depth: 32,
            em_iterations: 4,
            weight_prior: 0.01,
            mean_cosine_prior: 0.0,
            mean_cosine_prior_strength: 0.2,
            max_kappa: 32_000.0,
            step_exponent: 1.0,
            split_merge: false,
            split_threshold: 0.5,
            merge_threshold: 0.025,
            spatial_filter: false,
            filter_neighbours: 4,
            filter_radius: 1.5,
            samples: SampleKind::All,
            parallax: true,
        }
    }
}

/// Most neighbours the spatial filter keeps per region.
pub(crate) const MAX_NEIGHBOURS: usize = 16;

impl FieldConfig {
    /// Checks every setting; `Field::new` calls this.
    pub fn validate(&self) -> Result<(), GuidingError> {
        let err = |s: String| Err(GuidingError::InvalidConfig(s));
        if !(1..=MAX_LOBES).contains(&self.initial_lobes) {
            return err(format!("initial_lobes = {} (need 1 to {MAX_LOBES})", self.initial_lobes));
        }
        if !(self.initial_lobes..=MAX_LOBES).contains(&self.max_lobes) {
            return err(format!(
                "max_lobes = {} (need initial_lobes to {MAX_LOBES})",
                self.max_lobes
            ));
        }
        if self.max_samples_per_leaf < 2 {
            return err("max_samples_per_leaf must be at least 2".into());
        }
        if self.em_iterations == 0 {
            return err("em_iterations must be at least 1".into());
        }
        let finite_nonneg = [
            ("initial_kappa", self.initial_kappa),
            ("weight_prior", self.weight_prior),
            ("mean_cosine_prior_strength", self.mean_cosine_prior_strength),
            ("split_threshold", self.split_threshold),
            ("merge_threshold", self.merge_threshold),
            ("filter_radius", self.filter_radius),
        ];
        for (name, v) in finite_nonneg {
            if !(v.is_finite() && v >= 0.0) {
                return err(format!("{name} = {v} (need a finite value >= 0)"));
            }
        }
        if self.weight_prior <= 0.0 {
            return err("weight_prior must be positive (it keeps empty lobes defined)".into());
        }
        if !(0.0..1.0).contains(&self.mean_cosine_prior) {
            return err(format!(
                "mean_cosine_prior = {} (need 0 <= r0 < 1)",
                self.mean_cosine_prior
            ));
        }
        if !(self.max_kappa.is_finite() && self.max_kappa > 0.0 && self.max_kappa <= 1e6) {
            return err(format!("max_kappa = {} (need 0 < max_kappa <= 1e6)", self.max_kappa));
        }
        if !(self.step_exponent > 0.5 && self.step_exponent <= 1.0) {
            return err(format!("step_exponent = {} (need 0.5 < alpha <= 1)", self.step_exponent));
        }
        if !(1..=MAX_NEIGHBOURS).contains(&self.filter_neighbours) {
            return err(format!(
                "filter_neighbours = {} (need 1 to {MAX_NEIGHBOURS})",
                self.filter_neighbours
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        FieldConfig::default().validate().unwrap();
        let bad = FieldConfig { initial_lobes: 0, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("initial_lobes"));
        let bad = FieldConfig { weight_prior: f32::NAN, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("weight_prior"));
        let bad = FieldConfig { step_exponent: 0.3, ..Default::default() };
        assert!(bad.validate().is_err());
        let bad = FieldConfig { max_lobes: 4, ..Default::default() };
        assert!(bad.validate().is_err());
    }
}
