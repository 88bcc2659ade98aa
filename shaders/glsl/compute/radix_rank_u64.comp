#version 460
// Radix sort rank-and-scatter pass for 64-bit keys, small digits (see compute/radix_rank.glsl).
#define KEY64 1
#include "compute/radix_rank.glsl"
