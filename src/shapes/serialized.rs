//! A reader for Mitsuba's `.serialized` meshes: one or more meshes, each a two-short header
//! (0x041C, format version 3 or 4) and a zlib stream holding flags, (in version 4) a name,
//! the vertex and triangle counts, positions, optional normals, texture coordinates and
//! colours in single or double precision, and 32-bit indices; a table of the meshes' offsets
//! and their count closes the file. Texture coordinates are taken as written (Mitsuba flips
//! only OBJ's).
//!
//! The input is untrusted: the offset table is checked against the file, decompression stops
//! at the bytes the counts call for (and at a hard limit), and a stream that ends early is an
//! error naming how much was missing.

use super::ply::PlyMesh;
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3A};
use std::io::Read;

/// Why a serialized mesh could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("serialized mesh: {0}")]
pub struct SerializedError(String);

const MAGIC: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_TEXCOORDS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const DOUBLE_PRECISION: u32 = 0x2000;
/// The most decompressed bytes one mesh may take (as the largest input file zerovar reads).
const MAX_BYTES: u64 = crate::files::MAX_INPUT_BYTES;

fn fail<T>(message: impl Into<String>) -> Result<T, SerializedError> {
    Err(SerializedError(message.into()))
}

fn u16_at(data: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(data.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(data: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(data.get(at..at + 4)?.try_into().ok()?))
}

fn u64_at(data: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(data.get(at..at + 8)?.try_into().ok()?))
}

/// The mesh number `index` of the file's bytes `data`, in the file's (object) space.
pub(super) fn read(data: &[u8], index: u32) -> Result<PlyMesh, SerializedError> {
    let Some(version) = header(data, 0)? else {
        return fail("the file is too short for a header");
    };
    let start = if index == 0 { 4 } else { offset(data, version, index)? + 4 };
    let mut z = ZlibDecoder::new(data.get(start..).unwrap_or_default()).take(MAX_BYTES);
    let flags = next(&mut z, 4)? as u32;
    if version == 4 {
        // The mesh's name, zero-terminated.
        let mut length = 0;
        while next(&mut z, 1)? != 0 {
            length += 1;
            if length > 1 << 16 {
                return fail("the mesh's name runs past 65536 bytes without ending");
            }
        }
    }
    let vertices = next(&mut z, 8)?;
    let triangles = next(&mut z, 8)?;
    if vertices > u64::from(u32::MAX) || triangles > u64::from(u32::MAX) {
        return fail(format!(
            "{vertices} vertices and {triangles} triangles: more than 32-bit indices address"
        ));
    }
    let scalar = if flags & DOUBLE_PRECISION != 0 { 8 } else { 4 };
    let per_vertex = 3
        + 3 * u64::from(flags & HAS_NORMALS != 0)
        + 2 * u64::from(flags & HAS_TEXCOORDS != 0)
        + 3 * u64::from(flags & HAS_COLORS != 0);
    let needed = vertices * per_vertex * scalar + triangles * 12;
    if needed > MAX_BYTES {
        return fail(format!("its counts call for {needed} bytes, more than the {MAX_BYTES} read"));
    }
    let mut body = Vec::new();
    let got = z.take(needed).read_to_end(&mut body);
    if let Err(e) = got {
        return fail(format!("the compressed stream is corrupt: {e}"));
    }
    if (body.len() as u64) < needed {
        return fail(format!(
            "the mesh data ends early: {} of the {needed} bytes its {vertices} vertices and \
             {triangles} triangles need",
            body.len()
        ));
    }
    let (n, scalar) = (vertices as usize, scalar as usize);
    let mut at = 0;
    let mut floats = |count: usize| -> Vec<f32> {
        let bytes = &body[at..at + count * scalar];
        at += count * scalar;
        if scalar == 8 {
            bytes
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32)
                .collect()
        } else {
            bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
        }
    };
    let vec3 = |v: Vec<f32>| v.chunks_exact(3).map(|c| Vec3A::new(c[0], c[1], c[2])).collect();
    let positions: Vec<Vec3A> = vec3(floats(3 * n));
    let normals: Option<Vec<Vec3A>> = (flags & HAS_NORMALS != 0).then(|| vec3(floats(3 * n)));
    let uvs = (flags & HAS_TEXCOORDS != 0)
        .then(|| floats(2 * n).chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect());
    if flags & HAS_COLORS != 0 {
        floats(3 * n);
    }
    let triangles = body[at..]
        .chunks_exact(12)
        .map(|c| [0, 4, 8].map(|k| u32_at(c, k).unwrap_or(u32::MAX)))
        .collect();
    Ok(PlyMesh { positions, normals, uvs, triangles })
}

/// The next `n` (at most 8) little-endian bytes of the stream as a number.
fn next(z: &mut impl Read, n: usize) -> Result<u64, SerializedError> {
    let mut word = [0u8; 8];
    match z.read_exact(&mut word[..n]) {
        Ok(()) => Ok(u64::from_le_bytes(word)),
        Err(e) => fail(format!("the compressed stream ends or breaks in its header: {e}")),
    }
}

/// The format version of the mesh header at `at`, `None` past the end of the file.
fn header(data: &[u8], at: usize) -> Result<Option<u16>, SerializedError> {
    let (Some(magic), Some(version)) = (u16_at(data, at), u16_at(data, at + 2)) else {
        return Ok(None);
    };
    if magic != MAGIC {
        return fail(format!(
            "no mesh header at byte {at} (0x{magic:04X} where 0x041C belongs): not a Mitsuba \
             serialized file, or a corrupt one"
        ));
    }
    if version != 3 && version != 4 {
        return fail(format!("format version {version} at byte {at}; zerovar reads 3 and 4"));
    }
    Ok(Some(version))
}

/// The byte offset of mesh `index` from the table at the file's end.
fn offset(data: &[u8], version: u16, index: u32) -> Result<usize, SerializedError> {
    let Some(count) = data.len().checked_sub(4).and_then(|at| u32_at(data, at)) else {
        return fail("the file is too short for its table of meshes");
    };
    if index >= count {
        return fail(format!(
            "shape_index {index}, but the file holds {count} meshes (0 to {})",
            count.saturating_sub(1)
        ));
    }
    let entry = if version == 4 { 8 } else { 4 };
    let table = (data.len() - 4).checked_sub(entry * count as usize);
    let Some(table) = table else {
        return fail(format!("the table of {count} meshes at the end is cut short"));
    };
    let at = table + entry * index as usize;
    let offset = if version == 4 { u64_at(data, at) } else { u32_at(data, at).map(u64::from) };
    let offset = offset.and_then(|o| usize::try_from(o).ok()).filter(|&o| o < table);
    let Some(offset) = offset else {
        return fail(format!("mesh {index}'s offset in the table points outside the file"));
    };
    match header(data, offset)? {
        Some(v) if v == version => Ok(offset),
        Some(v) => fail(format!("mesh {index} has format version {v}, the file {version}")),
        None => fail(format!("mesh {index}'s offset in the table points outside the file")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// One mesh as Mitsuba writes it: header, then the zlib stream of `body`.
    fn blob(version: u16, body: &[u8]) -> Vec<u8> {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(body).unwrap();
        [&MAGIC.to_le_bytes()[..], &version.to_le_bytes(), &z.finish().unwrap()].concat()
    }

    /// A body: flags, a name (version 4), the counts, then the arrays.
    fn body(version: u16, flags: u32, vertices: u64, triangles: u64, rest: &[u8]) -> Vec<u8> {
        let name: &[u8] = if version == 4 { b"m\0" } else { b"" };
        [&flags.to_le_bytes()[..], name, &vertices.to_le_bytes(), &triangles.to_le_bytes(), rest]
            .concat()
    }

    fn triangle_f32() -> Vec<u8> {
        let p: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let i: [u32; 3] = [0, 1, 2];
        let mut out: Vec<u8> = p.iter().flat_map(|v| v.to_le_bytes()).collect();
        out.extend(i.iter().flat_map(|v| v.to_le_bytes()));
        out
    }

    #[test]
    fn reads_mitsubas_test_file_and_both_versions() {
        let data =
            std::fs::read(zerovar_testkit::files::repo("tests/data/mitsuba/two-meshes.serialized"))
                .unwrap();
        let octahedron = read(&data, 0).unwrap();
        assert_eq!((octahedron.positions.len(), octahedron.triangles.len()), (6, 8));
        assert!(octahedron.normals.is_none() && octahedron.uvs.is_none());
        let quad = read(&data, 1).unwrap();
        assert_eq!((quad.positions.len(), quad.triangles.len()), (4, 2));
        assert_eq!(quad.uvs.unwrap()[2], Vec2::new(0.8, 0.65), "not flipped");
        assert_eq!(quad.normals.unwrap()[0], Vec3A::Y);
        assert_eq!(quad.triangles, vec![[0, 3, 2], [0, 2, 1]]);
        // Version 3: 32-bit offsets in the table.
        let first = blob(3, &body(3, 0x1000, 3, 1, &triangle_f32()));
        let second = blob(3, &body(3, 0x1000, 3, 1, &triangle_f32()));
        let offset = first.len() as u32;
        let file =
            [&first[..], &second, &0u32.to_le_bytes(), &offset.to_le_bytes(), &2u32.to_le_bytes()]
                .concat();
        assert_eq!(read(&file, 1).unwrap().positions[1], Vec3A::X);
    }

    #[test]
    fn hostile_files_are_errors_that_say_what_is_wrong() {
        let good = blob(4, &body(4, 0x1000, 3, 1, &triangle_f32()));
        let table = |blobs: &[&[u8]], offsets: &[u64]| {
            let mut f: Vec<u8> = blobs.concat();
            f.extend(offsets.iter().flat_map(|o| o.to_le_bytes()));
            f.extend((offsets.len() as u32).to_le_bytes());
            f
        };
        let cases: Vec<(Vec<u8>, u32, &str)> = vec![
            (vec![0x1C], 0, "too short for a header"),
            (vec![0, 0, 4, 0], 0, "not a Mitsuba serialized file"),
            (blob(5, b""), 0, "format version 5"),
            (good[..8].to_vec(), 0, "ends or breaks"),
            (blob(4, &body(4, 0x1000, 3, 1, &triangle_f32()[..20])), 0, "ends early"),
            (blob(4, &body(4, 0x1000, 1 << 40, 1, b"")), 0, "more than 32-bit indices"),
            (table(&[&good], &[0]), 1, "shape_index 1, but the file holds 1 meshes"),
            (table(&[&good, &good], &[0, 999]), 1, "points outside the file"),
            (
                [&MAGIC.to_le_bytes()[..], &4u16.to_le_bytes(), b"not zlib at all"].concat(),
                0,
                "breaks",
            ),
        ];
        for (data, index, needle) in cases {
            match read(&data, index) {
                Ok(m) => panic!("{needle}: read {} vertices", m.positions.len()),
                Err(e) => assert!(e.to_string().contains(needle), "{needle}: {e}"),
            }
        }
        // A bad index is caught by the mesh builder, with the triangle named.
        let bad = [
            triangle_f32()[..36].to_vec(),
            [0u32, 1, 7].iter().flat_map(|v| v.to_le_bytes()).collect(),
        ]
        .concat();
        let mesh = read(&blob(4, &body(4, 0x1000, 3, 1, &bad)), 0).unwrap();
        let t = crate::transform::Transform::IDENTITY;
        let e = super::super::mesh::Mesh::new(mesh.positions, None, None, mesh.triangles, &t);
        assert!(e.unwrap_err().to_string().contains("refers to vertex 7"));
    }
}
