//! The unguided volumetric path tracer.
//!
//! Free flights come from each medium's tracker; at every real scattering event (in a medium or
//! on a non-null surface) it samples one light and weighs it with the power heuristic against
//! phase or BSDF sampling, then continues with phase or BSDF sampling. Null surfaces are
//! crossed without counting a bounce, switching the current medium. Depth counts scattering
//! events as Mitsuba 3's volpath does: `max_depth = 1` shows only emitters seen directly,
//! `max_depth = 2` adds single scattering. Russian roulette from `rr_depth` on keeps the
//! expected throughput (q = min(max(beta) eta^2, 0.95)).

use crate::bsdf::Bsdf;
use crate::lights::Light;
use crate::math::{Frame, Ray, Spectrum, power_heuristic};
use crate::rng::Sampler;
use crate::scene::{Scene, offset_origin};
use crate::stats::Counters;
use crate::tracking::{FlightEvent, sample_flight, transmittance};
use glam::Vec3A;

/// A path crossing more null surfaces than this in a row is stuck in degenerate geometry.
const MAX_NULL_CROSSINGS: u32 = 4096;

/// The unguided volumetric path tracer.
#[derive(Clone, Copy, Debug)]
pub struct VolPath {
    /// Longest path in scattering events; `None` is unlimited.
    pub max_depth: Option<u32>,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

/// How the current direction was chosen, for MIS when it finds an emitter.
#[derive(Clone, Copy)]
struct Previous {
    position: Vec3A,
    pdf: f32,
    delta: bool,
}

impl VolPath {
    /// The integrator with a scene's settings.
    pub fn from_scene(scene: &Scene) -> Self {
        Self { max_depth: scene.settings.max_depth, rr_depth: scene.settings.rr_depth }
    }

    /// Estimates the radiance arriving along `ray`, which starts in `medium`.
    pub fn radiance(
        &self,
        scene: &Scene,
        mut ray: Ray,
        mut medium: Option<u32>,
        sampler: &mut Sampler,
        counters: &mut Counters,
    ) -> Spectrum {
        let mut l = Spectrum::ZERO;
        let mut beta = Spectrum::ONE;
        let mut eta = 1.0f32;
        let mut depth = 0u32;
        let mut nulls = 0u32;
        let mut prev = Previous { position: ray.origin, pdf: 1.0, delta: true };
        counters.paths += 1;
        loop {
            counters.segments += 1;
            let hit = scene.intersect(&ray, f32::INFINITY);
            let t_max = hit.as_ref().map_or(f32::INFINITY, |h| h.t);

            if let Some(m) = medium {
                let mi = m as usize;
                let flight = sample_flight(
                    &scene.media[mi],
                    scene.trackers[mi],
                    &ray,
                    t_max,
                    beta,
                    sampler,
                    counters,
                );
                l += flight.emitted;
                beta *= flight.weight;
                if let FlightEvent::Scatter { t } = flight.event {
                    counters.medium_scatters += 1;
                    depth += 1;
                    if self.max_depth.is_some_and(|d| depth >= d) || beta.max_element() <= 0.0 {
                        break;
                    }
                    let p = ray.at(t);
                    let phase = scene.media[mi].phase;
                    let dir = ray.direction;
                    l += beta
                        * self.sample_light(scene, p, None, medium, sampler, counters, |wi| {
                            let v = phase.eval(dir, wi);
                            (Spectrum::splat(v), v)
                        });
                    let (wi, pdf) = phase.sample(dir, sampler.next_2d());
                    ray = Ray::new(p, wi);
                    prev = Previous { position: p, pdf, delta: false };
                    nulls = 0;
                    if !self.roulette(&mut beta, eta, depth, sampler) {
                        break;
                    }
                    continue;
                }
                if beta.max_element() <= 0.0 {
                    break;
                }
            }

            let Some(hit) = hit else {
                for &li in &scene.infinite_lights {
                    let light = &scene.lights[li as usize];
                    let (le, pdf) = light.eval_escaped(ray.direction);
                    if le.max_element() > 0.0 {
                        l += beta * le * self.mis_emitter(scene, prev, pdf);
                    }
                }
                break;
            };

            let surface = &scene.surfaces[hit.shape as usize];
            if let Some(li) = surface.light {
                let light = &scene.lights[li as usize];
                let le = light.eval_area(hit.ng, -ray.direction);
                if le.max_element() > 0.0 {
                    let pdf = light.pdf_area(&scene.shapes, prev.position, hit.p, hit.ng);
                    l += beta * le * self.mis_emitter(scene, prev, pdf);
                }
            }

            if surface.bsdf == Bsdf::Null {
                nulls += 1;
                if nulls > MAX_NULL_CROSSINGS {
                    break;
                }
                medium = scene.medium_after(&hit, ray.direction);
                ray = Ray::new(offset_origin(hit.p, hit.ng, ray.direction), ray.direction);
                continue;
            }

            counters.surface_scatters += 1;
            depth += 1;
            if self.max_depth.is_some_and(|d| depth >= d) {
                break;
            }
            let bsdf = surface.bsdf;
            let frame = Frame::from_z(hit.ns);
            let wo = frame.to_local(-ray.direction);
            if bsdf.has_smooth_component() {
                let eval = |wi: Vec3A| {
                    let wl = frame.to_local(wi);
                    (bsdf.eval(wo, wl, hit.uv), bsdf.pdf(wo, wl))
                };
                l += beta
                    * self.sample_light(
                        scene,
                        hit.p,
                        Some(hit.ng),
                        medium,
                        sampler,
                        counters,
                        eval,
                    );
            }
            let u1 = sampler.next_1d();
            let Some(bs) = bsdf.sample(wo, hit.uv, u1, sampler.next_2d()) else { break };
            let wi = frame.to_world(bs.wi).normalize();
            // Shading and geometric normals may disagree: a direction under the geometric
            // surface would leak light through it.
            if (wi.dot(hit.ng) > 0.0) != (bs.wi.z > 0.0) && !bs.delta {
                break;
            }
            beta *= bs.weight;
            eta *= bs.eta;
            medium = scene.medium_after(&hit, wi);
            ray = Ray::new(offset_origin(hit.p, hit.ng, wi), wi);
            prev = Previous { position: hit.p, pdf: bs.pdf, delta: bs.delta };
            nulls = 0;
            if !self.roulette(&mut beta, eta, depth, sampler) {
                break;
            }
        }
        l
    }

    /// MIS weight of an emitter found by the previous direction sample.
    #[inline]
    fn mis_emitter(&self, scene: &Scene, prev: Previous, light_pdf: f32) -> f32 {
        if prev.delta {
            1.0
        } else {
            power_heuristic(prev.pdf, light_pdf / scene.lights.len() as f32)
        }
    }

    /// Russian roulette; false when the path ends.
    #[inline]
    fn roulette(&self, beta: &mut Spectrum, eta: f32, depth: u32, sampler: &mut Sampler) -> bool {
        if depth < self.rr_depth {
            return true;
        }
        let q = (beta.max_element() * eta * eta).min(0.95);
        if q.is_nan() || q <= 0.0 || sampler.next_1d() >= q {
            return false;
        }
        *beta /= q;
        true
    }

    /// Next-event estimation: one light chosen uniformly, a direction sampled on it, weighed
    /// against the scattering strategy `eval(wi) -> (f, pdf)` with the power heuristic.
    #[allow(clippy::too_many_arguments)]
    fn sample_light(
        &self,
        scene: &Scene,
        p: Vec3A,
        ng: Option<Vec3A>,
        medium: Option<u32>,
        sampler: &mut Sampler,
        counters: &mut Counters,
        eval: impl Fn(Vec3A) -> (Spectrum, f32),
    ) -> Spectrum {
        let n = scene.lights.len();
        let pick = sampler.next_1d();
        let u = sampler.next_2d();
        if n == 0 {
            return Spectrum::ZERO;
        }
        let light = &scene.lights[((pick * n as f32) as usize).min(n - 1)];
        let Some(ls) = light.sample(&scene.shapes, p, u) else { return Spectrum::ZERO };
        let (f, pdf_dir) = eval(ls.wi);
        if f.max_element() <= 0.0 {
            return Spectrum::ZERO;
        }
        let origin = ng.map_or(p, |n| offset_origin(p, n, ls.wi));
        let reach = if matches!(light, Light::Area { .. }) {
            ls.distance * (1.0 - 1e-4)
        } else {
            ls.distance
        };
        let tr =
            shadow_transmittance(scene, Ray::new(origin, ls.wi), reach, medium, sampler, counters);
        if tr.max_element() <= 0.0 {
            return Spectrum::ZERO;
        }
        let light_pdf = ls.pdf / n as f32;
        let w = if ls.delta { 1.0 } else { power_heuristic(light_pdf, pdf_dir) };
        f * tr * ls.radiance * (w / light_pdf)
    }
}

/// Transmittance along a shadow ray through media and null surfaces; zero when anything else
/// blocks it.
pub fn shadow_transmittance(
    scene: &Scene,
    mut ray: Ray,
    mut distance: f32,
    mut medium: Option<u32>,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    let mut tr = Spectrum::ONE;
    for _ in 0..MAX_NULL_CROSSINGS {
        let hit = scene.intersect(&ray, distance);
        let seg = hit.as_ref().map_or(distance, |h| h.t);
        if let Some(m) = medium {
            tr *= transmittance(&scene.media[m as usize], &ray, seg, sampler, counters);
            if tr.max_element() <= 0.0 {
                return Spectrum::ZERO;
            }
        }
        let Some(hit) = hit else { return tr };
        if scene.surfaces[hit.shape as usize].bsdf != Bsdf::Null {
            return Spectrum::ZERO;
        }
        medium = scene.medium_after(&hit, ray.direction);
        let origin = offset_origin(hit.p, hit.ng, ray.direction);
        distance -= (origin - ray.origin).length();
        if distance <= 0.0 {
            return tr;
        }
        ray = Ray::new(origin, ray.direction);
    }
    Spectrum::ZERO
}
