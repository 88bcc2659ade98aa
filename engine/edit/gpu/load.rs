//! Loading a material scene into the GPU hash DAG, and saving any hash DAG scene back to a
//! `.vdag` file (`docs/editing-gpu.md`, "Load and save").
//!
//! Materials are per voxel *occurrence* while an svdag shares equal geometry, so one svdag node
//! can stand for several hash-DAG items (one per distinct material pattern under it). The host
//! therefore walks the svdag once in depth-first voxel order, as `HashDag::insert_svdag` does,
//! and makes per level the list of distinct *occurrence records* in the merge's input format
//! (a leaf: 2 mask words + 8 words of positional 4-bit materials; an inner node: 8 child values
//! naming records of the level below). Equal records are listed once (a hash map per level), so
//! the uploads are bounded by the distinct subtrees, not by the SVO. Everything else is the
//! GPU's, exactly as for an edit: canonical items (uniform leaves and nodes become full / empty
//! children, materials packed by rank), duplicate removal, the bulk find-or-insert into the
//! per-size tables, and the pointer resolution, level by level bottom-up.

use std::path::Path;
use std::sync::Arc;

use rustc_hash::FxHashMap;

use super::{
    GpuDagError, GpuHashDag, GpuHashDagConfig, HashDagImage, MergeLevel, VALUE_EMPTY, VALUE_TEMP,
};
use crate::attr::Materials;
use crate::dag::encode::{DigestBuilder, EncodedDag};
use crate::dag::{Svdag, VdagFile};
use crate::edit::item::{Root, TABLE_COUNT};
use crate::edit::walk;
use crate::gpu::{Buffer, GpuContext, MemLocation, Profiler};

/// Most records per level: record indices travel in the 28 index bits of a child value.
const MAX_RECORDS: usize = 1 << 28;

/// The per-level occurrence records of a material scene (module docs).
struct Records {
    /// 10 words per leaf record.
    leaves: Vec<u32>,
    /// Per inner level (index = level - 1): 8 child values per record.
    nodes: Vec<Vec<u32>>,
    leaf_index: FxHashMap<[u32; 10], u32>,
    node_index: Vec<FxHashMap<[u32; 8], u32>>,
}

impl Records {
    /// Items per table (index = item words - 2) the records make: a leaf has 2 words and one
    /// material nibble per voxel, an inner node 1 + one per child.
    fn items_per_table(&self) -> [u64; TABLE_COUNT as usize] {
        let mut items = [0u64; TABLE_COUNT as usize];
        for leaf in self.leaves.chunks_exact(10) {
            let voxels = leaf[0].count_ones() + leaf[1].count_ones();
            items[voxels.div_ceil(8) as usize] += 1;
        }
        for node in self.nodes.iter().flat_map(|level| level.chunks_exact(8)) {
            // An empty scene's root record names no child (and is no item).
            let children = node.iter().filter(|&&v| v != VALUE_EMPTY).count();
            if let Some(table) = children.checked_sub(1) {
                items[table] += 1;
            }
        }
        items
    }

    fn push_leaf(&mut self, record: [u32; 10]) -> Result<u32, GpuDagError> {
        if let Some(&i) = self.leaf_index.get(&record) {
            return Ok(i);
        }
        let i = self.leaf_index.len();
        if i >= MAX_RECORDS {
            return Err(GpuDagError::Invalid(
                "more than 2^28 distinct leaves in one level".into(),
            ));
        }
        self.leaves.extend_from_slice(&record);
        self.leaf_index.insert(record, i as u32);
        Ok(i as u32)
    }

    fn push_node(&mut self, level: u32, record: [u32; 8]) -> Result<u32, GpuDagError> {
        let l = level as usize - 1;
        if let Some(&i) = self.node_index[l].get(&record) {
            return Ok(i);
        }
        let i = self.node_index[l].len();
        if i >= MAX_RECORDS {
            return Err(GpuDagError::Invalid(format!(
                "more than 2^28 distinct nodes at level {level}"
            )));
        }
        self.nodes[l].extend_from_slice(&record);
        self.node_index[l].insert(record, i as u32);
        Ok(i as u32)
    }

    /// Record index of the svdag node at word `node` (level `level`) whose first voxel is
    /// `ids[*next]`.
    fn walk(
        &mut self,
        dag: &Svdag,
        node: usize,
        level: u32,
        ids: &[u8],
        next: &mut usize,
    ) -> Result<u32, GpuDagError> {
        if level == 0 {
            let mask = dag.leaf_mask(node);
            let mut record = [0u32; 10];
            record[0] = mask as u32;
            record[1] = (mask >> 32) as u32;
            for v in 0..64 {
                if mask >> v & 1 == 1 {
                    let m = *ids.get(*next).ok_or_else(|| {
                        GpuDagError::Invalid(format!("{} material ids, more voxels", ids.len()))
                    })?;
                    record[2 + v / 8] |= (m as u32) << (4 * (v % 8));
                    *next += 1;
                }
            }
            return self.push_leaf(record);
        }
        let mut record = [VALUE_EMPTY; 8];
        for (o, value) in record.iter_mut().enumerate() {
            if let Some(child) = dag.child(node, o as u32) {
                *value = VALUE_TEMP | self.walk(dag, child, level - 1, ids, next)?;
            }
        }
        self.push_node(level, record)
    }
}

impl GpuHashDag {
    /// Loads an `svdag32` DAG with per-voxel materials (one id per voxel in depth-first Morton
    /// order, below the palette size) into new tables with material leaves, on the GPU level
    /// by level bottom-up (module docs); its root becomes the current root and the palette is
    /// kept ([`GpuHashDag::palette`]).
    pub fn load_materials(
        ctx: &Arc<GpuContext>,
        config: &GpuHashDagConfig,
        dag: &Svdag,
        materials: &Materials,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<GpuHashDag, GpuDagError> {
        dag.validate()?;
        materials
            .validate()
            .map_err(|e| GpuDagError::Invalid(e.to_string()))?;
        let root_level = dag.root_level();
        let mut records = Records {
            leaves: Vec::new(),
            nodes: vec![Vec::new(); root_level as usize],
            leaf_index: FxHashMap::default(),
            node_index: vec![FxHashMap::default(); root_level as usize],
        };
        let mut next = 0;
        records.walk(dag, 0, root_level, &materials.ids, &mut next)?;
        if next != materials.ids.len() {
            return Err(GpuDagError::Invalid(format!(
                "{} material ids for {next} voxels",
                materials.ids.len()
            )));
        }
        let loaded = records.items_per_table();
        let Records { leaves, nodes, .. } = records;
        let mut hd = GpuHashDag::for_items(ctx, config, root_level, true, &loaded)?;
        hd.palette = materials.palette.clone();
        let mut below: Option<Buffer> = None;
        let levels = std::iter::once((leaves, 10)).chain(nodes.into_iter().map(|n| (n, 8)));
        for (level, (input, record_words)) in levels.enumerate() {
            let count = (input.len() / record_words) as u32;
            if count == 0 {
                // Only the leaves of an empty scene: the root record names no child.
                continue;
            }
            let input = ctx.upload("hash dag load records", &input)?;
            let results = ctx.create_buffer(
                "hash dag load results",
                4 * count as u64,
                MemLocation::GpuOnly,
            )?;
            hd.merge(
                &[MergeLevel {
                    input: (&input).into(),
                    count,
                    leaves: level == 0,
                    below: below.as_ref(),
                    results: &results,
                    result_index: None,
                }],
                false,
                profiler.as_deref_mut(),
            )?;
            below = Some(results);
        }
        let results = below.expect("the root level always has its record");
        // The root level has one record, the root.
        hd.roots = vec![hd.read_root(&results)?];
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok(hd)
    }

    /// The palette of a material scene as 16 RGBA8 sRGB entries (entries past the palette
    /// are zero); `None` for a geometry-only scene.
    pub fn palette(&self) -> Option<[u32; 16]> {
        (!self.palette.is_empty())
            .then(|| std::array::from_fn(|i| self.palette.get(i).copied().unwrap_or(0)))
    }

    /// The current root as a `.vdag` file (see [`HashDagImage::to_file`]).
    pub fn to_file(&self) -> Result<VdagFile, GpuDagError> {
        let palette = (!self.palette.is_empty()).then_some(self.palette.as_slice());
        self.download()?.to_file(self.root(), palette)
    }

    /// Saves the current root as a compact `svdag32` `.vdag` file, atomically, with its
    /// materials and palette when it has them: loading a file `voxdag build` wrote and saving
    /// it again gives the same bytes.
    pub fn save(&self, path: &Path) -> Result<(), GpuDagError> {
        Ok(self.to_file()?.save(path)?)
    }
}

impl HashDagImage {
    /// The scene under `root` as a `.vdag` file: the compact `svdag32` DAG, the voxel digest,
    /// and with materials the per-voxel ids (depth-first order) and `palette` (required then;
    /// every id must be below its size).
    pub fn to_file(&self, root: Root, palette: Option<&[u32]>) -> Result<VdagFile, GpuDagError> {
        // One streamed pass over the voxels for the digest (and the ids): no code list.
        let mut digest = DigestBuilder::default();
        let mut ids = Vec::new();
        let keep_ids = self.with_materials;
        walk::for_each_voxel(self, root, |code, m| {
            digest.push(code);
            if keep_ids {
                ids.push(m);
            }
        })?;
        let materials = match (self.with_materials, palette) {
            (true, Some(palette)) => Some(
                Materials::new(palette.to_vec(), ids)
                    .map_err(|e| GpuDagError::Invalid(format!("saving materials: {e}")))?,
            ),
            (true, None) => {
                return Err(GpuDagError::Invalid(
                    "saving a material scene needs its palette".into(),
                ))
            }
            (false, _) => None,
        };
        let digest = digest.finish();
        let dag = self.to_svdag(root)?;
        Ok(VdagFile {
            encoded: EncodedDag::Svdag32(dag),
            colors: Vec::new(),
            digest: Some(digest),
            stored_colors: None,
            materials,
        })
    }
}
