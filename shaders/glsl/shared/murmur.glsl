// The murmur3-style word mix behind every hash of the GPU passes: the GLSL twin of
// `hash::layout::{murmur_words, fmix32}`. A hash of n words is
//   h = seed ^ n; for each word: h = murmur_mix(h, word); return murmur_fmix32(h);
#ifndef VOXDAG_SHARED_MURMUR_GLSL
#define VOXDAG_SHARED_MURMUR_GLSL

uint murmur_rotl(uint x, uint r) {
    return (x << r) | (x >> (32u - r));
}

// Mixes one word into the running hash.
uint murmur_mix(uint h, uint word) {
    uint k = murmur_rotl(word * 0xcc9e2d51u, 15u) * 0x1b873593u;
    return murmur_rotl(h ^ k, 13u) * 5u + 0xe6546b64u;
}

// The final avalanche (also used alone as a 32-bit integer hash).
uint murmur_fmix32(uint h) {
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h;
}

#endif
