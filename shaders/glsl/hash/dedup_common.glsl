// Shared by the dedup_*.comp passes: the duplicate-detection table of a temporary SVO
// (dissertation §4.4.2), driven by engine/hash/dedup.rs (which mirrors both layouts).
//
// Subgroup teams (TEAM > 1) use a slab table: slabs of 32 slots, stored structure-of-arrays so
// that a scan touches the tags only:
//   tags[32] | values[32] | keys[32][KEY_WORDS] | next
// tag: 0 empty, 1 being written, 2 ready (key published). value: bitwise NOT of the smallest
// value of the inputs with this key (atomicMax on a zeroed word = atomicMin without an init pass).
// next: slab index of the next slab of the bucket, 0 = none (slab 0 is bucket 0's first slab and is
// never anyone's successor). Slabs [0, buckets) are the buckets' first slabs; overflow slabs come
// from a bump pool after them: the table lives for one batch, so it is freed as a whole.
//
// Single lanes (TEAM == 1, CPU devices) use a probe table instead (see "Probe table" below):
// there a load at per-lane addresses is a loop over the lanes and a loop body runs in full on
// every iteration, so a scan of a slab's ~16 used slots with a key comparison in its body costs
// far more than the ~2 probes of open addressing with the hash in the tag.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "gen/hash.glsl"
#include "shared/murmur.glsl"
#include "shared/probe.glsl"

layout(local_size_x_id = 0) in;
layout(constant_id = 1) const uint KEY_WORDS = 1;
// Lanes working on one input: the subgroup size (workgroups of one subgroup), or 1 (every lane
// its own input, no subgroup operations or barriers: faster on CPU devices, see docs/hash.md).
layout(constant_id = 2) const uint TEAM = 1;

const uint SLOTS = 32;
const uint TAG_EMPTY = 0;
const uint TAG_WRITING = 1;
const uint TAG_READY = 2;
const uint VALUES_OFFSET = SLOTS;
const uint KEYS_OFFSET = 2 * SLOTS;
const uint NEXT_OFFSET = KEYS_OFFSET + SLOTS * KEY_WORDS;
const uint SLAB_WORDS = NEXT_OFFSET + 1;
const uint NO_SLAB = 0;

// counters[] of the push constants.
const uint COUNTER_POOL_USED = 0;
const uint COUNTER_ENTRIES = 1;
const uint COUNTER_OVERFLOW = 2;
// Bits of counters[COUNTER_OVERFLOW].
const uint OVERFLOW_POOL = 1;        // pass 1 ran out of pool slabs (the host grows, reruns)
const uint OVERFLOW_NO_ENTRY = 2;    // pass 2 found a key without an entry
const uint OVERFLOW_BROKEN_CHAIN = 4; // a chain longer than the table has slabs (a loop)


layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer Words {
    uint w[];
};

// Members: `DedupPush` in engine/hash/gpu_shared.rs.
layout(push_constant, std430) uniform Push { DEDUP_PUSH_MEMBERS } push;

Words slab_at(uint slab) {
    return Words(push.table + uint64_t(slab) * uint64_t(push.slab_words) * 4ul);
}

// Whether a walk that has followed `links` links to `slab` must stop: more links than the table
// has slabs (a loop), or a slab outside the table. Every chain walk is bounded by this check.
bool chain_broken(uint links, uint slab) {
    return links > push.buckets + push.pool_slabs || slab >= push.buckets + push.pool_slabs;
}

// Murmur3-style hash of the key words of input `i` (the same function as `dedup::hash_key`).
uint hash_key(Words keys, uint i) {
    uint h = 0x9e3779b9u ^ KEY_WORDS;
    for (uint j = 0; j < KEY_WORDS; ++j) {
        h = murmur_mix(h, keys.w[i * KEY_WORDS + j]);
    }
    return murmur_fmix32(h);
}

// One input per team at a time (shared/team.glsl). With TEAM > 1 every lane of the subgroup
// runs the same control flow (atomics are issued by one elected lane and their results
// broadcast), as in the hash table passes: divergent per-invocation atomics on the same slabs
// gave wrong results on lavapipe (Mesa 22.3) in the subgroup algorithm.
#include "shared/team.glsl"

// Whether `s` holds the key of input `i` (key words only; the caller checked the tag).
bool key_equals(Words slab, uint s, Words keys, uint i) {
    bool equal = true;
    for (uint j = 0; j < KEY_WORDS; ++j) {
        equal = equal && slab.w[KEYS_OFFSET + s * KEY_WORDS + j] == keys.w[i * KEY_WORDS + j];
    }
    return equal;
}

// Whether slot `s` of `slab` is ready and holds the key of input `i` (false for s >= 32).
// Called by the whole subgroup: the barrier stays out of divergent code (on lavapipe a
// memoryBarrierBuffer() there loses invocations, see docs/hash.md).
bool slot_has_key(Words slab, uint s, Words keys, uint i) {
    bool ready = s < SLOTS && slab.w[min(s, SLOTS - 1)] == TAG_READY;
    memoryBarrierBuffer(); // the key words were published before the tag
    return ready && key_equals(slab, s, keys, i);
}

// The lowest slot of `slab` holding the key of input `i`, or SLOTS when there is none.
// `racing`: other inputs may be writing keys into the slab (pass 1). A single lane has no barrier
// to order its tag and key reads (it would be in divergent code): it re-reads a ready tag with an
// atomic before trusting the key words, so the key it compares was published. (SPIR-V calls that
// atomic relaxed; lavapipe emits every atomic as a sequentially consistent read-modify-write,
// which orders the key loads after it. Single lanes are what `TeamMode::Auto` picks only there.)
uint find_key(Words slab, Words keys, uint i, bool racing) {
    if (TEAM == 1u) {
        // Claims take the lowest empty slot, so the used slots are a prefix: stop at an empty
        // tag. (In pass 1 a slot claimed after that read is missed: a duplicate, allowed.)
        for (uint s = 0; s < SLOTS; ++s) {
            uint tag = slab.w[s];
            if (tag == TAG_EMPTY) {
                break;
            }
            if (tag == TAG_READY && (!racing || atomicOr(slab.w[s], 0u) == TAG_READY)
                && key_equals(slab, s, keys, i)) {
                return s;
            }
        }
        return SLOTS;
    }
    for (uint chunk = 0; chunk < SLOTS; chunk += gl_SubgroupSize) {
        uvec4 hits = subgroupBallot(slot_has_key(slab, chunk + gl_SubgroupInvocationID, keys, i));
        if (subgroupBallotBitCount(hits) != 0) {
            return chunk + subgroupBallotFindLSB(hits);
        }
    }
    return SLOTS;
}

// ---- Probe table (single lanes) ----
// Open addressing with linear probing over `push.buckets` slots (a power of two, at least twice
// the inputs, so it never fills up):
//   tags[slots] | values[slots] | keys[slots][KEY_WORDS]
// tag: 0 empty, 1 being written, else the key's hash with bit 1 set (ready: key published). Only
// a slot whose tag equals the input's own is compared word by word, so a probe costs one load.
// values: as in the slab table. Only tags and values are zeroed. Slots are never emptied while a
// batch runs, so every input finds its key's first copy at or after its home slot before any
// empty slot: pass 1 inserts there when no ready copy is seen (a copy being written is skipped,
// making a second copy), pass 2 takes the first copy along the same probe sequence.

// Word of the probe table holding word `j` of the key in `slot`.
uint probe_key_word(uint slot, uint j) {
    return 2u * push.buckets + slot * KEY_WORDS + j;
}

// Whether `slot` holds the key of input `i` (the caller checked the tag).
bool probe_key_equals(Words table, uint slot, Words keys, uint i) {
    bool equal = true;
    for (uint j = 0; j < KEY_WORDS; ++j) {
        equal = equal && table.w[probe_key_word(slot, j)] == keys.w[i * KEY_WORDS + j];
    }
    return equal;
}

