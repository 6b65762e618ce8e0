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
mod saved;
pub mod window;

pub use saved::{TRAINED_MAGIC, TRAINED_VERSION, TrainedField};

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
    /// During training: the next-event estimate of the fluence at a recorded vertex `x`
    /// (zero when it found nothing). The field learns only what the continuation brings
    /// back; these complete its fluence for the adjoint (see [`DirectFluence`]).
    fn record_direct(&mut self, _x: Vec3A, _fluence: f32) {}
    /// `(incident(w), mean_radiance())` at `x`, or `None` where `load` would fail; may be
    /// cheaper than `load` (no product state), and may leave the loaded point undefined.
    fn estimates(&mut self, x: Vec3A, u: f32, w: Vec3A) -> Option<(f32, f32)> {
        self.load(x, u).then(|| (self.incident(w), self.mean_radiance()))
    }
}

/// Smallest HG asymmetry `|g|` for which guided directions follow a product with the phase
/// function; below it HG is within 15% of isotropic and the incident radiance alone is used.
pub const PRODUCT_MIN_G: f32 = 0.05;
/// Smallest `|g|` for which the product is the exact one (every mixture lobe times each of
/// the four lobes of HG's fit); below it the mixture's lobes are only reweighted by their
/// convolution with HG (`VolumeDistribution::apply_hg_weights`), at about a third of the cost
/// (`cargo bench -p zerovar-guiding`: per vertex, load and product, a sample and a density,
/// 0.43 us against 1.2 us).
/// Measured at equal samples (`zerovar compare`, 32 spp, full guiding, training included):
/// light shaft (g 0.6) relMSE 0.073 reweighted vs 0.069 exact in 8.8 vs 12.1 s; occluded
/// light (g 0.3) 0.103 reweighted vs 0.151 with no product; back-lit cloud (g 0.85, 16 spp)
/// 1.02 reweighted vs 0.20 exact: strongly forward scattering needs the reshaped lobes.
pub const EXACT_PRODUCT_MIN_G: f32 = 0.7;

/// A trained guiding field as a radiance cache, with its per-thread query state.
#[derive(Clone, Debug)]
pub struct FieldCache<'a> {
    field: &'a Field,
    dist: VolumeDistribution,
    /// Per region, the fluence next-event estimation brings (absent for a loaded field).
    direct: Option<&'a DirectFluence>,
    /// The loaded region's direct fluence.
    direct_here: f32,
    /// Direct-fluence records of training paths, when training.
    records: Option<Vec<(Vec3A, f32)>>,
    /// The last `estimates`: region, direction, incident and mean radiance.
    memo: Option<(usize, Vec3A, f32, f32)>,
}

impl<'a> FieldCache<'a> {
    /// A cache over `field` alone: its adjoint misses the direct light that next-event
    /// estimation collects (a field loaded from a file has no [`DirectFluence`]).
    pub fn new(field: &'a Field) -> Self {
        Self {
            field,
            dist: VolumeDistribution::default(),
            direct: None,
            direct_here: 0.0,
            records: None,
            memo: None,
        }
    }

    /// A cache over `field` completed by the direct fluence of its regions; `record` keeps
    /// the direct-fluence records of training paths for [`take_records`](Self::take_records).
    pub fn with_direct(field: &'a Field, direct: Option<&'a DirectFluence>, record: bool) -> Self {
        Self { direct, records: record.then(Vec::new), ..Self::new(field) }
    }

    /// The direct-fluence records gathered so far.
    pub fn take_records(&mut self) -> Vec<(Vec3A, f32)> {
        self.records.as_mut().map(std::mem::take).unwrap_or_default()
    }

    #[inline]
    fn total_fluence(&self) -> f32 {
        self.dist.fluence() + self.direct_here
    }
}

/// Per region of a field, the mean next-event estimate of the fluence at its training
/// vertices. The field learns the radiance the continuation (phase or BSDF sampling) brings
/// back, MIS-weighted, because that is the integrand guided directions should follow: next
/// event estimation already samples delta and small lights, and a field trained on them spends
/// its lobes on directions where a continuation finds nothing new (a point light cannot be hit
/// at all). The adjoint of roulette and distance sampling needs all the light, so it adds this
/// table's value to the field's fluence.
#[derive(Clone, Debug, Default)]
pub struct DirectFluence {
    values: Vec<f32>,
}

impl DirectFluence {
    /// The mean of `records` (vertex, next-event fluence estimate) per region of `field`.
    pub fn build(field: &Field, records: &[(Vec3A, f32)]) -> Self {
        let n = field.regions().len();
        let (mut sums, mut counts) = (vec![0.0f64; n], vec![0u64; n]);
        for &(x, v) in records {
            if let Some(i) = field.lookup_index(x.into(), 0.5) {
                sums[i] += f64::from(v);
                counts[i] += 1;
            }
        }
        let values = sums
            .iter()
            .zip(&counts)
            .map(|(&s, &c)| if c > 0 { (s / c as f64) as f32 } else { 0.0 })
            .collect();
        Self { values }
    }

    /// The direct fluence of region `index` (zero when unknown).
    pub fn get(&self, index: usize) -> f32 {
        self.values.get(index).copied().unwrap_or(0.0)
    }
}

impl RadianceCache for FieldCache<'_> {
    #[inline]
    fn load(&mut self, x: Vec3A, u: f32) -> bool {
        let ok = self.dist.init(self.field, x.into(), u);
        self.direct_here = match (self.direct, self.dist.region_index()) {
            (Some(d), Some(i)) if ok => d.get(i as usize),
            _ => 0.0,
        };
        ok
    }
    #[inline]
    fn incident(&self, w: Vec3A) -> f32 {
        self.dist.incident_radiance(w.into())
    }
    #[inline]
    fn mean_radiance(&self) -> f32 {
        self.total_fluence() * crate::math::INV_FOUR_PI
    }
    #[inline]
    fn inscattered(&self, w: Vec3A, g: f32) -> f32 {
        // The direct part is taken as isotropic: the table keeps no directions.
        self.dist.inscattered_radiance(w.into(), g) + self.direct_here * crate::math::INV_FOUR_PI
    }
    #[inline]
    fn product_hg(&mut self, ray_dir: Vec3A, g: f32) -> bool {
        let g_abs = g.abs();
        if g_abs < PRODUCT_MIN_G {
            self.dist.clear_product();
        } else if g_abs < EXACT_PRODUCT_MIN_G {
            self.dist.apply_hg_weights(ray_dir.into(), g);
        } else {
            self.dist.apply_hg_product(ray_dir.into(), g);
        }
        true
    }
    #[inline]
    fn product_cosine(&mut self, _normal: Vec3A) -> bool {
        // The incident radiance alone. Both cosine products lower the error a little and
        // cost more than they save (light shaft, full guiding, 32 spp: relMSE 0.073 without,
        // 0.069 with the exact product, 0.070 with lobes reweighted by their clamped cosine,
        // which made a 16 spp single-thread render 9% slower; occluded light 0.103, 0.104,
        // 0.098): equal efficiency within noise, so the cheaper way.
        self.dist.clear_product();
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
    #[inline]
    fn estimates(&mut self, x: Vec3A, u: f32, w: Vec3A) -> Option<(f32, f32)> {
        // Straight from the region, without loading its mixture: a ray's segments mostly
        // fall in one region, so the last answer is kept too.
        let i = self.field.lookup_index(x.into(), u)?;
        if let Some((j, v, li, lm)) = self.memo
            && j == i
            && v == w
        {
            return Some((li, lm));
        }
        let region = &self.field.regions()[i];
        let direct = self.direct.map_or(0.0, |d| d.get(i));
        let li = region.fluence() * region.mixture().pdf(w.into());
        let lm = (region.fluence() + direct) * crate::math::INV_FOUR_PI;
        self.memo = Some((i, w, li, lm));
        Some((li, lm))
    }
    #[inline]
    fn record_direct(&mut self, x: Vec3A, fluence: f32) {
        if let Some(r) = &mut self.records {
            r.push((x, fluence));
        }
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
