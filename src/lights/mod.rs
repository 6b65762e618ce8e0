//! Light sources and next-event estimation towards them.
//!
//! Units follow Mitsuba 3: point and spot lights give radiant intensity (W/sr), area emitters
//! and environments give radiance, the sun gives irradiance on a surface facing it. Area
//! emitters emit from the front side of their shape only. Every light samples a direction from
//! a reference point and reports the solid-angle density, so the integrator can weigh light
//! sampling against phase and BSDF sampling with MIS; delta lights report `delta`.

mod envmap;
mod point;

pub use envmap::EnvMap;
pub use point::PointLight;

use crate::math::{Frame, Spectrum, uniform_cone};
use crate::shapes::Geometry;
use glam::{Vec2, Vec3A};
use std::f32::consts::{PI, TAU};

/// A light of the scene.
#[derive(Clone, Debug)]
pub enum Light {
    /// An isotropic point light.
    Point {
        /// Position.
        position: Vec3A,
        /// Radiant intensity.
        intensity: Spectrum,
    },
    /// A spot light with Mitsuba's linear angular falloff between beam width and cutoff.
    Spot {
        /// Position.
        position: Vec3A,
        /// Frame whose z axis is the spot's axis.
        frame: Frame,
        /// Radiant intensity on the axis.
        intensity: Spectrum,
        /// Cutoff half-angle, radians.
        cutoff: f32,
        /// Half-angle of full intensity, radians.
        beam_width: f32,
    },
    /// An emitter attached to a shape.
    Area {
        /// Index of the shape.
        shape: u32,
        /// Whether the shape's normals are flipped (the emitting side follows the normal).
        flip: bool,
        /// Emitted radiance.
        radiance: Spectrum,
    },
    /// A distant light: a delta direction, or a uniform disk of the given angular radius.
    Directional {
        /// Unit direction towards the light.
        to_light: Vec3A,
        /// Irradiance on a surface facing the light.
        irradiance: Spectrum,
        /// 1 - cos of the angular radius (0 for a delta light).
        one_minus_cos: f32,
    },
    /// Constant radiance from every direction.
    Constant {
        /// Radiance.
        radiance: Spectrum,
    },
    /// An environment map.
    EnvMap(Box<EnvMap>),
}

/// A sampled light direction.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point towards the light.
    pub wi: Vec3A,
    /// Distance to the light (infinite for lights at infinity).
    pub distance: f32,
    /// Radiance (or intensity over distance squared) arriving, before transmittance.
    pub radiance: Spectrum,
    /// Solid-angle density of the direction (1 for delta lights).
    pub pdf: f32,
    /// Whether no other strategy can find this light.
    pub delta: bool,
}

impl Light {
    /// Whether the light sits at infinity (found by rays that leave the scene).
    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Directional { .. } | Light::Constant { .. } | Light::EnvMap(_))
    }

    /// Whether the light is a point or a single direction, which only next-event estimation
    /// can reach.
    pub fn is_delta(&self) -> bool {
        match self {
            Light::Point { .. } | Light::Spot { .. } => true,
            Light::Directional { one_minus_cos, .. } => *one_minus_cos == 0.0,
            _ => false,
        }
    }

    /// A point or spot light as equiangular sampling aims at it.
    pub fn point_light(&self) -> Option<PointLight> {
        match self {
            Light::Point { position, .. } => Some(PointLight { position: *position, cone: None }),
            Light::Spot { position, frame, cutoff, .. } => {
                Some(PointLight { position: *position, cone: Some((frame.z, cutoff.cos())) })
            }
            _ => None,
        }
    }

    /// Samples a direction towards the light from `p`.
    pub fn sample(&self, shapes: &[Geometry], p: Vec3A, u: Vec2) -> Option<LightSample> {
        let delta = |to: Vec3A, intensity: Spectrum| {
            let d2 = to.length_squared();
            let distance = d2.sqrt();
            (distance > 0.0).then(|| LightSample {
                wi: to / distance,
                distance,
                radiance: intensity / d2,
                pdf: 1.0,
                delta: true,
            })
        };
        match self {
            Light::Point { position, intensity } => delta(*position - p, *intensity),
            Light::Spot { position, frame, intensity, cutoff, beam_width } => {
                let s = delta(*position - p, *intensity)?;
                let falloff = spot_falloff(frame.z.dot(-s.wi), *cutoff, *beam_width);
                (falloff > 0.0).then(|| LightSample { radiance: s.radiance * falloff, ..s })
            }
            Light::Area { shape, flip, radiance } => {
                let a = shapes[*shape as usize].sample(p, u)?;
                let to = a.p - p;
                let distance = to.length();
                let wi = to / distance;
                let n = if *flip { -a.n } else { a.n };
                (n.dot(wi) < 0.0 && distance > 0.0).then_some(LightSample {
                    wi,
                    distance,
                    radiance: *radiance,
                    pdf: a.pdf_solid_angle,
                    delta: false,
                })
            }
            Light::Directional { to_light, irradiance, one_minus_cos } => {
                if *one_minus_cos == 0.0 {
                    return Some(LightSample {
                        wi: *to_light,
                        distance: f32::INFINITY,
                        radiance: *irradiance,
                        pdf: 1.0,
                        delta: true,
                    });
                }
                let wi =
                    Frame::from_z(*to_light).to_world(uniform_cone(u, *one_minus_cos)).normalize();
                Some(LightSample {
                    wi,
                    distance: f32::INFINITY,
                    radiance: sun_radiance(*irradiance, *one_minus_cos),
                    pdf: 1.0 / (TAU * one_minus_cos),
                    delta: false,
                })
            }
            Light::Constant { radiance } => {
                let wi = crate::math::uniform_sphere(u);
                Some(LightSample {
                    wi,
                    distance: f32::INFINITY,
                    radiance: *radiance,
                    pdf: crate::math::INV_FOUR_PI,
                    delta: false,
                })
            }
            Light::EnvMap(m) => {
                let (wi, radiance, pdf) = m.sample(u)?;
                Some(LightSample { wi, distance: f32::INFINITY, radiance, pdf, delta: false })
            }
        }
    }

    /// Radiance arriving along a ray that left the scene in direction `d`, and the density with
    /// which `sample` would have picked `d` (infinite lights only).
    pub fn eval_escaped(&self, d: Vec3A) -> (Spectrum, f32) {
        match self {
            Light::Directional { to_light, irradiance, one_minus_cos } if *one_minus_cos > 0.0 => {
                if 1.0 - d.dot(*to_light) <= *one_minus_cos {
                    (sun_radiance(*irradiance, *one_minus_cos), 1.0 / (TAU * one_minus_cos))
                } else {
                    (Spectrum::ZERO, 0.0)
                }
            }
            Light::Constant { radiance } => (*radiance, crate::math::INV_FOUR_PI),
            Light::EnvMap(m) => (m.eval(d), m.pdf(d)),
            _ => (Spectrum::ZERO, 0.0),
        }
    }

    /// Radiance emitted by an area light at a hit with front normal `n` towards `wo`.
    #[inline]
    pub fn eval_area(&self, n: Vec3A, wo: Vec3A) -> Spectrum {
        match self {
            Light::Area { radiance, .. } if n.dot(wo) > 0.0 => *radiance,
            _ => Spectrum::ZERO,
        }
    }

    /// Density with which `sample` from `reference` picks the area light point `p`, normal `n`.
    pub fn pdf_area(&self, shapes: &[Geometry], reference: Vec3A, p: Vec3A, n: Vec3A) -> f32 {
        match self {
            Light::Area { shape, .. } => shapes[*shape as usize].pdf(reference, p, n),
            _ => 0.0,
        }
    }
}

/// Mitsuba's spot falloff: 1 inside the beam, linear in angle down to 0 at the cutoff.
fn spot_falloff(cos: f32, cutoff: f32, beam_width: f32) -> f32 {
    // Most directions are decided without acos, by bounds of the cosine's series:
    // 1 - x^2/2 <= cos x <= 1 - x^2/2 + x^4/24, with a margin far beyond rounding.
    const MARGIN: f32 = 1e-5;
    let (c2, b2) = (cutoff * cutoff, beam_width * beam_width);
    if cos < 1.0 - 0.5 * c2 - MARGIN {
        return 0.0;
    }
    if cos > 1.0 - 0.5 * b2 + b2 * b2 / 24.0 + MARGIN {
        return 1.0;
    }
    let angle = cos.clamp(-1.0, 1.0).acos();
    if angle >= cutoff {
        0.0
    } else if angle <= beam_width {
        1.0
    } else {
        (cutoff - angle) / (cutoff - beam_width)
    }
}

/// Radiance of a uniform disk source of the given `1 - cos` radius producing `irradiance`:
/// E = L * pi * sin^2, with sin^2 = (1 - cos)(1 + cos).
fn sun_radiance(irradiance: Spectrum, one_minus_cos: f32) -> Spectrum {
    irradiance / (PI * one_minus_cos * (2.0 - one_minus_cos))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;

    #[test]
    fn sun_disk_delivers_its_irradiance() {
        let to_light = Vec3A::new(0.2, 0.9, -0.3).normalize();
        let radius = 0.265f32.to_radians();
        let sun = Light::Directional {
            to_light,
            irradiance: Spectrum::splat(3.0),
            one_minus_cos: 1.0 - radius.cos(),
        };
        // Irradiance on a surface facing the sun: E[L cos / pdf].
        let mut s = Sampler::new(1, 0, 0);
        let est: zerovar_testkit::MeanEstimate = (0..4000)
            .map(|_| {
                let ls = sun.sample(&[], Vec3A::ZERO, s.next_2d()).unwrap();
                let (l, pdf) = sun.eval_escaped(ls.wi);
                assert!((pdf - ls.pdf).abs() < 1e-3 * pdf && l == ls.radiance);
                (ls.radiance.x * ls.wi.dot(to_light) / ls.pdf) as f64
            })
            .collect();
        assert!((est.mean - 3.0).abs() < 1e-3, "sun irradiance {}", est.mean);
    }

    #[test]
    fn spot_falloff_skips_acos_only_where_it_agrees() {
        // Against the falloff from the exact angle, across and around both edges.
        for (cutoff, beam) in [(0.35f32, 0.2f32), (0.05, 0.01), (1.5, 1.2), (3.1, 0.5)] {
            for i in 0..=20_000 {
                let angle = 3.2 * i as f32 / 20_000.0;
                let cos = angle.cos();
                let exact = cos.clamp(-1.0, 1.0).acos();
                let want = if exact >= cutoff {
                    0.0
                } else if exact <= beam {
                    1.0
                } else {
                    (cutoff - exact) / (cutoff - beam)
                };
                assert_eq!(spot_falloff(cos, cutoff, beam), want, "{cutoff} {beam} {angle}");
            }
        }
    }

    #[test]
    fn spot_falloff_is_linear_in_angle() {
        let (c, b) = (20f32.to_radians(), 15f32.to_radians());
        assert_eq!(spot_falloff(1.0, c, b), 1.0);
        assert!((spot_falloff(17.5f32.to_radians().cos(), c, b) - 0.5).abs() < 1e-3);
        assert_eq!(spot_falloff(25f32.to_radians().cos(), c, b), 0.0);
    }
}
