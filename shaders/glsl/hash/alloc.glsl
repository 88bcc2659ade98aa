// GPU slab allocator (SlabAlloc style): memory blocks of 1024 slabs with a 1024-bit bitmask,
// 16 blocks per super block, each super block its own buffer. Called by ONE invocation (e.g.
// inside subgroupElect()); uses no subgroup operations. Include after hash/common.glsl.
// Invariant: a free slab is all zeros; whoever frees a slab has zeroed it first.

// Random blocks tried before a linear sweep over the whole pool.
#define HASH_ALLOC_RANDOM_ATTEMPTS 8u

// Claims a free slab in one block; HASH_NO_SLAB when the block is full.
uint hash_alloc_in_block(uint64_t super_blocks, uint block, uint start_word) {
    uint sb = block / HASH_BLOCKS_PER_SUPER_BLOCK;
    uint b = block % HASH_BLOCKS_PER_SUPER_BLOCK;
    HashWords mask = HashWords(hash_super_block(super_blocks, sb)
                               + uint64_t(b * HASH_BLOCK_BITMASK_WORDS * 4u));
    for (uint i = 0u; i < HASH_BLOCK_BITMASK_WORDS; ++i) {
        uint wi = (start_word + i) % HASH_BLOCK_BITMASK_WORDS;
        uint m = mask.w[wi];
        while (m != 0xFFFFFFFFu) {
            uint bit = 1u << uint(findLSB(~m));
            uint old = atomicOr(mask.w[wi], bit);
            if ((old & bit) == 0u) {
                return sb * HASH_SLABS_PER_SUPER_BLOCK + b * HASH_SLABS_PER_BLOCK + wi * 32u
                     + uint(findLSB(bit));
            }
            m = old | bit;
        }
    }
    return HASH_NO_SLAB;
}

// Claims a free slab: random blocks first (hash of `rng`, which the caller derives from its
// invocation and attempt, spreads contention), then a sweep of every block. HASH_NO_SLAB means
// the pool was full when swept: the caller reports exhaustion.
uint hash_alloc_slab(uint64_t super_blocks, uint64_t status, uint blocks, uint rng) {
    // The counter never exceeds the slabs claimed, and only GC frees one: once it says every
    // slab is taken the pool stays full for the pass, so an item fails at once instead of
    // sweeping every block's bitmask (an exhausted insert of 58 K items took 300 ms that way).
    if (hash_allocated_slabs(status, false) >= blocks * HASH_SLABS_PER_BLOCK) {
        return HASH_NO_SLAB;
    }
    uint slab = HASH_NO_SLAB;
    for (uint a = 0u; a < HASH_ALLOC_RANDOM_ATTEMPTS && slab == HASH_NO_SLAB; ++a) {
        uint r = murmur_fmix32(rng + a * 0x9e3779b9u);
        slab = hash_alloc_in_block(super_blocks, r % blocks, r >> 27);
    }
    uint start = murmur_fmix32(rng ^ 0x68e31da4u) % blocks;
    for (uint i = 0u; i < blocks && slab == HASH_NO_SLAB; ++i) {
        slab = hash_alloc_in_block(super_blocks, (start + i) % blocks, 0u);
    }
    if (slab != HASH_NO_SLAB) {
        // Counted before the caller links it: chain walks bound themselves by this counter.
        // (No memoryBarrierBuffer() here: on lavapipe a barrier in divergent code loses lanes.)
        atomicAdd(HashStatus(status).allocated_slabs, 1u);
    }
    return slab;
}

// Returns a slab to the pool. The slab must be all zeros and linked from nowhere.
void hash_free_slab(uint64_t super_blocks, uint64_t status, uint slab) {
    uint sb = slab / HASH_SLABS_PER_SUPER_BLOCK;
    uint local = slab % HASH_SLABS_PER_SUPER_BLOCK;
    HashWords mask = HashWords(hash_super_block(super_blocks, sb));
    atomicAnd(mask.w[local / 32u], ~(1u << (local % 32u)));
    atomicAdd(HashStatus(status).allocated_slabs, 0xFFFFFFFFu);
}
