#version 460
// Slab hash search pass: handles[i] = handle of items[i], or HASH_MISS. One item per team (a
// subgroup, or one lane) at a time; every slab of the item's bucket scanned cooperatively (hash/slab.glsl).
// Driven by engine/hash/table.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/slab.glsl"

void main() {
    if (!team_size_ok()) {
        HashStatus(push.status).subgroup_mismatch = gl_SubgroupSize;
        return;
    }
    uint first = team_index();
    uint stride = team_count();
    HashWords handles = HashWords(push.handles);
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = first;
    if (i < push.count) for (;;) {
        uint item[HASH_MAX_ITEM_WORDS];
        hash_load_item(push.items, i, item);
        uint found = hash_item_valid(item) ? hash_search_chain(item, hash_item(item)) : HASH_MISS;
        if (team_leader()) {
            handles.w[i] = found;
        }
        i += stride;
        if (i >= push.count) break;
    }
}
