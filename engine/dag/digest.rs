//! The content digest of a `.vdag` file (section 7, `docs/vdag-format.md`): a 128-bit hash of
//! the canonical DAG plus a 64-bit hash of the decoded colours.
//!
//! The canonical DAG is the tree of the voxel set: a node is its level, its child mask and its
//! children's hashes (a leaf: its 64-bit mask). Any encoding of the same voxels (svdag32 with or
//! without shared nodes, ssvdag mirrors, tsvdag transforms) hashes the same, and because the
//! hash of a stored node is memoized, computing it costs O(stored nodes), not O(voxels): a
//! 1 KB file of a solid 2^21 grid (2^63 voxels) is checked instantly. It detects corruption and
//! encoder or decoder bugs; it is not a signature (whoever writes a file can write its digest).

use std::hash::Hash;

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::encode::{EncodeError, EncodedDag, TreeView};
use super::Svdag;
use crate::attr::{AttrError, ChunkedColors, Materials};

/// What section 7 stores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ContentDigest {
    /// Occupied voxels (counted through the DAG).
    pub voxels: u64,
    /// Hash of the canonical DAG.
    pub dag: [u64; 2],
    /// Hash of the decoded colours (count and every RGBA8 word in order).
    pub colors: u64,
}

/// Bytes of section 7.
pub(crate) const CONTENT_DIGEST_LEN: u64 = 32;

/// The splitmix64 finaliser: a bijective 64-bit mix.
fn mix(mut x: u64) -> u64 {
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Two independent 64-bit lanes absorbing words.
#[derive(Clone, Copy)]
struct Hasher2([u64; 2]);

impl Hasher2 {
    fn new(tag: u64) -> Hasher2 {
        Hasher2([
            mix(tag ^ 0x243f_6a88_85a3_08d3),
            mix(tag ^ 0x1319_8a2e_0370_7344),
        ])
    }
    fn absorb(&mut self, v: u64) {
        self.0[0] = mix(self.0[0].rotate_left(23) ^ v);
        self.0[1] = mix(self.0[1].wrapping_add(v).rotate_left(41) ^ 0x9e37_79b9_7f4a_7c15);
    }
}

/// Known (hash, voxel count) per (level, node handle): per level by the packed handle
/// (`TreeView::packed`, 32-byte entries: a 64K^3 TSVDAG has tens of millions of handles), the
/// rest (translated windows) by the handle itself.
struct Memo<N> {
    packed: Vec<FxHashMap<u64, ([u64; 2], u64)>>,
    other: FxHashMap<(u32, N), ([u64; 2], u64)>,
}

/// Hash and voxel count of a node of `view` at `level`, memoized per (level, handle).
fn node_hash<V: TreeView>(
    view: &V,
    node: &V::Node,
    level: u32,
    memo: &mut Memo<V::Node>,
) -> Result<([u64; 2], u64), EncodeError>
where
    V::Node: Hash + Eq,
{
    let packed = view.packed(node);
    let known = match packed {
        Some(key) => memo.packed[level as usize].get(&key),
        None => memo.other.get(&(level, node.clone())),
    };
    if let Some(&known) = known {
        return Ok(known);
    }
    let result = if level == 0 {
        let mask = view.leaf(node)?;
        let mut h = Hasher2::new(0);
        h.absorb(mask);
        (h.0, mask.count_ones() as u64)
    } else {
        let children = view.children(node, level)?;
        let mask = children
            .iter()
            .enumerate()
            .fold(0u64, |m, (o, c)| m | (c.is_some() as u64) << o);
        let mut h = Hasher2::new(level as u64);
        h.absorb(mask);
        let mut voxels = 0u64;
        for child in children.iter().flatten() {
            let (ch, n) = node_hash(view, child, level - 1, memo)?;
            h.absorb(ch[0]);
            h.absorb(ch[1]);
            voxels = voxels.saturating_add(n);
        }
        (h.0, voxels)
    };
    match packed {
        Some(key) => memo.packed[level as usize].insert(key, result),
        None => memo.other.insert((level, node.clone()), result),
    };
    Ok(result)
}

/// Hash and voxel count of the canonical DAG of `view`.
fn dag_hash<V: TreeView>(view: &V) -> Result<([u64; 2], u64), EncodeError>
where
    V::Node: Hash + Eq,
{
    let Some(root) = view.root()? else {
        return Ok((Hasher2::new(u64::MAX).0, 0));
    };
    let root_level = view.resolution().trailing_zeros() - 2;
    let mut memo = Memo {
        packed: vec![FxHashMap::default(); root_level as usize + 1],
        other: FxHashMap::default(),
    };
    node_hash(view, &root, root_level, &mut memo)
}

/// Hash of a colour array (its length first).
pub fn colors_hash(colors: &[u32]) -> u64 {
    let mut h = Hasher2::new(colors.len() as u64);
    for pair in colors.chunks(2) {
        let v = pair[0] as u64 | pair.get(1).map_or(0, |&c| (c as u64) << 32);
        h.absorb(v);
    }
    h.0[0] ^ h.0[1].rotate_left(17)
}

/// [`colors_hash`] of the decoded colours of `chunks`, decoded a batch of chunks at a time (in
/// parallel, absorbed in order): memory for one batch, not for every colour.
pub fn chunked_colors_hash(chunks: &ChunkedColors) -> Result<u64, AttrError> {
    const BATCH: usize = 256;
    let mut h = ColorsHasher::new(chunks.color_count());
    let count = chunks.chunk_count();
    for first in (0..count).step_by(BATCH) {
        let decoded: Vec<Vec<u32>> = (first..(first + BATCH).min(count))
            .into_par_iter()
            .map(|c| chunks.decode_chunk(c))
            .collect::<Result<_, _>>()?;
        for colors in &decoded {
            h.absorb(colors);
        }
    }
    Ok(h.finish())
}

/// Hash of a material scene's attributes (palette and ids; `docs/vdag-format.md` section 7),
/// stored in the digest's colour field in place of [`colors_hash`].
pub fn materials_hash(m: &Materials) -> u64 {
    let mut h = Hasher2::new(1 << 63 | m.ids.len() as u64);
    h.absorb(m.palette.len() as u64);
    for c in m.palette16() {
        h.absorb(c as u64);
    }
    for word in m.ids.chunks(16) {
        let v = word
            .iter()
            .enumerate()
            .fold(0u64, |v, (i, &id)| v | (id as u64) << (4 * i));
        h.absorb(v);
    }
    h.0[0] ^ h.0[1].rotate_left(17)
}

/// The colour field of the digest: [`materials_hash`] of a material scene, else
/// [`colors_hash`] of its colours.
pub fn attributes_hash(colors: &[u32], materials: Option<&Materials>) -> u64 {
    match materials {
        Some(m) => materials_hash(m),
        None => colors_hash(colors),
    }
}

/// Hash lanes of a leaf with `mask` (a node hash of the canonical DAG, computed bottom-up by
/// the streaming builder).
pub(crate) fn leaf_hash(mask: u64) -> [u64; 2] {
    let mut h = Hasher2::new(0);
    h.absorb(mask);
    h.0
}

/// Hash lanes of an inner node at `level` with child mask `mask` and its children's lanes in
/// octant order.
pub(crate) fn inner_hash(
    level: u32,
    mask: u32,
    children: impl Iterator<Item = [u64; 2]>,
) -> [u64; 2] {
    let mut h = Hasher2::new(level as u64);
    h.absorb(mask as u64);
    for c in children {
        h.absorb(c[0]);
        h.absorb(c[1]);
    }
    h.0
}

/// Hash lanes of the empty scene.
pub(crate) fn empty_hash() -> [u64; 2] {
    Hasher2::new(u64::MAX).0
}

/// [`colors_hash`] fed in pieces, for colours that are never all in memory at once; the count
/// is hashed first, so it must be known up front.
pub struct ColorsHasher {
    h: Hasher2,
    /// A colour waiting for its pair partner.
    odd: Option<u32>,
}

impl ColorsHasher {
    /// A hasher for `count` colours.
    pub fn new(count: u64) -> ColorsHasher {
        ColorsHasher {
            h: Hasher2::new(count),
            odd: None,
        }
    }

    /// Absorbs the next colours.
    pub fn absorb(&mut self, colors: &[u32]) {
        let mut rest = colors;
        if let Some(first) = self.odd.take() {
            let Some((&c, tail)) = rest.split_first() else {
                self.odd = Some(first);
                return;
            };
            self.h.absorb(first as u64 | (c as u64) << 32);
            rest = tail;
        }
        let pairs = rest.chunks_exact(2);
        self.odd = pairs.remainder().first().copied();
        for pair in pairs {
            self.h.absorb(pair[0] as u64 | (pair[1] as u64) << 32);
        }
    }

    /// The hash ([`colors_hash`] of the concatenation).
    pub fn finish(mut self) -> u64 {
        if let Some(c) = self.odd.take() {
            self.h.absorb(c as u64);
        }
        self.h.0[0] ^ self.h.0[1].rotate_left(17)
    }
}

impl ContentDigest {
    /// The digest of `encoded` with `colors` (the decoded colours a reader sees), in O(stored
    /// nodes) for every encoding: each distinct node handle (a tsvdag handle includes its
    /// transform and translation) is hashed once.
    pub fn of(encoded: &EncodedDag, colors: &[u32]) -> Result<ContentDigest, EncodeError> {
        let (dag, voxels) = match encoded {
            EncodedDag::Svdag32(d) => return ContentDigest::of_svdag(d, colors),
            EncodedDag::Ssvdag(d) => dag_hash(d)?,
            EncodedDag::Tsvdag(d) => dag_hash(d)?,
        };
        Ok(ContentDigest {
            voxels,
            dag,
            colors: colors_hash(colors),
        })
    }

    /// [`ContentDigest::of`] an SVDAG (no copy).
    pub fn of_svdag(dag: &Svdag, colors: &[u32]) -> Result<ContentDigest, EncodeError> {
        let (hash, voxels) = dag_hash(dag)?;
        Ok(ContentDigest {
            voxels,
            dag: hash,
            colors: colors_hash(colors),
        })
    }

    /// The 32 bytes of section 7.
    pub(crate) fn to_bytes(self) -> [u8; CONTENT_DIGEST_LEN as usize] {
        let mut b = [0u8; CONTENT_DIGEST_LEN as usize];
        for (i, v) in [self.voxels, self.dag[0], self.dag[1], self.colors]
            .into_iter()
            .enumerate()
        {
            b[8 * i..8 * i + 8].copy_from_slice(&v.to_le_bytes());
        }
        b
    }

    /// Parses the 32 bytes of section 7.
    pub(crate) fn from_bytes(b: &[u8]) -> ContentDigest {
        let w = |i: usize| u64::from_le_bytes(b[8 * i..8 * i + 8].try_into().expect("8 bytes"));
        ContentDigest {
            voxels: w(0),
            dag: [w(1), w(2)],
            colors: w(3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Voxels;

    #[test]
    fn chunked_colours_hash_like_their_decoded_values() {
        use crate::attr::{ColorCodec, LosslessVariant};
        // 1..=3 colours per chunk, past one decode batch of 256 chunks, odd sizes splitting
        // the hash's colour pairs.
        let colors: Vec<u32> = (0..1201u32)
            .map(|i| 0xff00_0000 | i.wrapping_mul(2_654_435_761) >> 8)
            .collect();
        let mut sizes = Vec::new();
        let mut left = colors.len() as u64;
        for k in 0.. {
            let n = (k % 3 + 1).min(left);
            sizes.push(n);
            left -= n;
            if left == 0 {
                break;
            }
        }
        assert!(sizes.len() > 256);
        let codec = ColorCodec::Lossless(LosslessVariant::Rgb888);
        let hidden = indicatif::ProgressBar::hidden();
        let chunks = ChunkedColors::encode(&colors, &sizes, codec, 0, &hidden).unwrap();
        assert_eq!(chunked_colors_hash(&chunks).unwrap(), colors_hash(&colors));
    }

    #[test]
    fn digest_is_canonical_and_detects_changes() {
        let v = Voxels::from_coords(16, [[1, 2, 3], [9, 9, 9], [15, 0, 7]]);
        let dag = Svdag::from_voxels(&v).unwrap();
        let d = ContentDigest::of(&EncodedDag::Svdag32(dag.clone()), &[]).unwrap();
        assert_eq!(d.voxels, 3);
        assert_eq!(ContentDigest::from_bytes(&d.to_bytes()), d);
        let w = Voxels::from_coords(16, [[1, 2, 3], [9, 9, 9], [15, 0, 6]]);
        let other = Svdag::from_voxels(&w).unwrap();
        let e = ContentDigest::of(&EncodedDag::Svdag32(other), &[]).unwrap();
        assert_ne!(d.dag, e.dag);
        assert_ne!(colors_hash(&[1, 2]), colors_hash(&[1, 3]));
        assert_ne!(colors_hash(&[]), colors_hash(&[0]));
        let colors: Vec<u32> = (0..11).map(|i| i * 0x0101_0101).collect();
        for split in [0, 1, 2, 5, 11] {
            let mut h = ColorsHasher::new(11);
            h.absorb(&colors[..split]);
            h.absorb(&[]);
            h.absorb(&colors[split..]);
            assert_eq!(h.finish(), colors_hash(&colors), "split at {split}");
        }
    }
}
