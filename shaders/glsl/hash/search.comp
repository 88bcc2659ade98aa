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

layout(push_constant, std430) uniform Push { HASH_PUSH_MEMBERS } push;

void main() {
    if (!team_size_ok()) {
        HashStatus(push.status).subgroup_mismatch = gl_SubgroupSize;
        return;
    }
    uint first = team_index();
    uint stride = team_count();
    HashWords heads = HashWords(push.heads);
    HashWords handles = HashWords(push.handles);
    for (uint i = first; i < push.count; i += stride) {
        uint item[HASH_MAX_ITEM_WORDS];
        hash_load_item(push.items, i, item);
        uint found = HASH_MISS;
        if (hash_item_valid(item)) {
            uint h = hash_item(item);
            uint sec = hash_secondary_stored_form(h);
            uint link = heads.w[h % push.buckets];
            // No insert runs meanwhile: the counter is exact.
            uint max_links = hash_allocated_slabs(push.status, false);
            for (uint links = 0u; link != 0u && found == HASH_MISS; ++links) {
                if (links == max_links || hash_link_outside(link, push.blocks)) {
                    if (team_leader()) hash_report_broken_chain(push.status);
                    break;
                }
                uint64_t addr = hash_slab_address(push.super_blocks, link - 1u);
                found = hash_find_in_slab(addr, link - 1u, item, sec);
                link = HashWords(addr).w[HASH_SLAB_NEXT];
            }
        }
        if (team_leader()) {
            handles.w[i] = found;
        }
    }
}
