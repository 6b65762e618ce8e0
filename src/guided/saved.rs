//! Fields saved by `zerovar train` and read by `zerovar render --field`: the guiding field
//! with the renderer's per-region direct-fluence table, which roulette and distance guiding
//! add to the field's fluence (see [`DirectFluence`]).
//!
//! The file is `ZVTRAIN\0`, a format version (u32), the field's length (u64) and the field in
//! the guiding crate's own format, then the table: a count (u32), that many f32 values, and
//! (from version 2) as many mean directions of three f32 each, then (from version 3) the
//! direct-light grid (`DirectGrid::write`), all little-endian. Version 1 files (no
//! directions: the direct light is then taken as isotropic), version 2 files (no grid: guided
//! flights then draw no extra collisions for delta lights) and bare guiding-crate fields
//! (another tool's, or an older `zerovar train`'s, without a table) are read too.

use super::{DirectFluence, DirectGrid};
use std::io::{Read, Write};
use zerovar_guiding::{Field, GuidingError};

/// The first bytes of a trained-field file.
pub const TRAINED_MAGIC: [u8; 8] = *b"ZVTRAIN\0";
/// Version of the trained-field layout.
pub const TRAINED_VERSION: u32 = 3;

/// A trained guiding field and what the renderer learned beside it.
#[derive(Clone, Debug)]
pub struct TrainedField {
    /// The guiding field.
    pub field: Field,
    /// Per region, the fluence next-event estimation collects; `None` for a bare field.
    pub direct: Option<DirectFluence>,
}

impl TrainedField {
    /// Writes the field and its table.
    pub fn save(&self, mut w: impl Write) -> Result<(), GuidingError> {
        let mut field = Vec::new();
        self.field.save(&mut field)?;
        let (values, axes) =
            self.direct.as_ref().map_or((&[][..], &[][..]), |d| (&d.values[..], &d.axes[..]));
        w.write_all(&TRAINED_MAGIC)?;
        w.write_all(&TRAINED_VERSION.to_le_bytes())?;
        w.write_all(&(field.len() as u64).to_le_bytes())?;
        w.write_all(&field)?;
        w.write_all(&(values.len() as u32).to_le_bytes())?;
        for v in values {
            w.write_all(&v.to_le_bytes())?;
        }
        for a in axes {
            for c in a.to_array() {
                w.write_all(&c.to_le_bytes())?;
            }
        }
        match &self.direct {
            Some(d) => d.grid.write(&mut w)?,
            None => DirectGrid::default().write(&mut w)?,
        }
        w.flush()?;
        Ok(())
    }

    /// Reads what [`save`](Self::save) wrote, or a bare guiding-crate field.
    pub fn load(mut r: impl Read) -> Result<Self, GuidingError> {
        let mut magic = [0u8; 8];
        r.read_exact(&mut magic).map_err(|_| GuidingError::BadMagic)?;
        if magic == zerovar_guiding::MAGIC {
            let field = Field::load(std::io::Cursor::new(magic).chain(r))?;
            return Ok(Self { field, direct: None });
        }
        if magic != TRAINED_MAGIC {
            return Err(GuidingError::BadMagic);
        }
        let found = u32::from_le_bytes(read_array(&mut r)?);
        if !(1..=TRAINED_VERSION).contains(&found) {
            return Err(GuidingError::Version { found, expected: TRAINED_VERSION });
        }
        let length = u64::from_le_bytes(read_array(&mut r)?);
        let field = Field::load((&mut r).take(length))?;
        let count = u32::from_le_bytes(read_array(&mut r)?) as usize;
        if count != 0 && count != field.regions().len() {
            return Err(GuidingError::Decode(format!(
                "the direct-fluence table has {count} entries for {} regions",
                field.regions().len()
            )));
        }
        // The count is checked against the field first, so a corrupt one allocates nothing.
        let mut values = Vec::with_capacity(count);
        for _ in 0..count {
            let v = f32::from_le_bytes(read_array(&mut r)?);
            if !(v.is_finite() && v >= 0.0) {
                return Err(GuidingError::Decode(format!("direct fluence {v} is not a fluence")));
            }
            values.push(v);
        }
        let mut axes = vec![glam::Vec3A::ZERO; if found >= 2 { count } else { 0 }];
        for a in &mut axes {
            let mut c = [0.0f32; 3];
            for x in &mut c {
                *x = f32::from_le_bytes(read_array(&mut r)?);
            }
            *a = glam::Vec3A::from_array(c);
            // A mean of unit vectors: finite, and no longer than 1 up to rounding.
            if !(a.is_finite() && a.length_squared() <= 1.0 + 1e-3) {
                return Err(GuidingError::Decode(format!(
                    "direct-light direction {c:?} is not a mean of directions"
                )));
            }
        }
        let grid = if found >= 3 { DirectGrid::read(&mut r)? } else { DirectGrid::default() };
        let direct = (count > 0).then_some(DirectFluence { values, axes, grid });
        Ok(Self { field, direct })
    }
}

fn read_array<const N: usize>(r: &mut impl Read) -> Result<[u8; N], GuidingError> {
    let mut b = [0u8; N];
    r.read_exact(&mut b).map_err(|e| GuidingError::Decode(format!("truncated: {e}")))?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guided::DirectRecord;
    use glam::Vec3A;
    use zerovar_guiding::{FieldConfig, Sample};

    fn trained() -> TrainedField {
        let mut field = Field::new(FieldConfig::default()).unwrap();
        let samples: Vec<Sample> = (0..2000)
            .map(|i| {
                let t = i as f32 * 0.01;
                Sample {
                    position: glam::Vec3::new(t.sin(), t.cos(), t * 0.1),
                    direction: glam::Vec3::Z,
                    radiance: 1.0,
                    pdf: 1.0,
                    distance: f32::INFINITY,
                    volume: true,
                }
            })
            .collect();
        field.update(&samples).unwrap();
        let records: Vec<DirectRecord> = (0..100)
            .map(|i| DirectRecord {
                position: Vec3A::splat(i as f32 * 0.01),
                fluence: 2.0,
                direction: Vec3A::new(0.6, 0.0, if i % 2 == 0 { 0.8 } else { -0.8 }),
            })
            .collect();
        let direct = DirectFluence::build(&field, &records);
        TrainedField { field, direct: Some(direct) }
    }

    #[test]
    fn a_caches_direct_light_along_a_ray_is_its_direct_light_at_each_part() {
        use crate::guided::{FieldCache, RadianceCache};
        let t = trained();
        let mut cache = FieldCache::with_direct(&t.field, t.direct.as_ref(), false);
        let (start, step, w) = (Vec3A::splat(-0.1), Vec3A::splat(0.07), Vec3A::X);
        let mut along = [f32::NAN; 16];
        cache.direct_along(start, step, w, 0.5, &mut along);
        for (j, v) in along.iter().enumerate() {
            assert_eq!(*v, cache.direct(start + (j as f32 + 0.5) * step, w, 0.5), "part {j}");
        }
        assert!(along.iter().any(|&v| v > 0.0) && along[0] == 0.0, "{along:?}");
    }

    #[test]
    fn round_trip_and_bare_fields() {
        let t = trained();
        let mut bytes = Vec::new();
        t.save(&mut bytes).unwrap();
        let back = TrainedField::load(&bytes[..]).unwrap();
        assert_eq!(back.direct.as_ref().unwrap().values, t.direct.as_ref().unwrap().values);
        assert_eq!(back.direct.as_ref().unwrap().axes, t.direct.as_ref().unwrap().axes);
        assert_eq!(back.direct.as_ref().unwrap().grid, t.direct.as_ref().unwrap().grid);
        assert!(back.direct.as_ref().unwrap().grid.fluence(Vec3A::splat(0.5)) > 0.0);
        assert_eq!(back.field.regions().len(), t.field.regions().len());
        let mut grid = Vec::new();
        t.direct.as_ref().unwrap().grid.write(&mut grid).unwrap();
        let n = bytes.len() - grid.len();
        // A version 2 file (no grid) loads without one.
        let mut v2 = bytes[..n].to_vec();
        v2[8..12].copy_from_slice(&2u32.to_le_bytes());
        let back = TrainedField::load(&v2[..]).unwrap();
        assert_eq!(back.direct.as_ref().unwrap().axes, t.direct.as_ref().unwrap().axes);
        assert_eq!(back.direct.unwrap().grid, DirectGrid::default());
        // A version 1 file (values, no directions) loads with isotropic direct light.
        let mut old = bytes[..n - 12 * t.field.regions().len()].to_vec();
        old[8..12].copy_from_slice(&1u32.to_le_bytes());
        let back = TrainedField::load(&old[..]).unwrap();
        let direct = back.direct.unwrap();
        assert_eq!(direct.values, t.direct.as_ref().unwrap().values);
        assert!((0..direct.values.len()).all(|i| direct.axis(i) == Vec3A::ZERO));
        // A bare guiding field loads without a table.
        let mut bare = Vec::new();
        t.field.save(&mut bare).unwrap();
        let back = TrainedField::load(&bare[..]).unwrap();
        assert!(back.direct.is_none());
        // Truncated, corrupt and foreign data are errors, never panics.
        for cut in [4, 12, 20, bytes.len() - 2] {
            assert!(TrainedField::load(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        // The last value, then the last direction's last component, then the grid's last cell
        // and its scale.
        let last_value = n - 12 * t.field.regions().len() - 4;
        let cells = [(last_value, "fluence"), (n - 4, "direction"), (bytes.len() - 4, "grid")];
        for (at, what) in cells.into_iter().chain([(n + 12, "grid")]) {
            let mut bad = bytes.clone();
            bad[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
            let e = TrainedField::load(&bad[..]).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        }
        // A direction longer than a mean of unit vectors can be.
        let mut bad = bytes.clone();
        bad[n - 4..n].copy_from_slice(&2.0f32.to_le_bytes());
        assert!(TrainedField::load(&bad[..]).unwrap_err().to_string().contains("direction"));
        assert!(matches!(TrainedField::load(&b"not a field"[..]), Err(GuidingError::BadMagic)));
    }
}
