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
//                                     // the leaves (2 words each), pointer tables (2 words per
//                                     // entry) and node streams (u16 pairs), unchanged
//   uint64_t dag_node_voxels(uint i); // voxels below the node at word i (svdag32) or at u16
//                                     // stream index i (encoded; at a translated pointer's
//                                     // first u16: the voxels of the translated subtree)
//   uint dag_info(uint i);            // word i of the format info block (DAG_INFO_* below)
// A node handle is (node, xform): svdag32 a word offset and 0; encoded formats a u16 index in
// the streams (inner levels) or a leaf index (level 0), and the transform id (SSVDAG: the
// mirror bits, which are the transform ids 0..7) the stored node is seen through.
#ifndef VOXDAG_RENDER_DAG_FORMATS_GLSL
#define VOXDAG_RENDER_DAG_FORMATS_GLSL

// Word offsets in the info block (`format::info` in engine/render/format.rs).
#define DAG_INFO_ROOT_XFORM 0u
#define DAG_INFO_SET 1u
#define DAG_INFO_STREAM_BASE 2u
#define DAG_INFO_TABLE_BASE 3u
#define DAG_INFO_CODING 4u
#define DAG_INFO_LEVEL_START 8u
#define DAG_INFO_TABLE_START 32u
#define DAG_INFO_COMPOSE 56u
#define DAG_INFO_INVERSE 632u
#define DAG_INFO_OCTANT 644u
#define DAG_INFO_CHILD_MASK 692u
#define DAG_INFO_HUFF_KIND 3764u
#define DAG_INFO_HUFF_COUNT 3788u
#define DAG_INFO_HUFF_SYMBOLS 4172u

// Byte `i` of the info block starting at word `base`.
uint dag_info_byte(uint base, uint i) {
    return (dag_info(base + (i >> 2u)) >> (8u * (i & 3u))) & 0xffu;
}

// Transform group (engine/dag/transform.rs): `a ∘ b`, inverse, octant and child-mask action.
uint xform_compose(uint a, uint b) {
    return dag_info_byte(DAG_INFO_COMPOSE, a * 48u + b);
}

uint xform_inverse(uint t) {
    return dag_info_byte(DAG_INFO_INVERSE, t);
}

uint xform_octant(uint t, uint o) {
    return (dag_info(DAG_INFO_OCTANT + t) >> (3u * o)) & 7u;
}

uint xform_child_mask(uint t, uint mask) {
    return dag_info_byte(DAG_INFO_CHILD_MASK, t * 256u + mask);
}

// Output axis i of transform t reads input axis `xform_axis(t, i)` (`PERMUTATIONS`).
uint xform_axis(uint t, uint i) {
    // PERMUTATIONS = [0,1,2] [0,2,1] [1,0,2] [1,2,0] [2,0,1] [2,1,0], 2 bits per axis.
    const uint perms[6] = uint[6](0x24u, 0x18u, 0x21u, 0x09u, 0x12u, 0x06u);
    return (perms[t >> 3u] >> (2u * i)) & 3u;
}

// `T(Shift_t(X)) = Shift_t'(T(X))`: the translation seen through t (`transform_translation`).
ivec3 xform_translation(uint t, ivec3 tr) {
    ivec3 out_t;
    for (uint i = 0u; i < 3u; i++) {
        int v = tr[xform_axis(t, i)];
        out_t[i] = ((t >> i) & 1u) != 0u ? -v : v;
    }
    return out_t;
}

#if defined(DAG_FORMAT_SSVDAG) || defined(DAG_FORMAT_TSVDAG)
#define DAG_ENCODED 1

// u16 `g` of the node streams.
uint dag_u16(uint g) {
    return (dag_word(dag_info(DAG_INFO_STREAM_BASE) + (g >> 1u)) >> ((g & 1u) << 4u)) & 0xffffu;
}

// 8-bit stored child mask of a 2-bit-per-octant header.
uint dag_header_mask(uint h) {
    uint x = (h | (h >> 1u)) & 0x5555u;
    x = (x | (x >> 1u)) & 0x3333u;
    x = (x | (x >> 2u)) & 0x0f0fu;
    return (x | (x >> 4u)) & 0x00ffu;
}

// The pointer of stored octant `so` of the node at u16 `node`: its value, size code (1..3 u16)
// and the u16 index of its first word.
uint64_t dag_read_pointer(uint node, uint so, out uint code, out uint at) {
    uint h = dag_u16(node);
    uint below = h & ((1u << (2u * so)) - 1u);
    at = node + 1u + uint(bitCount(below & 0x5555u)) + 2u * uint(bitCount(below & 0xaaaau));
    code = (h >> (2u * so)) & 3u;
    uint64_t v = uint64_t(dag_u16(at));
    if (code >= 2u) {
        v |= uint64_t(dag_u16(at + 1u)) << 16u;
    }
    if (code == 3u) {
        v |= uint64_t(dag_u16(at + 2u)) << 32u;
    }
    return v;
}

// Leaf `i`'s two mask words.
uvec2 dag_leaf_words(uint i) {
    return uvec2(dag_word(2u * i), dag_word(2u * i + 1u));
}

uint dag_stored_byte(uvec2 m, uint s) {
    return (m[s >> 2u] >> (8u * (s & 3u))) & 0xffu;
}

// The world mask of the non-empty 2^3 sub-blocks of a leaf seen through xform.
uint dag_leaf_block_mask(uint leaf, uint xform) {
    uvec2 m = dag_leaf_words(leaf);
    uint mask = 0u;
    for (uint s = 0u; s < 8u; s++) {
        if (dag_stored_byte(m, s) != 0u) {
            mask |= 1u << s;
        }
    }
    return xform_child_mask(xform, mask);
}

// World sub-block c of a leaf seen through xform (its voxels in world order).
uint dag_leaf_byte(uint leaf, uint xform, uint c) {
    uvec2 m = dag_leaf_words(leaf);
    return xform_child_mask(xform, dag_stored_byte(m, xform_octant(xform_inverse(xform), c)));
}

// Voxels of the leaf before world Morton code `code` (sub-block << 3 | voxel).
uint dag_leaf_rank(uint leaf, uint xform, uint code) {
    uvec2 m = dag_leaf_words(leaf);
    uint inv = xform_inverse(xform);
    uint cb = code >> 3u;
    uint rank = 0u;
    for (uint c = 0u; c < cb; c++) {
        rank += uint(bitCount(dag_stored_byte(m, xform_octant(inv, c))));
    }
    uint world = xform_child_mask(xform, dag_stored_byte(m, xform_octant(inv, cb)));
    return rank + uint(bitCount(world & ((1u << (code & 7u)) - 1u)));
}

// World child mask of the inner node (node, xform) at level >= 1.
uint dag_inner_mask(uint node, uint xform, uint level) {
    return xform_child_mask(xform, dag_header_mask(dag_u16(node)));
}

// Voxels of the child at world octant c of an inner node whose children are at `child_level`.
uint64_t dag_child_count(uint child, uint child_level, uint pointer_at, bool shifted) {
    if (shifted) {
        return dag_node_voxels(pointer_at);
    }
    if (child_level == 0u) {
        uvec2 m = dag_leaf_words(child);
        return uint64_t(bitCount(m.x) + bitCount(m.y));
    }
    return dag_node_voxels(child);
}
#endif

#if defined(DAG_FORMAT_SSVDAG)
// The root handle: node 0 of the root level, identity.
void dag_root(uint root_level, out uint node, out uint xform) {
    node = dag_info(DAG_INFO_LEVEL_START + root_level);
    xform = 0u;
}

// The child at world octant c (set in the world mask) of the inner node (node, xform) at
// `level`: its handle, the translation of its subtree (world frame) and the u16 index of the
// pointer. SSVDAG: stored octant c ^ mirror, child mirror = mirror ^ pointer mirror.
void dag_child(uint node, uint xform, uint mask, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    uint code;
    uint64_t v = dag_read_pointer(node, c ^ xform, code, at);
    uint target = uint(v >> 3u);
    child = level == 1u ? target : dag_info(DAG_INFO_LEVEL_START + level - 1u) + target;
    child_xform = xform ^ uint(v & 7ul);
    shift = ivec3(0);
}
#endif

#if defined(DAG_FORMAT_TSVDAG)
void dag_root(uint root_level, out uint node, out uint xform) {
    node = dag_info(DAG_INFO_LEVEL_START + root_level);
    xform = dag_info(DAG_INFO_ROOT_XFORM);
}

#if defined(TSVDAG_HUFFMAN)
// Canonical Huffman decode (`Huffman::decode`) of the low bits of e with child level cl's code:
// the symbol and its length.
uint tsvdag_huffman(uint cl, uint64_t e, out uint len) {
    uint kind = dag_info(DAG_INFO_HUFF_KIND + cl);
    len = 0u;
    if ((kind & 0xffffu) == 1u) {
        return kind >> 16u;
    }
    uint bits = uint(e & 0x7ffful);
    uint code = 0u;
    uint first = 0u;
    uint index = 0u;
    for (uint l = 1u; l <= 15u; l++) {
        code |= (bits >> (l - 1u)) & 1u;
        uint n = dag_info(DAG_INFO_HUFF_COUNT + cl * 16u + l);
        if (code < first + n) {
            uint i = index + code - first;
            len = l;
            return (dag_info(DAG_INFO_HUFF_SYMBOLS + cl * 192u + (i >> 1u)) >> ((i & 1u) << 4u)) &
                   0xffffu;
        }
        index += n;
        first = (first + n) << 1u;
        code <<= 1u;
    }
    // Validated files never get here (every pointer decodes on load).
    return 0u;
}
#endif

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
void dag_child(uint node, uint xform, uint mask, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    uint code;
    uint so = xform == 0u ? c : xform_octant(xform_inverse(xform), c);
    uint64_t v = dag_read_pointer(node, so, code, at);
    uint cl = level - 1u;
    uint64_t e = v;
#if defined(TSVDAG_LUT)
    bool tagged = ((dag_info(DAG_INFO_CODING) >> (8u + cl)) & 1u) != 0u;
    bool in_table = true;
    uint64_t index = v;
    if (code != 1u || tagged) {
        in_table = (v & 1ul) != 0ul;
        index = v >> 1u;
        e = v >> 1u;
    }
    if (in_table) {
        uint w = dag_info(DAG_INFO_TABLE_BASE) + 2u * (dag_info(DAG_INFO_TABLE_START + cl) + uint(index));
        e = uint64_t(dag_word(w)) | (uint64_t(dag_word(w + 1u)) << 32u);
    }
#endif
    uint t = 0u;
    ivec3 tr = ivec3(0);
#if defined(TSVDAG_TRANSLATIONS)
    bool translates = cl <= 2u;
    uint tb = cl + 3u;
    int side = 4 << cl;
#endif
#if defined(TSVDAG_HUFFMAN)
    uint len;
    uint sym = tsvdag_huffman(cl, e, len);
    e >>= len;
    t = sym >> 3u;
#if defined(TSVDAG_TRANSLATIONS)
    for (uint a = 0u; a < 3u; a++) {
        if (((sym >> a) & 1u) != 0u) {
            tr[a] = int(tsvdag_take(e, tb)) - side;
        }
    }
#endif
#else
    uint set_word = dag_info(DAG_INFO_SET);
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
            bool mask_coding = compact && ((dag_info(DAG_INFO_CODING) >> cl) & 1u) != 0u;
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
#endif
    uint target = uint(e);
    child = cl == 0u ? target : dag_info(DAG_INFO_LEVEL_START + cl) + target;
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

uint dag_leaf_block_mask(uint ptr, uint xform) {
    uint lo = dag_word(ptr);
    uint hi = dag_word(ptr + 1u);
    uint mask = 0u;
    for (uint s = 0u; s < 4u; s++) {
        if (((lo >> (8u * s)) & 0xffu) != 0u) {
            mask |= 1u << s;
        }
        if (((hi >> (8u * s)) & 0xffu) != 0u) {
            mask |= 1u << (s + 4u);
        }
    }
    return mask;
}

uint dag_leaf_byte(uint ptr, uint xform, uint s) {
    return (dag_word(ptr + (s >> 2u)) >> (8u * (s & 3u))) & 0xffu;
}

uint dag_leaf_rank(uint ptr, uint xform, uint code) {
    uint lo = dag_word(ptr);
    if (code < 32u) {
        return uint(bitCount(lo & ((1u << code) - 1u)));
    }
    uint hi = dag_word(ptr + 1u);
    return uint(bitCount(lo)) + uint(bitCount(hi & ((1u << (code - 32u)) - 1u)));
}

uint64_t dag_child_count(uint child, uint child_level, uint pointer_at, bool shifted) {
    return dag_node_voxels(child);
}
#endif

#endif
