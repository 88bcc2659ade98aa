#version 460
// Radix sort rank-and-scatter pass for 32-bit keys, small digits (see compute/radix_rank.glsl).
#define KEY64 0
#include "compute/radix_rank.glsl"
