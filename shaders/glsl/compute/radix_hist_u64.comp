#version 460
// Radix sort hist pass for 64-bit keys (see compute/radix_hist.glsl).
#define KEY64 1
#include "compute/radix_hist.glsl"
