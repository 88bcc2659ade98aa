#version 460
// Radix sort scatter pass for 64-bit keys (see compute/radix_scatter.glsl).
#define KEY64 1
#include "compute/radix_scatter.glsl"
