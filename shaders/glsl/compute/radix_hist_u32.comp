#version 460
// Radix sort hist pass for 32-bit keys (see compute/radix_hist.glsl).
#define KEY64 0
#include "compute/radix_hist.glsl"
