//! A reader for Stanford PLY meshes (ASCII, binary little- and big-endian), written here rather
//! than taken from a crate because the PLY crates on crates.io are unmaintained and the subset
//! a renderer needs is small: the `vertex` element's x, y, z (any numeric type), optional
//! nx, ny, nz and u, v (or s, t / texture_u, texture_v), and the `face` element's
//! `vertex_indices` (or `vertex_index`) list, whose polygons are fan-triangulated as Mitsuba
//! triangulates quads. Every other element and property is parsed and skipped.
//!
//! The input is untrusted: every count is checked against the bytes that are left before
//! anything is allocated for it, so a header that claims 10^12 vertices fails at once instead
//! of exhausting memory, and errors name the header line, the body line (ASCII) or the byte
//! offset (binary) where reading stopped.

use glam::{Vec2, Vec3A};

/// Why a PLY file could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlyError {
    /// Something wrong in the header, at a (1-based) line of the file.
    #[error("PLY header line {line}: {message}")]
    Header {
        /// Line number.
        line: usize,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// Something wrong in the data after the header.
    #[error("PLY data at {at}: {message}")]
    Body {
        /// "line N" (ASCII) or "byte N" (binary).
        at: String,
        /// What is wrong.
        message: String,
    },
}

/// The mesh data of a PLY file, in the file's own (object) space.
#[derive(Debug, Default)]
pub(super) struct PlyMesh {
    pub(super) positions: Vec<Vec3A>,
    /// Present only when the vertex element has all of nx, ny, nz.
    pub(super) normals: Option<Vec<Vec3A>>,
    /// Present only when the vertex element has both texture coordinates.
    pub(super) uvs: Option<Vec<Vec2>>,
    pub(super) triangles: Vec<[u32; 3]>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    Little,
    Big,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }
}

#[derive(Debug)]
enum Kind {
    Scalar(Scalar),
    /// A list: the count's type and the items' type.
    List(Scalar, Scalar),
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
    /// Header line, for errors about the element as a whole.
    line: usize,
}

impl Element {
    /// The fewest bytes one instance can take, so `count` can be checked against the data
    /// left: a binary scalar takes its size, a list at least its count; an ASCII value at
    /// least one character and one separator.
    fn min_bytes(&self, format: Format) -> usize {
        self.properties
            .iter()
            .map(|p| match (format, &p.kind) {
                (Format::Ascii, _) => 2,
                (_, Kind::Scalar(s)) | (_, Kind::List(s, _)) => s.size(),
            })
            .sum()
    }

    fn find(&self, names: &[&str]) -> Option<usize> {
        self.properties.iter().position(|p| names.contains(&p.name.as_str()))
    }
}

/// Reads a whole PLY file.
pub(super) fn read(data: &[u8]) -> Result<PlyMesh, PlyError> {
    let (format, elements, body_start, body_line) = header(data)?;
    let mut body = Body { data, pos: body_start, line: body_line, format };
    let mut mesh = PlyMesh::default();
    let mut vertices_read = false;
    let mut faces_read = false;
    for e in &elements {
        let left = data.len() - body.pos;
        let min = e.min_bytes(format);
        if min > 0 && e.count > left / min {
            return Err(body.err(format!(
                "element `{}` (header line {}) claims {} entries, more than the {left} bytes \
                 left can hold; the file is truncated or the count is wrong",
                e.name, e.line, e.count
            )));
        }
        match e.name.as_str() {
            "vertex" if !vertices_read => {
                vertices(&mut body, e, &mut mesh)?;
                vertices_read = true;
            }
            "face" if !faces_read => {
                faces(&mut body, e, &mut mesh)?;
                faces_read = true;
            }
            // An element without properties takes no bytes, however large its count.
            _ if e.properties.is_empty() => {}
            _ => {
                for _ in 0..e.count {
                    for p in &e.properties {
                        body.skip(&p.kind)?;
                    }
                }
            }
        }
    }
    if !vertices_read {
        return Err(PlyError::Header {
            line: 1,
            message: "no `element vertex`; a mesh needs vertices".into(),
        });
    }
    if !faces_read {
        return Err(PlyError::Header {
            line: 1,
            message: "no `element face`; zerovar renders triangle meshes, not point clouds".into(),
        });
    }
    Ok(mesh)
}

/// Reads the header: the format, the elements, and where (byte and line) the data begins.
fn header(data: &[u8]) -> Result<(Format, Vec<Element>, usize, usize), PlyError> {
    let err = |line: usize, message: String| PlyError::Header { line, message };
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = data[pos..].iter().position(|&b| b == b'\n') else {
            return Err(err(
                line_no + 1,
                "the header does not end; it must close with an `end_header` line".into(),
            ));
        };
        let raw = &data[pos..pos + len];
        pos += len + 1;
        line_no += 1;
        let Ok(text) = std::str::from_utf8(raw) else {
            return Err(err(line_no, "the header is not text".into()));
        };
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        if line_no == 1 {
            if words != ["ply"] {
                return Err(err(1, "not a PLY file: the first line must be `ply`".into()));
            }
            continue;
        }
        match words.as_slice() {
            [] => {}
            ["comment" | "obj_info", ..] => {}
            ["format", f, version] => {
                if format.is_some() {
                    return Err(err(line_no, "a second `format` line".into()));
                }
                if *version != "1.0" {
                    return Err(err(line_no, format!("PLY version {version}; only 1.0 exists")));
                }
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Little,
                    "binary_big_endian" => Format::Big,
                    other => {
                        return Err(err(
                            line_no,
                            format!(
                                "format `{other}`; use ascii, binary_little_endian or \
                                 binary_big_endian"
                            ),
                        ));
                    }
                });
            }
            ["element", name, count] => {
                let Ok(count) = count.parse::<usize>() else {
                    return Err(err(
                        line_no,
                        format!("element `{name}` has count `{count}`, not a whole number"),
                    ));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                    line: line_no,
                });
            }
            ["property", rest @ ..] => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(line_no, "a property before any `element` line".into()));
                };
                let ty = |name: &str| {
                    Scalar::parse(name).ok_or_else(|| {
                        err(
                            line_no,
                            format!(
                                "unknown type `{name}`; PLY types are char, uchar, short, \
                                 ushort, int, uint, float, double (or int8 ... float64)"
                            ),
                        )
                    })
                };
                let (kind, name) = match rest {
                    ["list", count, item, name] => {
                        let count = ty(count)?;
                        if !count.is_integer() {
                            return Err(err(
                                line_no,
                                format!("list `{name}` has a non-integer count type"),
                            ));
                        }
                        (Kind::List(count, ty(item)?), name)
                    }
                    [scalar, name] => (Kind::Scalar(ty(scalar)?), name),
                    _ => {
                        return Err(err(
                            line_no,
                            "a property is `property TYPE NAME` or `property list COUNT_TYPE \
                             ITEM_TYPE NAME`"
                                .into(),
                        ));
                    }
                };
                element.properties.push(Property { name: name.to_string(), kind });
            }
            ["end_header"] => break,
            _ => {
                return Err(err(line_no, format!("unexpected header line `{}`", text.trim())));
            }
        }
    }
    let Some(format) = format else {
        return Err(err(
            2,
            "no `format` line (ascii, binary_little_endian or ..._big_endian)".into(),
        ));
    };
    Ok((format, elements, pos, line_no + 1))
}

/// A position in the data after the header.
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    /// Current line, for ASCII errors.
    line: usize,
    format: Format,
}

impl Body<'_> {
    fn err(&self, message: impl Into<String>) -> PlyError {
        let at = match self.format {
            Format::Ascii => format!("line {}", self.line),
            _ => format!("byte {}", self.pos),
        };
        PlyError::Body { at, message: message.into() }
    }

    /// The next ASCII token, counting lines on the way.
    fn token(&mut self) -> Result<&str, PlyError> {
        while let Some(&b) = self.data.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            self.line += usize::from(b == b'\n');
            self.pos += 1;
        }
        let start = self.pos;
        while self.data.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.err("the data ends early; the file is truncated"));
        }
        std::str::from_utf8(&self.data[start..self.pos]).map_err(|_| PlyError::Body {
            at: format!("line {}", self.line),
            message: "not text".into(),
        })
    }

    /// One value of type `ty`, widened to f64 (exact for every PLY type).
    fn scalar(&mut self, ty: Scalar) -> Result<f64, PlyError> {
        if self.format == Format::Ascii {
            let line = self.line;
            let token = self.token()?;
            let value = if ty.is_integer() {
                token.parse::<i64>().ok().map(|v| v as f64)
            } else {
                token.parse::<f64>().ok()
            };
            return value.ok_or_else(|| PlyError::Body {
                at: format!("line {line}"),
                message: format!("`{token}` is not a {ty:?} number"),
            });
        }
        let n = ty.size();
        let Some(bytes) = self.data.get(self.pos..self.pos + n) else {
            return Err(self.err("the data ends early; the file is truncated"));
        };
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(bytes);
        if self.format == Format::Big {
            b[..n].reverse();
        }
        Ok(match ty {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }

    /// A list's length, checked against the data left before anyone allocates for it.
    fn list_len(&mut self, count: Scalar, item: Scalar) -> Result<usize, PlyError> {
        let n = self.scalar(count)?;
        let min = if self.format == Format::Ascii { 2 } else { item.size() };
        if n < 0.0 || n * min as f64 > (self.data.len() - self.pos) as f64 + 1.0 {
            return Err(self.err(format!(
                "a list claims {n} entries, more than the data left; the file is truncated or \
                 corrupt"
            )));
        }
        Ok(n as usize)
    }

    fn skip(&mut self, kind: &Kind) -> Result<(), PlyError> {
        match *kind {
            Kind::Scalar(s) => {
                self.scalar(s)?;
            }
            Kind::List(c, item) => {
                for _ in 0..self.list_len(c, item)? {
                    self.scalar(item)?;
                }
            }
        }
        Ok(())
    }
}

fn vertices(body: &mut Body<'_>, e: &Element, mesh: &mut PlyMesh) -> Result<(), PlyError> {
    let header_err = |message: String| PlyError::Header { line: e.line, message };
    let mut xyz = [0; 3];
    for (slot, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
        *slot = e.find(&[name]).ok_or_else(|| {
            header_err(format!("the vertex element has no `{name}` property; give x, y and z"))
        })?;
    }
    let normal: Option<Vec<usize>> = ["nx", "ny", "nz"].iter().map(|n| e.find(&[n])).collect();
    let uv = e.find(&["u", "s", "texture_u", "texture_s"]).zip(e.find(&[
        "v",
        "t",
        "texture_v",
        "texture_t",
    ]));
    for &i in xyz.iter().chain(normal.iter().flatten()).chain(uv.iter().flat_map(|(u, v)| [u, v])) {
        if matches!(e.properties[i].kind, Kind::List(..)) {
            return Err(header_err(format!(
                "vertex property `{}` is a list; it must be a number",
                e.properties[i].name
            )));
        }
    }
    // `e.count` was checked against the bytes left, so these allocations are bounded by the
    // file's size.
    mesh.positions.reserve_exact(e.count);
    let mut normals = normal.as_ref().map(|_| Vec::with_capacity(e.count));
    let mut uvs = uv.map(|_| Vec::with_capacity(e.count));
    let mut values = vec![0.0f64; e.properties.len()];
    for v in 0..e.count {
        for (value, p) in values.iter_mut().zip(&e.properties) {
            match p.kind {
                Kind::Scalar(s) => *value = body.scalar(s)?,
                _ => body.skip(&p.kind)?,
            }
        }
        let p = Vec3A::new(values[xyz[0]] as f32, values[xyz[1]] as f32, values[xyz[2]] as f32);
        if !p.is_finite() {
            return Err(body.err(format!(
                "vertex {v} is at {:?}; coordinates must be finite numbers",
                p.to_array()
            )));
        }
        mesh.positions.push(p);
        if let (Some(n), Some(idx)) = (&mut normals, &normal) {
            n.push(Vec3A::new(values[idx[0]] as f32, values[idx[1]] as f32, values[idx[2]] as f32));
        }
        if let (Some(t), Some((u, w))) = (&mut uvs, uv) {
            t.push(Vec2::new(values[u] as f32, values[w] as f32));
        }
    }
    mesh.normals = normals;
    mesh.uvs = uvs;
    Ok(())
}

fn faces(body: &mut Body<'_>, e: &Element, mesh: &mut PlyMesh) -> Result<(), PlyError> {
    let Some(list) = e.find(&["vertex_indices", "vertex_index"]) else {
        return Err(PlyError::Header {
            line: e.line,
            message: "the face element has no `vertex_indices` (or `vertex_index`) list".into(),
        });
    };
    let Kind::List(count_ty, item_ty) = e.properties[list].kind else {
        return Err(PlyError::Header {
            line: e.line,
            message: "`vertex_indices` must be a list (`property list uchar int vertex_indices`)"
                .into(),
        });
    };
    let vertex_count = mesh.positions.len();
    let mut polygon: Vec<u32> = Vec::new();
    for f in 0..e.count {
        for (i, p) in e.properties.iter().enumerate() {
            if i != list {
                body.skip(&p.kind)?;
                continue;
            }
            let n = body.list_len(count_ty, item_ty)?;
            if n < 3 {
                return Err(body.err(format!("face {f} has {n} vertices; a face needs at least 3")));
            }
            polygon.clear();
            for _ in 0..n {
                let index = body.scalar(item_ty)?;
                if !(index >= 0.0 && index.fract() == 0.0 && index < vertex_count as f64) {
                    return Err(body.err(format!(
                        "face {f} refers to vertex {index}, but there are {vertex_count} \
                         vertices (numbered from 0)"
                    )));
                }
                polygon.push(index as u32);
            }
            // A fan around the first corner: exact for the convex polygons PLY files hold.
            for k in 1..n - 1 {
                mesh.triangles.push([polygon[0], polygon[k], polygon[k + 1]]);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment a unit quad and a triangle\n\
        element vertex 5\nproperty float x\nproperty float y\nproperty double z\n\
        property float nx\nproperty float ny\nproperty float nz\n\
        element face 2\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n2 2 2 0 0 1\n\
        4 0 1 2 3\n3 0 1 4\n";

    /// The same mesh written in binary, with other types (ushort count, uint indices).
    fn binary(big: bool) -> Vec<u8> {
        let name = if big { "binary_big_endian" } else { "binary_little_endian" };
        let mut out = format!(
            "ply\r\nformat {name} 1.0\r\nelement vertex 5\r\nproperty double x\r\n\
             property float y\r\nproperty short z\r\nelement face 2\r\n\
             property uchar flags\r\nproperty list ushort uint vertex_index\r\nend_header\n"
        )
        .into_bytes();
        let put = |out: &mut Vec<u8>, le: &[u8]| {
            let mut b = le.to_vec();
            if big {
                b.reverse();
            }
            out.extend_from_slice(&b);
        };
        for (x, y, z) in [(0.0, 0.0, 0), (1.0, 0.0, 0), (1.0, 1.0, 0), (0.0, 1.0, 0), (2.0, 2.0, 2)]
        {
            put(&mut out, &f64::to_le_bytes(x));
            put(&mut out, &f32::to_le_bytes(y));
            put(&mut out, &i16::to_le_bytes(z));
        }
        for face in [&[0u32, 1, 2, 3][..], &[0, 1, 4]] {
            out.push(7);
            put(&mut out, &(face.len() as u16).to_le_bytes());
            for i in face {
                put(&mut out, &i.to_le_bytes());
            }
        }
        out
    }

    #[test]
    fn ascii_and_binary_read_alike() {
        let a = read(ASCII.as_bytes()).unwrap();
        assert_eq!(a.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
        assert_eq!(a.positions[4], Vec3A::new(2.0, 2.0, 2.0));
        assert_eq!(a.normals.as_ref().unwrap()[1], Vec3A::Z);
        assert!(a.uvs.is_none());
        for big in [false, true] {
            let b = read(&binary(big)).unwrap();
            assert_eq!(b.positions, a.positions, "big endian: {big}");
            assert_eq!(b.triangles, a.triangles, "big endian: {big}");
            assert!(b.normals.is_none());
        }
    }

    #[test]
    fn hostile_input_gives_errors_that_say_where() {
        let cases: [(String, &str); 8] = [
            (ASCII.replace("vertex 5", "vertex 99999999999"), "claims 99999999999 entries"),
            (ASCII.replace("3 0 1 4", "3 0 1 5"), "refers to vertex 5"),
            (ASCII.replace("2 2 2", "2 nan 2"), "vertex 4 is at"),
            (ASCII.replace("3 0 1 4\n", "3 0 1"), "line 20: a list claims 3 entries"),
            (ASCII.replace("3 0 1 4\n", ""), "line 20: the data ends early"),
            (ASCII.replace("end_header", "end_headr"), "header line 13"),
            (ASCII.replace("uchar int", "float int"), "non-integer count"),
            (ASCII.replace("4 0 1 2 3", "2 0 1"), "face 0 has 2 vertices"),
        ];
        for (text, expected) in cases {
            let e = read(text.as_bytes()).unwrap_err().to_string();
            assert!(e.contains(expected), "{e:?} lacks {expected:?}");
        }
        // A huge element without properties is nothing to read, not a long loop.
        let empty = ASCII.replace("end_header", "element nothing 18446744073709551615\nend_header");
        assert_eq!(read(empty.as_bytes()).unwrap().triangles.len(), 3);
        let mut truncated = binary(false);
        truncated.truncate(truncated.len() - 3);
        let e = read(&truncated).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        // A list count far beyond the data left is refused before reading it.
        let mut huge = binary(true);
        let n = huge.len();
        huge[n - 3 * 4 - 2..n - 3 * 4].copy_from_slice(&u16::MAX.to_be_bytes());
        let e = read(&huge).unwrap_err().to_string();
        assert!(e.contains("a list claims 65535 entries"), "{e}");
    }
}
