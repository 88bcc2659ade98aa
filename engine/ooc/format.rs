//! The scene directory: `index.bin` (header, bounds and one entry per batching point),
//! `geometry.bin` (one region of raw triangles per point) and `proxies-R.bin`. Every file is
//! untrusted on reading: sizes are checked before allocating, checksums before use, and each
//! error names the file and the byte offset.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use super::geom::{Aabb, Tri};
use super::OocError;

/// Magic bytes of `index.bin`.
pub const INDEX_MAGIC: &[u8; 8] = b"VXOOCIDX";
/// Magic bytes of `geometry.bin`.
pub const GEOMETRY_MAGIC: &[u8; 8] = b"VXOOCGEO";
/// Version of the index and geometry formats.
pub const FORMAT_VERSION: u32 = 1;
/// Bytes of the `geometry.bin` header (magic, version, reserved word).
pub const GEOMETRY_HEADER: u64 = 16;
/// Bytes of one triangle in `geometry.bin` (nine little-endian f32).
pub const TRI_BYTES: u64 = 36;
/// Bytes of one index entry.
pub const ENTRY_BYTES: u64 = 40;
/// Most triangles one batching point may hold.
pub const MAX_POINT_TRIANGLES: u32 = 1 << 24;

/// Name of the index file in a scene directory.
pub const INDEX_FILE: &str = "index.bin";
/// Name of the geometry file in a scene directory.
pub const GEOMETRY_FILE: &str = "geometry.bin";

/// Name of the proxy file at a resolution.
pub fn proxy_file(resolution: u32) -> String {
    format!("proxies-{resolution}.bin")
}

/// A little-endian reader over untrusted bytes that reports errors with file and offset.
pub(crate) struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at offset 0.
    pub(crate) fn new(path: &'a Path, bytes: &'a [u8]) -> Reader<'a> {
        Reader {
            path,
            bytes,
            pos: 0,
        }
    }

    /// An error at `offset` of this file.
    pub(crate) fn error(&self, offset: u64, reason: String) -> OocError {
        OocError::format(self.path, offset, reason)
    }

    /// Current offset.
    pub(crate) fn offset(&self) -> u64 {
        self.pos as u64
    }

    /// Bytes left after the current offset.
    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], OocError> {
        if self.remaining() < n {
            return Err(self.error(
                self.bytes.len() as u64,
                format!("truncated: {n} more bytes needed at offset {}", self.pos),
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    /// Checks the magic bytes.
    pub(crate) fn magic(&mut self, magic: &[u8; 8]) -> Result<(), OocError> {
        let got = self.take(8)?;
        if got != magic {
            return Err(self.error(
                0,
                format!("bad magic (expected {:?})", String::from_utf8_lossy(magic)),
            ));
        }
        Ok(())
    }

    /// Checks the format version.
    pub(crate) fn version(&mut self, version: u32) -> Result<(), OocError> {
        let at = self.offset();
        let got = self.u32()?;
        if got != version {
            return Err(self.error(
                at,
                format!("unsupported version {got} (expected {version})"),
            ));
        }
        Ok(())
    }

    /// Reads a u32.
    pub(crate) fn u32(&mut self) -> Result<u32, OocError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    /// Reads a u64.
    pub(crate) fn u64(&mut self) -> Result<u64, OocError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    /// Reads a finite f32.
    pub(crate) fn f32(&mut self) -> Result<f32, OocError> {
        let at = self.offset();
        let v = f32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes"));
        if !v.is_finite() {
            return Err(self.error(at, format!("non-finite value {v}")));
        }
        Ok(v)
    }

    /// Reads `n` u32 (the caller has checked the size).
    pub(crate) fn u32s(&mut self, n: usize) -> Result<Vec<u32>, OocError> {
        let s = self.take(4 * n)?;
        Ok(s.chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }

    /// Checks the trailing CRC-32 over everything before it.
    pub(crate) fn check_crc(&self) -> Result<(), OocError> {
        let n = self.bytes.len();
        if n < 4 {
            return Err(self.error(n as u64, "truncated: no checksum".into()));
        }
        let stored = u32::from_le_bytes(self.bytes[n - 4..].try_into().expect("4 bytes"));
        let actual = crc32fast::hash(&self.bytes[..n - 4]);
        if stored != actual {
            return Err(self.error(
                n as u64 - 4,
                format!("checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"),
            ));
        }
        Ok(())
    }
}

/// One batching point of the index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointEntry {
    /// Byte offset of its region in `geometry.bin`.
    pub offset: u64,
    /// Triangles in the region.
    pub triangles: u32,
    /// CRC-32 of the region.
    pub crc: u32,
    /// Bounds of its triangles.
    pub bounds: Aabb,
}

impl PointEntry {
    /// Bytes of its region.
    pub fn bytes(&self) -> u64 {
        self.triangles as u64 * TRI_BYTES
    }
}

/// An opened scene directory: the index in memory, the geometry file open for reads.
#[derive(Debug)]
pub struct OocScene {
    /// The scene directory.
    pub dir: PathBuf,
    /// The batching points.
    pub points: Vec<PointEntry>,
    /// Total triangles.
    pub triangles: u64,
    /// Bounds of the whole scene.
    pub bounds: Aabb,
    /// Size of `geometry.bin` in bytes.
    pub geometry_bytes: u64,
    geometry: File,
}

/// Serialises the index (with its trailing checksum).
pub(crate) fn index_bytes(
    points: &[PointEntry],
    triangles: u64,
    bounds: &Aabb,
    geometry_bytes: u64,
) -> Vec<u8> {
    let mut b = Vec::with_capacity(64 + points.len() * ENTRY_BYTES as usize);
    b.extend_from_slice(INDEX_MAGIC);
    b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    b.extend_from_slice(&(points.len() as u32).to_le_bytes());
    b.extend_from_slice(&triangles.to_le_bytes());
    b.extend_from_slice(&geometry_bytes.to_le_bytes());
    for v in bounds.lo.iter().chain(&bounds.hi) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for p in points {
        b.extend_from_slice(&p.offset.to_le_bytes());
        b.extend_from_slice(&p.triangles.to_le_bytes());
        b.extend_from_slice(&p.crc.to_le_bytes());
        for v in p.bounds.lo.iter().chain(&p.bounds.hi) {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

/// Reads a box (six finite f32, lo <= hi).
fn read_box(r: &mut Reader) -> Result<Aabb, OocError> {
    let at = r.offset();
    let mut b = Aabb::EMPTY;
    for k in 0..3 {
        b.lo[k] = r.f32()?;
    }
    for k in 0..3 {
        b.hi[k] = r.f32()?;
    }
    if (0..3).any(|k| b.lo[k] > b.hi[k]) {
        return Err(r.error(at, "box with min > max".into()));
    }
    Ok(b)
}

impl OocScene {
    /// Opens a scene directory, validating the index against the geometry file's size.
    pub fn open(dir: &Path) -> Result<OocScene, OocError> {
        let index_path = dir.join(INDEX_FILE);
        let meta = std::fs::metadata(&index_path).map_err(|e| OocError::io(&index_path, e))?;
        crate::safety::check_memory(format!("{}", index_path.display()), meta.len())?;
        let bytes = std::fs::read(&index_path).map_err(|e| OocError::io(&index_path, e))?;
        let mut r = Reader::new(&index_path, &bytes);
        r.magic(INDEX_MAGIC)?;
        r.version(FORMAT_VERSION)?;
        let at = r.offset();
        let n = r.u32()?;
        let triangles = r.u64()?;
        let geometry_bytes = r.u64()?;
        let bounds = read_box(&mut r)?;
        let need = n as u64 * ENTRY_BYTES + 4;
        if r.remaining() as u64 != need || n == 0 {
            return Err(r.error(
                at,
                format!(
                    "{n} points need {need} more bytes, the file has {}",
                    r.remaining()
                ),
            ));
        }
        r.check_crc()?;
        let geometry_path = dir.join(GEOMETRY_FILE);
        let geometry = File::open(&geometry_path).map_err(|e| OocError::io(&geometry_path, e))?;
        let actual = geometry
            .metadata()
            .map_err(|e| OocError::io(&geometry_path, e))?
            .len();
        if actual != geometry_bytes {
            return Err(OocError::format(
                &geometry_path,
                actual.min(geometry_bytes),
                format!("file has {actual} bytes, the index expects {geometry_bytes} (truncated?)"),
            ));
        }
        let mut points = Vec::with_capacity(n as usize);
        let mut next = GEOMETRY_HEADER;
        let mut sum = 0u64;
        for i in 0..n {
            let at = r.offset();
            let offset = r.u64()?;
            let tris = r.u32()?;
            let crc = r.u32()?;
            let b = read_box(&mut r)?;
            if offset != next || tris == 0 || tris > MAX_POINT_TRIANGLES {
                return Err(r.error(
                    at,
                    format!("point {i}: bad region (offset {offset}, {tris} triangles)"),
                ));
            }
            next = offset + tris as u64 * TRI_BYTES;
            if next > geometry_bytes {
                return Err(r.error(
                    at,
                    format!("point {i}: region ends at {next}, past the geometry file"),
                ));
            }
            sum += tris as u64;
            points.push(PointEntry {
                offset,
                triangles: tris,
                crc,
                bounds: b,
            });
        }
        if sum != triangles || next != geometry_bytes {
            return Err(r.error(at, format!("regions hold {sum} triangles up to byte {next}, header says {triangles} and {geometry_bytes}")));
        }
        // The geometry header.
        let mut head = [0u8; GEOMETRY_HEADER as usize];
        geometry
            .read_exact_at(&mut head, 0)
            .map_err(|e| OocError::io(&geometry_path, e))?;
        let mut g = Reader::new(&geometry_path, &head);
        g.magic(GEOMETRY_MAGIC)?;
        g.version(FORMAT_VERSION)?;
        Ok(OocScene {
            dir: dir.to_path_buf(),
            points,
            triangles,
            bounds,
            geometry_bytes,
            geometry,
        })
    }

    /// Path of `geometry.bin`.
    pub fn geometry_path(&self) -> PathBuf {
        self.dir.join(GEOMETRY_FILE)
    }

    /// Reads point `i`'s triangles, checking the region's checksum, that every value is finite
    /// and that every vertex lies inside the point's bounds (which the proxies rely on).
    pub fn read_point(&self, i: u32) -> Result<Vec<Tri>, OocError> {
        let p = &self.points[i as usize];
        let path = self.geometry_path();
        crate::safety::check_memory(format!("point {i} of {}", path.display()), p.bytes())?;
        let mut bytes = vec![0u8; p.bytes() as usize];
        self.geometry
            .read_exact_at(&mut bytes, p.offset)
            .map_err(|e| {
                OocError::format(
                    &path,
                    p.offset,
                    format!("point {i}: reading its region: {e}"),
                )
            })?;
        let crc = crc32fast::hash(&bytes);
        if crc != p.crc {
            return Err(OocError::format(
                &path,
                p.offset,
                format!(
                    "point {i}: region checksum mismatch (index {:#010x}, data {crc:#010x})",
                    p.crc
                ),
            ));
        }
        let mut tris = Vec::with_capacity(p.triangles as usize);
        for (t, c) in bytes.chunks_exact(TRI_BYTES as usize).enumerate() {
            let mut tri = [[0f32; 3]; 3];
            for (j, v) in c.chunks_exact(4).enumerate() {
                tri[j / 3][j % 3] = f32::from_le_bytes(v.try_into().expect("4 bytes"));
            }
            let inside = tri.iter().all(|v| {
                (0..3).all(|k| v[k].is_finite() && p.bounds.lo[k] <= v[k] && v[k] <= p.bounds.hi[k])
            });
            if !inside {
                return Err(OocError::format(
                    &path,
                    p.offset + t as u64 * TRI_BYTES,
                    format!("point {i}: triangle {t} is non-finite or outside the point's bounds"),
                ));
            }
            tris.push(tri);
        }
        Ok(tris)
    }

    /// Bytes of all scene files that rendering may read (geometry and index).
    pub fn file_bytes(&self) -> u64 {
        self.geometry_bytes + 64 + self.points.len() as u64 * ENTRY_BYTES
    }
}
