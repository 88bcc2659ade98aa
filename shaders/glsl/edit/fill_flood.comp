#version 460
// Fill, one flood step along axis push.level: one invocation per row of the fill box along
// that axis. A free voxel next to a flooded one (6-neighbours) becomes flooded; a forward and
// a backward sweep carry the flood along the whole row in one pass. Rows count themselves in
// counters[0] when they changed: the host repeats the passes until a round changes nothing
// (then no voxel can change: the flood is complete and equals tool.rs `FillSet`).
//   src2     tool parameters (EDIT_P_*)
//   dst      free bitmap, dst2 flooded bitmap
#include "edit/common.glsl"
layout(local_size_x = 64) in;

bool flooded(uint i) {
    return edit_bit(push.dst2, i);
}

void main() {
    uvec3 dims = uvec3(edit_param(EDIT_P_DIMS), edit_param(EDIT_P_DIMS + 1u), edit_param(EDIT_P_DIMS + 2u));
    uvec3 strides = uvec3(1u, dims.x, dims.x * dims.y);
    uint a = push.level;
    uint b = (a + 1u) % 3u;
    uint c = (a + 2u) % 3u;
    uint n = dims[a];
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint r = gl_GlobalInvocationID.x;
    if (r < push.count) for (;;) {
        uint ub = r % dims[b];
        uint uc = r / dims[b];
        uint base = ub * strides[b] + uc * strides[c];
        bool changed = false;
        for (uint pass = 0u; pass < 2u; ++pass) {
            bool carry = false;
            for (uint k = 0u; k < n; ++k) {
                uint t = pass == 0u ? k : n - 1u - k;
                uint i = base + t * strides[a];
                bool f = flooded(i);
                if (!f && edit_bit(push.dst, i)) {
                    bool next_to = carry
                        || (ub > 0u && flooded(i - strides[b]))
                        || (ub + 1u < dims[b] && flooded(i + strides[b]))
                        || (uc > 0u && flooded(i - strides[c]))
                        || (uc + 1u < dims[c] && flooded(i + strides[c]));
                    if (next_to) {
                        atomicOr(Words(push.dst2).w[i >> 5u], 1u << (i & 31u));
                        f = true;
                        changed = true;
                    }
                }
                carry = f;
            }
        }
        if (changed) atomicAdd(Words(push.counters).w[0], 1u);
        r += stride;
        if (r >= push.count) break;
    }
}
