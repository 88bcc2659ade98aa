// Linear probing over a table whose first `slots` words are its tags (a power of two of them):
// 0 empty, 1 being written, any other value the ready tag of one key (its hash with bit 1 set).
// Shared by the dedup table's probe layout (hash/dedup_common.glsl) and the hash tables' claim
// table (hash/claims.glsl). Needs GL_EXT_buffer_reference and 64-bit integers.
#ifndef VOXDAG_SHARED_PROBE_GLSL
#define VOXDAG_SHARED_PROBE_GLSL

const uint PROBE_EMPTY = 0u;
const uint PROBE_WRITING = 1u;

// The ready tag of a key with hash `h` (never PROBE_EMPTY or PROBE_WRITING).
uint probe_ready_tag(uint h) {
    return h | 2u;
}

layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer ProbeTags {
    uint w[];
};

// From `slot` on, the first slot whose tag is empty or `ready` (the slots between hold other
// keys or copies being written); `probes` counts the slots passed and stops the walk at the
// table's size. A loop of one load per slot: the costly steps stay out of its body.
uint probe_skip(uint64_t table, uint slots, uint slot, uint ready, inout uint probes,
                out uint tag) {
    ProbeTags tags = ProbeTags(table);
    uint mask = slots - 1u;
    tag = tags.w[slot];
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (tag != PROBE_EMPTY && tag != ready && probes < slots) for (;;) {
        slot = (slot + 1u) & mask;
        probes += 1u;
        tag = tags.w[slot];
        if (tag == PROBE_EMPTY || tag == ready || probes >= slots) break;
    }
    return slot;
}

#endif
