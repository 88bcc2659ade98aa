//! GPU renderer: uploads an SVDAG and ray casts it with `shaders/glsl/render/primary.comp`.
//!
//! The shader runs the same traversal and shading as the CPU reference
//! ([`super::cpu::render_cpu`]), built from the same [`RenderParams`]; one dispatch of 8x8
//! workgroups writes an RGBA8 storage image and a per-pixel `u32` hit buffer, both read back.
//! [`GpuRenderer::record`] records that pass into a caller's command buffer and image instead
//! (frames in flight, the viewer); [`GpuRenderer::render`] is a blocking wrapper over it.
//! Buffers are reached through device addresses passed as push constants, so the DAG may exceed
//! `maxStorageBufferRange` (up to `maxMemoryAllocationSize` per buffer).

use std::sync::{Arc, OnceLock};
use std::time::Instant;

use indicatif::ProgressBar;

use super::cpu::ColorSource;
use super::format::{GpuDagData, TraversalFormat};
use super::gpu_shared::{FirstHit, PrimaryPush};
use super::params::{RenderParams, FLAG_HAS_COLORS};
use super::{RenderOutput, RenderSettings};
use crate::attr::chunks::MAX_CHUNK_COLORS;
use crate::attr::{AttrError, ChunkedColors, ColorCodec, ColorFormat, LosslessVariant};
use crate::dag::encode::EncodedDag;
use crate::dag::Svdag;
use crate::edit::gpu::GpuHashDag;
use crate::edit::item::{Root, MATERIAL_COUNT, MAX_ITEM_WORDS, MIN_ITEM_WORDS, TABLE_COUNT};
use crate::gpu::{
    made_once, shaders, BindingKind, Bound, Buffer, Commands, ComputePipeline, ComputePipelineDesc,
    GpuContext, GpuError, Image, MemLocation, Profiler, TexelBuffer,
};

/// Workgroup size of `primary.comp` (specialization constants 0 and 1).
const WORKGROUP: [u32; 2] = [8, 8];

/// The host-visible frame constants of one frame slot, written by [`GpuRenderer::record`]
/// through their mapping (no allocation per frame).
pub struct RenderFrame {
    params: Buffer,
}

/// Renders DAGs on the GPU; holds the compiled pipelines (svdag32's full variant at creation,
/// the others when first recorded).
pub struct GpuRenderer {
    ctx: Arc<GpuContext>,
    /// Per traversal format, the primary-ray pipeline per [`PrimaryVariant::index`].
    primary: Vec<[OnceLock<ComputePipeline>; 4]>,
}

/// Which code the primary-ray pipeline compiles in (`primary.comp`'s specialization constants
/// 2 and 3). lavapipe runs an `if` that no lane takes (masked) and each loop body at least
/// once, so a geometry-only scene paid for every ray's colour index and a render without
/// shadows for one masked pass through the shadow ray's traversal (docs/rendering.md, "Code
/// that no pixel needs").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PrimaryVariant {
    /// The hit's colour index is computed (colours to shade, or first hits to write).
    colors: bool,
    /// Shadow rays are traced (`FLAG_SHADOWS`).
    shadows: bool,
}

impl PrimaryVariant {
    /// The variant that renders everything.
    const FULL: PrimaryVariant = PrimaryVariant {
        colors: true,
        shadows: true,
    };

    /// Slot of the variant in `GpuRenderer::primary`.
    fn index(self) -> usize {
        self.colors as usize | (self.shadows as usize) << 1
    }
}

/// An SVDAG uploaded to the GPU: its words, per-node voxel counts and colour chunks (encoded
/// words and both chunk tables, `attr::ChunkedColors`).
pub struct GpuScene {
    pub(super) format: TraversalFormat,
    /// The format info block and tables (`GpuDagData::info`), word pairs as texels.
    pub(super) tables: TexelBuffer,
    pub(super) words: Buffer,
    pub(super) node_voxels: Buffer,
    pub(super) color_words: Buffer,
    pub(super) chunk_starts: Buffer,
    pub(super) chunk_offsets: Buffer,
    pub(super) color_format: ColorFormat,
    pub(super) chunk_count: u32,
    /// The root the traversal starts from, per dispatch (`PrimaryPush::dag_root`): the hash
    /// DAG's root child value; 0 for the other formats (their root is in their data).
    pub(super) dag_root: u32,
    /// The hash DAG's super-block table addresses this scene reads (empty for other formats).
    hash_tables: Vec<u64>,
    resolution: u32,
    color_count: u64,
}

/// Colours per chunk of [`colors_for_allocation`]: the binary search of the chunk table stays
/// short (sponza-crytek at 8192: 605 chunks) and every chunk is far below `MAX_CHUNK_COLORS`.
const FITTED_CHUNK_COLORS: u64 = 1 << 20;

/// Raw colours (one RGBA8 word per voxel) whose words exceed `max_allocation` bytes (the
/// device's largest buffer) or one chunk's index range, re-encoded for the upload as lossless
/// RGB888 chunks of `FITTED_CHUNK_COLORS` colours: exact (alpha is 255 on the GPU either way)
/// and far smaller (sponza-crytek at 8192: 2.54 GB of raw words against lavapipe's 2 GiB
/// limit, ~0.1 GB of chunks). `None` when the raw words fit as they are. The chunks follow the
/// colour order, not SVO nodes (`chunk_depth` 0): they are made for the GPU, never stored.
pub fn colors_for_allocation(
    colors: &[u32],
    max_allocation: u64,
) -> Result<Option<ChunkedColors>, AttrError> {
    let count = colors.len() as u64;
    if count * 4 <= max_allocation && count <= MAX_CHUNK_COLORS {
        return Ok(None);
    }
    let sizes: Vec<u64> = (0..count.div_ceil(FITTED_CHUNK_COLORS))
        .map(|c| FITTED_CHUNK_COLORS.min(count - c * FITTED_CHUNK_COLORS))
        .collect();
    let codec = ColorCodec::Lossless(LosslessVariant::Rgb888);
    ChunkedColors::encode(colors, &sizes, codec, 0, &ProgressBar::hidden()).map(Some)
}

/// Palette of a hash DAG with materials: the sRGB RGB8 colour of each material id.
pub type Palette = [[u8; 3]; MATERIAL_COUNT as usize];

/// Words of the hash DAG binding's info block (`HDAG_INFO_*` in `render/dag_hash.glsl`): the
/// table variant id, a reserved word, then each table's super-block table address (u64, low
/// word first).
const HASH_INFO_VARIANT: usize = 0;
const HASH_INFO_TABLES: usize = 2;
const HASH_INFO_WORDS: usize = HASH_INFO_TABLES + 2 * TABLE_COUNT as usize;

/// The child value the hash DAG traversal starts from (`EDIT_EMPTY`, `EDIT_FULL | m`, or the
/// pointer), after checking that it names a slab the tables have.
fn hash_root_value(dag: &GpuHashDag, root: Root) -> Result<u32, GpuError> {
    match root {
        Root::Empty => Ok(0xFFFF_FFFF),
        Root::Full(m) if (m as u32) < MATERIAL_COUNT => Ok(0xF000_0000 | m as u32),
        Root::Node(p) => {
            let slabs = dag
                .table(p.words())
                .map_or(0, |t| t.pool().capacity_slabs());
            if p.words() > MAX_ITEM_WORDS || (p.handle() >> 5) as u64 >= slabs {
                return Err(GpuError::InvalidArgument(format!(
                    "hash DAG root {:#010x} names no slab of its tables",
                    p.0
                )));
            }
            Ok(p.0)
        }
        Root::Full(m) => Err(GpuError::InvalidArgument(format!(
            "hash DAG root full with material {m} (materials are 0..{MATERIAL_COUNT})"
        ))),
    }
}

/// The super-block table address of each of the hash DAG's nine tables.
fn hash_table_addresses(dag: &GpuHashDag) -> Vec<u64> {
    (MIN_ITEM_WORDS..=MAX_ITEM_WORDS)
        .map(|w| dag.table(w).map_or(0, |t| t.pool().table_address()))
        .collect()
}

impl GpuScene {
    /// Grid side length N of the uploaded DAG.
    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Number of per-voxel colours (0 when the scene has none).
    pub fn color_count(&self) -> u64 {
        self.color_count
    }

    /// The DAG format the scene is traversed in.
    pub fn format(&self) -> TraversalFormat {
        self.format
    }

    /// Device memory held by the scene's node data (words, voxel counts, info block), in bytes.
    pub fn dag_bytes(&self) -> u64 {
        self.words.size() + self.node_voxels.size() + self.tables.buffer().size()
    }

    /// Device memory held by the scene's buffers, in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.tables.buffer().size()
            + self.words.size()
            + self.node_voxels.size()
            + self.color_words.size()
            + self.chunk_starts.size()
            + self.chunk_offsets.size()
    }

    /// Stored format of the uploaded colours.
    pub fn color_format(&self) -> ColorFormat {
        self.color_format
    }

    /// Makes `root` (of the hash DAG this scene was bound to with
    /// [`GpuRenderer::bind_hash_dag`]) the root later recordings traverse: the editor calls it
    /// every frame with the current root (no allocation, nothing recorded; recordings already
    /// made keep the root they were recorded with). Errors when the scene is not a binding of
    /// `dag` (its tables moved or it is another DAG) or `root` names no slab of its tables.
    pub fn set_hash_root(&mut self, dag: &GpuHashDag, root: Root) -> Result<(), GpuError> {
        if self.format != TraversalFormat::HashDag
            || dag.resolution() != self.resolution
            || hash_table_addresses(dag) != self.hash_tables
        {
            return Err(GpuError::InvalidArgument(
                "set_hash_root: the scene is not a binding of this hash DAG (bind it again)".into(),
            ));
        }
        self.dag_root = hash_root_value(dag, root)?;
        Ok(())
    }
}

impl GpuRenderer {
    /// Builds the primary-ray pipeline (svdag32's full variant; the others on first use).
    pub fn new(ctx: &Arc<GpuContext>) -> Result<GpuRenderer, GpuError> {
        let renderer = GpuRenderer {
            ctx: Arc::clone(ctx),
            primary: (0..shaders::RENDER_PRIMARY_BY_FORMAT.len())
                .map(|_| Default::default())
                .collect(),
        };
        renderer.pipeline(TraversalFormat::Svdag32, PrimaryVariant::FULL)?;
        Ok(renderer)
    }

    /// The primary-ray pipeline of `format` compiled for `variant`, created unless it exists.
    fn pipeline(
        &self,
        format: TraversalFormat,
        variant: PrimaryVariant,
    ) -> Result<&ComputePipeline, GpuError> {
        made_once(&self.primary[format.index()][variant.index()], || {
            let name = format!(
                "primary rays ({}{}{})",
                format.name(),
                if variant.colors {
                    ""
                } else {
                    ", no colour index"
                },
                if variant.shadows { "" } else { ", no shadows" },
            );
            let spec = [
                WORKGROUP[0],
                WORKGROUP[1],
                variant.colors as u32,
                variant.shadows as u32,
            ];
            self.ctx.create_compute_pipeline(&ComputePipelineDesc {
                name: &name,
                spirv: shaders::RENDER_PRIMARY_BY_FORMAT[format.index()],
                spec_constants: &spec,
                push_constant_size: std::mem::size_of::<PrimaryPush>() as u32,
                bindings: &[BindingKind::StorageImage, BindingKind::TexelBuffer],
            })
        })
    }

    /// Uploads `dag.words`, its colours (as one raw chunk, or as lossless chunks when they do not
    /// fit one: [`colors_for_allocation`]) and the per-node voxel counts of `VoxelIndex` (`u64`:
    /// colour indices of huge scenes exceed 2^32). Errors when the DAG has 2^32 or more words
    /// (GPU word indices are `uint`), or when a buffer exceeds the device's allocation limit.
    pub fn upload(&self, dag: &Svdag) -> Result<GpuScene, GpuError> {
        self.upload_with(dag, ColorSource::Raw(&dag.colors))
    }

    /// [`GpuRenderer::upload`] with colours from `colors`: encoded chunks are uploaded as they
    /// are and decoded by the shader per hit.
    pub fn upload_with(&self, dag: &Svdag, colors: ColorSource) -> Result<GpuScene, GpuError> {
        self.upload_data(&GpuDagData::svdag32(dag), colors)
    }

    /// Uploads a DAG in any encoding as it is (SSVDAG and TSVDAG are traversed directly by
    /// their shader variant, see `render::format`), with colours from `colors` (one per voxel
    /// in Morton order, raw or chunked).
    pub fn upload_encoded(
        &self,
        dag: &EncodedDag,
        colors: ColorSource,
    ) -> Result<GpuScene, GpuError> {
        let data = GpuDagData::new(dag)
            .map_err(|e| GpuError::InvalidArgument(format!("DAG layout for the GPU: {e}")))?;
        self.upload_data(&data, colors)
    }

    /// Binds a live hash DAG for rendering, read in place: the scene holds the device addresses
    /// of `dag`'s nine super-block tables (no copy, no conversion) and its current root. Edits
    /// and pool growth keep the binding valid (a pool's super-block table has a fixed capacity
    /// and growth only appends to it); switch roots with [`GpuScene::set_hash_root`]. Keep `dag`
    /// alive while the scene is rendered. `palette`: the colour of each material (scenes with
    /// materials); `None` shades every voxel grey, like svdag32 scenes without colours.
    pub fn bind_hash_dag(
        &self,
        dag: &GpuHashDag,
        palette: Option<&Palette>,
    ) -> Result<GpuScene, GpuError> {
        if palette.is_some() && !dag.with_materials() {
            return Err(GpuError::InvalidArgument(
                "a palette needs a hash DAG with materials (this one is geometry only)".into(),
            ));
        }
        let tables = hash_table_addresses(dag);
        let mut info = vec![0u32; HASH_INFO_WORDS];
        info[HASH_INFO_VARIANT] = dag.config().variant.id();
        for (t, a) in tables.iter().enumerate() {
            info[HASH_INFO_TABLES + 2 * t] = *a as u32;
            info[HASH_INFO_TABLES + 2 * t + 1] = (*a >> 32) as u32;
        }
        let data = GpuDagData {
            format: TraversalFormat::HashDag,
            resolution: dag.resolution(),
            words: vec![0],
            node_voxels: vec![0],
            info,
        };
        // The palette is one raw colour chunk indexed by material (the hits' colour index).
        let colors: Vec<u32> = palette.map_or(Vec::new(), |p| {
            p.iter()
                .map(|c| c[0] as u32 | (c[1] as u32) << 8 | (c[2] as u32) << 16 | 0xff00_0000)
                .collect()
        });
        let mut scene = self.upload_layout(&data, ColorSource::Raw(&colors))?;
        scene.hash_tables = tables;
        scene.dag_root = hash_root_value(dag, dag.root())?;
        Ok(scene)
    }

    /// Uploads a laid-out DAG and its colours.
    pub fn upload_data(&self, dag: &GpuDagData, colors: ColorSource) -> Result<GpuScene, GpuError> {
        if dag.format == TraversalFormat::HashDag {
            return Err(GpuError::InvalidArgument(
                "a hash DAG is not uploaded: bind it with bind_hash_dag".into(),
            ));
        }
        self.upload_layout(dag, colors)
    }

    /// [`GpuRenderer::upload_data`] for every format.
    fn upload_layout(&self, dag: &GpuDagData, colors: ColorSource) -> Result<GpuScene, GpuError> {
        let invalid = |m: String| GpuError::InvalidArgument(m);
        if dag.words.is_empty() || dag.words.len() as u64 > u32::MAX as u64 {
            return Err(invalid(format!(
                "DAG has {} words; the GPU needs 1..2^32",
                dag.words.len()
            )));
        }
        // Raw colours too large for one buffer (or one chunk) go up as exact lossless chunks.
        let max_allocation = self.ctx.info().max_memory_allocation_size;
        let fitted = match colors {
            ColorSource::Raw(raw) => colors_for_allocation(raw, max_allocation)
                .map_err(|e| invalid(format!("encoding raw colours for the GPU: {e}")))?,
            ColorSource::Chunked(_) => None,
        };
        let colors = fitted.as_ref().map_or(colors, ColorSource::Chunked);
        let words = self.ctx.upload("dag words", &dag.words)?;
        let node_voxels = self.ctx.upload("dag node voxel counts", &dag.node_voxels)?;
        let pairs: Vec<[u32; 2]> = dag
            .info
            .chunks(2)
            .map(|p| [p[0], p.get(1).copied().unwrap_or(0)])
            .collect();
        let tables = self
            .ctx
            .upload_texels("dag format info and tables", &pairs)?;
        // Raw colours are one chunk of the raw format: the shader has a single colour path.
        let (format, words_of_colors, starts, offsets) = match colors {
            ColorSource::Chunked(c) => {
                c.validate_tables().map_err(|e| invalid(e.to_string()))?;
                let tables = (c.chunk_starts.clone(), c.chunk_offsets.clone());
                (c.format, c.words.as_slice(), tables.0, tables.1)
            }
            ColorSource::Raw(raw) => {
                let n = raw.len() as u64;
                (ColorFormat::Raw, raw, vec![0, n], vec![0, n])
            }
        };
        let (color_count, chunk_count) = (*starts.last().expect("validated"), starts.len() - 1);
        if chunk_count as u64 >= u32::MAX as u64 {
            return Err(invalid(format!(
                "{color_count} colours in {chunk_count} chunks: the GPU needs fewer than 2^32 chunks"
            )));
        }
        // Empty buffers are not allowed: scenes without colours get one word (never read: the
        // colour flag is off).
        let color_words = if words_of_colors.is_empty() {
            self.ctx.upload("dag colour words (none)", &[0u32])?
        } else {
            self.ctx.upload("dag colour words", words_of_colors)?
        };
        let chunk_starts = self.ctx.upload("dag colour chunk starts", &starts)?;
        let chunk_offsets = self.ctx.upload("dag colour chunk offsets", &offsets)?;
        Ok(GpuScene {
            format: dag.format,
            tables,
            words,
            node_voxels,
            color_words,
            chunk_starts,
            chunk_offsets,
            color_format: format,
            chunk_count: chunk_count as u32,
            dag_root: 0,
            hash_tables: Vec::new(),
            resolution: dag.resolution,
            color_count,
        })
    }

    /// Frame constants for `scene`: camera and light from `settings` via [`RenderParams::new`]
    /// (with the scene's resolution), colour fields from the uploaded scene.
    pub fn params(
        &self,
        scene: &GpuScene,
        settings: &RenderSettings,
    ) -> Result<RenderParams, GpuError> {
        // RenderParams::new reads only the resolution and the colour count of the DAG.
        let header = Svdag {
            resolution: scene.resolution,
            words: Vec::new(),
            level_starts: Vec::new(),
            colors: Vec::new(),
        };
        let mut p = RenderParams::new(settings, &header)
            .map_err(|e| GpuError::InvalidArgument(format!("render settings: {e}")))?;
        if scene.color_count > 0 {
            p.flags |= FLAG_HAS_COLORS;
        }
        p.color_count = scene.color_count;
        Ok(p)
    }

    /// A parameter block for [`GpuRenderer::record`] (one per frame in flight).
    pub fn create_frame(&self) -> Result<RenderFrame, GpuError> {
        let params = self.ctx.create_buffer(
            "render params",
            std::mem::size_of::<RenderParams>() as u64,
            MemLocation::CpuToGpu,
        )?;
        Ok(RenderFrame { params })
    }

    /// Records the primary-ray pass (profiled as "primary rays") into `cmd`, writing the
    /// `settings.width x settings.height` image (camera, light and shadows from `settings`) into
    /// the top-left corner of `target`, and the hit mask into `hits` when given (one `u32` per
    /// pixel, row-major). The frame constants go through `frame`'s mapping: nothing is allocated.
    ///
    /// `scene` and `frame` are read through device addresses: keep both alive, and do not record
    /// with `frame` again, until the GPU has finished `cmd` (one [`RenderFrame`] per frame slot).
    #[allow(clippy::too_many_arguments)]
    pub fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        scene: &GpuScene,
        frame: &mut RenderFrame,
        settings: &RenderSettings,
        target: &'a Image,
        hits: Option<&Buffer>,
        profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        self.record_full(cmd, scene, frame, settings, target, hits, None, profiler)
    }

    /// [`GpuRenderer::record`] that also writes one [`FirstHit`] per pixel (row-major, the
    /// `settings` size) into `first_hits`: the editor reads the hit under the cursor from it.
    #[allow(clippy::too_many_arguments)]
    pub fn record_with_first_hits<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        scene: &GpuScene,
        frame: &mut RenderFrame,
        settings: &RenderSettings,
        target: &'a Image,
        first_hits: &Buffer,
        profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        self.record_full(
            cmd,
            scene,
            frame,
            settings,
            target,
            None,
            Some(first_hits),
            profiler,
        )
    }

    /// [`GpuRenderer::record`] that also writes one [`FirstHit`] per pixel into `first_hits`.
    #[allow(clippy::too_many_arguments)]
    fn record_full<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        scene: &GpuScene,
        frame: &mut RenderFrame,
        settings: &RenderSettings,
        target: &'a Image,
        hits: Option<&Buffer>,
        first_hits: Option<&Buffer>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let (w, h) = (settings.width, settings.height);
        if w > target.width() || h > target.height() {
            return Err(GpuError::InvalidArgument(format!(
                "render size {w}x{h} exceeds target '{}' ({}x{})",
                target.name(),
                target.width(),
                target.height()
            )));
        }
        let first_hit_need = w as u64 * h as u64 * std::mem::size_of::<FirstHit>() as u64;
        for (buffer, need) in [
            (hits, w as u64 * h as u64 * 4),
            (first_hits, first_hit_need),
        ] {
            let Some(hits) = buffer else { continue };
            if hits.size() < need {
                return Err(GpuError::OutOfRange {
                    name: hits.name().to_string(),
                    offset: 0,
                    len: need,
                    size: hits.size(),
                });
            }
        }
        let params = self.params(scene, settings)?;
        let pipeline = self.pipeline(
            scene.format,
            PrimaryVariant {
                colors: params.has_colors() || first_hits.is_some(),
                shadows: params.shadows(),
            },
        )?;
        self.ctx
            .write_mapped(&mut frame.params, 0, std::slice::from_ref(&params))?;
        let push = PrimaryPush {
            params: frame.params.address(),
            words: scene.words.address(),
            node_voxels: scene.node_voxels.address(),
            color_words: scene.color_words.address(),
            chunk_starts: scene.chunk_starts.address(),
            chunk_offsets: scene.chunk_offsets.address(),
            hits: hits.map_or(0, Buffer::address),
            first_hits: first_hits.map_or(0, Buffer::address),
            color_format: scene.color_format as u32,
            chunk_count: scene.chunk_count,
            dag_root: scene.dag_root,
            _pad: 0,
        };
        let groups = [w.div_ceil(WORKGROUP[0]), h.div_ceil(WORKGROUP[1]), 1];
        // begin_pass orders its begin timestamp before the dispatch (lavapipe flush).
        cmd.begin_pass(&mut profiler, "primary rays");
        let result = cmd.dispatch(
            pipeline,
            groups,
            bytemuck::bytes_of(&push),
            &[Bound::Image(target), Bound::Texels(&scene.tables)],
        );
        cmd.end_pass(&mut profiler);
        result
    }

    /// Renders one image, blocking: [`GpuRenderer::record`] into a new image and hit buffer,
    /// submit, then readback of both (CPU spans "readback image" / "readback hits").
    pub fn render(
        &self,
        scene: &GpuScene,
        settings: &RenderSettings,
        profiler: Option<&mut Profiler>,
    ) -> Result<RenderOutput, GpuError> {
        Ok(self.render_inner(scene, settings, false, profiler)?.0)
    }

    /// Renders one image and returns the primary rays' first hits too (one [`FirstHit`] per
    /// pixel, row-major): the exact traversal result every DAG format must reproduce.
    pub fn render_first_hits(
        &self,
        scene: &GpuScene,
        settings: &RenderSettings,
    ) -> Result<(RenderOutput, Vec<FirstHit>), GpuError> {
        self.render_inner(scene, settings, true, None)
    }

    fn render_inner(
        &self,
        scene: &GpuScene,
        settings: &RenderSettings,
        want_first_hits: bool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(RenderOutput, Vec<FirstHit>), GpuError> {
        let ctx = &self.ctx;
        let (w, h) = (settings.width, settings.height);
        let pixels = w as u64 * h as u64;

        let setup_start = Instant::now();
        // Validates the settings before anything is allocated.
        self.params(scene, settings)?;
        let mut frame = self.create_frame()?;
        let image = ctx.create_storage_image("render target", w, h)?;
        let hits = ctx.create_buffer("render hits", pixels * 4, MemLocation::GpuOnly)?;
        let first_hits = if want_first_hits {
            let size = pixels * std::mem::size_of::<FirstHit>() as u64;
            Some(ctx.create_buffer("render first hits", size, MemLocation::GpuOnly)?)
        } else {
            None
        };
        if let Some(p) = profiler.as_deref_mut() {
            p.record_cpu_span("render setup", setup_start, Instant::now());
        }

        let mut cmd = ctx.begin_commands("render")?;
        self.record_full(
            &mut cmd,
            scene,
            &mut frame,
            settings,
            &image,
            Some(&hits),
            first_hits.as_ref(),
            profiler.as_deref_mut(),
        )?;
        cmd.submit()?;
        if let Some(p) = profiler.as_deref_mut() {
            p.resolve()?;
        }

        let t = Instant::now();
        let rgba = ctx.read_image(&image)?;
        let t2 = Instant::now();
        let hits = ctx.download::<u32>(&hits)?;
        if let Some(p) = profiler {
            p.record_cpu_span("readback image", t, t2);
            p.record_cpu_span("readback hits", t2, Instant::now());
        }
        let first = match &first_hits {
            Some(b) => ctx.download::<FirstHit>(b)?,
            None => Vec::new(),
        };
        Ok((
            RenderOutput {
                width: w,
                height: h,
                rgba,
                hits,
            },
            first,
        ))
    }
}
