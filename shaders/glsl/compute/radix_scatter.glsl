// Radix sort pass 3: workgroup t sorts its tile by the digit in shared memory, stably, with one
// split per digit bit (each a workgroup exclusive sum, so any subgroup size works), then writes
// each element to offsets[digit * tiles + t] + its rank among equal digits in the tile.
// Positions past the end get the largest key: they sort last (stably after real maxima) and are
// not written. Include after defining KEY64.
#include "compute/radix.glsl"

shared KEY_T tile_keys[BLOCK];
shared uint tile_values[BLOCK];
shared uint digit_start[BINS];
shared uint digit_offset[BINS];

void main() {
    uint tile = workgroup_linear();
    uint tiles = tile_count();
    if (tile >= tiles) {
        return;
    }
    uint t = gl_LocalInvocationID.x;
    uint base = tile * BLOCK;
    uint valid = min(BLOCK, push.n - base);
    KEYS_T keys_in = KEYS_T(push.keys_in);
    U32s values_in = U32s(push.values_in);
    KEY_T k[ITEMS];
    uint v[ITEMS];
    // Invocation t holds tile positions t*ITEMS .. t*ITEMS+ITEMS-1 (the order the scan uses).
    for (uint j = 0u; j < ITEMS; j++) {
        uint p = t * ITEMS + j;
        if (p < valid) {
            k[j] = keys_in.v[base + p];
            v[j] = values_in.v[base + p];
        } else {
            k[j] = KEY_MAX;
            v[j] = 0u;
        }
    }
    for (uint b = 0u; b < BITS; b++) {
        uint sh = push.shift + b;
        uint zeros = 0u;
        for (uint j = 0u; j < ITEMS; j++) {
            zeros += 1u - (uint(k[j] >> sh) & 1u);
        }
        uint total_zeros;
        uint z = wg_exclusive_add(zeros, total_zeros);
        for (uint j = 0u; j < ITEMS; j++) {
            uint p = t * ITEMS + j;
            uint one = uint(k[j] >> sh) & 1u;
            // Zeros keep their order at the front, ones after them (p - z ones precede p).
            uint dst = one == 0u ? z : total_zeros + p - z;
            z += 1u - one;
            tile_keys[dst] = k[j];
            tile_values[dst] = v[j];
        }
        barrier();
        for (uint j = 0u; j < ITEMS; j++) {
            k[j] = tile_keys[t * ITEMS + j];
            v[j] = tile_values[t * ITEMS + j];
        }
        barrier();
    }
    // The tile is sorted by digit: find where each digit starts, and fetch its global offset.
    U32s offsets = U32s(push.offsets);
    for (uint d = t; d < BINS; d += gl_WorkGroupSize.x) {
        digit_offset[d] = offsets.v[d * tiles + tile];
    }
    for (uint j = 0u; j < ITEMS; j++) {
        uint p = t * ITEMS + j;
        if (p < valid) {
            uint d = digit_of(k[j]);
            if (p == 0u || digit_of(tile_keys[p - 1u]) != d) {
                digit_start[d] = p;
            }
        }
    }
    barrier();
    KEYS_T keys_out = KEYS_T(push.keys_out);
    U32s values_out = U32s(push.values_out);
    // Neighbouring invocations write neighbouring positions (coalesced).
    for (uint j = 0u; j < ITEMS; j++) {
        uint p = j * gl_WorkGroupSize.x + t;
        if (p < valid) {
            KEY_T key = tile_keys[p];
            uint d = digit_of(key);
            uint dst = digit_offset[d] + p - digit_start[d];
            keys_out.v[dst] = key;
            values_out.v[dst] = tile_values[p];
        }
    }
}
