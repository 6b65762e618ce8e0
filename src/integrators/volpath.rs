//! The unguided volumetric path tracer: the shared random walk (`walk`) with nothing guided.
//!
//! Free flights come from each medium's tracker, with an extra collision aimed at point and
//! spot lights where a flight passes close to one; at every real scattering event (in a medium or
//! on a non-null surface) it samples one light and weighs it with the power heuristic against
//! phase or BSDF sampling, then continues with phase or BSDF sampling. Null surfaces are
//! crossed without counting a bounce, switching the current medium. Depth counts scattering
//! events as Mitsuba 3's volpath does: `max_depth = 1` shows only emitters seen directly,
//! `max_depth = 2` adds single scattering. Russian roulette from `rr_depth` on keeps the
//! expected throughput (q = min(max(beta) eta^2, 0.95)).

use super::walk::{self, WalkContext, WalkSettings};
use crate::guided::{Components, NoCache};
use crate::math::{Ray, Spectrum};
use crate::rng::Sampler;
use crate::scene::Scene;
use crate::stats::Counters;

/// The unguided volumetric path tracer.
#[derive(Clone, Copy, Debug)]
pub struct VolPath {
    /// Longest path in scattering events; `None` is unlimited.
    pub max_depth: Option<u32>,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

impl VolPath {
    /// The integrator with a scene's settings.
    pub fn from_scene(scene: &Scene) -> Self {
        Self { max_depth: scene.settings.max_depth, rr_depth: scene.settings.rr_depth }
    }

    /// The walk settings of this integrator.
    pub fn settings(&self) -> WalkSettings {
        WalkSettings {
            max_depth: self.max_depth,
            rr_depth: self.rr_depth,
            guide: Components::OFF,
            alpha: 0.0,
            surface_alpha: 0.0,
            distance_alpha: 0.0,
            collision_windows: false,
            point_light_collisions: true,
        }
    }

    /// Estimates the radiance arriving along `ray`, which starts in `medium`.
    pub fn radiance(
        &self,
        scene: &Scene,
        ray: Ray,
        medium: Option<u32>,
        sampler: &mut Sampler,
        counters: &mut Counters,
    ) -> Spectrum {
        let mut ctx = WalkContext { cache: &mut NoCache, pixel: None, recorder: None, trace: None };
        let start = walk::PathStart::unbounded(ray, medium);
        walk::radiance(&self.settings(), scene, start, &mut ctx, sampler, counters)
    }
}
