//! `voxdag`: the command-line front end of the engine (build, stats, export, render, bench, demo).

mod bench;
mod commands;
mod edit;
mod editor;
mod hash_render;
mod limited_alloc;
mod ooc;
mod partition;
mod pathtrace;
mod stream;
mod view;
mod window;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use voxdag::attr::ColorCodec;

/// Sparse voxel DAGs on Vulkan: import meshes and .vox files, build SVDAGs, render them on the GPU.
#[derive(Parser)]
#[command(name = "voxdag", version, about)]
struct Cli {
    /// Hide progress bars.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Memory limit in bytes (suffixes K, M, G, T: powers of 1024). Default: the smallest of
    /// physical RAM, the cgroup limit and RLIMIT_AS. Input-sized allocations are checked first.
    #[arg(long, global = true, value_parser = commands::parse_bytes)]
    memory_limit: Option<u64>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Import a mesh (.obj/.gltf/.glb) or MagicaVoxel file (.vox), voxelize it and save an SVDAG (or re-encode a .vdag).
    Build(BuildArgs),
    /// Print resolution, voxel count, bytes per encoding and per-level node counts of a .vdag file.
    Stats(StatsArgs),
    /// Traverse the stored encoding of a .vdag file and check it holds exactly the original voxels.
    Verify(VerifyArgs),
    /// Export the occupied voxels of a .vdag file for other tools.
    ExportVoxels(ExportArgs),
    /// Render a .vdag file to a PNG on the GPU (or the CPU reference renderer).
    Render(RenderArgs),
    /// Open a window that renders a .vdag file every frame (orbit/fly camera, egui overlay).
    View(ViewArgs),
    /// Run benchmarks and write JSON plus a Markdown table.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Out-of-core path tracing of triangle scenes: prepare, generate, render.
    #[command(subcommand)]
    Ooc(ooc::OocCommand),
    /// Build, render and describe the bundled default scene (assets/avocado) into an output folder.
    Demo(DemoArgs),
    /// Merge the part files of a partitioned build (`build --part i/K`) into one .vdag.
    Merge(partition::MergeArgs),
    /// Apply a HashDAG replay (edits, undo/redo) to a scene and save the result.
    Edit(edit::EditArgs),
    /// A real-time voxel editor on the GPU hash DAG (sphere / cube tools, undo, egui panels).
    Editor(editor::EditorArgs),
}

/// Arguments of `voxdag build`.
#[derive(Args)]
pub struct BuildArgs {
    /// Input scene: .obj, .gltf, .glb or .vox; or a built .vdag to re-encode (no voxelization).
    input: PathBuf,
    /// Grid resolution N (power of two, 8..=131072). Default: 1024 for meshes, the model's size for .vox.
    #[arg(long, short)]
    resolution: Option<u32>,
    /// Integer scale factor for .vox models.
    #[arg(long, default_value_t = 1)]
    vox_scale: u32,
    /// Base-colour texture for OBJ files that have no material library.
    #[arg(long)]
    texture: Option<PathBuf>,
    /// Folder the model's referenced files (buffers, textures, material libraries) may also
    /// lie in, besides the model's own folder (see docs/security.md).
    #[arg(long)]
    asset_root: Option<PathBuf>,
    /// Drop voxel colours (same as `--colors none`).
    #[arg(long, conflicts_with = "colors")]
    no_colors: bool,
    /// How colours are stored: none, raw, lossless, lossless565, lossy[=T], dolonius[=T] or dado
    /// (T: per-channel error threshold in (0, 1], default 0.06). See docs/colors.md.
    #[arg(long, default_value = "lossless", value_parser = commands::parse_colors)]
    colors: ColorsArg,
    /// Quantize the colours into a palette of at most K (1..=16) materials, stored as one
    /// 4-bit id per voxel instead of colours (see docs/materials.md).
    #[arg(long, value_name = "K", conflicts_with_all = ["colors", "no_colors"],
          value_parser = clap::value_parser!(u32).range(1..=16))]
    materials: Option<u32>,
    /// Depth below the root of the SVO nodes that own one colour chunk each (default: nodes of
    /// 256^3 voxels for the exact codecs, 128^3 for the lossy ones).
    #[arg(long)]
    chunk_depth: Option<u32>,
    /// Output .vdag file.
    #[arg(long, short)]
    output: PathBuf,
    /// Also write a JSON report of the build (times, peak memory, counts) to this file.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Node encoding stored in the file.
    #[arg(long, value_enum, default_value = "svdag32")]
    encoding: EncodingArg,
    /// Transforms the tsvdag encoding may use (sat: S+A plus translations).
    #[arg(long, value_enum, default_value = "sat")]
    transforms: TransformsArg,
    /// tsvdag: the pointer mode (default: encode all three, keep the smallest).
    #[arg(long, value_enum, conflicts_with_all = ["no_lut", "no_huffman"])]
    tsvdag_mode: Option<TsvdagModeArg>,
    /// tsvdag: no pointer look-up tables (pins the mode; with `--no-huffman`: `base`).
    #[arg(long)]
    no_lut: bool,
    /// tsvdag: no Huffman coding of transform ids (pins the mode; alone: `lut`).
    #[arg(long)]
    no_huffman: bool,
    /// Peak memory the streaming build may use (suffixes K, M, G, T): refused at start when
    /// the working set alone does not fit, stopped with an error if the DAG outgrows it
    /// (model in docs/scaling.md). Default: no budget.
    #[arg(long, value_parser = commands::parse_bytes, conflicts_with = "in_memory")]
    memory_budget: Option<u64>,
    /// Hold every voxel in memory and build the DAG afterwards (the pre-streaming path; the
    /// output is byte-identical).
    #[arg(long)]
    in_memory: bool,
    /// Build only part i of K (`i/K`) of a partitioned build: the output is a part file
    /// (.vdagp) for `voxdag merge` (docs/scaling.md).
    #[arg(long, value_name = "i/K", value_parser = partition::parse_part,
          conflicts_with_all = ["in_memory", "materials", "memory_budget", "report"])]
    part: Option<(u32, u32)>,
}

/// Pointer modes of the tsvdag encoding (`voxdag build --tsvdag-mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TsvdagModeArg {
    /// No tables, no Huffman: every pointer inline.
    Base,
    /// Per-level pointer look-up tables.
    Lut,
    /// Tables plus Huffman-coded transform ids and translation masks.
    Huffman,
}

/// A `--colors` value: a codec, or `None` for `none`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColorsArg(pub Option<ColorCodec>);

/// Node encodings of `voxdag build --encoding`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum EncodingArg {
    /// 32-bit SVDAG words.
    Svdag32,
    /// SSVDAG (Villanueva et al. 2016), 16/32-bit pointers.
    Ssvdag,
    /// Transform-aware SVDAG (dissertation §3.4).
    Tsvdag,
}

/// Transform sets of `voxdag build --transforms`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TransformsArg {
    /// No transforms (plain SVDAG in the compact encoding).
    None,
    /// The 8 mirrors.
    S,
    /// The 6 axis permutations.
    A,
    /// All 48.
    Sa,
    /// All 48 plus translations.
    Sat,
}

/// Arguments of `voxdag verify`.
#[derive(Args)]
pub struct VerifyArgs {
    /// The .vdag file.
    file: PathBuf,
    /// Also compare the voxels and colours (or materials) with another .vdag file (reports the
    /// first differing voxel, colour or material id).
    #[arg(long)]
    against: Option<PathBuf>,
}

/// Arguments of `voxdag stats`.
#[derive(Args)]
pub struct StatsArgs {
    /// The .vdag file.
    file: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Only the SVO/SVDAG counts and bytes: skip the symmetry and translation searches (which take
    /// minutes on large scenes) and the compact encodings.
    #[arg(long)]
    quick: bool,
}

/// Output formats of `voxdag export-voxels`.
#[derive(Clone, Copy, ValueEnum)]
pub enum ExportFormat {
    /// Raw little-endian u32 x, y, z per occupied voxel, in Morton order.
    XyzU32,
    /// MagicaVoxel .vox (resolution 256 at most).
    Vox,
}

/// Arguments of `voxdag export-voxels`.
#[derive(Args)]
pub struct ExportArgs {
    /// The .vdag file.
    file: PathBuf,
    /// Output format.
    #[arg(long, value_enum)]
    format: ExportFormat,
    /// Output file (`-`: stdout).
    #[arg(long, short)]
    output: PathBuf,
    /// Refuse, before writing, an export larger than this many bytes (suffixes K, M, G, T).
    #[arg(long, value_parser = commands::parse_bytes)]
    max_output: Option<u64>,
}

/// Arguments of `voxdag render`.
#[derive(Args)]
pub struct RenderArgs {
    /// The .vdag file.
    file: PathBuf,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768", value_parser = commands::parse_size)]
    size: (u32, u32),
    /// Output PNG (with --pt: .png tonemapped or .exr linear HDR).
    #[arg(long)]
    out: PathBuf,
    /// Camera position in grid coordinates, "x,y,z" (default: an orbit view of the whole scene).
    #[arg(long, value_parser = commands::parse_vec3, allow_hyphen_values = true)]
    eye: Option<[f32; 3]>,
    /// Point the camera looks at, "x,y,z" (default: the grid centre).
    #[arg(long, value_parser = commands::parse_vec3, allow_hyphen_values = true)]
    target: Option<[f32; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    fov: Option<f32>,
    /// Disable shadow rays.
    #[arg(long)]
    no_shadows: bool,
    /// Use the CPU reference renderer instead of the GPU.
    #[arg(long)]
    cpu: bool,
    /// Print a per-pass GPU timing table.
    #[arg(long)]
    profile: bool,
    /// Write a Chrome trace-event JSON of the GPU passes (opens in Perfetto).
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Load the scene into the GPU hash DAG of the editor (nine slab hash tables) and render
    /// that, traversed in place (geometry only; docs/rendering.md).
    #[arg(long)]
    hash_dag: bool,
    /// With --hash-dag: the tables' slab layout (atomic64, ticket_board, accel32, accel8).
    #[arg(long, value_name = "VARIANT")]
    hash_table: Option<String>,
    /// Path tracing (--pt and its flags).
    #[command(flatten)]
    pt: pathtrace::PtArgs,
}

/// Arguments of `voxdag view`.
#[derive(Args)]
pub struct ViewArgs {
    /// The .vdag file.
    file: PathBuf,
    /// Window size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = commands::parse_size)]
    size: (u32, u32),
    /// Internal resolution as a fraction of the window (0.1..=1); the overlay has a slider.
    #[arg(long, default_value_t = 1.0)]
    render_scale: f32,
    /// Present without waiting for vertical blank (MAILBOX, else IMMEDIATE).
    #[arg(long)]
    no_vsync: bool,
    /// Frames the CPU may record ahead of the GPU.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4))]
    frames_in_flight: u32,
    /// Exit after this many frames.
    #[arg(long)]
    frames: Option<u32>,
    /// Save the last frame (default camera, render scale 1, without the overlay) as a PNG; needs
    /// --frames.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Write frame rate, CPU frame-loop cost and GPU pass times as JSON at exit.
    #[arg(long)]
    stats_json: Option<PathBuf>,
}

/// Arguments of `voxdag demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Folder for the outputs (scene .vdag, PNG, stats JSON).
    #[arg(long, default_value = "out")]
    out_dir: PathBuf,
    /// Grid resolution of the default scene.
    #[arg(long, default_value_t = 512)]
    resolution: u32,
}

/// Counts heap bytes against the memory limit; any allocation failure is one line and exit 1.
#[global_allocator]
static ALLOCATOR: limited_alloc::LimitedAlloc = limited_alloc::LimitedAlloc;

/// No panic text reaches the user: silent where the panic is caught and turned into an error
/// (third-party parsers), otherwise one line, temporary files removed, exit 1.
fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        if voxdag::safety::catching_panics() {
            return;
        }
        let payload = info.payload();
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("error: internal error: {message}{at}");
        voxdag::atomic_file::remove_temp_files();
        std::process::exit(1);
    }));
}

/// The error and its causes on one line, each cause once (an OS error wrapped by an error
/// that already prints it is not repeated).
fn one_line(err: &anyhow::Error) -> String {
    let mut line = err.to_string();
    for cause in err.chain().skip(1) {
        let text = cause.to_string();
        if !line.contains(&text) {
            line += ": ";
            line += &text;
        }
    }
    line.replace('\n', " ")
}

fn main() {
    install_panic_hook();
    voxdag::atomic_file::install_signal_handlers();
    let cli = Cli::parse();
    if let Some(limit) = cli.memory_limit {
        voxdag::safety::set_memory_limit(limit);
    }
    limited_alloc::set_limit(voxdag::safety::memory_limit());
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("voxdag=info"))
        .format_timestamp(None)
        .init();
    let result = match cli.command {
        Command::Build(args) => commands::build(&args, cli.quiet),
        Command::Stats(args) => commands::stats(&args, cli.quiet),
        Command::Verify(args) => commands::verify(&args),
        Command::ExportVoxels(args) => commands::export_voxels(&args),
        Command::Render(args) => commands::render(&args),
        Command::View(args) => view::view(&args),
        Command::Bench(cmd) => bench::run(cmd, cli.quiet),
        Command::Demo(args) => commands::demo(&args, cli.quiet),
        Command::Ooc(cmd) => ooc::run(cmd, cli.quiet),
        Command::Merge(args) => partition::merge(&args),
        Command::Edit(args) => edit::edit(&args),
        Command::Editor(args) => editor::editor(&args),
    };
    if let Err(err) = result {
        voxdag::atomic_file::remove_temp_files();
        if let Some(unproven) = err.downcast_ref::<commands::Unproven>() {
            eprintln!("{unproven}");
            std::process::exit(2);
        }
        // One line: the whole cause chain, no backtrace, no panic.
        eprintln!("error: {}", one_line(&err));
        std::process::exit(1);
    }
}
