#!/usr/bin/env python3
"""Writes src/scene/xml/cie.rs: the CIE 1931 2-degree colour matching functions and the CIE D65
illuminant (scaled as Mitsuba 3 scales it) every 5 nm from 360 to 830 nm, the tables zerovar
uses to turn a Mitsuba `<spectrum>` given as wavelength:value pairs into RGB as Mitsuba's RGB
variants do. The values are the published CIE tables; they are read from the `mitsuba` Python
package so that both renderers integrate against the same numbers.

Usage: python3 tools/make-cie-table.py > src/scene/xml/cie.rs
"""
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
lo, hi, step = 360, 830, 5
rows = []
for w in range(lo, hi + 1, step):
    x, y, z = mi.cie1931_xyz(float(w))
    d = mi.cie_d65(float(w))
    # Mitsuba holds them as 32-bit floats: printed in their shortest form.
    rows.append("    [" + ", ".join(str(np.float32(v)) for v in (x, y, z, d)) + "],")
print(f"""//! The CIE 1931 2-degree colour matching functions (x, y, z) and the CIE D65 illuminant
//! (scaled by Mitsuba's `MI_CIE_D65_NORMALIZATION`) every {step} nm from {lo} to {hi} nm, as
//! Mitsuba 3 tabulates and linearly interpolates them. Written by `tools/make-cie-table.py`.

/// The first and last wavelength of the tables, and their spacing, in nm.
pub(super) const CIE_MIN: f64 = {lo}.0;
pub(super) const CIE_MAX: f64 = {hi}.0;
pub(super) const CIE_STEP: f64 = {step}.0;
/// One over the integral of the y curve (Mitsuba's `MI_CIE_Y_NORMALIZATION`).
pub(super) const CIE_Y_NORMALIZATION: f64 = {mi.MI_CIE_Y_NORMALIZATION!r};

/// Per wavelength: x, y, z and D65.
#[rustfmt::skip]
pub(super) const CIE_TABLE: [[f32; 4]; {len(rows)}] = [""")
print("\n".join(rows))
print("];")
