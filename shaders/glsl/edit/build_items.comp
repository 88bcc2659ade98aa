#version 460
// Bottom-up, one invocation per temporary node or leaf of a level: its canonical form
// (engine/edit/item.rs). Nodes whose children are all one empty or full value become EDIT_EMPTY / EDIT_FULL | m in the results; the
// others append their item to the buffer of its size and leave EDIT_PENDING | size index.
//   src      temporary nodes (8 child values) or leaves (2 mask words, + 8 material words
//            with materials (edit_materials()): nibble v = material of voxel v); word
//            push.first of the input view
//   src2     the level below's results (EDIT_TEMP | i children read entry i; pending ones
//            are resolved here when the address buffer names the level below's, as in
//            resolve.comp, whose pass the recorded merge leaves out)
//   dst      results (one per node; at result_index[i] with EDIT_FLAG_RESULT_INDEX)
//   dst2     result_index (u32 per node)
//   tables   the level's buffer addresses (EDIT_LEVEL_* in edit/common.glsl)
//   counters 9 per-size item counts
//
// Shaped by lavapipe (docs/editing-gpu.md, "Speed, round 8" and "round 10"): every load or
// store through a buffer address is a loop over the SIMD lanes, run for every child slot
// whether or not a lane needs it, and an array indexed by a per-lane value is another such
// loop. So the reads go through word views (texel fetches, gathered for all lanes), the child
// loops are unrolled (constant indices), the addresses every node shares are read once per
// invocation, and an item's words go straight from registers to its size's buffer (no array
// of them).
#include "edit/common.glsl"
layout(local_size_x = 64) in;

// Whether the reads go through the word views below (1) or through addresses (0: a buffer has
// more words than a view takes; engine/edit/gpu/build_items.rs).
layout(constant_id = 2) const uint EDIT_SPEC_TEXELS = 1u;

// lavapipe fetches a texel for all SIMD lanes at once, where a load through a buffer address
// is a loop over them (docs/editing-gpu.md, "Speed, round 10"): the input (word push.first on
// is src's first), the level below's results (src2), and the slots, representatives and
// handles of the level whose pending results this pass resolves.
layout(set = 0, binding = 0) uniform usamplerBuffer input_texels;
layout(set = 0, binding = 1) uniform usamplerBuffer below_results_texels;
layout(set = 0, binding = 2) uniform usamplerBuffer below_slots_texels;
layout(set = 0, binding = 3) uniform usamplerBuffer below_reps_texels;
layout(set = 0, binding = 4) uniform usamplerBuffer below_handles_texels;

// A node's child values two at a time (one 64-bit load is one loop over the lanes, a uvec2 two).
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer WordPairs {
    uint64_t p[];
};

uint texel_word(usamplerBuffer t, uint i) {
    return texelFetch(t, int(i)).x;
}

// Word i of the input.
uint input_word(uint i) {
    if (EDIT_SPEC_TEXELS != 0u) return texel_word(input_texels, push.first + i);
    return Words(push.src).w[i];
}

// Words 2k and 2k + 1 of the input.
uvec2 input_pair(uint k) {
    if (EDIT_SPEC_TEXELS != 0u) return uvec2(input_word(2u * k), input_word(2u * k + 1u));
    return unpackUint2x32(WordPairs(push.src).p[k]);
}

// Entry j of the level below's results.
uint below_result(uint j) {
    if (EDIT_SPEC_TEXELS != 0u) return texel_word(below_results_texels, j);
    return Words(push.src2).w[j];
}

// The NodePtr of the level below's pending result r of node j (edit_resolve_slot through the
// views), or r where its item has no handle.
uint below_resolve(EditLevelHandles level, Words slots, uint j, uint r) {
    if (EDIT_SPEC_TEXELS == 0u) return edit_resolve_slot(level, slots.w[j], r);
    uint base = (r & 15u) * level.stride;
    uint rep = texel_word(below_reps_texels, base + texel_word(below_slots_texels, j));
    return edit_resolved(r, texel_word(below_handles_texels, base + rep));
}

#include "edit/build_items_pass.glsl"

void main() {
    edit_build_items_pass(gl_GlobalInvocationID.x, gl_NumWorkGroups.x * 64u);
}
