#version 460
// Radix sort scatter pass for 32-bit keys (see compute/radix_scatter.glsl).
#define KEY64 0
#include "compute/radix_scatter.glsl"
