//! OpenVDB `.vdb` float grids, read without the OpenVDB library and turned into a dense grid.
//!
//! Supported: file format versions 222 to 224 (everything OpenVDB 3 to 12 writes), trees of
//! type `Tree_float_5_4_3` (also saved as half floats), data uncompressed, zip-compressed or
//! blosc-compressed with the lz4 or zlib codec (OpenVDB's default is blosc + lz4), with or
//! without active-mask compression, and scale, translate and affine index-to-world maps. The
//! active voxels and active tiles of the chosen grid, within their index bounding box grown by
//! one voxel on every side, become a dense grid; every other voxel of the box holds the
//! background value, so trilinear lookups fade to the background at the box's faces as
//! OpenVDB's own trilinear sampler does at the edge of the active voxels. The dense box is
//! checked against `MAX_DENSE_VOXELS` before anything of its size is allocated, and every
//! length read from the file is checked against the bytes that remain before it is used, so a
//! hostile file costs at most a small multiple of its own size in memory.
//!
//! Placement: OpenVDB puts voxel `ijk`'s centre at `index_to_world(ijk)`. The dense box spans
//! index space `[min - 1/2, max + 1/2]`, which `cube_to_world` maps from our unit cube, so the
//! cell-centred voxels of `Grid` land exactly on OpenVDB's voxel centres.
//!
//! The reader is our own rather than the `vdb-rs` crate: that crate panics on malformed input
//! (`todo!`, `assert!`, `unwrap`), allocates whatever sizes the file states, passes untrusted
//! buffers to the blosc C library, and pulls in a second `glam` and a C build.

use glam::{DAffine3, DMat3, DVec3};
use std::io::Read;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The most voxels a `.vdb` grid may expand to (a 512^3 box, 512 MiB of densities).
pub const MAX_DENSE_VOXELS: u64 = 1 << 27;

const MAGIC: u64 = 0x5644_4220;
/// Per-node compression flags and per-grid metadata bytes, introduced with version 222.
const MIN_VERSION: u32 = 222;
const MAX_VERSION: u32 = 224;
const COMPRESS_ZIP: u32 = 0x1;
const COMPRESS_ACTIVE_MASK: u32 = 0x2;
const COMPRESS_BLOSC: u32 = 0x4;
const FLOAT_TREE: &str = "Tree_float_5_4_3";
const HALF_SUFFIX: &str = "_HalfFloat";

/// What can be wrong with a `.vdb` file. Every variant names the file and says how to fix it.
#[derive(Debug, Error)]
pub enum VdbError {
    /// The file could not be read.
    #[error("{path}: cannot read the VDB file: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system error.
        source: std::io::Error,
    },
    /// The file does not start like an OpenVDB file.
    #[error("{path}: not an OpenVDB file: {what}")]
    NotVdb {
        /// The file.
        path: PathBuf,
        /// What was found instead.
        what: String,
    },
    /// The file ends inside a structure.
    #[error(
        "{path}: truncated: {what} at byte {at} needs {need} bytes but only {left} remain; \
         re-export the file"
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The structure being read.
        what: &'static str,
        /// Its byte offset.
        at: usize,
        /// Bytes it needs.
        need: u64,
        /// Bytes left in the file.
        left: usize,
    },
    /// An offset points past the end of the file.
    #[error(
        "{path}: truncated: {what} starts at byte {pos} of a {len}-byte file; re-export the file"
    )]
    TruncatedAt {
        /// The file.
        path: PathBuf,
        /// The structure the offset locates.
        what: &'static str,
        /// The offset.
        pos: u64,
        /// The file's length.
        len: usize,
    },
    /// The structure is inconsistent.
    #[error("{path}: corrupt VDB file: {what}; re-export the file")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is inconsistent.
        what: String,
    },
    /// A valid OpenVDB feature zerovar does not read.
    #[error("{path}: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The feature and the way around it.
        what: String,
    },
    /// No grid of the requested name, or no obvious default.
    #[error("{path}: {what}")]
    NoGrid {
        /// The file.
        path: PathBuf,
        /// What was asked for and what the file holds.
        what: String,
    },
    /// The grid's active box expands to too many voxels.
    #[error(
        "{path}: grid `{name}`: its active voxels span index box {min:?} to {max:?}, {voxels} \
         voxels with a border of one, more than zerovar's limit of {limit}; crop or resample \
         the grid"
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The grid.
        name: String,
        /// Smallest active index.
        min: [i64; 3],
        /// Largest active index.
        max: [i64; 3],
        /// Voxels of the dense box (the active box and a border of one voxel).
        voxels: u128,
        /// `MAX_DENSE_VOXELS`.
        limit: u64,
    },
    /// A value no density can take.
    #[error("{path}: grid `{name}`: {place} holds {value}: {why}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// The grid.
        name: String,
        /// The voxel or the background.
        place: String,
        /// The value.
        value: f32,
        /// Why it is rejected.
        why: &'static str,
    },
}

/// A float grid of a `.vdb` file expanded to its active index box.
#[derive(Clone, Debug, PartialEq)]
pub struct VdbGrid {
    /// The grid's name in the file.
    pub name: String,
    /// Index of the box's first voxel.
    pub index_min: [i32; 3],
    /// Voxels along x, y, z.
    pub resolution: [usize; 3],
    /// One value per voxel, x fastest (as in `VolGrid`).
    pub data: Vec<f32>,
    /// OpenVDB's map from index space (voxel centres at integers) to its world space.
    pub index_to_world: DAffine3,
}

impl VdbGrid {
    /// Reads the grid named `name`, or by default the grid `density` or else the file's only
    /// float grid.
    pub fn read(path: &Path, name: Option<&str>) -> Result<Self> {
        let bytes = crate::files::read(path)
            .map_err(|source| VdbError::Io { path: path.into(), source })?;
        Self::parse(path, &bytes, name)
    }

    /// Parses the bytes of a `.vdb` file; `path` only names it in errors.
    pub fn parse(path: &Path, bytes: &[u8], name: Option<&str>) -> Result<Self> {
        Reader { path, b: bytes, pos: 0, version: 0, tile_voxels: 0 }.grid(name)
    }

    /// The affine map from zerovar's unit cube to OpenVDB's world space: the cube's faces lie
    /// half a voxel outside the outermost voxel centres.
    pub fn cube_to_world(&self) -> DAffine3 {
        let res = DVec3::from_array(self.resolution.map(|r| r as f64));
        let min = DVec3::from_array(self.index_min.map(f64::from)) - 0.5;
        self.index_to_world
            * DAffine3::from_scale_rotation_translation(res, Default::default(), min)
    }

    /// The value at index `ijk`, or `None` outside the box.
    pub fn value(&self, ijk: [i32; 3]) -> Option<f32> {
        let mut at = [0usize; 3];
        for a in 0..3 {
            let d = i64::from(ijk[a]) - i64::from(self.index_min[a]);
            if d < 0 || d as usize >= self.resolution[a] {
                return None;
            }
            at[a] = d as usize;
        }
        Some(self.data[(at[2] * self.resolution[1] + at[1]) * self.resolution[0] + at[0]])
    }
}

/// A grid descriptor: where a grid's parts lie in the file.
struct Descriptor {
    name: String,
    kind: String,
    instance_of: String,
    grid_pos: u64,
    block_pos: u64,
}

/// An active constant region: a tile of an internal or root node.
struct Tile {
    origin: [i64; 3],
    size: i64,
    value: f32,
}

/// A leaf's origin and active mask, from the topology.
struct Leaf {
    origin: [i64; 3],
    mask: [u64; 8],
}

/// A grid's dense box of voxels being filled: the background, then tiles, then leaves, each
/// value checked.
struct Dense<'a> {
    name: &'a str,
    path: &'a Path,
    min: [i64; 3],
    res: [usize; 3],
    data: Vec<f32>,
}

impl Dense<'_> {
    fn index(&self, p: [i64; 3]) -> usize {
        let d = [0, 1, 2].map(|a| (p[a] - self.min[a]) as usize);
        (d[2] * self.res[1] + d[1]) * self.res[0] + d[0]
    }

    fn bad(&self, place: String, value: f32) -> VdbError {
        VdbError::BadValue {
            path: self.path.into(),
            name: self.name.to_string(),
            place,
            value,
            why: if value.is_finite() {
                "densities cannot be negative"
            } else {
                "grids must hold finite numbers"
            },
        }
    }

    /// The box filled with the background, then the active tiles.
    fn fill(&mut self, background: f32, tiles: &[Tile]) -> Result<()> {
        if !(background.is_finite() && background >= 0.0) {
            return Err(self.bad("the background".into(), background));
        }
        self.data = vec![background; self.res.iter().product()];
        for t in tiles {
            if !(t.value.is_finite() && t.value >= 0.0) {
                return Err(self.bad(format!("the tile at index {:?}", t.origin), t.value));
            }
            for z in 0..t.size {
                for y in 0..t.size {
                    let row = self.index([t.origin[0], t.origin[1] + y, t.origin[2] + z]);
                    self.data[row..row + t.size as usize].fill(t.value);
                }
            }
        }
        Ok(())
    }

    /// A leaf's active voxels (`values` in the leaf's order, z fastest).
    fn leaf(&mut self, leaf: &Leaf, mask: &[u64; 8], values: &[f32]) -> Result<()> {
        for (i, v) in values.iter().enumerate() {
            if mask[i / 64] >> (i % 64) & 1 == 1 {
                let p = [i >> 6, (i >> 3) & 7, i & 7];
                let p = [0, 1, 2].map(|a| leaf.origin[a] + p[a] as i64);
                if !(v.is_finite() && *v >= 0.0) {
                    return Err(self.bad(format!("voxel {p:?}"), *v));
                }
                let at = self.index(p);
                self.data[at] = *v;
            }
        }
        Ok(())
    }
}

/// The grid's compression and value encoding.
#[derive(Clone, Copy)]
struct Coding {
    flags: u32,
    half: bool,
}

struct Reader<'a> {
    path: &'a Path,
    b: &'a [u8],
    pos: usize,
    version: u32,
    /// Voxels covered by the active tiles so far: tiles never overlap, so past
    /// `MAX_DENSE_VOXELS` the box is too large, and a file cannot list tiles without bound.
    tile_voxels: u64,
}

type Result<T> = std::result::Result<T, VdbError>;

impl<'a> Reader<'a> {
    fn corrupt<T>(&self, what: impl Into<String>) -> Result<T> {
        Err(VdbError::Corrupt { path: self.path.into(), what: what.into() })
    }

    fn unsupported<T>(&self, what: impl Into<String>) -> Result<T> {
        Err(VdbError::Unsupported { path: self.path.into(), what: what.into() })
    }

    /// The next `n` bytes, refused before anything of size `n` exists if the file is shorter.
    fn take(&mut self, n: u64, what: &'static str) -> Result<&'a [u8]> {
        let left = self.b.len() - self.pos;
        if n > left as u64 {
            return Err(VdbError::Truncated {
                path: self.path.into(),
                what,
                at: self.pos,
                need: n,
                left,
            });
        }
        let s = &self.b[self.pos..self.pos + n as usize];
        self.pos += n as usize;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N]> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N as u64, what)?);
        Ok(a)
    }

    fn u8(&mut self, what: &'static str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }

    fn u32(&mut self, what: &'static str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    fn i32(&mut self, what: &'static str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    fn u64(&mut self, what: &'static str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    fn f32(&mut self, what: &'static str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }

    fn f64(&mut self, what: &'static str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    fn vec3d(&mut self, what: &'static str) -> Result<DVec3> {
        Ok(DVec3::new(self.f64(what)?, self.f64(what)?, self.f64(what)?))
    }

    fn coord(&mut self, what: &'static str) -> Result<[i64; 3]> {
        Ok([self.i32(what)?.into(), self.i32(what)?.into(), self.i32(what)?.into()])
    }

    /// A length-prefixed string (names are ASCII; anything else is shown lossily).
    fn string(&mut self, what: &'static str) -> Result<String> {
        let n = self.u32(what)?;
        Ok(String::from_utf8_lossy(self.take(n.into(), what)?).into_owned())
    }

    fn mask<const W: usize>(&mut self, what: &'static str) -> Result<[u64; W]> {
        let mut m = [0u64; W];
        let bytes = self.take(8 * W as u64, what)?;
        for (w, b) in m.iter_mut().zip(bytes.chunks_exact(8)) {
            *w = u64::from_le_bytes(b.try_into().unwrap_or_default());
        }
        Ok(m)
    }

    fn seek(&mut self, pos: u64, what: &'static str) -> Result<()> {
        if pos > self.b.len() as u64 {
            return Err(VdbError::TruncatedAt {
                path: self.path.into(),
                what,
                pos,
                len: self.b.len(),
            });
        }
        self.pos = pos as usize;
        Ok(())
    }

    /// Skips a metadata table: every entry carries its own byte count.
    fn skip_metadata(&mut self) -> Result<()> {
        let count = self.u32("metadata count")?;
        for _ in 0..count {
            self.string("metadata name")?;
            self.string("metadata type")?;
            let n = self.u32("metadata size")?;
            self.take(n.into(), "metadata value")?;
        }
        Ok(())
    }

    fn grid(mut self, wanted: Option<&str>) -> Result<VdbGrid> {
        self.header()?;
        let grids = self.descriptors()?;
        let d = self.choose(&grids, wanted)?;
        if !d.instance_of.is_empty() {
            return self.unsupported(format!(
                "grid `{}` is an instance of `{}`; re-save the file without instancing",
                d.name, d.instance_of
            ));
        }
        let half = d.kind.ends_with(HALF_SUFFIX);
        self.seek(d.grid_pos, "the grid")?;
        let flags = self.u32("grid compression")?;
        if flags & !(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC) != 0 {
            return self.corrupt(format!("unknown compression flags {flags:#x}"));
        }
        let coding = Coding { flags, half };
        self.skip_metadata()?;
        let index_to_world = self.transform()?;
        let (background, tiles, leaves) = self.topology(coding)?;
        let name = d.name.clone();
        let (min, res) = self.active_box(&name, &tiles, &leaves)?;
        let mut dense = Dense { name: &name, path: self.path, min, res, data: Vec::new() };
        dense.fill(background, &tiles)?;
        self.seek(d.block_pos, "the grid's voxel data")?;
        for leaf in &leaves {
            let mask = self.mask::<8>("leaf mask")?;
            if mask != leaf.mask {
                return self.corrupt(format!(
                    "the leaf at index {:?} has different active voxels in its topology and its \
                     data",
                    leaf.origin
                ));
            }
            let values = self.values(coding, 512, &mask)?;
            dense.leaf(leaf, &mask, &values)?;
        }
        let data = dense.data;
        Ok(VdbGrid {
            name,
            // The box fits in i32: it lies within the file's i32 coordinates.
            index_min: min.map(|m| m as i32),
            resolution: res,
            data,
            index_to_world,
        })
    }

    /// The file header: magic number, format version (checked), library version, the
    /// offsets flag, the file's UUID and its metadata.
    fn header(&mut self) -> Result<()> {
        let magic = self.take(8, "header").map_err(|_| VdbError::NotVdb {
            path: self.path.into(),
            what: format!("{} bytes is too short for the header", self.b.len()),
        })?;
        if u64::from_le_bytes(magic.try_into().unwrap_or_default()) != MAGIC {
            return Err(VdbError::NotVdb {
                path: self.path.into(),
                what: "it does not start with OpenVDB's magic number".into(),
            });
        }
        self.version = self.u32("file version")?;
        if self.version < MIN_VERSION {
            return self.unsupported(format!(
                "file format version {} predates version {MIN_VERSION} (OpenVDB 2.0); re-save the \
                 file with a current OpenVDB",
                self.version
            ));
        }
        if self.version > MAX_VERSION {
            return self.unsupported(format!(
                "file format version {} is newer than zerovar reads (up to {MAX_VERSION})",
                self.version
            ));
        }
        self.take(8, "library version")?;
        if self.u8("grid offsets flag")? != 1 {
            return self.unsupported("grids without offsets are not supported; re-save the file");
        }
        self.take(36, "file UUID")?;
        self.skip_metadata()
    }

    /// The file's grid descriptors, each with its offsets checked.
    fn descriptors(&mut self) -> Result<Vec<Descriptor>> {
        let count = self.i32("grid count")?;
        let mut grids = Vec::new();
        for _ in 0..count.max(0) {
            let name = self.string("grid name")?;
            // Duplicate names carry a suffix after the record separator.
            let name = name.split('\u{1e}').next().unwrap_or_default().to_string();
            let kind = self.string("grid type")?;
            let instance_of = self.string("grid instance parent")?;
            let (grid_pos, block_pos, end_pos) =
                (self.u64("grid offset")?, self.u64("block offset")?, self.u64("end offset")?);
            if !(self.pos as u64 <= grid_pos && grid_pos <= block_pos && block_pos <= end_pos) {
                return self.corrupt(format!(
                    "grid `{name}` has offsets {grid_pos}, {block_pos}, {end_pos} out of order"
                ));
            }
            grids.push(Descriptor { name, kind, instance_of, grid_pos, block_pos });
            self.seek(end_pos, "the next grid")?;
        }
        Ok(grids)
    }

    /// The grid asked for, else `density`, else the only float grid.
    fn choose<'g>(&self, grids: &'g [Descriptor], wanted: Option<&str>) -> Result<&'g Descriptor> {
        let is_float =
            |d: &Descriptor| d.kind == FLOAT_TREE || d.kind == FLOAT_TREE.to_string() + HALF_SUFFIX;
        let floats: Vec<&str> =
            grids.iter().filter(|d| is_float(d)).map(|d| d.name.as_str()).collect();
        let list = |names: &[&str]| {
            if names.is_empty() { "none".to_string() } else { format!("`{}`", names.join("`, `")) }
        };
        let no_grid = |what: String| VdbError::NoGrid { path: self.path.into(), what };
        let found = match wanted {
            Some(w) => grids.iter().find(|d| d.name == w).ok_or_else(|| {
                no_grid(format!(
                    "has no grid named `{w}`; its float grids: {}; choose one with grid_name",
                    list(&floats)
                ))
            })?,
            None => match grids.iter().find(|d| d.name == "density") {
                Some(d) => d,
                None => match floats.as_slice() {
                    [only] => grids
                        .iter()
                        .find(|d| d.name == *only)
                        .ok_or_else(|| no_grid("lost its only float grid".into()))?,
                    names => {
                        return Err(no_grid(format!(
                            "has no grid named `density` and {} float grids ({}); choose one \
                             with grid_name",
                            names.len(),
                            list(names)
                        )));
                    }
                },
            },
        };
        if !is_float(found) {
            return self.unsupported(format!(
                "grid `{}` is of type {}; zerovar reads float grids ({FLOAT_TREE}); its float \
                 grids: {}",
                found.name,
                found.kind,
                list(&floats)
            ));
        }
        Ok(found)
    }

    /// OpenVDB's index-to-world map: scale, translation or a full affine matrix.
    fn transform(&mut self) -> Result<DAffine3> {
        let kind = self.string("transform type")?;
        let t = match kind.as_str() {
            "UniformScaleMap" | "ScaleMap" => {
                let scale = self.vec3d("transform")?;
                // Voxel size, inverse scale, inverse square scale, inverse twice scale.
                self.take(4 * 24, "transform")?;
                DAffine3::from_scale(scale)
            }
            "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
                let translation = self.vec3d("transform")?;
                let scale = self.vec3d("transform")?;
                self.take(4 * 24, "transform")?;
                DAffine3 { matrix3: DMat3::from_diagonal(scale), translation }
            }
            "TranslationMap" => DAffine3::from_translation(self.vec3d("transform")?),
            "AffineMap" => {
                // Row-major with row vectors: the first three rows are the images of the axes.
                let rows: Vec<DVec3> = (0..4)
                    .map(|_| -> Result<DVec3> {
                        let r = self.vec3d("transform")?;
                        self.f64("transform")?;
                        Ok(r)
                    })
                    .collect::<Result<_>>()?;
                DAffine3 {
                    matrix3: DMat3::from_cols(rows[0], rows[1], rows[2]),
                    translation: rows[3],
                }
            }
            other => {
                return self.unsupported(format!(
                    "the grid's transform `{other}` is not supported (zerovar reads scale, \
                     translation and affine maps, not frustums); resample the grid"
                ));
            }
        };
        let det = t.matrix3.determinant();
        if !(t.matrix3.is_finite() && t.translation.is_finite() && det.abs() > 1e-300) {
            return self
                .corrupt(format!("the {kind} index-to-world transform is singular or not finite"));
        }
        Ok(t)
    }

    /// The tree's shape: background, active tiles and leaves with their active masks.
    fn topology(&mut self, coding: Coding) -> Result<(f32, Vec<Tile>, Vec<Leaf>)> {
        if self.u32("buffer count")? != 1 {
            return self.corrupt("the tree must have exactly one buffer");
        }
        let background = self.f32("background")?;
        let tile_count = self.u32("root tile count")?;
        let child_count = self.u32("root child count")?;
        let (mut tiles, mut leaves) = (Vec::new(), Vec::new());
        for _ in 0..tile_count {
            let origin = self.coord("root tile")?;
            let value = self.f32("root tile")?;
            if self.u8("root tile")? != 0 {
                self.push_tile(&mut tiles, Tile { origin, size: 1 << 12, value })?;
            }
        }
        for _ in 0..child_count {
            let origin = self.coord("root child origin")?;
            self.internal(coding, origin, 5, &mut tiles, &mut leaves)?;
        }
        Ok((background, tiles, leaves))
    }

    /// An internal node of `2^(3 log2)` slots: masks, tile values, then children in slot order.
    fn internal(
        &mut self,
        coding: Coding,
        origin: [i64; 3],
        log2: u32,
        tiles: &mut Vec<Tile>,
        leaves: &mut Vec<Leaf>,
    ) -> Result<()> {
        // A slot spans a 16^3 child of 8^3 leaves under a root child, or one leaf.
        let child_log2 = if log2 == 5 { 7 } else { 3 };
        let (children, active) = if log2 == 5 {
            (self.mask::<512>("node mask")?.to_vec(), self.mask::<512>("node mask")?.to_vec())
        } else {
            (self.mask::<64>("node mask")?.to_vec(), self.mask::<64>("node mask")?.to_vec())
        };
        let slots = 1usize << (3 * log2);
        let values = self.values(coding, slots, &active)?;
        let slot_origin = |i: usize| {
            let l = [i >> (2 * log2), (i >> log2) & ((1 << log2) - 1), i & ((1 << log2) - 1)];
            [0, 1, 2].map(|a| origin[a] + ((l[a] as i64) << child_log2))
        };
        let on = |m: &[u64], i: usize| m[i / 64] >> (i % 64) & 1 == 1;
        for (i, v) in values.iter().enumerate() {
            if on(&active, i) && !on(&children, i) {
                let tile = Tile { origin: slot_origin(i), size: 1 << child_log2, value: *v };
                self.push_tile(tiles, tile)?;
            }
        }
        for i in (0..slots).filter(|&i| on(&children, i)) {
            if log2 == 5 {
                self.internal(coding, slot_origin(i), 4, tiles, leaves)?;
            } else {
                leaves.push(Leaf { origin: slot_origin(i), mask: self.mask("leaf mask")? });
            }
        }
        Ok(())
    }

    fn push_tile(&mut self, tiles: &mut Vec<Tile>, tile: Tile) -> Result<()> {
        self.tile_voxels = self.tile_voxels.saturating_add((tile.size as u64).pow(3));
        if self.tile_voxels > MAX_DENSE_VOXELS {
            return self.unsupported(format!(
                "the grid's active tiles cover more than {MAX_DENSE_VOXELS} voxels, zerovar's \
                 limit; crop or resample the grid"
            ));
        }
        tiles.push(tile);
        Ok(())
    }

    /// The index box of every active voxel and tile, checked against `MAX_DENSE_VOXELS`.
    fn active_box(
        &self,
        name: &str,
        tiles: &[Tile],
        leaves: &[Leaf],
    ) -> Result<([i64; 3], [usize; 3])> {
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        let mut grow = |a: [i64; 3], b: [i64; 3]| {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        };
        for t in tiles {
            grow(t.origin, t.origin.map(|o| o + t.size - 1));
        }
        for leaf in leaves {
            for (w, &bits) in leaf.mask.iter().enumerate() {
                let mut bits = bits;
                while bits != 0 {
                    let i = 64 * w + bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let p = [i >> 6, (i >> 3) & 7, i & 7];
                    let p = [0, 1, 2].map(|a| leaf.origin[a] + p[a] as i64);
                    grow(p, p);
                }
            }
        }
        if lo[0] > hi[0] {
            return Err(VdbError::NoGrid {
                path: self.path.into(),
                what: format!("grid `{name}` has no active voxels"),
            });
        }
        // One voxel of background on every side, so that interpolation fades to the
        // background across the outermost half voxel, as OpenVDB's trilinear sampler does.
        let dims = [0, 1, 2].map(|a| (hi[a] - lo[a] + 3) as u128);
        let voxels = dims[0] * dims[1] * dims[2];
        let outside_i32 = (0..3).any(|a| lo[a] <= i32::MIN.into() || hi[a] >= i32::MAX.into());
        if voxels > MAX_DENSE_VOXELS.into() || outside_i32 {
            return Err(VdbError::TooLarge {
                path: self.path.into(),
                name: name.into(),
                min: lo,
                max: hi,
                voxels,
                limit: MAX_DENSE_VOXELS,
            });
        }
        Ok((lo.map(|l| l - 1), dims.map(|d| d as usize)))
    }

    /// `count` values of a node (OpenVDB's `readCompressedValues`): per-node metadata, then the
    /// active values only (with active-mask compression) or all of them. Inactive slots come
    /// back as zero: zerovar gives them the background.
    fn values(&mut self, coding: Coding, count: usize, active: &[u64]) -> Result<Vec<f32>> {
        let meta = self.u8("node metadata")?;
        if meta > 6 {
            return self.corrupt(format!("node metadata {meta} (0 to 6 exist)"));
        }
        // Metadata 2, 4, 5 store one or two inactive values; 3, 4, 5 a selection mask.
        if matches!(meta, 2 | 4 | 5) {
            self.take(4, "inactive value")?;
        }
        if meta == 5 {
            self.take(4, "inactive value")?;
        }
        if matches!(meta, 3..=5) {
            self.take(count as u64 / 8, "selection mask")?;
        }
        let on = |i: usize| active[i / 64] >> (i % 64) & 1 == 1;
        let stored = if coding.flags & COMPRESS_ACTIVE_MASK != 0 && meta != 6 {
            (0..count).filter(|&i| on(i)).count()
        } else {
            count
        };
        let size = if coding.half { 2 } else { 4 };
        // OpenVDB's half writer stores nothing at all for no values; the float one still
        // writes a (compressed) empty block.
        let bytes = if coding.half && stored == 0 {
            Vec::new()
        } else {
            self.data(coding.flags, stored * size)?
        };
        let decoded: Vec<f32> = if coding.half {
            bytes.chunks_exact(2).map(|b| half_to_f32(u16::from_le_bytes([b[0], b[1]]))).collect()
        } else {
            bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        if stored == count {
            return Ok(decoded);
        }
        let mut out = vec![0.0; count];
        let mut next = decoded.into_iter();
        for (i, slot) in out.iter_mut().enumerate() {
            if on(i) {
                *slot = next.next().unwrap_or_default();
            }
        }
        Ok(out)
    }

    /// `n` bytes of node data, decompressed as the grid's flags say.
    fn data(&mut self, flags: u32, n: usize) -> Result<Vec<u8>> {
        if flags & (COMPRESS_BLOSC | COMPRESS_ZIP) == 0 {
            return Ok(self.take(n as u64, "node values")?.to_vec());
        }
        let stored = i64::from_le_bytes(self.array("compressed size")?);
        if stored <= 0 {
            // A non-positive size marks data stored uncompressed.
            let raw = self.take(stored.unsigned_abs(), "node values")?;
            if raw.len() != n {
                return self
                    .corrupt(format!("{} bytes of node values where {n} belong", raw.len()));
            }
            return Ok(raw.to_vec());
        }
        let packed = self.take(stored as u64, "compressed node values")?;
        let out = if flags & COMPRESS_BLOSC != 0 { blosc(packed, n) } else { zlib(packed, n) };
        match out {
            Ok(v) => Ok(v),
            Err(why) => self.corrupt(why),
        }
    }
}

/// Inflates a zlib stream to exactly `n` bytes.
fn zlib(packed: &[u8], n: usize) -> std::result::Result<Vec<u8>, String> {
    let mut out = vec![0; n];
    flate2::read::ZlibDecoder::new(packed)
        .read_exact(&mut out)
        .map_err(|e| format!("zip data does not inflate to {n} bytes: {e}"))?;
    Ok(out)
}

/// Decodes a blosc 1 buffer of `n` bytes: a 16-byte header, block offsets, then blocks, each
/// optionally split into one stream per byte of a value and byte-shuffled.
fn blosc(buf: &[u8], n: usize) -> std::result::Result<Vec<u8>, String> {
    let bad = |what: &str| Err(format!("blosc data: {what}"));
    if buf.len() < 16 {
        return bad("shorter than its 16-byte header");
    }
    let word = |i: usize| u32::from_le_bytes([buf[i], buf[i + 1], buf[i + 2], buf[i + 3]]) as usize;
    let (flags, typesize) = (buf[2], usize::from(buf[3]));
    let (nbytes, blocksize, cbytes) = (word(4), word(8), word(12));
    if nbytes != n || cbytes > buf.len() {
        return bad(&format!("holds {nbytes} bytes in {cbytes} where {n} in {} belong", buf.len()));
    }
    if flags & 0x2 != 0 {
        // Stored without compression.
        return match buf.get(16..16 + n) {
            Some(raw) => Ok(raw.to_vec()),
            None => bad("shorter than its stored bytes"),
        };
    }
    if flags & 0x4 != 0 {
        return Err("blosc bit-shuffling is not supported; re-save with OpenVDB's defaults".into());
    }
    let codec = flags >> 5;
    if codec != 1 && codec != 3 {
        let name = ["blosclz", "lz4", "snappy", "zlib", "zstd"].get(usize::from(codec));
        return Err(format!(
            "blosc codec {} is not supported (lz4 and zlib are); re-save with OpenVDB's defaults",
            name.unwrap_or(&"unknown")
        ));
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    if blocksize == 0 || typesize == 0 {
        return bad("zero block or type size");
    }
    let blocks = n.div_ceil(blocksize);
    if 16 + 4 * blocks > buf.len() {
        return bad("block offsets run past the end");
    }
    let mut out = vec![0u8; n];
    let mut block = vec![0u8; blocksize.min(n)];
    for b in 0..blocks {
        let bsize = blocksize.min(n - b * blocksize);
        let leftover = bsize < blocksize;
        // Newer blosc flags unsplit blocks (0x10); older ones split by this same rule.
        let split = flags & 0x10 == 0 && typesize <= 16 && blocksize / typesize >= 128 && !leftover;
        let streams = if split { typesize } else { 1 };
        if bsize % streams != 0 {
            return bad("a block is not a whole number of values");
        }
        let stream_len = bsize / streams;
        let mut pos = word(16 + 4 * b);
        for s in 0..streams {
            let Some(len) = buf.get(pos..pos + 4) else { return bad("a stream runs past the end") };
            let len = i32::from_le_bytes([len[0], len[1], len[2], len[3]]);
            pos += 4;
            let Some(src) = usize::try_from(len).ok().and_then(|l| buf.get(pos..pos + l)) else {
                return bad("a stream runs past the end");
            };
            pos += src.len();
            let dst = &mut block[s * stream_len..(s + 1) * stream_len];
            if src.len() == stream_len {
                dst.copy_from_slice(src);
            } else if codec == 1 {
                if lz4(src, dst).is_err() {
                    return bad("an lz4 stream is corrupt");
                }
            } else {
                let inflated = zlib(src, stream_len)?;
                dst.copy_from_slice(&inflated);
            }
        }
        let dst = &mut out[b * blocksize..b * blocksize + bsize];
        if flags & 0x1 != 0 && typesize > 1 {
            // Byte shuffle: byte j of every value, then byte j + 1; a tail of less than one
            // value is stored as is.
            let values = bsize / typesize;
            for i in 0..values {
                for j in 0..typesize {
                    dst[i * typesize + j] = block[j * values + i];
                }
            }
            dst[values * typesize..].copy_from_slice(&block[values * typesize..bsize]);
        } else {
            dst.copy_from_slice(&block[..bsize]);
        }
    }
    Ok(out)
}

/// Decodes an LZ4 block that must fill `dst` exactly.
fn lz4(src: &[u8], dst: &mut [u8]) -> std::result::Result<(), ()> {
    let (mut i, mut o) = (0usize, 0usize);
    let length = |i: &mut usize, mut n: usize| -> std::result::Result<usize, ()> {
        if n == 15 {
            loop {
                let b = *src.get(*i).ok_or(())?;
                *i += 1;
                n = n.checked_add(b.into()).ok_or(())?;
                if b != 255 {
                    break;
                }
            }
        }
        Ok(n)
    };
    loop {
        let token = *src.get(i).ok_or(())?;
        i += 1;
        let lits = length(&mut i, usize::from(token >> 4))?;
        let end = i.checked_add(lits).ok_or(())?;
        let out_end = o.checked_add(lits).ok_or(())?;
        dst.get_mut(o..out_end).ok_or(())?.copy_from_slice(src.get(i..end).ok_or(())?);
        (i, o) = (end, out_end);
        if i == src.len() {
            // The last sequence has literals only.
            return if o == dst.len() { Ok(()) } else { Err(()) };
        }
        let offset =
            usize::from(u16::from_le_bytes([*src.get(i).ok_or(())?, *src.get(i + 1).ok_or(())?]));
        i += 2;
        let len = length(&mut i, usize::from(token & 15))? + 4;
        if offset == 0 || offset > o || o + len > dst.len() {
            return Err(());
        }
        // Matches may overlap their own output, so copy forwards byte by byte.
        for k in 0..len {
            dst[o + k] = dst[o + k - offset];
        }
        o += len;
    }
}

/// An IEEE half-precision value as f32.
fn half_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    match exp {
        0 => sign * frac * 2f32.powi(-24),
        31 if frac == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        _ => sign * (1.0 + frac / 1024.0) * 2f32.powi(exp - 15),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::media::VolGrid;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/vdb").join(name)
    }

    fn read(name: &str, grid: Option<&str>) -> Result<VdbGrid> {
        VdbGrid::read(&data(name), grid)
    }

    #[test]
    fn matches_the_vol_written_from_the_same_array_voxel_for_voxel() {
        // OpenVDB wrote blob.vdb (blosc + lz4, active-mask compression, eight root children
        // around the origin) from the array that blob.vol holds with a border of zeros.
        let g = read("blob.vdb", None).unwrap();
        let vol = VolGrid::read(&data("blob.vol")).unwrap();
        assert_eq!((g.resolution, g.index_min), ([18, 14, 10], [-9, -7, -5]));
        assert_eq!((vol.resolution, &vol.data), (g.resolution, &g.data));
        // Voxels of 1/8 shifted by 1/16: the faces of the box (the active voxels' box grown by
        // a voxel) lie exactly on +-1.125, +-0.875, +-0.625.
        let c = g.cube_to_world();
        assert_eq!(c.matrix3, DMat3::from_diagonal(DVec3::new(2.25, 1.75, 1.25)));
        assert_eq!(c.translation, DVec3::new(-1.125, -0.875, -0.625));
    }

    #[test]
    fn raw_and_zip_data_read_like_blosc() {
        // blob-raw.vdb is blob.vdb rewritten by OpenVDB with active-mask compression only.
        let (raw, blosc) = (read("blob-raw.vdb", None).unwrap(), read("blob.vdb", None).unwrap());
        assert_eq!(raw, blosc);
        // This OpenVDB build writes no zip, so zip framing is checked on its own: an i64 byte
        // count, then a zlib stream, or a negative count and the bytes as they are.
        let values: Vec<u8> = (0..64u8).collect();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        std::io::Write::write_all(&mut z, &values).unwrap();
        let z = z.finish().unwrap();
        let mut zipped = (z.len() as i64).to_le_bytes().to_vec();
        zipped.extend_from_slice(&z);
        let mut stored = (-64i64).to_le_bytes().to_vec();
        stored.extend_from_slice(&values);
        for bytes in [zipped, stored] {
            let reader = || Reader {
                path: Path::new("z.vdb"),
                b: &bytes,
                pos: 0,
                version: 224,
                tile_voxels: 0,
            };
            let mut r = reader();
            assert_eq!(r.data(COMPRESS_ZIP, 64).unwrap(), values);
            assert_eq!(r.pos, bytes.len());
            assert!(reader().data(COMPRESS_ZIP, 65).is_err());
        }
    }

    #[test]
    fn half_floats_round_to_the_nearest_half() {
        let (g, vol) = (read("half.vdb", None).unwrap(), VolGrid::read(&data("blob.vol")).unwrap());
        assert_eq!(g.resolution, vol.resolution);
        for (h, f) in g.data.iter().zip(&vol.data) {
            // Half precision keeps 11 significant bits: rounding moves a value by at most 2^-11
            // of itself (these are all normal halves).
            assert!((h - f).abs() <= f * 2f32.powi(-11), "{h} vs {f}");
        }
        assert_ne!(g.data, vol.data, "the file should hold halves, not floats");
        assert_eq!(half_to_f32(0x3c00), 1.0);
        assert_eq!(half_to_f32(0xc000), -2.0);
        assert_eq!(half_to_f32(0x0001), 2f32.powi(-24));
        assert!(half_to_f32(0x7e00).is_nan() && half_to_f32(0x7c00) == f32::INFINITY);
    }

    #[test]
    fn active_tiles_fill_their_regions_and_inactive_voxels_hold_the_background() {
        let g = read("tiles.vdb", None).unwrap();
        assert_eq!((g.resolution, g.index_min), ([23, 10, 10], [-1, -1, -1]));
        assert_eq!(g.value([0, 0, 0]), Some(1.0));
        assert_eq!(g.value([15, 7, 7]), Some(1.0));
        assert_eq!(g.value([20, 3, 3]), Some(2.0));
        assert_eq!(g.value([18, 0, 0]), Some(0.0));
        assert_eq!(g.value([21, 8, -1]), Some(0.0));
        assert_eq!(g.value([22, 0, 0]), None);
        assert_eq!(g.data.iter().filter(|&&v| v == 1.0).count(), 16 * 8 * 8);
    }

    #[test]
    fn picks_grids_by_name_and_refuses_what_it_cannot_read() {
        let err = read("multi.vdb", None).unwrap_err().to_string();
        assert!(
            err.contains("no grid named `density`")
                && err.contains("`smoke`, `temperature`")
                && err.contains("grid_name"),
            "{err}"
        );
        let t = read("multi.vdb", Some("temperature")).unwrap();
        assert_eq!(t.resolution, [6, 6, 6]);
        assert_eq!(
            (t.value([0, 0, 0]), t.value([3, 3, 3]), t.value([4, 0, 0])),
            (Some(1.0), Some(1.0), Some(0.0))
        );
        let err = read("multi.vdb", Some("vel")).unwrap_err().to_string();
        assert!(err.contains("grid `vel` is of type Tree_vec3s_5_4_3"), "{err}");
        let err = read("multi.vdb", Some("nope")).unwrap_err().to_string();
        assert!(err.contains("multi.vdb: has no grid named `nope`"), "{err}");
    }

    #[test]
    fn refuses_huge_boxes_negative_values_and_other_files() {
        let err = read("huge.vdb", None).unwrap_err();
        assert!(
            matches!(
                err,
                VdbError::TooLarge { voxels: 1_009_027_027, max: [1000, 1000, 1000], .. }
            ),
            "{err}"
        );
        let err = read("negative.vdb", None).unwrap_err().to_string();
        assert!(err.contains("voxel [1, 0, 1] holds -1") && err.contains("negative"), "{err}");
        let err = read("blob.vol", None).unwrap_err().to_string();
        assert!(err.contains("blob.vol: not an OpenVDB file"), "{err}");
        let err = read("missing.vdb", None).unwrap_err().to_string();
        assert!(err.contains("missing.vdb: cannot read"), "{err}");
    }

    #[test]
    fn every_truncation_and_corruption_is_an_error_not_a_panic() {
        let bytes = std::fs::read(data("blob.vdb")).unwrap();
        let path = Path::new("t.vdb");
        for n in (0..bytes.len()).step_by(97).chain([bytes.len() - 1]) {
            let err = VdbGrid::parse(path, &bytes[..n], None);
            assert!(err.is_err(), "{n} of {} bytes parsed", bytes.len());
        }
        // Flip bytes at seeded positions: anything may come back but a panic.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..3000 {
            let mut b = bytes.clone();
            for _ in 0..4 {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let i = (state >> 33) as usize % b.len();
                b[i] ^= (state >> 13) as u8 | 1;
            }
            let _ = VdbGrid::parse(path, &b, None);
        }
    }

    #[test]
    fn lz4_decodes_overlapping_matches_and_rejects_bad_offsets() {
        // "ab" then a match of 6 at offset 2, then literal "c".
        let src = [0x22, b'a', b'b', 2, 0, 0x10, b'c'];
        let mut dst = [0u8; 9];
        lz4(&src, &mut dst).unwrap();
        assert_eq!(&dst, b"abababab\x63");
        let mut dst = [0u8; 9];
        assert!(lz4(&[0x22, b'a', b'b', 3, 0, 0x10, b'c'], &mut dst).is_err());
    }
}
