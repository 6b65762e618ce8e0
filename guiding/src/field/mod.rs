//! The guiding field: a kd-tree of regions, each with a fitted incident-radiance mixture and a
//! fluence estimate, trained between render passes and queried during them.
//!
//! Ownership separates the two phases: `update` takes `&mut self` (between passes), every
//! query takes `&self` (while rendering, from any number of threads). An update routes the
//! samples to leaves, splits leaves that have seen enough samples, then refits every region
//! that received samples, in parallel. Each region's fit reads only its own samples in input
//! order, so the result does not depend on the number of threads. With parallax on
//! (`FieldConfig::parallax`), each region fits its mixture to the directions from its centre
//! towards where its samples' light came from, and lookups re-aim the lobes at those sources
//! from the query point.

pub(crate) mod io;
mod splitmerge;
pub(crate) mod stats;

use crate::GuidingError;
use crate::config::{FieldConfig, MAX_NEIGHBOURS, SampleKind};
use crate::data::sample::{Sample, validate_all};
use crate::directional::em::{self, EmSettings, EmStats, WeightedDir};
use crate::directional::mixture::{MAX_LOBES, Mixture};
use crate::directional::product::RegionLanes;
use crate::spatial::{KdTree, SpatialStats};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use stats::FieldStats;
use std::time::Instant;

/// A leaf of the spatial tree: the incident radiance `L(x, w) = Phi(x) V_L(w)` there.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    pub(crate) mixture: Mixture,
    fluence: f32,
    pub(crate) em: EmStats,
    pub(crate) split_merge: splitmerge::LobeStats,
    spatial: SpatialStats,
    centre: Vec3,
    spread: f32,
    depth: u32,
    neighbours: [u32; MAX_NEIGHBOURS],
    neighbour_count: u8,
    /// The mixture as `VolumeDistribution::init` loads it; derived, refreshed whenever the
    /// mixture changes, never saved.
    #[serde(skip)]
    pub(crate) lanes: RegionLanes,
}

impl Region {
    fn new(config: &FieldConfig) -> Self {
        let mixture = em::initial_mixture(config.initial_lobes, config.initial_kappa);
        Self {
            lanes: RegionLanes::new(&mixture, &[0.0; MAX_LOBES]),
            mixture,
            fluence: 0.0,
            em: EmStats::default(),
            split_merge: splitmerge::LobeStats::default(),
            spatial: SpatialStats::default(),
            centre: Vec3::ZERO,
            spread: 0.0,
            depth: 0,
            neighbours: [0; MAX_NEIGHBOURS],
            neighbour_count: 0,
        }
    }

    /// The fitted directional distribution `V_L` of incident radiance (normalised).
    pub fn mixture(&self) -> &Mixture {
        &self.mixture
    }

    /// The mixture's density `V_L(dir)` as fitted, seen from the region's centre: as
    /// `mixture().pdf(dir)` but from the region's lane blocks (faster; equal to within
    /// rounding).
    #[inline]
    pub fn density(&self, dir: Vec3) -> f32 {
        self.lanes.lobes.pdf(dir)
    }

    /// The mixture's density `V_L(dir)` as seen from `pos`: with parallax-aware lobes
    /// re-aimed from the region's centre to `pos` (as `VolumeDistribution::init` does).
    #[inline]
    pub fn density_at(&self, pos: Vec3, dir: Vec3) -> f32 {
        if !self.lanes.parallax {
            return self.lanes.lobes.pdf(dir);
        }
        self.lanes.lobes.pdf_shifted(dir, &self.lanes.inv_distance, self.centre - pos)
    }

    /// The mixture's first moment `sum_i w_i A(kappa_i) mu_i` as fitted (without parallax): the
    /// mean direction towards the light, of length 0 (light from everywhere alike) to 1 (from
    /// one direction). Cheap: kept with the region, not computed per call.
    #[inline]
    pub fn mean_direction(&self) -> Vec3 {
        self.lanes.mean_direction
    }

    /// The fluence estimate `Phi(x)`: the mean of `radiance / pdf` over the region's samples,
    /// an unbiased estimate of the integral of incident radiance over the sphere.
    pub fn fluence(&self) -> f32 {
        self.fluence
    }

    /// Samples the region has learned from (after the step-size scaling of older batches).
    pub fn sample_count(&self) -> f64 {
        self.em.count
    }

    /// Mean position of the samples the region has seen since it was created.
    pub fn centre(&self) -> Vec3 {
        self.centre
    }

    /// Depth of the region's leaf in the tree.
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Checks what lookups compute with (a loaded field's regions come from a file).
    pub(crate) fn validate(&self) -> Result<(), String> {
        let lobes_ok = self.mixture.lobes().iter().all(|l| {
            l.mean.is_finite()
                && (l.mean.length() - 1.0).abs() < 1e-3
                && l.kappa.is_finite()
                && l.kappa >= 0.0
                && l.weight.is_finite()
                && l.weight >= 0.0
        });
        if !lobes_ok {
            return Err("a lobe with a non-unit mean or a bad concentration or weight".into());
        }
        self.em.validate()?;
        if !(self.fluence.is_finite() && self.fluence >= 0.0 && self.centre.is_finite()) {
            return Err(format!("fluence {} at centre {}", self.fluence, self.centre));
        }
        Ok(())
    }

    /// True once the region has seen a sample carrying light; untrained regions are not
    /// returned by lookups.
    pub fn is_trained(&self) -> bool {
        self.em.total_weight > 0.0
    }
}

/// The guiding field (see the module documentation).
#[derive(Clone, Debug)]
pub struct Field {
    pub(crate) config: FieldConfig,
    pub(crate) tree: KdTree,
    pub(crate) regions: Vec<Region>,
    pub(crate) iterations: u32,
    pub(crate) total_samples: u64,
    pub(crate) last_update_seconds: f64,
    trained_regions: usize,
    /// Each region's centre, packed: the spatial filter reads its neighbours' centres at every
    /// lookup, and in the regions themselves (kilobytes apart) each costs a cache miss.
    centres: Vec<Vec3>,
}

impl Field {
    /// An empty field; fails if the configuration is invalid.
    pub fn new(config: FieldConfig) -> Result<Self, GuidingError> {
        config.validate()?;
        let root = Region::new(&config);
        Ok(Self::from_parts(config, KdTree::new(), vec![root], 0, 0, 0.0))
    }

    pub(crate) fn from_parts(
        config: FieldConfig,
        mut tree: KdTree,
        mut regions: Vec<Region>,
        iterations: u32,
        total_samples: u64,
        last_update_seconds: f64,
    ) -> Self {
        for r in &mut regions {
            r.lanes = RegionLanes::new(&r.mixture, &r.em.lobe_inverse_distances());
        }
        tree.index_cells();
        let trained_regions = regions.iter().filter(|r| r.is_trained()).count();
        let centres = regions.iter().map(|r| r.centre).collect();
        Self {
            config,
            tree,
            regions,
            iterations,
            total_samples,
            last_update_seconds,
            trained_regions,
            centres,
        }
    }

    /// The configuration the field was created with.
    pub fn config(&self) -> &FieldConfig {
        &self.config
    }

    /// True once some region has been trained, so lookups can succeed.
    pub fn is_trained(&self) -> bool {
        self.trained_regions > 0
    }

    /// Number of completed updates.
    pub fn iterations(&self) -> u32 {
        self.iterations
    }

    /// All regions, indexed as `lookup_index` and `VolumeDistribution::region_index` report.
    pub fn regions(&self) -> &[Region] {
        &self.regions
    }

    /// The trained region for a query at `pos`, or `None` when there is none (the renderer
    /// then falls back to unguided sampling). `u` in `[0, 1)` drives the stochastic spatial
    /// filter when `FieldConfig::spatial_filter` is on, and is ignored otherwise.
    #[inline]
    pub fn lookup(&self, pos: Vec3, u: f32) -> Option<&Region> {
        self.lookup_index(pos, u).map(|i| &self.regions[i])
    }

    /// Like [`lookup`](Self::lookup), returning the region's index.
    ///
    /// With the spatial filter on, the candidates are the region containing `pos` and those
    /// of its nearest regions whose centre lies within `filter_radius` times the region's
    /// sample spread of `pos`; `u` picks one uniformly. This blurs region boundaries in
    /// expectation, as a stochastic box filter does, without blending mixtures.
    #[inline]
    pub fn lookup_index(&self, pos: Vec3, u: f32) -> Option<usize> {
        if self.trained_regions == 0 {
            return None;
        }
        let (r, _) = self.tree.lookup(pos);
        let region = &self.regions[r];
        if !self.config.spatial_filter || region.neighbour_count == 0 {
            return region.is_trained().then_some(r);
        }
        let radius = self.config.filter_radius * region.spread;
        let radius2 = radius * radius;
        let mut candidates = [0u32; MAX_NEIGHBOURS + 1];
        let mut n = 0;
        if region.is_trained() {
            candidates[0] = r as u32;
            n = 1;
        }
        for &j in &region.neighbours[..region.neighbour_count as usize] {
            if (self.centres[j as usize] - pos).length_squared() <= radius2 {
                candidates[n] = j;
                n += 1;
            }
        }
        if n == 0 {
            return None;
        }
        let pick = ((u.clamp(0.0, 1.0) * n as f32) as usize).min(n - 1);
        Some(candidates[pick] as usize)
    }

    /// How far from `pos` along the unit `dir` the region containing `pos` reaches (infinite
    /// where it is unbounded that way), ignoring the spatial filter: where a sampler that
    /// follows the regions along a ray needs its next lookup.
    #[inline]
    pub fn region_exit(&self, pos: Vec3, dir: Vec3) -> f32 {
        self.tree.exit(pos, dir)
    }

    /// Trains the field on one pass's samples.
    ///
    /// Fails, changing nothing, if any sample is invalid (non-finite position, non-unit
    /// direction, negative or non-finite radiance, non-positive or non-finite pdf); the error
    /// names the first bad sample's index. Samples whose kind does not match
    /// `FieldConfig::samples` are ignored.
    pub fn update(&mut self, samples: &[Sample]) -> Result<(), GuidingError> {
        let start = Instant::now();
        validate_all(samples)?;
        let kind = self.config.samples;
        let tree = &self.tree;
        // The tree lookups in parallel (a pass holds millions of samples), the lists filled
        // in sample order.
        let leaves: Vec<u32> = samples
            .par_iter()
            .map(|s| {
                let accepted = match kind {
                    SampleKind::All => true,
                    SampleKind::Volume => s.volume,
                    SampleKind::Surface => !s.volume,
                };
                if accepted { tree.lookup(s.position).0 as u32 } else { u32::MAX }
            })
            .collect();
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); self.regions.len()];
        let mut accepted_count = 0u64;
        for (i, &leaf) in leaves.iter().enumerate().filter(|(_, l)| **l != u32::MAX) {
            lists[leaf as usize].push(i as u32);
            accepted_count += 1;
        }
        self.refine(samples, &mut lists);
        self.tree.index_cells();

        let settings = self.em_settings();
        let config = &self.config;
        self.regions.par_iter_mut().zip(lists.par_iter()).for_each(|(region, list)| {
            if list.is_empty() {
                return;
            }
            // The batch is already in the spatial statistics (`refine`): the centre is the
            // pivot the lobes are fitted from and re-aimed from. It moves a little as samples
            // accumulate (and to a child's own samples at a split), and the stored statistics
            // keep directions seen from where it was: a small error that new batches outweigh.
            region.centre = region.spatial.mean().as_vec3();
            region.spread = region.spatial.variance().element_sum().sqrt() as f32;
            let near = PARALLAX_NEAREST * region.spread;
            let dirs: Vec<WeightedDir> = list
                .iter()
                .map(|&i| {
                    let s = &samples[i as usize];
                    let (dir, inv_distance) = if config.parallax {
                        reproject(s, region.centre, near)
                    } else {
                        (s.direction.normalize(), 0.0)
                    };
                    WeightedDir { dir, weight: s.weight(), pdf: s.pdf, inv_distance }
                })
                .collect();
            em::update(&mut region.mixture, &mut region.em, &dirs, &settings);
            if config.split_merge {
                splitmerge::update(
                    &mut splitmerge::Lobes {
                        mixture: &mut region.mixture,
                        em: &mut region.em,
                        stats: &mut region.split_merge,
                    },
                    &dirs,
                    config,
                );
            }
            // Without parallax every sample's inverse distance is 0, and so is every lobe's.
            region.lanes = RegionLanes::new(&region.mixture, &region.em.lobe_inverse_distances());
            let fluence =
                if region.em.count > 0.0 { region.em.total_weight / region.em.count } else { 0.0 };
            region.fluence = fluence.min(f64::from(f32::MAX)) as f32;
        });
        self.trained_regions = self.regions.iter().filter(|r| r.is_trained()).count();
        self.centres = self.regions.iter().map(|r| r.centre).collect();
        if self.config.spatial_filter {
            self.build_neighbours();
        }
        self.iterations += 1;
        self.total_samples += accepted_count;
        self.last_update_seconds = start.elapsed().as_secs_f64();
        Ok(())
    }

    pub(crate) fn em_settings(&self) -> EmSettings {
        let c = &self.config;
        EmSettings {
            iterations: c.em_iterations,
            weight_prior: f64::from(c.weight_prior),
            mean_cosine_prior: f64::from(c.mean_cosine_prior),
            mean_cosine_prior_strength: f64::from(c.mean_cosine_prior_strength),
            max_kappa: f64::from(c.max_kappa),
            step_exponent: f64::from(c.step_exponent),
            initial_kappa: c.initial_kappa,
        }
    }

    /// Adds the batch's positions to the leaves' spatial statistics and splits every leaf
    /// that has now seen enough samples, recursively, re-routing the batch as it goes.
    fn refine(&mut self, samples: &[Sample], lists: &mut Vec<Vec<u32>>) {
        let threshold = self.config.max_samples_per_leaf as f64;
        let mut work = Vec::new();
        for (r, list) in lists.iter().enumerate() {
            if let Some(&first) = list.first() {
                for &i in list {
                    self.regions[r].spatial.add(samples[i as usize].position);
                }
                work.push((r, self.tree.lookup(samples[first as usize].position).1));
            }
        }
        while let Some((r, node)) = work.pop() {
            let region = &self.regions[r];
            if region.spatial.count < threshold || region.depth >= self.config.max_depth {
                continue;
            }
            let Some((axis, at)) = region.spatial.split_plane() else { continue };
            let (lower, upper): (Vec<u32>, Vec<u32>) =
                lists[r].iter().partition(|&&i| samples[i as usize].position[axis] < at);
            // The batch decides how the history is shared between the halves.
            let n = (lower.len() + upper.len()) as f64;
            let f_lower = (lower.len() as f64 + 0.5) / (n + 1.0);
            let mut hi = self.regions[r].clone();
            let lo = &mut self.regions[r];
            for (child, list, f) in [(&mut *lo, &lower, f_lower), (&mut hi, &upper, 1.0 - f_lower)]
            {
                child.em.scale(f);
                child.split_merge.scale(f);
                child.depth += 1;
                child.neighbour_count = 0;
                child.spatial = SpatialStats::default();
                for &i in list {
                    child.spatial.add(samples[i as usize].position);
                }
            }
            let u = self.regions.len();
            self.regions.push(hi);
            lists[r] = lower;
            lists.push(upper);
            self.tree.split(node, axis, at, r as u32, u as u32);
            let first_child = self.tree.node_count() - 2;
            work.push((r, first_child));
            work.push((u, first_child + 1));
        }
    }

    /// Finds each region's nearest trained regions for the spatial filter (kiddo).
    fn build_neighbours(&mut self) {
        use kiddo::{ImmutableKdTree, SquaredEuclidean};
        let trained: Vec<u32> = (0..self.regions.len() as u32)
            .filter(|&i| self.regions[i as usize].is_trained())
            .collect();
        let points: Vec<[f32; 3]> =
            trained.iter().map(|&i| self.regions[i as usize].centre.to_array()).collect();
        let k = self.config.filter_neighbours.min(trained.len());
        let Some(k_plus_self) = std::num::NonZeroUsize::new(k + 1) else { return };
        let Ok(tree) = ImmutableKdTree::<f32, 3>::new_from_slice(&points) else { return };
        for (r, region) in self.regions.iter_mut().enumerate() {
            let found = tree
                .query(&region.centre.to_array())
                .nearest_n::<SquaredEuclidean<f32>>(k_plus_self)
                .execute();
            let mut n = 0;
            for item in found {
                let j = trained[item.item as usize];
                if j as usize != r && n < k {
                    region.neighbours[n] = j;
                    n += 1;
                }
            }
            region.neighbour_count = n as u8;
        }
    }

    /// Counts and timings of the field.
    pub fn stats(&self) -> FieldStats {
        let regions = &self.regions;
        let counts = regions.iter().map(|r| r.mixture().len());
        FieldStats {
            regions: regions.len(),
            trained_regions: regions.iter().filter(|r| r.is_trained()).count(),
            lobes: counts.clone().sum(),
            lobes_min_max: (counts.clone().min().unwrap_or(0), counts.max().unwrap_or(0)),
            tree_nodes: self.tree.node_count(),
            tree_depth: self.tree.depth(),
            memory_bytes: std::mem::size_of::<Field>()
                + regions.capacity() * std::mem::size_of::<Region>()
                + self.tree.memory_bytes(),
            last_update_seconds: self.last_update_seconds,
            total_samples: self.total_samples,
            iterations: self.iterations,
        }
    }
}

/// A sample's light source nearer to it than this many times the spread of its region's
/// samples is moved out to that distance along the sample's direction before the direction is
/// re-aimed from the pivot: a source inside the region has no one direction from it, and
/// this keeps re-aimed directions close to the observed ones (Open PGL clamps similarly).
const PARALLAX_NEAREST: f32 = 3.0;

/// A sample's direction seen from `pivot`, towards the point its light came from (moved at
/// least `near` from the sample), and one over that point's distance from `pivot`; light
/// from infinitely far keeps its direction.
fn reproject(s: &Sample, pivot: Vec3, near: f32) -> (Vec3, f32) {
    let dir = s.direction.normalize();
    if !s.distance.is_finite() {
        return (dir, 0.0);
    }
    let source = s.position + dir * s.distance.max(near);
    let to = source - pivot;
    let len = to.length();
    if !(len > 0.0 && len.is_finite()) {
        return (dir, 0.0);
    }
    (to / len, 1.0 / len)
}
