// Radix sort pass 3, counting variant for small digits (4 bits; the Rust side uses it then):
// instead of sorting the tile in shared memory, every invocation counts the digits of its
// ITEMS consecutive keys into its own column of `rank_counts` ([digit * WG + invocation]); one
// workgroup exclusive sum over that digit-major table gives each (digit, invocation) the tile
// rank of its first key, so each key goes straight to offsets[digit * tiles + t] + its rank
// among equal digits in the tile. Stable: ranks follow tile positions. One workgroup scan per
// pass instead of one per digit bit. Include after defining KEY64.
#include "compute/radix.glsl"

shared uint rank_counts[BINS * gl_WorkGroupSize.x];
shared uint digit_start[BINS];
shared uint digit_offset[BINS];

void main() {
    uint tile = workgroup_linear();
    uint tiles = tile_count();
    if (tile >= tiles) {
        return;
    }
    uint t = gl_LocalInvocationID.x;
    uint wg = gl_WorkGroupSize.x;
    uint base = tile * BLOCK;
    uint valid = min(BLOCK, push.n - base);
    // Until the scan, an invocation touches only its own column: no barrier needed.
    for (uint d = 0u; d < BINS; d++) {
        rank_counts[d * wg + t] = 0u;
    }
    KEYS_T keys_in = KEYS_T(push.keys_in);
    for (uint j = 0u; j < ITEMS; j++) {
        uint p = t * ITEMS + j;
        if (p < valid) {
            rank_counts[digit_of(keys_in.v[base + p]) * wg + t] += 1u;
        }
    }
    barrier();
    // Invocation t scans entries t*BINS .. t*BINS+BINS-1 of the digit-major table (its own
    // entries only, so reads and writes never race).
    uint sum = 0u;
    for (uint i = 0u; i < BINS; i++) {
        sum += rank_counts[t * BINS + i];
    }
    uint total;
    uint running = wg_exclusive_add(sum, total);
    for (uint i = 0u; i < BINS; i++) {
        uint x = rank_counts[t * BINS + i];
        rank_counts[t * BINS + i] = running;
        running += x;
    }
    barrier();
    U32s offsets = U32s(push.offsets);
    for (uint d = t; d < BINS; d += wg) {
        digit_start[d] = rank_counts[d * wg];
        digit_offset[d] = offsets.v[d * tiles + tile];
    }
    barrier();
    U32s values_in = U32s(push.values_in);
    KEYS_T keys_out = KEYS_T(push.keys_out);
    U32s values_out = U32s(push.values_out);
    for (uint j = 0u; j < ITEMS; j++) {
        uint p = t * ITEMS + j;
        if (p < valid) {
            KEY_T key = keys_in.v[base + p];
            uint d = digit_of(key);
            uint rank = rank_counts[d * wg + t];
            rank_counts[d * wg + t] = rank + 1u;
            uint dst = digit_offset[d] + rank - digit_start[d];
            keys_out.v[dst] = key;
            values_out.v[dst] = values_in.v[base + p];
        }
    }
}
