//! A procedural cloud: fractal gradient noise shaped by a spherical falloff inside the unit
//! cube, so a cloud needs no file. The density is clamped to [0, 1] before scaling, which makes
//! the medium's scale an exact majorant.

use crate::rng::mix64;
use glam::Vec3A;
use serde::{Deserialize, Serialize};

/// Parameters of the noise cloud (see scenes/README.md for their effect).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseCloud {
    /// Noise cells across the unit cube.
    pub frequency: f32,
    /// Octaves of noise summed, each at twice the frequency and half the amplitude.
    pub octaves: u32,
    /// Selects the noise pattern.
    pub seed: u32,
    /// How strongly the noise erodes the spherical base shape.
    pub amplitude: f32,
    /// Subtracted before clamping: larger values give a smaller, wispier cloud.
    pub threshold: f32,
    /// Multiplies the shaped value before clamping: larger values give harder edges.
    pub sharpness: f32,
}

impl Default for NoiseCloud {
    fn default() -> Self {
        Self {
            frequency: 4.0,
            octaves: 5,
            seed: 1,
            amplitude: 0.6,
            threshold: 0.25,
            sharpness: 3.0,
        }
    }
}

impl NoiseCloud {
    /// Density in [0, 1] at a point of the unit cube.
    pub fn density(&self, p: Vec3A) -> f32 {
        let q = p * 2.0 - Vec3A::ONE;
        let base = 1.0 - q.length();
        if base + self.amplitude <= self.threshold {
            return 0.0;
        }
        let mut sum = 0.0;
        let (mut freq, mut amp, mut norm) = (self.frequency, 1.0, 0.0);
        for octave in 0..self.octaves {
            sum += amp * gradient_noise(p * freq, self.seed.wrapping_add(octave));
            norm += amp;
            freq *= 2.0;
            amp *= 0.5;
        }
        let n = if norm > 0.0 { sum / norm } else { 0.0 };
        ((base + self.amplitude * n - self.threshold) * self.sharpness).clamp(0.0, 1.0)
    }
}

/// Gradient noise in about [-1, 1]: hashed unit gradients at lattice points, quintic fade.
fn gradient_noise(p: Vec3A, seed: u32) -> f32 {
    let cell = p.floor();
    let f = p - cell;
    let fade = f * f * f * (f * (f * 6.0 - Vec3A::splat(15.0)) + Vec3A::splat(10.0));
    let [cx, cy, cz] = cell.to_array().map(|c| c as i64);
    let mut corners = [0.0f32; 8];
    for (k, corner) in corners.iter_mut().enumerate() {
        let o = [(k & 1) as i64, ((k >> 1) & 1) as i64, ((k >> 2) & 1) as i64];
        let h = mix64(
            (cx + o[0]) as u64
                ^ mix64((cy + o[1]) as u64 ^ mix64((cz + o[2]) as u64 ^ seed as u64)),
        );
        let g = Vec3A::new(
            (h & 0xffff) as f32 / 32767.5 - 1.0,
            ((h >> 16) & 0xffff) as f32 / 32767.5 - 1.0,
            ((h >> 32) & 0xffff) as f32 / 32767.5 - 1.0,
        );
        let d = f - Vec3A::new(o[0] as f32, o[1] as f32, o[2] as f32);
        *corner = g.dot(d);
    }
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(corners[0], corners[1], fade.x);
    let x10 = lerp(corners[2], corners[3], fade.x);
    let x01 = lerp(corners[4], corners[5], fade.x);
    let x11 = lerp(corners[6], corners[7], fade.x);
    lerp(lerp(x00, x10, fade.y), lerp(x01, x11, fade.y), fade.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_is_bounded_and_not_trivial() {
        let c = NoiseCloud::default();
        let mut inside = 0;
        let n = 24;
        for i in 0..n * n * n {
            let p = Vec3A::new((i % n) as f32, (i / n % n) as f32, (i / n / n) as f32);
            let d = c.density((p + Vec3A::splat(0.5)) / n as f32);
            assert!((0.0..=1.0).contains(&d));
            inside += (d > 0.0) as usize;
        }
        let frac = inside as f32 / (n * n * n) as f32;
        assert!(frac > 0.05 && frac < 0.6, "cloud fills {frac} of its box");
        assert_eq!(c.density(Vec3A::new(0.0, 0.0, 0.0)), 0.0);
    }
}
