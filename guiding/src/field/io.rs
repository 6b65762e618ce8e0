//! Saving and loading a field: magic bytes, a little-endian format version, then the field's
//! data encoded with postcard (serde).
//!
//! The version is checked before anything else is decoded, so a file written by another
//! version fails with `GuidingError::Version` rather than with garbage. Change
//! [`FORMAT_VERSION`] whenever a serialised struct changes.

use super::{Field, Region};
use crate::GuidingError;
use crate::config::FieldConfig;
use crate::spatial::KdTree;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};

/// The bytes every saved field starts with.
pub const MAGIC: [u8; 8] = *b"ZVGUIDE\0";

/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 3;

#[derive(Serialize, Deserialize)]
struct FieldData {
    config: FieldConfig,
    tree: KdTree,
    regions: Vec<Region>,
    iterations: u32,
    total_samples: u64,
    last_update_seconds: f64,
}

impl Field {
    /// Writes the field (magic, version, postcard data).
    pub fn save(&self, mut w: impl Write) -> Result<(), GuidingError> {
        let data = FieldData {
            config: self.config.clone(),
            tree: self.tree.clone(),
            regions: self.regions.clone(),
            iterations: self.iterations,
            total_samples: self.total_samples,
            last_update_seconds: self.last_update_seconds,
        };
        let bytes = postcard::to_stdvec(&data).map_err(|e| GuidingError::Decode(e.to_string()))?;
        w.write_all(&MAGIC)?;
        w.write_all(&FORMAT_VERSION.to_le_bytes())?;
        w.write_all(&bytes)?;
        w.flush()?;
        Ok(())
    }

    /// Reads a field written by [`save`](Self::save). Fails with `BadMagic` for other data,
    /// `Version` for another format version and `Decode` for truncated or corrupt data.
    pub fn load(mut r: impl Read) -> Result<Field, GuidingError> {
        let mut magic = [0u8; 8];
        r.read_exact(&mut magic).map_err(|_| GuidingError::BadMagic)?;
        if magic != MAGIC {
            return Err(GuidingError::BadMagic);
        }
        let mut version = [0u8; 4];
        r.read_exact(&mut version)?;
        let found = u32::from_le_bytes(version);
        if found != FORMAT_VERSION {
            return Err(GuidingError::Version { found, expected: FORMAT_VERSION });
        }
        let mut bytes = Vec::new();
        r.read_to_end(&mut bytes)?;
        let data: FieldData =
            postcard::from_bytes(&bytes).map_err(|e| GuidingError::Decode(e.to_string()))?;
        data.config.validate().map_err(|e| GuidingError::Decode(e.to_string()))?;
        data.tree.validate(data.regions.len()).map_err(GuidingError::Decode)?;
        for (i, r) in data.regions.iter().enumerate() {
            r.validate().map_err(|e| GuidingError::Decode(format!("region {i}: {e}")))?;
        }
        Ok(Field::from_parts(
            data.config,
            data.tree,
            data.regions,
            data.iterations,
            data.total_samples,
            data.last_update_seconds,
        ))
    }
}
