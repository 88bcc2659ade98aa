// The DAG formats every shader that includes `render/traverse.glsl` is compiled for: one
// SPIR-V variant per entry, `(name, GLSL defines)`, in `TraversalFormat::index` order. Read
// twice: by build.rs (which compiles the variants) and by engine/render/format.rs (which picks
// one), so both agree on the list. Entry 0 is the default compilation (no define: svdag32).
[
    ("svdag32", &[]),
    ("ssvdag", &["DAG_FORMAT_SSVDAG"]),
    ("tsvdag_base", &["DAG_FORMAT_TSVDAG"]),
    ("tsvdag_lut", &["DAG_FORMAT_TSVDAG", "TSVDAG_LUT"]),
    ("tsvdag_huffman", &["DAG_FORMAT_TSVDAG", "TSVDAG_LUT", "TSVDAG_HUFFMAN"]),
    ("tsvdag_huffman_nolut", &["DAG_FORMAT_TSVDAG", "TSVDAG_HUFFMAN"]),
    ("tsvdag_base_t", &["DAG_FORMAT_TSVDAG", "TSVDAG_TRANSLATIONS"]),
    ("tsvdag_lut_t", &["DAG_FORMAT_TSVDAG", "TSVDAG_LUT", "TSVDAG_TRANSLATIONS"]),
    ("tsvdag_huffman_t", &["DAG_FORMAT_TSVDAG", "TSVDAG_LUT", "TSVDAG_HUFFMAN", "TSVDAG_TRANSLATIONS"]),
    ("tsvdag_huffman_nolut_t", &["DAG_FORMAT_TSVDAG", "TSVDAG_HUFFMAN", "TSVDAG_TRANSLATIONS"]),
    ("hash_dag", &["DAG_FORMAT_HASH"]),
]
