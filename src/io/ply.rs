//! Point clouds as PLY (the output contract) and a generic PLY vertex
//! reader.
//!
//! The writer emits `binary_little_endian 1.0` (or ASCII on request) with
//! vertex properties `double x y z` (calibration units), `float u v` (the
//! left-camera pixel the point was measured at) and per-point quality as
//! scalar fields named with CloudCompare's `scalar_` prefix, because
//! CloudCompare imports only such properties as scalar fields (see
//! shared/notes/interop.md): `scalar_source_period` (px),
//! `scalar_modulation` (DN), `scalar_sigma_z_um` (height uncertainty in
//! micrometres), `scalar_intensity` (DN) and `scalar_order_evidence` (how
//! the fringe orders were decided: 0 own samples, 1 neighbours, 2 patch).
//! Header comments carry the
//! generator, unit and source, and what a lossless read-back needs (the
//! organizing grid and the set index of each period).
//!
//! The reader takes any PLY (ASCII, binary little or big endian; every scalar
//! type and its alias; other elements and list properties skipped) and returns
//! the vertices' coordinates with their other scalar properties by name.

use std::io::Write;
use std::path::Path;

use super::atomic::write_atomic_sequential;
use super::error::IoError;
use crate::engine::length_unit::{LengthUnit, UnknownLengthUnit};
use crate::engine::point_cloud::PointCloud;

/// PLY body encodings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlyFormat {
    #[default]
    BinaryLittleEndian,
    BinaryBigEndian,
    Ascii,
}

impl PlyFormat {
    fn keyword(self) -> &'static str {
        match self {
            PlyFormat::BinaryLittleEndian => "binary_little_endian",
            PlyFormat::BinaryBigEndian => "binary_big_endian",
            PlyFormat::Ascii => "ascii",
        }
    }
}

/// How [`write_ply`] writes a cloud.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyWriteOptions {
    pub format: PlyFormat,
    /// Where the cloud came from (e.g. the manifest path), written as a comment.
    pub source: Option<String>,
}

/// What is wrong with a PLY file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlyFault {
    #[error("is not a PLY file (it does not start with the line 'ply')")]
    NotPly,
    #[error("header line {line}: {message}")]
    Header { line: usize, message: String },
    #[error("has no 'vertex' element, so it holds no points")]
    NoVertices,
    #[error("its vertices lack the coordinate property '{missing}'")]
    MissingCoordinate { missing: &'static str },
    #[error(
        "ends at byte {offset} inside {element} {index} of {count} ({needed} more bytes needed): the file is truncated; \
         copy or export it again"
    )]
    Truncated { offset: usize, element: String, index: usize, count: usize, needed: usize },
    #[error("line {line}: {message}")]
    Ascii { line: usize, message: String },
    #[error("byte {offset}: list of {element} {index} has the invalid length {length}")]
    BadListLength { offset: usize, element: String, index: usize, length: f64 },
    #[error("has {extra} bytes after its last element; the header's counts do not match the data")]
    TrailingData { extra: usize },
    #[error("is not a Sheen point cloud: its vertices lack {missing}")]
    NotSheen { missing: String },
    #[error("header comment 'unit': {0}")]
    UnknownUnit(#[from] UnknownLengthUnit),
}

/// Vertices of a PLY file: coordinates plus every other scalar property.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyVertices {
    pub format: PlyFormat,
    /// Header comments, without the `comment ` keyword.
    pub comments: Vec<String>,
    pub xyz: Vec<[f64; 3]>,
    /// Other scalar vertex properties in file order, converted to `f64`
    /// (exact for every PLY scalar type).
    pub scalars: Vec<(String, Vec<f64>)>,
}

impl PlyVertices {
    pub fn scalar(&self, name: &str) -> Option<&[f64]> {
        self.scalars.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }

    /// The value of a `comment KEY value...` line.
    fn comment_value(&self, key: &str) -> Option<&str> {
        self.comments.iter().find_map(|c| c.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
    }

    /// The length unit of the coordinates (`comment unit`, mm without one,
    /// as CloudCompare and MeshLab files have none); an unknown unit is an
    /// error rather than coordinates taken in the wrong scale.
    pub fn unit(&self) -> Result<LengthUnit, PlyFault> {
        Ok(self.comment_value("unit").map_or(Ok(LengthUnit::Mm), |u| u.trim().parse())?)
    }

    /// Back to a [`PointCloud`], when the Sheen fields are present. The set
    /// index of each point comes from the `sheen_source_sets` comment (set
    /// index per period) or, without it, from the rank of its period among
    /// those present (largest first).
    pub fn to_point_cloud(&self) -> Result<PointCloud, PlyFault> {
        let unit = self.unit()?;
        let um_per_unit = unit.um_per_unit();
        let sigma = match (self.scalar("scalar_sigma_z_um"), self.scalar("scalar_sigma_z")) {
            (Some(s), _) => Some(s.iter().map(|v| (v / um_per_unit) as f32).collect::<Vec<_>>()),
            (_, Some(s)) => Some(s.iter().map(|&v| v as f32).collect()),
            _ => None,
        };
        let column = |name: &str| self.scalar(name).map(|v| v.iter().map(|&x| x as f32).collect::<Vec<f32>>());
        let (u, v, period, modulation, intensity, sigma_z) = match (
            column("u"),
            column("v"),
            column("scalar_source_period"),
            column("scalar_modulation"),
            column("scalar_intensity"),
            sigma,
        ) {
            (Some(u), Some(v), Some(p), Some(m), Some(i), Some(s)) => (u, v, p, m, i, s),
            _ => {
                let needed = ["u", "v", "scalar_source_period", "scalar_modulation", "scalar_intensity"];
                let mut missing: Vec<&str> = needed.into_iter().filter(|n| self.scalar(n).is_none()).collect();
                if self.scalar("scalar_sigma_z_um").is_none() && self.scalar("scalar_sigma_z").is_none() {
                    missing.push("scalar_sigma_z_um");
                }
                return Err(PlyFault::NotSheen { missing: missing.join(", ") });
            }
        };
        let mut set_of_period: Vec<(f32, i8)> = self
            .comment_value("sheen_source_sets")
            .map(|list| {
                list.split_whitespace()
                    .filter_map(|pair| {
                        let (set, period) = pair.split_once(':')?;
                        Some((period.parse::<f32>().ok()?, set.parse::<i8>().ok()?))
                    })
                    .collect()
            })
            .unwrap_or_default();
        if set_of_period.is_empty() {
            let mut periods: Vec<f32> = period.iter().copied().filter(|p| p.is_finite()).collect();
            periods.sort_by(|a, b| b.total_cmp(a));
            periods.dedup();
            set_of_period = periods.into_iter().enumerate().map(|(i, p)| (p, i.min(127) as i8)).collect();
        }
        let source_set = period
            .iter()
            .map(|p| set_of_period.iter().find(|(q, _)| q == p).map_or(crate::engine::fusion::SOURCE_NONE, |(_, s)| *s))
            .collect();
        let (grid_width, grid_height) = self
            .comment_value("sheen_grid")
            .and_then(|g| {
                let mut it = g.split_whitespace().map(|x| x.parse::<usize>().ok());
                Some((it.next()??, it.next()??))
            })
            .unwrap_or((0, 0));
        Ok(PointCloud {
            unit,
            xyz: self.xyz.clone(),
            pixel_uv: u.into_iter().zip(v).map(|(u, v)| [u, v]).collect(),
            source_set,
            source_period_px: period,
            modulation_dn: modulation,
            sigma_z,
            intensity_dn: intensity,
            // Absent in PLYs of Sheen 0.1: every order was then decided on its own pixel.
            order_evidence: match self.scalar("scalar_order_evidence") {
                Some(e) => e.iter().map(|&x| x as u8).collect(),
                None => vec![0; self.xyz.len()],
            },
            grid_width,
            grid_height,
        })
    }
}

/// Writes a cloud as PLY, atomically.
pub fn write_ply(path: &Path, cloud: &PointCloud, options: &PlyWriteOptions) -> Result<(), IoError> {
    write_atomic_sequential(path, |w| write_ply_to(w, cloud, options))
}

/// Points per block of a binary PLY's body (about 6.8 MB): large enough for
/// one write per block, small enough that two blocks add little to a run's
/// peak memory.
const BINARY_BLOCK_POINTS: usize = 128 * 1024;

/// Writes a cloud as PLY to any writer.
pub fn write_ply_to<W: Write + Send>(w: &mut W, cloud: &PointCloud, options: &PlyWriteOptions) -> std::io::Result<()> {
    write_ply_in_blocks(w, cloud, options, BINARY_BLOCK_POINTS)
}

fn write_ply_in_blocks<W: Write + Send>(
    w: &mut W,
    cloud: &PointCloud,
    options: &PlyWriteOptions,
    block_points: usize,
) -> std::io::Result<()> {
    let n = cloud.len();
    let lengths = [
        cloud.pixel_uv.len(),
        cloud.source_period_px.len(),
        cloud.modulation_dn.len(),
        cloud.sigma_z.len(),
        cloud.intensity_dn.len(),
    ];
    // A cloud built without fringe-order evidence (older code, other
    // sources) has every order decided on its own pixel.
    let evidence_ok = cloud.order_evidence.is_empty() || cloud.order_evidence.len() == n;
    let order_evidence = |i: usize| cloud.order_evidence.get(i).copied().unwrap_or(0);
    if lengths.iter().any(|&l| l != n) || !evidence_ok {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "the point cloud's fields have different lengths ({n} points, fields {lengths:?}, order evidence {})",
                cloud.order_evidence.len()
            ),
        ));
    }
    let (sigma_name, sigma_factor) = ("scalar_sigma_z_um", cloud.um_per_unit());
    let one_line = |s: &str| s.replace(['\n', '\r'], " ");
    let mut header = String::new();
    header.push_str("ply\n");
    header.push_str(&format!("format {} 1.0\n", options.format.keyword()));
    header.push_str(&format!("comment generator Sheen {}\n", env!("CARGO_PKG_VERSION")));
    header.push_str(&format!("comment unit {}\n", cloud.unit));
    if let Some(source) = &options.source {
        header.push_str(&format!("comment source {}\n", one_line(source)));
    }
    header.push_str(&format!("comment sheen_grid {} {}\n", cloud.grid_width, cloud.grid_height));
    // Each set's period as its first point has it, in set order: a table by
    // set number, not a sort of every point (a full-size cloud's 3 M pairs
    // took 30 ms of one thread).
    let slot = |s: i8| usize::from(s as u8 ^ 0x80);
    let mut period_by_set: [Option<f32>; 256] = [None; 256];
    for (&s, &p) in cloud.source_set.iter().zip(&cloud.source_period_px) {
        period_by_set[slot(s)].get_or_insert(p);
    }
    let sets: Vec<(i8, f32)> = (i8::MIN..=i8::MAX).filter_map(|s| period_by_set[slot(s)].map(|p| (s, p))).collect();
    if !sets.is_empty() {
        let list: Vec<String> = sets.iter().map(|(s, p)| format!("{s}:{p}")).collect();
        header.push_str(&format!("comment sheen_source_sets {}\n", list.join(" ")));
    }
    header.push_str(&format!("element vertex {n}\n"));
    for p in ["x", "y", "z"] {
        header.push_str(&format!("property double {p}\n"));
    }
    for p in
        ["u", "v", "scalar_source_period", "scalar_modulation", sigma_name, "scalar_intensity", "scalar_order_evidence"]
    {
        header.push_str(&format!("property float {p}\n"));
    }
    header.push_str("end_header\n");
    w.write_all(header.as_bytes())?;

    let sigma = |i: usize| (f64::from(cloud.sigma_z[i]) * sigma_factor) as f32;
    match options.format {
        PlyFormat::Ascii => {
            for i in 0..n {
                let [x, y, z] = cloud.xyz[i];
                let [u, v] = cloud.pixel_uv[i];
                writeln!(
                    w,
                    "{x} {y} {z} {u} {v} {} {} {} {} {}",
                    cloud.source_period_px[i],
                    cloud.modulation_dn[i],
                    sigma(i),
                    cloud.intensity_dn[i],
                    order_evidence(i)
                )?;
            }
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            // Encoded in parallel chunks, a block at a time into two reused
            // buffers, the next block encoded while the last one is written:
            // a full-size cloud is about 150 MB, which record by record
            // through an 8 KiB buffer took a fifth of a one-shot run, encoded
            // whole took 150 MB of fresh pages (their faults cost about 0.1 s
            // here) on top of the run's peak memory, and encoded and written
            // in turn left a core idle while each block was copied out.
            use rayon::prelude::*;
            const RECORD: usize = 52;
            const CHUNK_POINTS: usize = 16 * 1024;
            let block_points = block_points.max(1);
            let big = options.format == PlyFormat::BinaryBigEndian;
            let encode = |first: usize, block: &mut [u8]| {
                block.par_chunks_mut(CHUNK_POINTS * RECORD).enumerate().for_each(|(c, chunk)| {
                    for (k, record) in chunk.chunks_exact_mut(RECORD).enumerate() {
                        let i = first + c * CHUNK_POINTS + k;
                        let (doubles, floats) = record.split_at_mut(24);
                        for (out, v) in doubles.chunks_exact_mut(8).zip(cloud.xyz[i]) {
                            out.copy_from_slice(&if big { v.to_be_bytes() } else { v.to_le_bytes() });
                        }
                        let values = [
                            cloud.pixel_uv[i][0],
                            cloud.pixel_uv[i][1],
                            cloud.source_period_px[i],
                            cloud.modulation_dn[i],
                            sigma(i),
                            cloud.intensity_dn[i],
                            f32::from(order_evidence(i)),
                        ];
                        for (out, v) in floats.chunks_exact_mut(4).zip(values) {
                            out.copy_from_slice(&if big { v.to_be_bytes() } else { v.to_le_bytes() });
                        }
                    }
                });
            };
            let block_len = |first: usize| (n - first).min(block_points) * RECORD;
            let mut ready = vec![0u8; n.min(block_points) * RECORD];
            let mut next = ready.clone();
            let mut written = 0;
            if n > 0 {
                encode(0, &mut ready[..block_len(0)]);
            }
            while written < n {
                let following = written + block_points;
                let (result, ()) = rayon::join(
                    || w.write_all(&ready[..block_len(written)]),
                    || {
                        if following < n {
                            encode(following, &mut next[..block_len(following)]);
                        }
                    },
                );
                result?;
                std::mem::swap(&mut ready, &mut next);
                written = following;
            }
        }
    }
    Ok(())
}

/// Reads the vertices of a PLY file.
pub fn read_ply(path: &Path) -> Result<PlyVertices, IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    parse_ply(&bytes, path)
}

/// Parses PLY bytes; `path` is named in errors.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<PlyVertices, IoError> {
    parse(bytes).map_err(|fault| IoError::Ply { path: path.to_path_buf(), fault })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    /// Decodes one value from exactly `size()` bytes.
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                f64::from(if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) })
            }};
        }
        match self {
            ScalarType::I8 => f64::from(b[0] as i8),
            ScalarType::U8 => f64::from(b[0]),
            ScalarType::I16 => num!(i16, 2),
            ScalarType::U16 => num!(u16, 2),
            ScalarType::I32 => num!(i32, 4),
            ScalarType::U32 => num!(u32, 4),
            ScalarType::F32 => num!(f32, 4),
            ScalarType::F64 => num!(f64, 8),
        }
    }
}

#[derive(Clone, Debug)]
enum PropKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

/// The largest header accepted; real headers are a few hundred bytes.
const MAX_HEADER_BYTES: usize = 1 << 20;

struct Header {
    format: PlyFormat,
    comments: Vec<String>,
    elements: Vec<Element>,
    body_start: usize,
    /// Line number of the body's first line (ASCII errors count from the file's start).
    body_line: usize,
}

/// The header line starting at `*pos` (without its line break), advancing `*pos`.
fn next_line(bytes: &[u8], pos: &mut usize) -> Option<String> {
    if *pos >= bytes.len() || *pos >= MAX_HEADER_BYTES {
        return None;
    }
    let end = bytes[*pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| *pos + i);
    let line = String::from_utf8_lossy(&bytes[*pos..end]).trim_end_matches('\r').to_string();
    *pos = (end + 1).min(bytes.len());
    Some(line)
}

fn parse_header(bytes: &[u8]) -> Result<Header, PlyFault> {
    let mut pos = 0;
    let mut line_no = 0;
    let header_err = |line: usize, message: String| PlyFault::Header { line, message };
    match next_line(bytes, &mut pos) {
        Some(l) if l.trim() == "ply" => line_no += 1,
        _ => return Err(PlyFault::NotPly),
    }
    let mut format = None;
    let mut comments = Vec::new();
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(line) = next_line(bytes, &mut pos) else {
            return Err(header_err(line_no + 1, "the header has no 'end_header' line (truncated or not PLY)".into()));
        };
        line_no += 1;
        let mut words = line.split_whitespace();
        match words.next() {
            None => {}
            Some("end_header") => break,
            Some("comment") | Some("obj_info") => {
                let rest = line.trim_start();
                let rest = rest.split_once(char::is_whitespace).map_or("", |(_, r)| r).trim().to_string();
                if line.trim_start().starts_with("comment") {
                    comments.push(rest);
                }
            }
            Some("format") => {
                let f = match words.next() {
                    Some("ascii") => PlyFormat::Ascii,
                    Some("binary_little_endian") => PlyFormat::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyFormat::BinaryBigEndian,
                    other => {
                        return Err(header_err(
                            line_no,
                            format!(
                                "unknown format '{}'; expected ascii, binary_little_endian or binary_big_endian",
                                other.unwrap_or("")
                            ),
                        ));
                    }
                };
                format = Some(f);
            }
            Some("element") => {
                let name = words.next().ok_or_else(|| header_err(line_no, "element without a name".into()))?;
                let count = words
                    .next()
                    .and_then(|c| c.parse::<usize>().ok())
                    .ok_or_else(|| header_err(line_no, format!("element '{name}' has no valid count")))?;
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(header_err(line_no, "property before any element".into()));
                };
                let ty = words.next().unwrap_or("");
                let kind = if ty == "list" {
                    let count = words.next().and_then(ScalarType::parse);
                    let item = words.next().and_then(ScalarType::parse);
                    match (count, item) {
                        (Some(count), Some(item)) => PropKind::List { count, item },
                        _ => return Err(header_err(line_no, "list property with unknown types".into())),
                    }
                } else {
                    PropKind::Scalar(
                        ScalarType::parse(ty)
                            .ok_or_else(|| header_err(line_no, format!("unknown property type '{ty}'")))?,
                    )
                };
                let name = words.next().ok_or_else(|| header_err(line_no, "property without a name".into()))?;
                element.props.push(Property { name: name.to_string(), kind });
            }
            Some(other) => return Err(header_err(line_no, format!("unknown header keyword '{other}'"))),
        }
    }
    let format = format.ok_or_else(|| header_err(line_no, "the header has no 'format' line".into()))?;
    Ok(Header { format, comments, elements, body_start: pos, body_line: line_no + 1 })
}

fn parse(bytes: &[u8]) -> Result<PlyVertices, PlyFault> {
    let header = parse_header(bytes)?;
    let vertex_index = header.elements.iter().position(|e| e.name == "vertex").ok_or(PlyFault::NoVertices)?;
    let vertex = &header.elements[vertex_index];
    let coordinate = |c: &'static str| {
        vertex
            .props
            .iter()
            .position(|p| p.name == c && matches!(p.kind, PropKind::Scalar(_)))
            .ok_or(PlyFault::MissingCoordinate { missing: c })
    };
    let xyz_props = [coordinate("x")?, coordinate("y")?, coordinate("z")?];
    // Columns for the other scalar properties, in file order.
    let column_of: Vec<Option<usize>> = {
        let mut next = 0;
        vertex
            .props
            .iter()
            .enumerate()
            .map(|(i, p)| {
                (matches!(p.kind, PropKind::Scalar(_)) && !xyz_props.contains(&i)).then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let mut scalars: Vec<(String, Vec<f64>)> = vertex
        .props
        .iter()
        .zip(&column_of)
        .filter(|(_, c)| c.is_some())
        .map(|(p, _)| (p.name.clone(), Vec::new()))
        .collect();
    let mut xyz: Vec<[f64; 3]> = Vec::new();
    let mut record = vec![0.0f64; vertex.props.len()];
    let store = |values: &[f64], xyz: &mut Vec<[f64; 3]>, scalars: &mut Vec<(String, Vec<f64>)>| {
        xyz.push([values[xyz_props[0]], values[xyz_props[1]], values[xyz_props[2]]]);
        for (i, c) in column_of.iter().enumerate() {
            if let Some(c) = c {
                scalars[*c].1.push(values[i]);
            }
        }
    };
    let body = &bytes[header.body_start.min(bytes.len())..];
    match header.format {
        PlyFormat::Ascii => {
            let mut tokens = AsciiTokens { body, pos: 0, line: header.body_line };
            for (ei, element) in header.elements.iter().enumerate() {
                // An element without properties has no data, however large its count.
                if element.props.is_empty() {
                    continue;
                }
                let is_vertex = ei == vertex_index;
                if is_vertex {
                    // Each vertex takes at least one token per property.
                    let cap = element.count.min(body.len() / (2 * element.props.len().max(1)) + 1);
                    xyz.reserve(cap);
                }
                for index in 0..element.count {
                    for (pi, prop) in element.props.iter().enumerate() {
                        match prop.kind {
                            PropKind::Scalar(_) => {
                                let v = tokens.number(&element.name, index, element.count)?;
                                if is_vertex {
                                    record[pi] = v;
                                }
                            }
                            PropKind::List { .. } => {
                                let line = tokens.line;
                                let n = tokens.number(&element.name, index, element.count)?;
                                if !(n >= 0.0 && n.fract() == 0.0) {
                                    return Err(PlyFault::Ascii {
                                        line,
                                        message: format!("list length {n} of {} {index} is not a count", element.name),
                                    });
                                }
                                for _ in 0..n as u64 {
                                    tokens.number(&element.name, index, element.count)?;
                                }
                            }
                        }
                    }
                    if is_vertex {
                        store(&record, &mut xyz, &mut scalars);
                    }
                }
            }
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            let big = header.format == PlyFormat::BinaryBigEndian;
            let mut offset = header.body_start;
            for (ei, element) in header.elements.iter().enumerate() {
                // An element without properties has no data, however large its count.
                if element.props.is_empty() {
                    continue;
                }
                let is_vertex = ei == vertex_index;
                let fixed: Option<usize> = element
                    .props
                    .iter()
                    .map(|p| match p.kind {
                        PropKind::Scalar(t) => Some(t.size()),
                        PropKind::List { .. } => None,
                    })
                    .sum();
                // With fixed-size records, a short file is known before reading it.
                if let Some(size) = fixed {
                    let available = bytes.len().saturating_sub(offset);
                    let needed = size.saturating_mul(element.count);
                    if needed > available {
                        let index = available / size.max(1);
                        return Err(PlyFault::Truncated {
                            offset: bytes.len(),
                            element: element.name.clone(),
                            index,
                            count: element.count,
                            needed: needed - available,
                        });
                    }
                    if is_vertex {
                        xyz.reserve(element.count);
                        scalars.iter_mut().for_each(|(_, c)| c.reserve(element.count));
                    }
                }
                for index in 0..element.count {
                    for (pi, prop) in element.props.iter().enumerate() {
                        let take = |t: ScalarType, offset: &mut usize| -> Result<f64, PlyFault> {
                            let size = t.size();
                            let b = bytes.get(*offset..*offset + size).ok_or_else(|| PlyFault::Truncated {
                                offset: bytes.len(),
                                element: element.name.clone(),
                                index,
                                count: element.count,
                                needed: *offset + size - bytes.len(),
                            })?;
                            *offset += size;
                            Ok(t.decode(b, big))
                        };
                        match prop.kind {
                            PropKind::Scalar(t) => {
                                let v = take(t, &mut offset)?;
                                if is_vertex {
                                    record[pi] = v;
                                }
                            }
                            PropKind::List { count, item } => {
                                let at = offset;
                                let n = take(count, &mut offset)?;
                                if !(n >= 0.0 && n.fract() == 0.0) {
                                    return Err(PlyFault::BadListLength {
                                        offset: at,
                                        element: element.name.clone(),
                                        index,
                                        length: n,
                                    });
                                }
                                let skip = (n as usize).saturating_mul(item.size());
                                if offset.saturating_add(skip) > bytes.len() {
                                    return Err(PlyFault::Truncated {
                                        offset: bytes.len(),
                                        element: element.name.clone(),
                                        index,
                                        count: element.count,
                                        needed: offset.saturating_add(skip) - bytes.len(),
                                    });
                                }
                                offset += skip;
                            }
                        }
                    }
                    if is_vertex {
                        store(&record, &mut xyz, &mut scalars);
                    }
                }
            }
            if offset < bytes.len() {
                return Err(PlyFault::TrailingData { extra: bytes.len() - offset });
            }
        }
    }
    Ok(PlyVertices { format: header.format, comments: header.comments, xyz, scalars })
}

/// Whitespace-separated numbers of an ASCII body, with line numbers for errors.
struct AsciiTokens<'a> {
    body: &'a [u8],
    pos: usize,
    /// 1-based line of the file where the last token started.
    line: usize,
}

impl AsciiTokens<'_> {
    fn number(&mut self, element: &str, index: usize, count: usize) -> Result<f64, PlyFault> {
        while self.pos < self.body.len() && self.body[self.pos].is_ascii_whitespace() {
            if self.body[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < self.body.len() && !self.body[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(PlyFault::Ascii {
                line: self.line,
                message: format!("the data ends inside {element} {index} of {count}: the file is truncated"),
            });
        }
        let token = String::from_utf8_lossy(&self.body[start..self.pos]);
        token.parse::<f64>().map_err(|_| PlyFault::Ascii {
            line: self.line,
            message: format!("'{token}' in {element} {index} is not a number"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cloud(n: usize) -> PointCloud {
        PointCloud {
            unit: crate::engine::length_unit::LengthUnit::Mm,
            xyz: (0..n).map(|i| [i as f64 * 0.1 + 1e-9, -(i as f64) / 3.0, 1.0 / (i as f64 + 7.0)]).collect(),
            pixel_uv: (0..n).map(|i| [(i % 11) as f32 + 0.25, (i / 11) as f32 - 0.125]).collect(),
            source_set: (0..n).map(|i| [3, 3, 2, 0][i % 4]).collect(),
            source_period_px: (0..n).map(|i| [12.0, 12.0, 24.0, 912.0][i % 4]).collect(),
            modulation_dn: (0..n).map(|i| 10.0 + i as f32 / 7.0).collect(),
            sigma_z: (0..n).map(|i| 1.0e-4 * (1.0 + i as f32 / 13.0)).collect(),
            intensity_dn: (0..n).map(|i| (i * 3 % 256) as f32).collect(),
            order_evidence: (0..n).map(|i| [0, 0, 1, 2][i % 4]).collect(),
            grid_width: 11,
            grid_height: 9,
        }
    }

    fn round_trip(format: PlyFormat) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cloud.ply");
        let c = cloud(97);
        let options = PlyWriteOptions { format, source: Some("/data/set\n1/fringe-set.json".into()) };
        write_ply(&path, &c, &options).unwrap();
        let v = read_ply(&path).unwrap();
        assert_eq!(v.format, format);
        assert_eq!(v.xyz, c.xyz);
        let f = |name: &str| v.scalar(name).unwrap().iter().map(|&x| x as f32).collect::<Vec<_>>();
        assert_eq!(f("u"), c.pixel_uv.iter().map(|p| p[0]).collect::<Vec<_>>());
        assert_eq!(f("v"), c.pixel_uv.iter().map(|p| p[1]).collect::<Vec<_>>());
        assert_eq!(f("scalar_source_period"), c.source_period_px);
        assert_eq!(f("scalar_modulation"), c.modulation_dn);
        assert_eq!(f("scalar_intensity"), c.intensity_dn);
        let sigma_um: Vec<f32> = c.sigma_z.iter().map(|s| (f64::from(*s) * 1e3) as f32).collect();
        assert_eq!(f("scalar_sigma_z_um"), sigma_um);
        let names: Vec<&str> = v.scalars.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "u",
                "v",
                "scalar_source_period",
                "scalar_modulation",
                "scalar_sigma_z_um",
                "scalar_intensity",
                "scalar_order_evidence"
            ]
        );
        assert!(v.comments.iter().any(|c| c == "unit mm"));
        assert!(v.comments.iter().any(|c| c == "source /data/set 1/fringe-set.json"));
        assert!(v.comments.iter().any(|c| c.starts_with("generator Sheen")));
        assert!(v.comments.iter().any(|c| c == "sheen_source_sets 0:912 2:24 3:12"), "{:?}", v.comments);
        let back = v.to_point_cloud().unwrap();
        assert_eq!(back.xyz, c.xyz);
        assert_eq!(back.source_set, c.source_set);
        assert_eq!(back.pixel_uv, c.pixel_uv);
        assert_eq!(back.order_evidence, c.order_evidence);
        assert_eq!((back.grid_width, back.grid_height, back.unit.as_str()), (11, 9, "mm"));
        for (a, b) in back.sigma_z.iter().zip(&c.sigma_z) {
            assert!((a - b).abs() <= b * 2e-7, "{a} vs {b}");
        }
    }

    #[test]
    fn binary_round_trip_is_exact() {
        round_trip(PlyFormat::BinaryLittleEndian);
        round_trip(PlyFormat::BinaryBigEndian);
    }

    #[test]
    fn a_body_written_in_many_blocks_is_the_body_written_in_one() {
        // 97 points in blocks of 5 (the last one partial): each block is
        // encoded while the one before is written, so every record must
        // still land once, in order.
        let c = cloud(97);
        for format in [PlyFormat::BinaryLittleEndian, PlyFormat::BinaryBigEndian] {
            let options = PlyWriteOptions { format, source: None };
            let (mut one, mut many) = (Vec::new(), Vec::new());
            write_ply_in_blocks(&mut one, &c, &options, 1000).unwrap();
            write_ply_in_blocks(&mut many, &c, &options, 5).unwrap();
            assert_eq!(one, many, "{format:?}");
        }
        // A disk that fails midway fails the write, whichever block it hits.
        struct FullAfter(usize);
        impl Write for FullAfter {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                if buf.len() > self.0 {
                    return Err(std::io::Error::new(std::io::ErrorKind::StorageFull, "disk full"));
                }
                self.0 -= buf.len();
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let err = write_ply_in_blocks(&mut FullAfter(1500), &c, &PlyWriteOptions::default(), 5).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::StorageFull);
    }

    #[test]
    fn ascii_round_trip_is_exact() {
        round_trip(PlyFormat::Ascii);
    }

    #[test]
    fn binary_header_is_the_contract() {
        let mut out = Vec::new();
        write_ply_to(&mut out, &cloud(2), &PlyWriteOptions::default()).unwrap();
        let text = String::from_utf8_lossy(&out);
        let header = &text[..text.find("end_header\n").unwrap() + 11];
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
        let props: Vec<&str> = header.lines().filter(|l| l.starts_with("property")).collect();
        assert_eq!(
            props,
            [
                "property double x",
                "property double y",
                "property double z",
                "property float u",
                "property float v",
                "property float scalar_source_period",
                "property float scalar_modulation",
                "property float scalar_sigma_z_um",
                "property float scalar_intensity",
                "property float scalar_order_evidence",
            ]
        );
        assert_eq!(out.len(), header.len() + 2 * 52);
    }

    #[test]
    fn reads_foreign_files_with_aliases_lists_and_other_elements() {
        // A mesh-like file: uchar/int16/uint32 vertex properties, a list in
        // the vertex, a face element before and after.
        let mut bytes = b"ply\r\nformat binary_big_endian 1.0\r\ncomment made elsewhere\r\nobj_info x\r\n\
element face 1\r\nproperty list uchar int vertex_indices\r\n\
element vertex 2\r\nproperty float32 x\r\nproperty float32 y\r\nproperty float64 z\r\n\
property uint8 red\r\nproperty list uint8 float32 normals\r\nproperty int16 t\r\nproperty uint c\r\n\
element edge 1\r\nproperty int a\r\nend_header\r\n"
            .to_vec();
        bytes.push(3);
        for i in [0i32, 1, 2] {
            bytes.extend_from_slice(&i.to_be_bytes());
        }
        for (x, y, z, r, t, c) in
            [(1.5f32, -2.0f32, 3.25f64, 200u8, -7i16, 4_000_000_000u32), (0.0, 1.0, -1.0, 1, 300, 0)]
        {
            bytes.extend_from_slice(&x.to_be_bytes());
            bytes.extend_from_slice(&y.to_be_bytes());
            bytes.extend_from_slice(&z.to_be_bytes());
            bytes.push(r);
            bytes.push(2);
            bytes.extend_from_slice(&0.5f32.to_be_bytes());
            bytes.extend_from_slice(&0.5f32.to_be_bytes());
            bytes.extend_from_slice(&t.to_be_bytes());
            bytes.extend_from_slice(&c.to_be_bytes());
        }
        bytes.extend_from_slice(&9i32.to_be_bytes());
        let v = parse_ply(&bytes, Path::new("mesh.ply")).unwrap();
        assert_eq!(v.xyz, vec![[1.5, -2.0, 3.25], [0.0, 1.0, -1.0]]);
        assert_eq!(v.scalar("red").unwrap(), [200.0, 1.0]);
        assert_eq!(v.scalar("t").unwrap(), [-7.0, 300.0]);
        assert_eq!(v.scalar("c").unwrap(), [4.0e9, 0.0]);
        assert!(v.scalar("normals").is_none());
        assert_eq!(v.comments, ["made elsewhere"]);
        assert!(matches!(v.to_point_cloud(), Err(PlyFault::NotSheen { .. })));
        // The same as ASCII.
        let ascii = "ply\nformat ascii 1.0\nelement vertex 2\nproperty char x\nproperty short y\nproperty int z\n\
property list uchar int idx\nproperty ushort w\nend_header\n-3 7 9 2 1 1 65535\n4 5 6 0 12\n";
        let v = parse_ply(ascii.as_bytes(), Path::new("a.ply")).unwrap();
        assert_eq!(v.xyz, vec![[-3.0, 7.0, 9.0], [4.0, 5.0, 6.0]]);
        assert_eq!(v.scalar("w").unwrap(), [65535.0, 12.0]);
        assert_eq!(v.unit().unwrap(), LengthUnit::Mm, "no unit comment: millimetres");
    }

    #[test]
    fn the_unit_comment_is_parsed_and_an_unknown_unit_refused() {
        let ply = |unit: &str| {
            format!(
                "ply\nformat ascii 1.0\ncomment unit {unit}\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n"
            )
        };
        for (name, unit) in [("nm", LengthUnit::Nm), ("µm", LengthUnit::Um), ("m", LengthUnit::M)] {
            let v = parse_ply(ply(name).as_bytes(), Path::new("u.ply")).unwrap();
            assert_eq!(v.unit().unwrap(), unit, "{name}");
        }
        let v = parse_ply(ply("inch").as_bytes(), Path::new("u.ply")).unwrap();
        assert!(matches!(v.unit(), Err(PlyFault::UnknownUnit(u)) if u.found == "inch"));
        assert!(matches!(v.to_point_cloud(), Err(PlyFault::UnknownUnit(_))));
    }

    #[test]
    fn malformed_files_report_where() {
        let mut good = Vec::new();
        write_ply_to(&mut good, &cloud(10), &PlyWriteOptions::default()).unwrap();
        let cut = &good[..good.len() - 30];
        let err = parse_ply(cut, Path::new("/out/cloud.ply")).unwrap_err().to_string();
        assert!(err.contains("/out/cloud.ply") && err.contains(&format!("ends at byte {}", cut.len())), "{err}");
        assert!(err.contains("inside vertex 9 of 10"), "{err}");
        let mut ascii = Vec::new();
        write_ply_to(&mut ascii, &cloud(10), &PlyWriteOptions { format: PlyFormat::Ascii, source: None }).unwrap();
        let text = String::from_utf8(ascii).unwrap().replacen("0.25", "0.2x5", 3);
        // The lines before end_header, end_header itself, then the data.
        let first_data_line = text[..text.find("end_header").unwrap()].lines().count() + 2;
        let err = parse_ply(text.as_bytes(), Path::new("a.ply")).unwrap_err().to_string();
        assert!(err.contains(&format!("line {first_data_line}: '0.2x5' in vertex 0 is not a number")), "{err}");
        let cases: [(&[u8], &str); 6] = [
            (b"PLY?", "does not start with the line 'ply'"),
            (b"ply\nformat binary 1.0\nend_header\n", "header line 2: unknown format 'binary'"),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty int128 x\nend_header\n",
                "header line 4: unknown property type 'int128'",
            ),
            (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no 'end_header'"),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
                "lack the coordinate property 'z'",
            ),
            (b"ply\nformat ascii 1.0\nelement face 1\nend_header\n", "has no 'vertex' element"),
        ];
        for (bytes, expected) in cases {
            let err = parse_ply(bytes, Path::new("x.ply")).unwrap_err().to_string();
            assert!(err.contains(expected) && err.contains("x.ply"), "expected {expected:?} in {err}");
        }
        let huge = b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999999\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
        let err = parse_ply(huge, Path::new("h.ply")).unwrap_err().to_string();
        assert!(err.contains("truncated"), "{err}");
        // Huge counts of elements without properties hold no data (and must not spin).
        let empty = b"ply\nformat ascii 1.0\nelement junk 18446744073709551615\nelement vertex 1\nproperty float x\n\
property float y\nproperty float z\nend_header\n1 2 3\n";
        assert_eq!(parse_ply(empty, Path::new("e.ply")).unwrap().xyz, vec![[1.0, 2.0, 3.0]]);
        let mut extra = good.clone();
        extra.extend_from_slice(&[0; 5]);
        let err = parse_ply(&extra, Path::new("e.ply")).unwrap_err().to_string();
        assert!(err.contains("5 bytes after its last element"), "{err}");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

        #[test]
        fn reader_never_panics_on_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
            let _ = parse_ply(&bytes, Path::new("fuzz.ply"));
        }

        /// A valid header over an arbitrary body: an error or vertices.
        #[test]
        fn reader_never_panics_on_arbitrary_bodies(
            body in prop::collection::vec(any::<u8>(), 0..300),
            ascii in any::<bool>(),
            count in 0usize..20,
        ) {
            let format = if ascii { "ascii" } else { "binary_little_endian" };
            let mut bytes = format!(
                "ply\nformat {format} 1.0\nelement vertex {count}\nproperty float x\nproperty list uchar short l\n\
                 property double y\nproperty uchar z\nelement face 2\nproperty list int uint idx\nend_header\n"
            )
            .into_bytes();
            bytes.extend_from_slice(&body);
            if let Ok(v) = parse_ply(&bytes, Path::new("fuzz.ply")) {
                prop_assert_eq!(v.xyz.len(), count);
            }
        }
    }
}
