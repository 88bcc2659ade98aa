// The format-specific half of the DAG traversal (traverse.glsl): how to find a node's children,
// its world-order child mask, a leaf's bytes and the voxel counts the colour index needs, for
// one DAG format per compiled shader variant (build.rs, engine/render/traversal_variants.rs):
//   (no define)        svdag32: `Svdag::words`
//   DAG_FORMAT_SSVDAG  SSVDAG: 16/32-bit pointers `target << 3 | mirror`
//   DAG_FORMAT_TSVDAG  TSVDAG: 16/32/48-bit pointers with transform ids; TSVDAG_LUT (pointer
//                      tables), TSVDAG_HUFFMAN (Huffman-coded symbols), TSVDAG_TRANSLATIONS
//                      (translated subtrees: traverse.glsl's second stack).
//   DAG_FORMAT_HASH    the live hash DAG of the editor, read in place: render/dag_hash.glsl.
// Layouts: docs/encodings.md; what is uploaded where: engine/render/format.rs.
//
// The includer defines, BEFORE including traverse.glsl:
//   uint dag_word(uint i);            // svdag32: word i of `Svdag::words`; encoded formats:
//                                     // the leaves (2 words each) and node streams (u16
//                                     // pairs), unchanged
//   uint64_t dag_node_voxels(uint i); // voxels below the node at word i (svdag32) or at u16
//                                     // stream index i (encoded; at a translated pointer's
//                                     // first u16: the voxels of the translated subtree)
//   uint dag_info(uint i);            // word i of the format info block (DAG_INFO_* below),
//                                     // followed by the Huffman decode tables and pointer
//                                     // tables (TSVDAG); render/dag_tables.glsl
// A node handle is (node, xform): svdag32 a word offset and 0; encoded formats a u16 index in
// the streams (inner levels) or a leaf index (level 0), and the transform id (SSVDAG: the
// mirror bits, which are the transform ids 0..7) the stored node is seen through.
//
// What a format provides to traverse.glsl (names with a default below need not be defined):
//   dag_root (or dag_root_frame, DAG_HAS_ROOT_FRAME: the root handle with its aux word and
//     world mask), dag_child(node, xform, aux, level, c, ...), dag_inner_mask, dag_leaf_byte;
//   dag_begin (DAG_HAS_BEGIN; default: nothing): per-invocation setup (constants into registers);
//   dag_node_aux / dag_frame_mask (DAG_HAS_AUX; default: aux = the world child mask): the word
//     a frame keeps for `dag_child` and the world mask derived from it (encoded: the header);
//   dag_child_masks (DAG_HAS_CHILD_MASKS; default: dag_inner_mask or dag_leaf_bits);
//   dag_leaf_bits (DAG_HAS_LEAF_BITS; default: 8 x dag_leaf_byte): a leaf's 64 world-order bits;
//   dag_voxels_before (DAG_HAS_VOXELS_BEFORE; default: each preceding sibling's
//     dag_child + dag_child_count, so a format without it defines dag_child_count);
//   dag_leaf_rank (DAG_HAS_LEAF_RANK; default: the popcount of the leaf bits before the voxel):
//     the colour index's part inside the leaf.
#ifndef VOXDAG_RENDER_DAG_FORMATS_GLSL
#define VOXDAG_RENDER_DAG_FORMATS_GLSL

// Word offsets in the info block (`format::info` in engine/render/format.rs).
#define DAG_INFO_ROOT_XFORM 0u
#define DAG_INFO_SET 1u
#define DAG_INFO_STREAM_BASE 2u
#define DAG_INFO_CODING 3u
// Per level l, two words at DAG_INFO_LEVELS + 2 l (`info::LEVELS`): the u16 index of its
// stream (0 for the leaves) and (TSVDAG) the info word of its pointer table | the Huffman index
// bits << DAG_TABLE_BITS_SHIFT.
#define DAG_INFO_LEVELS 8u
#define DAG_TABLE_BITS_SHIFT 28u

// Words i and i + 1 of the DAG. Includers that can load both at once (one 64-bit load, which
// lavapipe executes as one per-lane loop instead of two) define DAG_HAS_WORD_PAIR and
// `uvec2 dag_word_pair(uint i)` before including traverse.glsl.
#if !defined(DAG_HAS_WORD_PAIR)
uvec2 dag_word_pair(uint i) {
    return uvec2(dag_word(i), dag_word(i + 1u));
}
#endif

// Words i and i + 1 of the info block; DAG_HAS_INFO_PAIR and `uvec2 dag_info_pair(uint i)`
// likewise.
#if !defined(DAG_HAS_INFO_PAIR)
uvec2 dag_info_pair(uint i) {
    return uvec2(dag_info(i), dag_info(i + 1u));
}
#endif

// The record of level l: one load for everything a child fetch needs to know about its level.
uvec2 dag_level(uint l) {
    return dag_info_pair(DAG_INFO_LEVELS + 2u * l);
}

// The info word where a level's pointer table starts (even: two words per entry), from its
// record's second word; its Huffman decode table fills the `1 << bits` words before it.
uint dag_level_tables(uint record_y) {
    return record_y & ((1u << DAG_TABLE_BITS_SHIFT) - 1u);
}

#include "render/xform.glsl"

#if defined(DAG_FORMAT_SSVDAG) || defined(DAG_FORMAT_TSVDAG)
#define DAG_ENCODED 1

// Copies of the info block's scalars, read once per invocation (`dag_begin`, called by
// `traverse_begin`) instead of once per child fetch. The per-level words are read where they
// are used: an array of them indexed by level costs more on lavapipe than the load (A/B in
// docs/pathtracing.md, "Where the time goes on lavapipe").
uint g_dag_stream_base;
// The root frame: node 0 of the root level's stream, its transform (TSVDAG; SSVDAG: 0), its
// header and world child mask. Read once per invocation: the root's header address comes from
// a texel, so lavapipe would load it one lane at a time on every ray.
uint g_dag_root;
uint g_dag_root_xform;
uint g_dag_root_aux;
uint g_dag_root_mask;
#if defined(DAG_FORMAT_TSVDAG)
uint g_dag_set;
uint g_dag_coding;
#endif

// u16 `g` of the node streams.
uint dag_u16(uint g) {
    return (dag_word(g_dag_stream_base + (g >> 1u)) >> ((g & 1u) << 4u)) & 0xffffu;
}

// 8-bit stored child mask of a 2-bit-per-octant header.
uint dag_header_mask(uint h) {
    uint x = (h | (h >> 1u)) & 0x5555u;
    x = (x | (x >> 1u)) & 0x3333u;
    x = (x | (x >> 2u)) & 0x0f0fu;
    return (x | (x >> 4u)) & 0x00ffu;
}

// The u16 index of the pointer of stored octant `so` (set in the header) of the node at u16
// `node` with header h: the node's header, then its pointers of 1..3 u16 each.
uint dag_pointer_index(uint node, uint h, uint so) {
    uint below = h & ((1u << (2u * so)) - 1u);
    return node + 1u + uint(bitCount(below & 0x5555u)) + 2u * uint(bitCount(below & 0xaaaau));
}

// The pointer of stored octant `so` of the node at u16 `node` with header h: its value, size
// code (1..3 u16)
// and the u16 index of its first word. The up to three u16 are read as one word pair (the
// streams end with a zero word, so the pair never leaves the buffer).
uint64_t dag_read_pointer(uint node, uint h, uint so, out uint code, out uint at) {
    at = dag_pointer_index(node, h, so);
    code = (h >> (2u * so)) & 3u;
    uint64_t pair = packUint2x32(dag_word_pair(g_dag_stream_base + (at >> 1u)));
    uint64_t v = pair >> ((at & 1u) << 4u);
    uint64_t keep = code == 1u ? 0xfffful : (code == 2u ? 0xfffffffful : 0xfffffffffffful);
    return v & keep;
}

// Leaf `i`'s two mask words.
uvec2 dag_leaf_words(uint i) {
    return dag_word_pair(2u * i);
}

uint dag_stored_byte(uvec2 m, uint s) {
    return (m[s >> 2u] >> (8u * (s & 3u))) & 0xffu;
}

// The leaf's 64 voxel bits seen through xform, in world Morton order.
#define DAG_HAS_LEAF_BITS 1
uvec2 dag_leaf_bits(uint leaf, uint xform) {
    return xform_leaf(xform, dag_leaf_words(leaf));
}

// World sub-block c of a leaf seen through xform (its voxels in world order).
uint dag_leaf_byte(uint leaf, uint xform, uint c) {
    uvec2 m = dag_leaf_words(leaf);
    return xform_child_mask(xform, dag_stored_byte(m, xform_stored_octant(xform, c)));
}

// A frame's aux word is the node's 2-bit-per-octant header: child fetches and pops need no
// header load.
#define DAG_HAS_AUX 1
uint dag_node_aux(uint node, uint xform, uint level) {
    return dag_u16(node);
}

// World child mask of a node with header `aux` seen through xform.
uint dag_frame_mask(uint aux, uint xform) {
    return xform_child_mask(xform, dag_header_mask(aux));
}

#define DAG_HAS_BEGIN 1
void dag_begin(uint root_level) {
    g_dag_stream_base = dag_info(DAG_INFO_STREAM_BASE);
    g_dag_root = dag_level(root_level).x;
    g_dag_root_xform = 0u;
#if defined(DAG_FORMAT_TSVDAG)
    g_dag_root_xform = dag_info(DAG_INFO_ROOT_XFORM);
    g_dag_set = dag_info(DAG_INFO_SET);
    g_dag_coding = dag_info(DAG_INFO_CODING);
#endif
    g_dag_root_aux = dag_node_aux(g_dag_root, g_dag_root_xform, root_level);
    g_dag_root_mask = dag_frame_mask(g_dag_root_aux, g_dag_root_xform);
}

// The root handle, its aux word and world child mask.
#define DAG_HAS_ROOT_FRAME 1
void dag_root_frame(uint root_level, out uint node, out uint xform, out uint aux,
                    out uint mask) {
    node = g_dag_root;
    xform = g_dag_root_xform;
    aux = g_dag_root_aux;
    mask = g_dag_root_mask;
}

// World child mask of the inner node (node, xform) at level >= 1.
uint dag_inner_mask(uint node, uint xform, uint level) {
    return dag_frame_mask(dag_u16(node), xform);
}

// The child masks of (child, xform) at child_level: the world child mask and header of an
// inner node, or the world voxel bits of a leaf, from one word-pair load at the header or the
// leaf.
#define DAG_HAS_CHILD_MASKS 1
void dag_child_masks(uint child, uint xform, uint child_level, out uint mask, out uvec2 leaf,
                     out uint aux) {
    uvec2 pair = dag_word_pair(child_level == 0u ? 2u * child : g_dag_stream_base + (child >> 1u));
    aux = (pair.x >> ((child & 1u) << 4u)) & 0xffffu;
    // The leaf's voxels and the inner node's mask go through one in-byte transform (all lanes
    // run both cases anyway); only the leaf's sub-blocks move.
    uvec2 in_bytes = xform_in_bytes(xform, child_level == 0u ? pair : uvec2(dag_header_mask(aux), 0u));
    leaf = xform_bytes(xform, in_bytes);
    mask = in_bytes.x;
}

// Voxels of the children before world octant c of the inner node (node, xform) with header
// `aux`: the counts stored at their pointers' first u16 (`GpuDagData`: the voxels of the
// subtree each pointer leads to), found from the header alone (no pointer decoded).
#define DAG_HAS_VOXELS_BEFORE 1
uint64_t dag_voxels_before(uint node, uint xform, uint aux, uint level, uint c) {
    uint64_t sum = 0ul;
    uint before = dag_frame_mask(aux, xform) & ((1u << c) - 1u);
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (before != 0u) for (;;) {
        uint k = uint(findLSB(before));
        before &= before - 1u;
        sum += dag_node_voxels(dag_pointer_index(node, aux, xform_stored_octant(xform, k)));
        if (before == 0u) break;
    }
    return sum;
}
#endif

#if defined(DAG_FORMAT_SSVDAG)
// The child at world octant c (set in the world mask) of the inner node (node, xform) at
// `level`: its handle, the translation of its subtree (world frame) and the u16 index of the
// pointer. SSVDAG: stored octant c ^ mirror, child mirror = mirror ^ pointer mirror.
void dag_child(uint node, uint xform, uint aux, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    uint code;
    uint64_t v = dag_read_pointer(node, aux, c ^ xform, code, at);
    uint target = uint(v >> 3u);
    child = dag_level(level - 1u).x + target;
    child_xform = xform ^ uint(v & 7ul);
    shift = ivec3(0);
}
#endif

#if defined(DAG_FORMAT_TSVDAG)
// Takes the low `bits` bits of e.
uint tsvdag_take(inout uint64_t e, uint bits) {
    uint x = uint(e & ((1ul << bits) - 1ul));
    e >>= bits;
    return x;
}

// TSVDAG child fetch (`TsvdagEncoding::decode_pointer` + `TreeView::children`): stored octant
// = xform^-1(c); the pointer value, through the table when it is an index, then the transform
// field or Huffman symbol, the translation, the target; child transform = xform ∘ pointer
// transform, translation seen through xform.
void dag_child(uint node, uint xform, uint aux, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    uint code;
    uint so = xform_stored_octant(xform, c);
    uint64_t v = dag_read_pointer(node, aux, so, code, at);
    uint cl = level - 1u;
    uvec2 level_record = dag_level(cl);
    uint64_t e = v;
    bool in_table = false;
    uint index = 0u;
#if defined(TSVDAG_LUT)
    bool tagged = ((g_dag_coding >> (8u + cl)) & 1u) != 0u;
    in_table = true;
    index = uint(v);
    if (code != 1u || tagged) {
        in_table = (v & 1ul) != 0ul;
        index = uint(v >> 1u);
        e = v >> 1u;
    }
#if !defined(TSVDAG_HUFFMAN)
    if (in_table) {
        e = packUint2x32(dag_info_pair(dag_level_tables(level_record.y) + 2u * index));
    }
#endif
#endif
    uint t = 0u;
    ivec3 tr = ivec3(0);
#if defined(TSVDAG_TRANSLATIONS)
    bool translates = cl <= 2u;
    uint tb = cl + 3u;
    int side = 4 << cl;
#endif
    uint target;
#if defined(TSVDAG_HUFFMAN)
    // One read of the tables: a tabled pointer's entry, stored decoded as [target, symbol |
    // the bits after the code << 16] (`predecoded_entry` in engine/render/format.rs), or the
    // canonical Huffman decode entry (symbol | length << 16, `huffman_decode_table`) of an
    // inline pointer's low bits, in the 1 << bits words before the pointer table (a level
    // with one implied symbol or none: one entry of length 0).
    uint tables = dag_level_tables(level_record.y);
    uint bits = level_record.y >> DAG_TABLE_BITS_SHIFT;
    uint w = in_table ? tables + 2u * index
                      : tables - (1u << bits) + (uint(e) & ((1u << bits) - 1u));
    uvec2 pair = dag_info_pair(w & ~1u);
    uint decoded = (w & 1u) != 0u ? pair.y : pair.x;
    uint sym = (in_table ? pair.y : decoded) & 0xffffu;
    e >>= in_table ? 0u : decoded >> 16u;
    t = sym >> 3u;
#if defined(TSVDAG_TRANSLATIONS)
    // The fields of the axes in the symbol's low 3 bits, x first, each tb bits (at most 15
    // bits in all: read from the low word with 32-bit shifts).
    uint fields = in_table ? pair.y >> 16u : uint(e);
    uint field_mask = (1u << tb) - 1u;
    uint off_y = (sym & 1u) * tb;
    uint off_z = off_y + ((sym >> 1u) & 1u) * tb;
    uint used = off_z + ((sym >> 2u) & 1u) * tb;
    ivec3 value = ivec3(fields & field_mask, (fields >> off_y) & field_mask,
                        (fields >> off_z) & field_mask) - side;
    tr = mix(ivec3(0), value, notEqual(uvec3(sym) & uvec3(1u, 2u, 4u), uvec3(0u)));
    e >>= used;
#endif
    target = in_table ? pair.x : uint(e);
#else
    uint set_word = g_dag_set;
    uint set = set_word & 3u;
#if defined(TSVDAG_TRANSLATIONS)
    bool flagged = set != 0u || translates;
#else
    bool flagged = set != 0u;
#endif
    if (flagged && tsvdag_take(e, 1u) == 1u) {
        uint field = tsvdag_take(e, set == 0u ? 0u : (set == 3u ? 6u : 3u));
        t = set == 2u ? field << 3u : field;
#if defined(TSVDAG_TRANSLATIONS)
        if (translates) {
            // Translation coding of child level cl: full (3 fields), escape (a zero first
            // field means none) or mask (3-bit mask of the fields present).
            bool compact = ((set_word >> 4u) & 1u) != 0u;
            bool mask_coding = compact && ((g_dag_coding >> cl) & 1u) != 0u;
            uint axes = 7u;
            if (mask_coding) {
                axes = tsvdag_take(e, 3u);
            } else if (compact) {
                uint x = tsvdag_take(e, tb);
                axes = x == 0u ? 0u : 6u;
                tr.x = int(x) - side;
                if (x == 0u) {
                    tr.x = 0;
                }
            }
            for (uint a = 0u; a < 3u; a++) {
                if (((axes >> a) & 1u) != 0u) {
                    tr[a] = int(tsvdag_take(e, tb)) - side;
                }
            }
        }
#endif
    }
    target = uint(e);
#endif
    child = level_record.x + target;
    child_xform = xform_compose(xform, t);
    shift = xform_translation(xform, tr);
}
#endif

#if defined(DAG_FORMAT_HASH)
#include "render/dag_hash.glsl"
#endif

#if !defined(DAG_ENCODED) && !defined(DAG_FORMAT_HASH)
// svdag32: word offsets, no transforms (xform is always 0).
void dag_root(uint root_level, out uint node, out uint xform) {
    node = 0u;
    xform = 0u;
}

void dag_child(uint node, uint xform, uint mask, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    at = node + 1u + uint(bitCount(mask & ((1u << c) - 1u)));
    child = dag_word(at);
    child_xform = 0u;
    shift = ivec3(0);
}

uint dag_inner_mask(uint node, uint xform, uint level) {
    return dag_word(node) & 0xffu;
}

#define DAG_HAS_LEAF_BITS 1
uvec2 dag_leaf_bits(uint ptr, uint xform) {
    return dag_word_pair(ptr);
}

uint dag_leaf_byte(uint ptr, uint xform, uint s) {
    return (dag_word(ptr + (s >> 2u)) >> (8u * (s & 3u))) & 0xffu;
}

// The child masks of (child, xform) at child_level: its world child mask (inner node) or its
// 64 voxel bits (leaf), from one load of two words either way.
#define DAG_HAS_CHILD_MASKS 1
void dag_child_masks(uint child, uint xform, uint child_level, out uint mask, out uvec2 leaf,
                     out uint aux) {
    leaf = dag_word_pair(child);
    mask = leaf.x & 0xffu;
    aux = mask;
}

// Voxels of the children before world octant c of the inner node at `node` (with mask): the
// count stored at the child's pointer word (`GpuDagData::svdag32`).
#define DAG_HAS_VOXELS_BEFORE 1
uint64_t dag_voxels_before(uint node, uint xform, uint mask, uint level, uint c) {
    return dag_node_voxels(node + 1u + uint(bitCount(mask & ((1u << c) - 1u))));
}
#endif

// Defaults for formats that do not provide the optional hooks.
#if !defined(DAG_HAS_BEGIN)
void dag_begin(uint root_level) {
}
#endif

#if !defined(DAG_HAS_AUX)
// Formats without an aux word: it is the world child mask (what `dag_child` takes).
uint dag_node_aux(uint node, uint xform, uint level) {
    return dag_inner_mask(node, xform, level);
}

uint dag_frame_mask(uint aux, uint xform) {
    return aux;
}
#endif

#if !defined(DAG_HAS_ROOT_FRAME)
// The root handle, its aux word and world child mask (formats whose root is known without a
// load: svdag32's word 0, the hash DAG's push constant).
void dag_root_frame(uint root_level, out uint node, out uint xform, out uint aux,
                    out uint mask) {
    dag_root(root_level, node, xform);
    aux = dag_node_aux(node, xform, root_level);
    mask = dag_frame_mask(aux, xform);
}
#endif

#if !defined(DAG_HAS_CHILD_MASKS)
void dag_child_masks(uint child, uint xform, uint child_level, out uint mask, out uvec2 leaf,
                     out uint aux) {
    leaf = uvec2(0u);
    mask = 0u;
    if (child_level == 0u) {
        leaf = dag_leaf_bits(child, xform);
    } else {
        mask = dag_inner_mask(child, xform, child_level);
    }
    aux = mask;
}
#endif

#if !defined(DAG_HAS_VOXELS_BEFORE)
// Voxels of the children before world octant c of the inner node (node, xform) with world mask
// `mask` at `level`: each preceding sibling's count.
uint64_t dag_voxels_before(uint node, uint xform, uint aux, uint level, uint c) {
    uint64_t sum = 0ul;
    uint before = dag_frame_mask(aux, xform) & ((1u << c) - 1u);
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (before != 0u) for (;;) {
        uint k = uint(findLSB(before));
        before &= before - 1u;
        uint sib;
        uint sib_xform;
        ivec3 sib_shift;
        uint at;
        dag_child(node, xform, aux, level, k, sib, sib_xform, sib_shift, at);
        sum += dag_child_count(sib, level - 1u, at, any(notEqual(sib_shift, ivec3(0))));
        if (before == 0u) break;
    }
    return sum;
}
#endif

#if !defined(DAG_HAS_LEAF_BITS)
uvec2 dag_leaf_bits(uint leaf, uint xform) {
    uvec2 bits = uvec2(0u);
    for (uint s = 0u; s < 8u; s++) {
        bits[s >> 2u] |= dag_leaf_byte(leaf, xform, s) << (8u * (s & 3u));
    }
    return bits;
}
#endif

#endif
