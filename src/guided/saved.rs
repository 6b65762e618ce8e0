//! Fields saved by `zerovar train` and read by `zerovar render --field`: the guiding field
//! with the renderer's per-region direct-fluence table, which roulette and distance guiding
//! add to the field's fluence (see [`DirectFluence`]).
//!
//! The file is `ZVTRAIN\0`, a format version (u32), the field's length (u64) and the field in
//! the guiding crate's own format, then the table: a count (u32), that many f32 values, and
//! (from version 2) as many mean directions of three f32 each, then (from version 3) the
//! direct-light grid (`DirectGrid::write`), then (from version 4) the bounds of the scene it
//! was trained on (six f32, the lower corner first), all little-endian, and nothing after.
//! Version 1 files (no directions: the direct light is then taken as isotropic), version 2
//! files (no grid: guided flights then draw no extra collisions for delta lights), version 3
//! files (no bounds: any scene takes them) and bare guiding-crate fields (another tool's, or an
//! older `zerovar train`'s, without a table) are read too.

use super::{DirectFluence, DirectGrid};
use crate::math::Aabb;
use std::io::{Read, Write};
use zerovar_guiding::{Field, GuidingError};

/// The first bytes of a trained-field file.
pub const TRAINED_MAGIC: [u8; 8] = *b"ZVTRAIN\0";
/// Version of the trained-field layout.
pub const TRAINED_VERSION: u32 = 4;

/// A trained guiding field and what the renderer learned beside it.
#[derive(Clone, Debug)]
pub struct TrainedField {
    /// The guiding field.
    pub field: Field,
    /// Per region, the fluence next-event estimation collects; `None` for a bare field.
    pub direct: Option<DirectFluence>,
    /// The bounds of the scene it was trained on (`Scene::bounds`), which a render checks;
    /// `None` for files before version 4 and bare fields.
    pub scene_bounds: Option<Aabb>,
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
        let bounds = self.scene_bounds.unwrap_or(Aabb::EMPTY);
        for c in bounds.min.to_array().into_iter().chain(bounds.max.to_array()) {
            w.write_all(&c.to_le_bytes())?;
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
            return Ok(Self { field, direct: None, scene_bounds: None });
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
        let scene_bounds = if found >= 4 {
            let mut c = [0.0f32; 6];
            for x in &mut c {
                *x = f32::from_le_bytes(read_array(&mut r)?);
            }
            let b = Aabb {
                min: glam::Vec3A::from_slice(&c[..3]),
                max: glam::Vec3A::from_slice(&c[3..]),
            };
            // The empty box (no shapes) holds infinities; anything else must be finite.
            let a_box = b.min.is_finite() && b.max.is_finite() && b.min.cmple(b.max).all();
            if !(a_box || b == Aabb::EMPTY) {
                return Err(GuidingError::Decode(format!("scene bounds {c:?} are not a box")));
            }
            Some(b)
        } else {
            None
        };
        // A file that goes on (another version's layout under this number, or appended data)
        // is not what it claims to be.
        let mut rest = [0u8; 1];
        if r.read(&mut rest).is_ok_and(|n| n > 0) {
            return Err(GuidingError::Decode(format!(
                "data after the end of a version {found} field: the file is corrupt, or its version was altered"
            )));
        }
        Ok(Self { field, direct, scene_bounds })
    }

    /// Whether the field was trained on a scene with `bounds` (within rounding), or does not
    /// know its scene.
    pub fn fits(&self, bounds: &Aabb) -> bool {
        let Some(trained) = self.scene_bounds else { return true };
        if trained.is_empty() || bounds.is_empty() {
            return trained.is_empty() == bounds.is_empty();
        }
        let extent = (trained.max - trained.min).max(bounds.max - bounds.min).max_element();
        let tolerance = 1e-4 * extent.max(1e-6);
        (trained.min - bounds.min).abs().max_element() <= tolerance
            && (trained.max - bounds.max).abs().max_element() <= tolerance
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
        let scene_bounds = Some(Aabb::from_points(Vec3A::splat(-1.0), Vec3A::new(1.0, 2.0, 3.0)));
        TrainedField { field, direct: Some(direct), scene_bounds }
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
        assert_eq!(back.scene_bounds, t.scene_bounds);
        let mut grid = Vec::new();
        t.direct.as_ref().unwrap().grid.write(&mut grid).unwrap();
        // The grid, then the bounds.
        let n = bytes.len() - grid.len() - 24;
        // A version 3 file (no bounds) loads, fitting any scene.
        let mut v3 = bytes[..bytes.len() - 24].to_vec();
        v3[8..12].copy_from_slice(&3u32.to_le_bytes());
        let back = TrainedField::load(&v3[..]).unwrap();
        assert!(back.scene_bounds.is_none() && back.fits(&Aabb::EMPTY));
        // Relabelled to an older version, or with data appended, a file is refused.
        let mut relabelled = bytes.clone();
        relabelled[8..12].copy_from_slice(&3u32.to_le_bytes());
        let e = TrainedField::load(&relabelled[..]).unwrap_err().to_string();
        assert!(e.contains("after the end"), "{e}");
        let mut appended = bytes.clone();
        appended.push(0);
        assert!(TrainedField::load(&appended[..]).is_err());
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
        let cells = [
            (last_value, "fluence"),
            (n - 4, "direction"),
            (bytes.len() - 28, "grid"),
            (bytes.len() - 4, "bounds"),
        ];
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

    #[test]
    fn a_field_fits_the_scene_it_was_trained_on_only() {
        let t = trained();
        let own = t.scene_bounds.unwrap();
        assert!(t.fits(&own));
        let nudged = Aabb { max: own.max + Vec3A::splat(1e-6), ..own };
        assert!(t.fits(&nudged), "rounding is not another scene");
        let other = Aabb { max: own.max * 2.0, ..own };
        assert!(!t.fits(&other));
        assert!(!t.fits(&Aabb::EMPTY));
    }
}
