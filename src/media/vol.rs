//! Mitsuba's binary `.vol` grid format: read, validate and write.
//!
//! Layout (little endian): the bytes `VOL`, version 3, an i32 encoding (1 = f32), three i32
//! resolutions (x, y, z), an i32 channel count, six f32 of a bounding box, then
//! x * y * z * channels f32 values with x varying fastest and channels interleaved. Like
//! Mitsuba 3, zerovar places a grid by the medium's `to_world` transform (the unit cube) and
//! ignores the stored box.

use std::io::Write;
use std::path::{Path, PathBuf};
use thiserror::Error;

const HEADER_BYTES: usize = 48;

/// What can be wrong with a `.vol` file. Every variant names the file and says how to fix it.
#[derive(Debug, Error)]
pub enum VolError {
    /// The file could not be read.
    #[error("{path}: cannot read the volume file: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system error.
        source: std::io::Error,
    },
    /// The header is not a version-3 float `.vol` header.
    #[error("{path}: not a Mitsuba .vol grid: {what}")]
    Header {
        /// The file.
        path: PathBuf,
        /// What was found instead.
        what: String,
    },
    /// Fewer data bytes than the header promises.
    #[error(
        "{path}: truncated: the header promises {expected} bytes of grid data but the file holds \
         {found}; re-export the grid"
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes promised.
        expected: usize,
        /// Bytes present.
        found: usize,
    },
    /// A value that no medium can hold.
    #[error("{path}: voxel ({x}, {y}, {z}) channel {channel} holds {value}: {why}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// Voxel x.
        x: usize,
        /// Voxel y.
        y: usize,
        /// Voxel z.
        z: usize,
        /// Channel.
        channel: usize,
        /// The value.
        value: f32,
        /// Why it is rejected.
        why: &'static str,
    },
}

/// A dense grid as read from a `.vol` file, or built in code with [`VolGrid::new`]: its size
/// always matches its values, and every value is finite and non-negative.
#[derive(Clone, Debug, PartialEq)]
pub struct VolGrid {
    /// Resolution along x, y, z.
    pub(crate) resolution: [usize; 3],
    /// Values per voxel.
    pub(crate) channels: usize,
    /// `resolution[0] * resolution[1] * resolution[2] * channels` values, x fastest.
    pub(crate) data: Vec<f32>,
}

impl VolGrid {
    /// A grid of `resolution` voxels with `channels` values each, from `data` (x fastest,
    /// channels interleaved), checked as a file's would be.
    pub fn new(resolution: [usize; 3], channels: usize, data: Vec<f32>) -> Result<Self, VolError> {
        let path = Path::new("<grid built in code>");
        let expected = resolution
            .iter()
            .try_fold(channels, |n, &r| n.checked_mul(r))
            .filter(|&n| n > 0)
            .ok_or_else(|| VolError::Header {
                path: path.into(),
                what: format!(
                    "resolution {resolution:?} with {channels} channels is empty or too large"
                ),
            })?;
        if data.len() != expected {
            return Err(VolError::Header {
                path: path.into(),
                what: format!(
                    "resolution {resolution:?} with {channels} channels needs {expected} values, \
                     not {}",
                    data.len()
                ),
            });
        }
        check_values(path, resolution, channels, &data)?;
        Ok(Self { resolution, channels, data })
    }

    /// Resolution along x, y, z.
    pub fn resolution(&self) -> [usize; 3] {
        self.resolution
    }

    /// Values per voxel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The values, x fastest, channels interleaved.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Reads and validates a grid: every value must be finite and non-negative, since it is a
    /// density or an albedo.
    pub fn read(path: &Path) -> Result<Self, VolError> {
        let bytes = crate::files::read(path)
            .map_err(|source| VolError::Io { path: path.into(), source })?;
        Self::parse(path, &bytes)
    }

    /// The bounding box a `.vol` file's header gives (`min`, `max`), read without the grid:
    /// where Mitsuba's `use_grid_bbox` places it.
    pub fn read_bounds(path: &Path) -> Result<[glam::Vec3; 2], VolError> {
        use std::io::Read;
        let header = |what: String| VolError::Header { path: path.into(), what };
        let mut bytes = [0u8; HEADER_BYTES];
        std::fs::File::open(path)
            .and_then(|mut f| f.read_exact(&mut bytes))
            .map_err(|source| VolError::Io { path: path.into(), source })?;
        if &bytes[..3] != b"VOL" {
            return Err(header("it does not start with the bytes 'VOL'".into()));
        }
        let float =
            |i: usize| f32::from_le_bytes(bytes[24 + 4 * i..28 + 4 * i].try_into().unwrap());
        let (lo, hi) = (
            glam::Vec3::new(float(0), float(1), float(2)),
            glam::Vec3::new(float(3), float(4), float(5)),
        );
        if !(lo.is_finite() && hi.is_finite() && lo.cmplt(hi).all()) {
            return Err(header(format!(
                "its bounding box {lo} to {hi} is not a box (use_grid_bbox needs one)"
            )));
        }
        Ok([lo, hi])
    }

    /// Parses the bytes of a `.vol` file; `path` only names it in errors.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Self, VolError> {
        let header = |what: String| VolError::Header { path: path.into(), what };
        if bytes.len() < HEADER_BYTES {
            return Err(header(format!(
                "{} bytes is shorter than the 48-byte header",
                bytes.len()
            )));
        }
        if &bytes[..3] != b"VOL" {
            return Err(header("it does not start with the bytes 'VOL'".into()));
        }
        if bytes[3] != 3 {
            return Err(header(format!("version {} (only version 3 exists)", bytes[3])));
        }
        let int = |i: usize| i32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().unwrap());
        if int(0) != 1 {
            return Err(header(format!(
                "encoding {} (only 1 = 32-bit float is supported; convert the grid)",
                int(0)
            )));
        }
        let dims = [int(1), int(2), int(3), int(4)];
        if dims.iter().any(|&d| d <= 0) {
            return Err(header(format!(
                "resolution {}x{}x{} with {} channels: all must be positive",
                dims[0], dims[1], dims[2], dims[3]
            )));
        }
        let [x, y, z, c] = dims.map(|d| d as usize);
        let count = x.checked_mul(y).and_then(|n| n.checked_mul(z)).and_then(|n| n.checked_mul(c));
        let expected = count
            .and_then(|n| n.checked_mul(4))
            .ok_or_else(|| header(format!("resolution {x}x{y}x{z}x{c} is too large to address")))?;
        let found = bytes.len() - HEADER_BYTES;
        if found < expected {
            return Err(VolError::Truncated { path: path.into(), expected, found });
        }
        let data: Vec<f32> = bytes[HEADER_BYTES..HEADER_BYTES + expected]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        check_values(path, [x, y, z], c, &data)?;
        Ok(Self { resolution: [x, y, z], channels: c, data })
    }

    /// Writes the grid as a version-3 float `.vol` file with a unit bounding box.
    pub fn write(&self, mut out: impl Write) -> std::io::Result<()> {
        out.write_all(b"VOL\x03")?;
        out.write_all(&1i32.to_le_bytes())?;
        for d in self.resolution.iter().chain(std::iter::once(&self.channels)) {
            out.write_all(&(*d as i32).to_le_bytes())?;
        }
        for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0] {
            out.write_all(&v.to_le_bytes())?;
        }
        for v in &self.data {
            out.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    }
}

/// Every value must be finite and non-negative, since it is a density or an albedo.
fn check_values(
    path: &Path,
    [x, y, _]: [usize; 3],
    c: usize,
    data: &[f32],
) -> Result<(), VolError> {
    if let Some((i, &value)) = data.iter().enumerate().find(|(_, v)| !v.is_finite() || **v < 0.0) {
        let voxel = i / c;
        return Err(VolError::BadValue {
            path: path.into(),
            x: voxel % x,
            y: voxel / x % y,
            z: voxel / (x * y),
            channel: i % c,
            value,
            why: if value.is_finite() {
                "densities and albedos cannot be negative"
            } else {
                "grids must hold finite numbers"
            },
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> VolGrid {
        VolGrid { resolution: [3, 2, 2], channels: 1, data: (0..12).map(|i| i as f32).collect() }
    }

    #[test]
    fn grids_built_in_code_are_checked_like_files() {
        assert_eq!(VolGrid::new([3, 2, 2], 1, grid().data).unwrap(), grid());
        let cases: [([usize; 3], usize, Vec<f32>, &str); 4] = [
            ([3, 2, 2], 1, vec![1.0; 11], "needs 12 values, not 11"),
            ([0, 2, 2], 1, vec![], "empty or too large"),
            ([usize::MAX, 2, 2], 1, vec![], "empty or too large"),
            ([2, 1, 1], 1, vec![1.0, -0.5], "voxel (1, 0, 0) channel 0 holds -0.5"),
        ];
        for (res, c, data, says) in cases {
            let e = VolGrid::new(res, c, data).unwrap_err().to_string();
            assert!(e.contains(says) && e.contains("<grid built in code>"), "{e}");
        }
        let e = VolGrid::new([1, 1, 1], 2, vec![0.0, f32::NAN]).unwrap_err().to_string();
        assert!(e.contains("finite"), "{e}");
    }

    fn bytes(g: &VolGrid) -> Vec<u8> {
        let mut b = Vec::new();
        g.write(&mut b).unwrap();
        b
    }

    #[test]
    fn round_trip() {
        let g = grid();
        assert_eq!(VolGrid::parse(Path::new("a.vol"), &bytes(&g)).unwrap(), g);
    }

    #[test]
    fn rejects_truncated_and_bad_values() {
        let b = bytes(&grid());
        let err = VolGrid::parse(Path::new("a.vol"), &b[..b.len() - 3]).unwrap_err();
        assert!(matches!(err, VolError::Truncated { expected: 48, found: 45, .. }), "{err}");
        let mut g = grid();
        g.data[7] = -1.0;
        let err = VolGrid::parse(Path::new("a.vol"), &bytes(&g)).unwrap_err().to_string();
        assert!(err.contains("a.vol: voxel (1, 0, 1)") && err.contains("negative"), "{err}");
        g.data[7] = f32::NAN;
        let err = VolGrid::parse(Path::new("a.vol"), &bytes(&g)).unwrap_err().to_string();
        assert!(err.contains("finite"), "{err}");
        let err = VolGrid::parse(Path::new("a.vol"), b"VOL").unwrap_err().to_string();
        assert!(err.contains("header"), "{err}");
    }

    #[test]
    fn hostile_resolutions_are_refused_before_any_voxel_is_allocated() {
        // A header claiming 10^12 voxels over 12 voxels of data, and one whose byte count
        // does not fit in memory addresses at all: errors from the header alone.
        let mut b = bytes(&grid());
        for (i, d) in [10_000i32, 10_000, 10_000, 1].into_iter().enumerate() {
            b[8 + 4 * i..12 + 4 * i].copy_from_slice(&d.to_le_bytes());
        }
        let err = VolGrid::parse(Path::new("a.vol"), &b).unwrap_err();
        assert!(
            matches!(err, VolError::Truncated { expected: 4_000_000_000_000, found: 48, .. }),
            "{err}"
        );
        b[8..24].copy_from_slice(&[i32::MAX.to_le_bytes(); 4].concat());
        let err = VolGrid::parse(Path::new("a.vol"), &b).unwrap_err().to_string();
        assert!(err.contains("too large to address"), "{err}");
    }
}
