// Radix sort pass 1: workgroup t counts the digits of its tile into hist[digit * tiles + t]
// (shared atomics). Include after defining KEY64.
#include "compute/radix.glsl"

shared uint tile_hist[BINS];

void main() {
    uint tile = workgroup_linear();
    uint tiles = tile_count();
    if (tile >= tiles) {
        return;
    }
    uint t = gl_LocalInvocationID.x;
    for (uint d = t; d < BINS; d += gl_WorkGroupSize.x) {
        tile_hist[d] = 0u;
    }
    barrier();
    KEYS_T keys = KEYS_T(push.keys_in);
    uint base = tile * BLOCK;
    for (uint j = 0u; j < ITEMS; j++) {
        uint i = base + j * gl_WorkGroupSize.x + t;
        if (i < push.n) {
            atomicAdd(tile_hist[digit_of(keys.v[i])], 1u);
        }
    }
    barrier();
    U32s hist = U32s(push.offsets);
    for (uint d = t; d < BINS; d += gl_WorkGroupSize.x) {
        hist.v[d * tiles + tile] = tile_hist[d];
    }
}
