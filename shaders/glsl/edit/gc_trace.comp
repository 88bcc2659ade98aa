#version 460
// GC of the hash DAG, mark (dissertation §4.4.3), one level top-down: every node of the
// frontier sets the GC bit of each child it points to in the child's slab `active` word (the
// word the tables' sweep reads, engine/hash/gc.rs); a child whose bit was clear is new and
// joins the next level's frontier, so every reachable item is expanded once.
//   src = frontier (NodePtrs), count = its length, dst = next frontier (capacity entries),
//   dst2 = slabs in each table's pool (9 u32), tables = the nine super-block tables,
//   counters: [0] next frontier length, [1] pointers naming no allocated slab. (The items kept
//   per table are the sweep's count: a count per mark here, even in shared memory, took ~10 %
//   of the trace on lavapipe.)
//   EDIT_FLAG_GC_ROOTS: the frontier items are marked too (the live roots, distinct).
//   EDIT_FLAG_GC_LAST: the children are leaves; they are marked, not listed.
#include "edit/common.glsl"
layout(local_size_x = 64) in;

#define EDIT_FLAG_GC_ROOTS 16u
#define EDIT_FLAG_GC_LAST 32u

// Per workgroup: pointers naming no allocated slab, added to the global counter once at the end
// (per item, two threads' atomics on the one counter line made the trace bound by that line's
// ping-pong: docs/editing-gpu.md, "GC trace counters").
shared uint group_bad;

// Sets the GC bit of the item `ptr` names; true when it was clear. A pointer naming no
// allocated slab of its table is counted and not marked (a bit in a free slab would break the
// allocator's all-zero invariant).
bool gc_mark(uint ptr) {
    uint table = ptr >> 28u;
    uint handle = ptr & EDIT_INDEX_MASK;
    uint slab = handle >> 5u;
    if (table >= 9u || slab >= Words(push.dst2).w[table]) {
        atomicAdd(group_bad, 1u);
        return false;
    }
    uint64_t base = Addresses(Addresses(push.tables).a[table]).a[slab / HASH_SLABS_PER_SUPER_BLOCK];
    uint local = slab % HASH_SLABS_PER_SUPER_BLOCK;
    if (((Words(base).w[local / 32u] >> (local % 32u)) & 1u) == 0u) {
        atomicAdd(group_bad, 1u);
        return false;
    }
    uint64_t at = base + uint64_t(HASH_SUPER_BLOCK_BITMASK_WORDS * 4u)
                + uint64_t(local) * uint64_t(edit_slab_words(table + 2u) * 4u);
    uint bit = 1u << (handle & 31u);
    uint old = atomicOr(Words(at).w[HASH_SLAB_ACTIVE], bit);
    return (old & bit) == 0u;
}

void main() {
    Words frontier = Words(push.src);
    Words next = Words(push.dst);
    Words counters = Words(push.counters);
    if (gl_LocalInvocationIndex == 0u) group_bad = 0u;
    barrier();
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uint ptr = frontier.w[i];
        // Roots are distinct and the bits clear between collections: a false here is a bad root.
        if ((push.flags & EDIT_FLAG_GC_ROOTS) == 0u || gc_mark(ptr)) {
            uint children[8];
            edit_children(ptr, children);
            // The children this node marked first join the next frontier, in one append.
            uint fresh = 0u;
            [[unroll]] for (uint o = 0u; o < 8u; ++o) {
                uint c = children[o];
                if (edit_is_ptr(c) && gc_mark(c)) fresh |= 1u << o;
            }
            if ((push.flags & EDIT_FLAG_GC_LAST) == 0u && fresh != 0u) {
                uint at = atomicAdd(counters.w[0], uint(bitCount(fresh)));
                [[unroll]] for (uint o = 0u; o < 8u; ++o) {
                    if (((fresh >> o) & 1u) != 0u) {
                        if (at < push.capacity) next.w[at] = children[o];
                        at += 1u;
                    }
                }
            }
        }
        i += stride;
        if (i >= push.count) break;
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u && group_bad != 0u) {
        atomicAdd(counters.w[1], group_bad);
    }
}
