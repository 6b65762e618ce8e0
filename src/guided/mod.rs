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
mod equiangular;
mod flight;
mod grid;
pub mod halo;
mod plain_flight;
mod saved;
pub mod window;

pub use grid::DirectGrid;
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

    /// Whether a scattering vertex reads the cache: for its guided direction or its weight
    /// window. Guided distances read it along the flight instead, never at the vertex.
    pub fn at_vertices(&self) -> bool {
        self.directions || self.roulette
    }

    /// Weight-window roulette and splitting alone.
    pub const ROULETTE: Components =
        Components { directions: false, distances: false, roulette: true };

    /// The name [`parse`](Self::parse) reads back: `off`, `full`, or a `+`-joined list.
    pub fn name(&self) -> String {
        if *self == Self::FULL {
            return "full".into();
        }
        let parts: Vec<&str> =
            [(self.directions, "directions"), (self.distances, "distances"), (self.roulette, "rr")]
                .iter()
                .filter_map(|&(on, name)| on.then_some(name))
                .collect();
        if parts.is_empty() { "off".into() } else { parts.join("+") }
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
    /// Samples a direction from the prepared product (whose density is [`pdf`](Self::pdf):
    /// the walk needs the mixture with standard sampling's density anyway, so a sample does
    /// not pay for a second evaluation).
    fn sample(&self, u: Vec2) -> Vec3A;
    /// Density of the prepared product at `w`.
    fn pdf(&self, w: Vec3A) -> f32;
    /// During training: the next-event estimate of the fluence at a recorded vertex `x`
    /// (zero when it found nothing). The field learns only what the continuation brings
    /// back; these complete its fluence for the adjoint (see [`DirectFluence`]).
    fn record_direct(&mut self, _record: DirectRecord) {}
    /// `incident(w)` and `inscattered(w, g)` at `x` for distance sampling, or `None` where
    /// `load` would fail; may be cheaper than `load` (no product state, a coarser
    /// in-scattering estimate), and may leave the loaded point undefined.
    fn estimates(&mut self, x: Vec3A, u: f32, w: Vec3A, g: f32) -> Option<Estimates> {
        self.load(x, u)
            .then(|| Estimates { incident: self.incident(w), inscattered: self.inscattered(w, g) })
    }
    /// How far from `x` along `w` the cache's estimates stay those of `x`'s region (infinite
    /// for a cache without regions): guided distance sampling looks the cache up once per
    /// region the ray crosses.
    fn region_exit(&self, _x: Vec3A, _w: Vec3A) -> f32 {
        f32::INFINITY
    }
    /// The radiance delta lights scatter towards `-w` at `x` (HG with `g`), for placing extra
    /// collisions (`distance::ExtraCollision`); called for many points along a ray, so it
    /// should be cheap. A cache that cannot tell direct from indirect light gives all the
    /// in-scattered radiance.
    fn direct(&mut self, x: Vec3A, w: Vec3A, g: f32) -> f32 {
        self.estimates(x, 0.5, w, g).map_or(0.0, |e| e.inscattered)
    }
    /// [`direct`](Self::direct) at the middles of equal parts along a ray, `start + (j + 0.5)
    /// step` for each `out[j]`, for a path travelling along `w`.
    fn direct_along(&mut self, start: Vec3A, step: Vec3A, w: Vec3A, g: f32, out: &mut [f32]) {
        for (j, v) in out.iter_mut().enumerate() {
            *v = self.direct(start + (j as f32 + 0.5) * step, w, g);
        }
    }
}

/// What distance sampling asks of a cache at a point, for a path travelling along `w`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimates {
    /// Radiance arriving from `w`: `L(x, w)`.
    pub incident: f32,
    /// Radiance scattered towards `-w`: `L_s(x, w)`.
    pub inscattered: f32,
}

/// Smallest HG asymmetry `|g|` for which guided directions follow a product with the phase
/// function; below it HG is within 15% of isotropic and the incident radiance alone is used.
pub const PRODUCT_MIN_G: f32 = 0.05;
/// Smallest `|g|` for which the product is the exact one (every mixture lobe times each of
/// the four lobes of HG's fit); below it HG is stood in for by one vMF lobe of its mean
/// cosine (`VolumeDistribution::apply_hg_lobe_product`), one product lobe per mixture lobe.
/// At moderate `g` that lobe is close to HG, and the product keeps HG's forward peak inside
/// broad radiance lobes; strongly forward scattering needs HG's sharp peak and heavy tail
/// (see docs/experiments.md).
pub const EXACT_PRODUCT_MIN_G: f32 = 0.7;

/// A trained guiding field as a radiance cache, with its per-thread query state.
#[derive(Clone, Debug)]
pub struct FieldCache<'a> {
    field: &'a Field,
    dist: VolumeDistribution,
    /// Per region, the fluence next-event estimation brings (absent for a loaded field).
    direct: Option<&'a DirectFluence>,
    /// The loaded region's direct fluence and its mean direction (see [`DirectFluence`]).
    direct_here: (f32, Vec3A),
    /// Direct-fluence records of training paths, when training.
    records: Option<Vec<DirectRecord>>,
    /// The last `estimates`: region, direction, g and the estimates.
    memo: Option<(usize, Vec3A, f32, Estimates)>,
}

impl<'a> FieldCache<'a> {
    /// A cache over `field` alone: its adjoint misses the direct light that next-event
    /// estimation collects (a field loaded from a file has no [`DirectFluence`]).
    pub fn new(field: &'a Field) -> Self {
        Self {
            field,
            dist: VolumeDistribution::default(),
            direct: None,
            direct_here: (0.0, Vec3A::ZERO),
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
    pub fn take_records(&mut self) -> Vec<DirectRecord> {
        self.records.as_mut().map(std::mem::take).unwrap_or_default()
    }

    #[inline]
    fn total_fluence(&self) -> f32 {
        self.dist.fluence() + self.direct_here.0
    }
}

/// A next-event estimate at a training vertex: where, the fluence it estimates, and the
/// direction towards the light it sampled.
#[derive(Clone, Copy, Debug)]
pub struct DirectRecord {
    /// The vertex.
    pub position: Vec3A,
    /// The estimate of the fluence next-event estimation collects there (zero when the light
    /// sample found nothing).
    pub fluence: f32,
    /// Unit direction from the vertex towards the sampled light.
    pub direction: Vec3A,
}

/// Radiance HG scatters towards `-w` out of a fluence `fluence` whose mean direction is `axis`
/// (its length the fluence-weighted mean resultant length, at most 1): HG with `g`
/// times that length about the axis, which is exact for light from one direction (the sun, a
/// small light) and isotropic for light from everywhere, the moment-matched answer between
/// (as `VolumeDistribution::apply_hg_weights` in the guiding crate treats a lobe).
#[inline]
fn inscattered_about(fluence: f32, axis: Vec3A, w: Vec3A, g: f32) -> f32 {
    if fluence <= 0.0 {
        return 0.0;
    }
    let r = axis.length();
    if r <= 1e-6 || g == 0.0 {
        return fluence * crate::math::INV_FOUR_PI;
    }
    fluence * crate::phase::hg(g * r.min(1.0), axis.dot(w) / r)
}

/// Per region of a field, the mean next-event estimate of the fluence at its training
/// vertices. The field learns the radiance the continuation (phase or BSDF sampling) brings
/// back, MIS-weighted, because that is the integrand guided directions should follow: next
/// event estimation already samples delta and small lights, and a field trained on them spends
/// its lobes on directions where a continuation finds nothing new (a point light cannot be hit
/// at all). The adjoint of roulette and distance sampling needs all the light, so it adds this
/// table's value to the field's fluence.
///
/// Distance sampling needs the radiance scattered towards the path, and under a strongly
/// forward phase function that depends on where the direct light comes from (a back-lit
/// cloud's rim is bright only towards the sun): each region also keeps the fluence-weighted
/// mean of the directions to the lights, whose length says how concentrated they are.
#[derive(Clone, Debug, Default)]
pub struct DirectFluence {
    values: Vec<f32>,
    axes: Vec<Vec3A>,
    /// The same records on a fine uniform grid, for placing extra collisions: regions are
    /// far coarser than a shaft of sunlight.
    grid: DirectGrid,
}

impl DirectFluence {
    /// The mean of `records` per region of `field`, and their fluence-weighted mean direction.
    pub fn build(field: &Field, records: &[DirectRecord]) -> Self {
        use rayon::prelude::*;
        // The grid beside the regions, and the regions' lookups in parallel; the sums stay in
        // record order, so the result does not depend on the thread count.
        let (regions, grid) = rayon::join(
            || {
                records
                    .par_iter()
                    .map(|r| {
                        field.lookup_index(r.position.into(), 0.5).map_or(u32::MAX, |i| i as u32)
                    })
                    .collect::<Vec<u32>>()
            },
            || DirectGrid::build(records),
        );
        let n = field.regions().len();
        let (mut sums, mut counts) = (vec![0.0f64; n], vec![0u64; n]);
        let mut moments = vec![glam::DVec3::ZERO; n];
        for (r, &i) in records.iter().zip(&regions).filter(|(_, i)| **i != u32::MAX) {
            let i = i as usize;
            sums[i] += f64::from(r.fluence);
            moments[i] += r.direction.as_dvec3() * f64::from(r.fluence);
            counts[i] += 1;
        }
        let values = sums
            .iter()
            .zip(&counts)
            .map(|(&s, &c)| if c > 0 { (s / c as f64) as f32 } else { 0.0 })
            .collect();
        let axes = sums
            .iter()
            .zip(&moments)
            .map(|(&s, &m)| {
                let a = if s > 0.0 { (m / s).as_vec3a() } else { Vec3A::ZERO };
                // Rounding may leave a unit mean a hair long.
                if a.length_squared() > 1.0 { a.normalize() } else { a }
            })
            .collect();
        Self { values, axes, grid }
    }

    /// The direct fluence of region `index` (zero when unknown).
    pub fn get(&self, index: usize) -> f32 {
        self.values.get(index).copied().unwrap_or(0.0)
    }

    /// The fluence-weighted mean direction towards the lights in region `index`: its length
    /// is 1 for light from one direction and near 0 for light from all around (zero when
    /// unknown).
    pub fn axis(&self, index: usize) -> Vec3A {
        self.axes.get(index).copied().unwrap_or(Vec3A::ZERO)
    }
}

impl RadianceCache for FieldCache<'_> {
    #[inline]
    fn load(&mut self, x: Vec3A, u: f32) -> bool {
        let ok = self.dist.init(self.field, x.into(), u);
        self.direct_here = match (self.direct, self.dist.region_index()) {
            (Some(d), Some(i)) if ok => (d.get(i as usize), d.axis(i as usize)),
            _ => (0.0, Vec3A::ZERO),
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
        let (direct, axis) = self.direct_here;
        self.dist.inscattered_radiance(w.into(), g) + inscattered_about(direct, axis, w, g)
    }
    #[inline]
    fn product_hg(&mut self, ray_dir: Vec3A, g: f32) -> bool {
        let g_abs = g.abs();
        if g_abs < PRODUCT_MIN_G {
            self.dist.clear_product();
        } else if g_abs < EXACT_PRODUCT_MIN_G {
            self.dist.apply_hg_lobe_product(ray_dir.into(), g);
        } else {
            self.dist.apply_hg_product(ray_dir.into(), g);
        }
        true
    }
    #[inline]
    fn product_cosine(&mut self, _normal: Vec3A) -> bool {
        // The incident radiance alone. Both cosine products lower the error a little and
        // cost more than they save: equal efficiency within noise, so the cheaper way (see
        // docs/experiments.md).
        self.dist.clear_product();
        true
    }
    #[inline]
    fn sample(&self, u: Vec2) -> Vec3A {
        self.dist.sample(u).into()
    }
    #[inline]
    fn pdf(&self, w: Vec3A) -> f32 {
        self.dist.pdf(w.into())
    }
    #[inline]
    fn estimates(&mut self, x: Vec3A, u: f32, w: Vec3A, g: f32) -> Option<Estimates> {
        // Straight from the region, without loading its mixture. The last answer is kept too:
        // the spatial filter may map a refresh, or the next flight's start, to the same region.
        let i = self.field.lookup_index(x.into(), u)?;
        if let Some((j, v, gm, e)) = self.memo
            && j == i
            && v == w
            && gm == g
        {
            return Some(e);
        }
        let region = &self.field.regions()[i];
        let (fluence, axis) = self.direct.map_or((0.0, Vec3A::ZERO), |d| (d.get(i), d.axis(i)));
        // Both parts scatter about their mean directions, the field's own (indirect) part from
        // its mixture's first moment: cheaper than the mixture's exact HG convolution per
        // segment (a lobe-by-lobe sum), and exact in its mean.
        let e = Estimates {
            incident: region.fluence() * region.density_at(x.into(), w.into()),
            inscattered: inscattered_about(region.fluence(), region.mean_direction().into(), w, g)
                + inscattered_about(fluence, axis, w, g),
        };
        self.memo = Some((i, w, g, e));
        Some(e)
    }
    #[inline]
    fn region_exit(&self, x: Vec3A, w: Vec3A) -> f32 {
        self.field.region_exit(x.into(), w.into())
    }
    // Isotropic: exact in its shape along a ray for the sun (one direction everywhere), and a
    // sampling density needs no more.
    #[inline]
    fn direct(&mut self, x: Vec3A, _w: Vec3A, _g: f32) -> f32 {
        self.direct.map_or(0.0, |d| d.grid.fluence(x) * crate::math::INV_FOUR_PI)
    }
    #[inline]
    fn direct_along(&mut self, start: Vec3A, step: Vec3A, _w: Vec3A, _g: f32, out: &mut [f32]) {
        match self.direct {
            Some(d) => {
                d.grid.fluence_along(start, step, out);
                out.iter_mut().for_each(|v| *v *= crate::math::INV_FOUR_PI);
            }
            None => out.fill(0.0),
        }
    }
    #[inline]
    fn record_direct(&mut self, record: DirectRecord) {
        if let Some(r) = &mut self.records {
            r.push(record);
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
    fn sample(&self, _: Vec2) -> Vec3A {
        Vec3A::Z
    }
    fn pdf(&self, _: Vec3A) -> f32 {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Directions spread evenly over the sphere (a Fibonacci lattice), each standing for
    /// `4 pi / n` of solid angle.
    fn sphere(n: usize) -> impl Iterator<Item = Vec3A> {
        let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
        (0..n).map(move |i| {
            let z = 1.0 - (2 * i + 1) as f32 / n as f32;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f32;
            Vec3A::new(r * phi.cos(), r * phi.sin(), z)
        })
    }

    #[test]
    fn component_names_parse_back() {
        for bits in 0..8u8 {
            let c = Components {
                directions: bits & 1 != 0,
                distances: bits & 2 != 0,
                roulette: bits & 4 != 0,
            };
            assert_eq!(Components::parse(&c.name()), Some(c), "{}", c.name());
        }
        assert_eq!(Components::FULL.name(), "full");
        assert_eq!(Components::OFF.name(), "off");
        assert_eq!(Components::ROULETTE.name(), "rr");
    }

    #[test]
    fn direct_inscattering_keeps_the_fluence_and_the_lights_direction() {
        let n = 200_000;
        let axis = Vec3A::new(0.36, -0.48, 0.8);
        for g in [-0.9f32, -0.3, 0.0, 0.6, 0.85] {
            for r in [0.0f32, 0.3, 0.9, 1.0] {
                // HG scatters all of the fluence, whatever the direction spread.
                let total: f64 = sphere(n)
                    .map(|w| f64::from(inscattered_about(2.0, axis * r, w, g)))
                    .sum::<f64>()
                    * 4.0
                    * std::f64::consts::PI
                    / n as f64;
                assert!((total - 2.0).abs() < 2e-3 * 2.0, "g {g}, r {r}: {total}");
            }
            // Light from one direction scatters exactly as HG does, peaked towards the light.
            for w in [axis, -axis, Vec3A::X, Vec3A::new(0.6, 0.0, 0.8)] {
                let expected = 2.0 * crate::phase::hg(g, axis.dot(w));
                let got = inscattered_about(2.0, axis, w, g);
                assert!((got - expected).abs() <= 1e-5 * expected, "g {g}: {got} vs {expected}");
            }
        }
        // Light from all around (mean direction zero) is isotropic; no light scatters none.
        let iso = inscattered_about(2.0, Vec3A::ZERO, Vec3A::Z, 0.9);
        assert!((iso - 2.0 * crate::math::INV_FOUR_PI).abs() < 1e-7);
        assert_eq!(inscattered_about(0.0, axis, axis, 0.9), 0.0);
    }

    #[test]
    fn the_direct_table_keeps_each_regions_mean_direction() {
        let mut field =
            zerovar_guiding::Field::new(zerovar_guiding::FieldConfig::default()).unwrap();
        let sample = zerovar_guiding::Sample {
            position: glam::Vec3::ZERO,
            direction: glam::Vec3::Z,
            radiance: 1.0,
            pdf: 1.0,
            distance: f32::INFINITY,
            volume: true,
        };
        field.update(&[sample; 10]).unwrap();
        assert_eq!(field.regions().len(), 1);
        // One region: two lights, the second three times as bright, at right angles.
        let (a, b) = (Vec3A::X, Vec3A::Y);
        let records: Vec<DirectRecord> = [(a, 1.0), (b, 3.0), (b, 0.0)]
            .iter()
            .map(|&(direction, fluence)| DirectRecord { position: Vec3A::ZERO, fluence, direction })
            .collect();
        let table = DirectFluence::build(&field, &records);
        assert!((table.get(0) - 4.0 / 3.0).abs() < 1e-6);
        let expected = (a * 1.0 + b * 3.0) / 4.0;
        assert!((table.axis(0) - expected).length() < 1e-6, "{}", table.axis(0));
        // Regions the records never reached, or a table that does not know the region.
        assert_eq!(DirectFluence::default().axis(3), Vec3A::ZERO);
    }

    #[test]
    fn distance_estimates_scatter_the_fields_light_about_its_direction() {
        // Light from one direction, a little spread: the estimate distance sampling reads must
        // conserve the fluence and follow the exact convolution of the mixture with HG.
        let mut field =
            zerovar_guiding::Field::new(zerovar_guiding::FieldConfig::default()).unwrap();
        let light = glam::Vec3::new(0.6, 0.0, 0.8);
        let samples: Vec<_> = (0..400)
            .map(|i| {
                let a = i as f32 * 2.399;
                let d = (light + 0.15 * glam::Vec3::new(a.cos(), a.sin(), 0.0)).normalize();
                zerovar_guiding::Sample {
                    position: glam::Vec3::ZERO,
                    direction: d,
                    radiance: 1.0,
                    pdf: 1.0,
                    distance: f32::INFINITY,
                    volume: true,
                }
            })
            .collect();
        for _ in 0..4 {
            field.update(&samples).unwrap();
        }
        let mut cache = FieldCache::new(&field);
        let fluence = field.regions()[0].fluence();
        let n = 20_000;
        for g in [-0.7f32, 0.0, 0.3, 0.7, 0.9] {
            // The estimate's total, and its L1 distance from the exact convolution and the
            // isotropic stand-in's, both relative to the fluence.
            let (mut total, mut ours, mut isotropic) = (0.0f64, 0.0f64, 0.0f64);
            for w in sphere(n) {
                let e = cache.estimates(Vec3A::ZERO, 0.5, w, g).expect("trained");
                assert!(cache.load(Vec3A::ZERO, 0.5));
                let exact = f64::from(cache.inscattered(w, g));
                total += f64::from(e.inscattered);
                ours += (f64::from(e.inscattered) - exact).abs();
                isotropic += (f64::from(fluence * crate::math::INV_FOUR_PI) - exact).abs();
            }
            let to_fluence = 4.0 * std::f64::consts::PI / n as f64 / f64::from(fluence);
            let (total, ours, isotropic) =
                (total * to_fluence, ours * to_fluence, isotropic * to_fluence);
            assert!(
                (total - 1.0).abs() < 3e-3,
                "g {g}: the estimate scatters {total} of the light"
            );
            // HG about the mean direction is exact in the mean only: it loosens as g sharpens.
            let bound = if g.abs() <= 0.7 { 0.1 } else { 0.3 };
            assert!(
                ours <= bound && ours <= isotropic / 5.0,
                "g {g}: L1 distance {ours:.4} from the exact convolution, isotropic {isotropic:.4}"
            );
        }
    }
}
