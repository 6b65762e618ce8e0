//! Zero-variance guiding of the volumetric random walk (Herholz et al. 2019): what the guided
//! integrator asks of a radiance cache, and the decisions it guides.
//!
//! The cache (a trained `zerovar_guiding::Field`, or an analytic one in tests) estimates the
//! radiance arriving at a point from a direction, `L(x, w)`, and the in-scattered radiance
//! `L_s(x, w)`. From them the walk guides its distances (`distance`), its directions (the
//! product of the incident-radiance mixture with the phase function or cosine), and its
//! Russian roulette and splitting (`window`). Every guided density is mixed with the standard
//! one, `p = alpha p_guided + (1 - alpha) p_standard`, so every estimator stays unbiased and
//! robust where the cache is poor.

pub mod distance;
pub mod window;

use glam::{Vec2, Vec3A};
use serde::Serialize;
use zerovar_guiding::{Field, VolumeDistribution};

/// Which decisions of the walk are guided.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Components {
    /// Directions: product sampling of incident radiance with the phase function or cosine.
    pub directions: bool,
    /// Distances: the zero-variance collision density along each ray in a medium.
    pub distances: bool,
    /// Russian roulette and splitting by weight windows around the pixel estimate.
    pub roulette: bool,
}

impl Components {
    /// Nothing guided.
    pub const OFF: Components = Components { directions: false, distances: false, roulette: false };
    /// Everything guided.
    pub const FULL: Components = Components { directions: true, distances: true, roulette: true };

    /// Whether anything is guided (and a field must be trained).
    pub fn any(&self) -> bool {
        self.directions || self.distances || self.roulette
    }

    /// Parses `off`, `directions`, `distances`, `rr`, `full`, or a `+`-joined list.
    pub fn parse(text: &str) -> Option<Self> {
        let mut c = Components::OFF;
        for part in text.split('+') {
            match part.trim() {
                "off" | "none" => {}
                "directions" => c.directions = true,
                "distances" => c.distances = true,
                "rr" | "roulette" => c.roulette = true,
                "full" | "all" => c = Components::FULL,
                _ => return None,
            }
        }
        Some(c)
    }
}

/// Estimates of radiance the guided walk steers by.
pub trait RadianceCache {
    /// Loads the estimates at `x` (`u` drives stochastic spatial filtering); false when the
    /// cache knows nothing there, and the walk samples as if unguided.
    fn load(&mut self, x: Vec3A, u: f32) -> bool;
    /// Radiance arriving at the loaded point from direction `w` (pointing away from it).
    fn incident(&self, w: Vec3A) -> f32;
    /// The incident radiance averaged over all directions at the loaded point (fluence over
    /// 4 pi): a smooth adjoint for roulette, robust where the directional fit is poor.
    fn mean_radiance(&self) -> f32;
    /// Radiance the phase function (HG with `g`) scatters towards `-w` at the loaded point,
    /// for a path travelling along `w`.
    fn inscattered(&self, w: Vec3A, g: f32) -> f32;
    /// Prepares the product of incident radiance with HG for a path along `ray_dir`; false
    /// when the cache has no directional distribution (then directions are not guided).
    fn product_hg(&mut self, ray_dir: Vec3A, g: f32) -> bool;
    /// Prepares the product of incident radiance with the clamped cosine about `normal`.
    fn product_cosine(&mut self, normal: Vec3A) -> bool;
    /// Samples the prepared product; returns the direction and its density.
    fn sample(&self, u: Vec2) -> (Vec3A, f32);
    /// Density of the prepared product at `w`.
    fn pdf(&self, w: Vec3A) -> f32;
}

/// A trained guiding field as a radiance cache, with its per-thread query state.
#[derive(Clone, Debug)]
pub struct FieldCache<'a> {
    field: &'a Field,
    dist: VolumeDistribution,
}

impl<'a> FieldCache<'a> {
    /// A cache over `field`.
    pub fn new(field: &'a Field) -> Self {
        Self { field, dist: VolumeDistribution::default() }
    }
}

impl RadianceCache for FieldCache<'_> {
    #[inline]
    fn load(&mut self, x: Vec3A, u: f32) -> bool {
        self.dist.init(self.field, x.into(), u)
    }
    #[inline]
    fn incident(&self, w: Vec3A) -> f32 {
        self.dist.incident_radiance(w.into())
    }
    #[inline]
    fn mean_radiance(&self) -> f32 {
        self.dist.fluence() * crate::math::INV_FOUR_PI
    }
    #[inline]
    fn inscattered(&self, w: Vec3A, g: f32) -> f32 {
        self.dist.inscattered_radiance(w.into(), g)
    }
    #[inline]
    fn product_hg(&mut self, ray_dir: Vec3A, g: f32) -> bool {
        self.dist.apply_hg_product(ray_dir.into(), g);
        true
    }
    #[inline]
    fn product_cosine(&mut self, normal: Vec3A) -> bool {
        self.dist.apply_cosine_product(normal.into());
        true
    }
    #[inline]
    fn sample(&self, u: Vec2) -> (Vec3A, f32) {
        let (d, pdf) = self.dist.sample_with_pdf(u);
        (d.into(), pdf)
    }
    #[inline]
    fn pdf(&self, w: Vec3A) -> f32 {
        self.dist.pdf(w.into())
    }
}

/// A cache that knows nothing: the walk falls back to standard sampling everywhere.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCache;

impl RadianceCache for NoCache {
    fn load(&mut self, _: Vec3A, _: f32) -> bool {
        false
    }
    fn incident(&self, _: Vec3A) -> f32 {
        0.0
    }
    fn mean_radiance(&self) -> f32 {
        0.0
    }
    fn inscattered(&self, _: Vec3A, _: f32) -> f32 {
        0.0
    }
    fn product_hg(&mut self, _: Vec3A, _: f32) -> bool {
        false
    }
    fn product_cosine(&mut self, _: Vec3A) -> bool {
        false
    }
    fn sample(&self, _: Vec2) -> (Vec3A, f32) {
        (Vec3A::Z, 0.0)
    }
    fn pdf(&self, _: Vec3A) -> f32 {
        0.0
    }
}
