// Slab hash tables: memory layout shared word for word with engine/hash/layout.rs
// (docs/hash.md draws it). Needs GL_EXT_buffer_reference and 64-bit integer types.
#ifndef HASH_LAYOUT_H
#define HASH_LAYOUT_H

#define HASH_SLAB_SLOTS 32u
#define HASH_SLABS_PER_BLOCK 1024u
#define HASH_BLOCKS_PER_SUPER_BLOCK 16u
#define HASH_SLABS_PER_SUPER_BLOCK 16384u
#define HASH_BLOCK_BITMASK_WORDS 32u
// 16 block bitmasks at the start of every super block buffer (2 KiB), slabs follow.
#define HASH_SUPER_BLOCK_BITMASK_WORDS 512u

#define HASH_MISS 0xFFFFFFFFu
#define HASH_INVALID 0xFFFFFFFEu
// Returned by hash_alloc_slab when no free slab was found.
#define HASH_NO_SLAB 0xFFFFFFFFu

// Variant ids (specialization constant 2).
#define HASH_ATOMIC64 0u
#define HASH_TICKET_BOARD 1u
#define HASH_ACCEL32 2u
#define HASH_ACCEL8 3u

// Slab header words. A link is slab + 1; 0 ends the chain (zeroed memory = empty).
#define HASH_SLAB_NEXT 0u
#define HASH_SLAB_ACTIVE 1u     // owned by garbage collection; zero otherwise
#define HASH_SLAB_OCCUPANCY 2u  // Ticket Board and Acceleration Hash only

// HashPush::flags bits (FLAG_* in engine/hash/layout.rs).
#define HASH_FLAG_HOLES 1u      // GC may have punched holes: Atomic64 inserts scan whole slabs
#define HASH_FLAG_CLAIMS 2u     // insert only the representatives the claim table names

#define HASH_SEED 0x9747b28cu
#define HASH_SECONDARY_SALT 0x85ebca6bu

// Status block and push constants: members from `HashStatus` and `HashPush` in
// engine/hash/gpu_shared.rs (generated into gen/hash.glsl by build.rs).
#include "gen/hash.glsl"

layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer HashStatus {
    HASH_STATUS_MEMBERS
};

#endif
