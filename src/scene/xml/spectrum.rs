//! `<spectrum>` values as RGB, the way Mitsuba 3's RGB variants read them. What a spectrum
//! becomes depends on where it is: inside an `<emitter>` a one-value spectrum is that much
//! equal-energy light, whose sRGB colour is not grey (`value * xyz_to_srgb(1, 1, 1)`), while
//! elsewhere it is grey. A list of wavelength:value pairs is integrated against the CIE 1931
//! curves (times D65 outside emitters, so that a flat reflectance stays grey) and converted to
//! linear sRGB; out-of-gamut results are clamped as Mitsuba clamps them: to [0, 1] for bounded
//! quantities (reflectances, albedos), to 0 from below for emitters and unbounded ones.

use super::cie::{CIE_MAX, CIE_MIN, CIE_STEP, CIE_TABLE, CIE_Y_NORMALIZATION};
use crate::scene::desc::Rgb;

/// Where a spectrum is given, which decides how it becomes RGB.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Place {
    /// A property of an `<emitter>` (its `radiance`, `irradiance`, `intensity`).
    pub(super) emitter: bool,
    /// A quantity Mitsuba leaves unbounded above: indices of refraction and `sigma_t`.
    pub(super) unbounded: bool,
}

impl Place {
    /// The place of property `name` of an object with tag `tag`.
    pub(super) fn of(tag: &str, name: &str) -> Self {
        // Mitsuba 3.9 clamps a `sigma_t` given as a list to 1 (a defect its later versions
        // fix by listing it here); zerovar reads it unbounded, as they do.
        let unbounded = matches!(name, "eta" | "k" | "int_ior" | "ext_ior" | "sigma_t");
        Self { emitter: tag == "emitter", unbounded }
    }
}

/// Linear sRGB from CIE XYZ (the matrix Mitsuba uses, sRGB primaries and D65 white).
fn xyz_to_srgb(xyz: [f64; 3]) -> [f64; 3] {
    const M: [[f64; 3]; 3] = [
        [3.240479, -1.537150, -0.498535],
        [-0.969256, 1.875991, 0.041556],
        [0.055648, -0.204043, 1.057311],
    ];
    M.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2])
}

/// The x, y, z curves and D65 at wavelength `w` (nm), linearly interpolated.
fn cie(w: f64) -> [f64; 4] {
    let t = ((w - CIE_MIN) / CIE_STEP).max(0.0);
    let i = (t as usize).min(CIE_TABLE.len() - 2);
    let f = t - i as f64;
    let (a, b) = (CIE_TABLE[i], CIE_TABLE[i + 1]);
    [0, 1, 2, 3].map(|k| f64::from(a[k]) * (1.0 - f) + f64::from(b[k]) * f)
}

/// A one-value spectrum.
pub(super) fn uniform(value: f32, place: Place) -> Rgb {
    if place.emitter && !place.unbounded {
        let c = xyz_to_srgb([1.0; 3]).map(|c| (c * f64::from(value)) as f32);
        Rgb::Rgb(c)
    } else {
        Rgb::Grey(value)
    }
}

/// A spectrum given as wavelength:value pairs, wavelengths in nm and strictly increasing
/// (`tree` checks both, and that there are at least two).
pub(super) fn pairs(pairs: &[[f64; 2]], place: Place) -> Rgb {
    let bounded = !(place.emitter || place.unbounded);
    let d65 = !place.emitter || place.unbounded;
    // Mitsuba's quadrature: 1000 equally spaced wavelengths over the tables' range, of which
    // those inside the given range count, each with the linear interpolant of the pairs.
    const STEPS: usize = 1000;
    let (first, last) = (pairs[0][0], pairs[pairs.len() - 1][0]);
    let mut xyz = [0.0f64; 3];
    for i in 0..STEPS {
        let w = CIE_MIN + (i as f64 / (STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        if w < first || w > last {
            continue;
        }
        let j = pairs[..pairs.len() - 1].iter().rposition(|p| p[0] <= w).unwrap_or(0);
        let ([w0, v0], [w1, v1]) = (pairs[j], pairs[j + 1]);
        let v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1) * CIE_Y_NORMALIZATION;
        let c = cie(w);
        let light = if d65 { c[3] } else { 1.0 };
        for k in 0..3 {
            xyz[k] += c[k] * v * light;
        }
    }
    let rgb = xyz_to_srgb(xyz.map(|x| x * (CIE_MAX - CIE_MIN) / STEPS as f64));
    let clamp = |c: f64| if bounded { c.clamp(0.0, 1.0) } else { c.max(0.0) };
    Rgb::Rgb(rgb.map(|c| clamp(c) as f32))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgb(c: Rgb) -> [f32; 3] {
        match c {
            Rgb::Grey(v) => [v; 3],
            Rgb::Rgb(c) => c,
        }
    }

    fn close(a: Rgb, b: [f32; 3]) {
        let a = rgb(a);
        for k in 0..3 {
            // Mitsuba sums in 32-bit floats, zerovar in 64: they differ in the last bits.
            assert!((a[k] - b[k]).abs() <= 1e-6 * b[k].abs().max(1.0), "{a:?} vs {b:?}");
        }
    }

    const REFLECTANCE: Place = Place { emitter: false, unbounded: false };
    const EMITTER: Place = Place { emitter: true, unbounded: false };

    /// Expected values: `mi.traverse` of the same properties in Mitsuba 3.9.1 `scalar_rgb`,
    /// an independent implementation (see `tools/make-cie-table.py` for the tables).
    #[test]
    fn spectra_become_what_mitsuba_makes_of_them() {
        let r = pairs(&[[400.0, 0.1], [500.0, 0.5], [600.0, 0.8], [700.0, 0.9]], REFLECTANCE);
        close(r, [0.87801546, 0.6357789, 0.27034214]);
        close(
            pairs(&[[400.0, 0.2], [700.0, 0.9]], REFLECTANCE),
            [0.7619722, 0.53347015, 0.29421127],
        );
        let e = pairs(&[[400.0, 0.0], [500.0, 0.3], [600.0, 0.8], [700.0, 1.1]], EMITTER);
        close(e, [1.1268704, 0.48819396, 0.08803434]);
        close(pairs(&[[400.0, 1.0], [700.0, 1.0]], EMITTER), [1.1996936, 0.94952035, 0.90344334]);
        close(uniform(2.0, EMITTER), [2.4095879, 1.896582, 1.8178321]);
        close(uniform(0.5, REFLECTANCE), [0.5; 3]);
        // Out of gamut: a reflectance above 1 is clamped to 1.
        close(pairs(&[[400.0, 1.5], [700.0, 1.5]], REFLECTANCE), [1.0; 3]);
    }

    /// A flat reflectance over the whole range is grey: the D65 weighting makes the white
    /// point of sRGB.
    #[test]
    fn a_flat_reflectance_is_grey() {
        let c = rgb(pairs(&[[CIE_MIN, 0.5], [CIE_MAX, 0.5]], REFLECTANCE));
        for v in c {
            assert!((v - 0.5).abs() < 2e-3, "{c:?}");
        }
    }

    #[test]
    fn places() {
        assert_eq!(Place::of("emitter", "radiance"), EMITTER);
        assert_eq!(Place::of("bsdf", "reflectance"), REFLECTANCE);
        assert!(Place::of("medium", "sigma_t").unbounded);
        assert!(!Place::of("medium", "albedo").unbounded);
    }
}
